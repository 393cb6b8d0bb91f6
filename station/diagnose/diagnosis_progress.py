"""Progress of a diagnosis: the stages :func:`station.diagnose.report.diagnose` runs, told to a callback.

The diagnosis does no I/O: a caller that wants to show progress (the CLI on a long recording) passes a
:class:`Progress` callable, which receives one :class:`Stage` when each stage starts and a last one when
the diagnosis is done. The ``index`` of the calls rises by one each time, from 0 to ``total`` (a rig-free
recording's diagnosis, :mod:`station.diagnose.rigfree_diagnosis`, tells only 0 and ``total``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

#: The stages of a diagnosis, in order.
STAGES: tuple[str, ...] = ("base fit", "candidate selection", "simulator re-run", "calibration check")
DONE = "done"


@dataclass(frozen=True)
class Stage:
    """One step of a diagnosis.

    Attributes:
        index: 0-based stage number; ``total`` when the diagnosis is done.
        total: number of stages (``len(STAGES)``).
        name: the stage (one of :data:`STAGES`, or :data:`DONE`).
        elapsed_s: wall time since the diagnosis started (s).
        samples: samples in the recording.
    """

    index: int
    total: int
    name: str
    elapsed_s: float
    samples: int

    @property
    def done(self) -> bool:
        return self.index >= self.total


class Progress(Protocol):
    """A callback for the stages of a diagnosis (must not raise; called in the diagnosing thread)."""

    def __call__(self, stage: Stage, /) -> None: ...


__all__ = ["DONE", "STAGES", "Progress", "Stage"]
