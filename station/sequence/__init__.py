"""The calibration sequence: steps, the concurrent runner, its records, limits, provisioning and verification.

- :mod:`station.sequence.steps`: the plan as plain functions receiving their hardware.
- :mod:`station.sequence.runner`: :class:`SequenceRunner` for N units on one rig.
- :mod:`station.sequence.prompts`: the prompts to the operator (load, close the lid, unload, confirm).
- :mod:`station.sequence.records`: what a run emits (RunStarted ... RunFinished, :class:`Outcome`).
- :mod:`station.sequence.limits`: product limits (Table 1 ranges by default).
- :mod:`station.sequence.provision`, :mod:`station.sequence.verify`: writing the image and verifying it on the rig.
"""

from station.sequence.options import SequenceOptions
from station.sequence.records import (
    Measured,
    Outcome,
    PromptAnswered,
    PromptShown,
    Record,
    RigReading,
    RunFinished,
    RunStarted,
    StepFinished,
    StepStarted,
    UnitFinished,
)
from station.sequence.runner import Provisioner, RunResult, SequenceRunner, UnitResult

__all__ = [
    "Measured",
    "Outcome",
    "PromptAnswered",
    "PromptShown",
    "Provisioner",
    "Record",
    "RigReading",
    "RunFinished",
    "RunResult",
    "RunStarted",
    "SequenceOptions",
    "SequenceRunner",
    "StepFinished",
    "StepStarted",
    "UnitFinished",
    "UnitResult",
]
