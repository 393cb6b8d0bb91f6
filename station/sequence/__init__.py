"""The calibration sequence: steps, the concurrent runner, its records, limits and the demo.

- :mod:`station.sequence.steps`: the plan as plain functions receiving their hardware.
- :mod:`station.sequence.runner`: :class:`SequenceRunner` / :func:`run_sequence` for N units on one rig.
- :mod:`station.sequence.records`: what a run emits (RunStarted ... RunFinished, :class:`Outcome`).
- :mod:`station.sequence.limits`: product limits (Table 1 ranges by default).
- :mod:`station.sequence.demo`: :func:`run_demo`, the one-command simulated station.
"""

from station.sequence.options import SequenceOptions, rig_client_options
from station.sequence.records import (
    Measurement,
    Outcome,
    Record,
    RigReading,
    RunFinished,
    RunStarted,
    StepFinished,
    StepStarted,
    UnitFinished,
)
from station.sequence.runner import Provisioner, RunResult, SequenceRunner, UnitResult, run_sequence

__all__ = [
    "Measurement",
    "Outcome",
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
    "rig_client_options",
    "run_sequence",
]
