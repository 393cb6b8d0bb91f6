"""Immutable records a sequence run emits to its subscribers.

A run emits, in order: one :class:`RunStarted`; per step a :class:`StepStarted`,
the step's :class:`Measured` records (one per unit and quality gate) and a
:class:`StepFinished`; after the fit the limit :class:`Measured` records; one
:class:`UnitFinished` per fixture slot; and one :class:`RunFinished`. Every record
carries the ``run_id``. Times ``t_s`` are station clock seconds (rig seconds);
``at`` is the wall-clock time (UTC, ISO 8601) for people and databases.

Outcomes: PASS (the unit is within limits), FAIL (the unit is out of limits or a
measurement gate showed it defective), ERROR (the station failed: rig timeout or
fault, serial link fault, lost samples) and ABORTED (the operator stopped the run).
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from enum import Enum

from station.kernel.measurement import Measurement


class Outcome(Enum):
    """Result of a unit or a run; severity PASS < RETEST < FAIL < REFUSED < ERROR < ABORTED.

    PASS: calibrated, within limits, written and verified. RETEST: a limit verdict was inconclusive
    (its uncertainty interval straddles the limit) and the limits file maps that to a retest; it
    does not count as a failed attempt. FAIL: the unit is out of limits (counts as an attempt).
    REFUSED: the retest policy refused the unit before anything moved (over its attempts, or
    scrapped). ERROR: a station fault. ABORTED: the operator or a signal stopped the run.
    """

    PASS = "PASS"
    RETEST = "RETEST"
    FAIL = "FAIL"
    REFUSED = "REFUSED"
    ERROR = "ERROR"
    ABORTED = "ABORTED"

    @property
    def severity(self) -> int:
        return _SEVERITY[self]

    @property
    def exit_code(self) -> int:
        """The command's exit code for a run with this outcome."""
        return _EXIT[self]


_SEVERITY = {o: k for k, o in enumerate(Outcome)}
_EXIT = {Outcome.PASS: 0, Outcome.FAIL: 1, Outcome.ERROR: 2, Outcome.REFUSED: 3, Outcome.RETEST: 4,
         Outcome.ABORTED: 130}


def worst(outcomes: Iterable[Outcome]) -> Outcome:
    """The most severe of ``outcomes`` (PASS for none)."""
    return max(outcomes, key=lambda o: o.severity, default=Outcome.PASS)


@dataclass(frozen=True)
class RunStarted:
    """A run began.

    Attributes:
        run_id: unique id of the run.
        at: wall-clock start (UTC, ISO 8601).
        t_s: station clock time (s).
        station: station name.
        rig: rig description (URL or firmware id).
        sensors: sensor URLs, one per fixture slot.
        steps: names of the planned steps, in order.
        holds_s: each step's planned capture time (s), in order (empty: not told); the time remaining
            is estimated from them.
    """

    run_id: str
    at: str
    t_s: float
    station: str
    rig: str
    sensors: tuple[str, ...]
    steps: tuple[str, ...]
    holds_s: tuple[float, ...] = ()


@dataclass(frozen=True)
class StepStarted:
    """A step began (before the rig moves for it).

    Attributes:
        index: 0-based step number; name: e.g. ``'rest'``, ``'pose -z'``, ``'rate x +50'``;
        kind: ``'rest'``, ``'pose'`` or ``'rate'``; t_s: station clock (s);
        hold_s: planned capture duration (s).
    """

    run_id: str
    index: int
    name: str
    kind: str
    t_s: float
    hold_s: float


@dataclass(frozen=True)
class StepFinished:
    """A step ended.

    Attributes:
        ok: the rig did its part and every unit still active passed the step's gates.
        duration_s: station clock time the step took, rig motion included (s).
        units_active: units still being measured after this step.
        message: why not ok ('' if ok).
    """

    run_id: str
    index: int
    name: str
    t_s: float
    duration_s: float
    ok: bool
    units_active: int
    message: str = ""


@dataclass(frozen=True)
class Measured:
    """A unit's :class:`~station.kernel.measurement.Measurement` in a step (a capture gate, a limit check).

    Attributes:
        slot: fixture slot; serial: the unit's serial number ('' if unknown yet).
        step: the step name, ``'limits'`` for the product limits after the fit, ``'verify'`` for the
            on-rig verification of the corrected output.
        measurement: what was measured, its limits and verdict, unchanged.
    """

    run_id: str
    slot: int
    serial: str
    step: str
    measurement: Measurement


@dataclass(frozen=True)
class UnitFinished:
    """A unit's result.

    Attributes:
        outcome: see :class:`Outcome`.
        message: the reason for anything but PASS ('' for PASS).
        session_path: the saved session recording, or None.
        params_path: the saved parameter set (JSON), or None.
    """

    run_id: str
    slot: int
    serial: str
    outcome: Outcome
    message: str
    session_path: str | None = None
    params_path: str | None = None


@dataclass(frozen=True)
class RunFinished:
    """The run ended (teardown done).

    Attributes:
        outcome: the most severe unit outcome (ABORTED/ERROR also when no unit got that far).
        t_s: station clock (s); duration_s: station clock time of the whole run (s).
        wall_s: wall-clock duration (s).
        units: every slot's result.
        message: why the run as a whole did not complete ('' otherwise).
        rig_at_rest: the rig confirmed rest during teardown.
    """

    run_id: str
    outcome: Outcome
    t_s: float
    duration_s: float
    wall_s: float
    units: tuple[UnitFinished, ...]
    message: str = ""
    rig_at_rest: bool = True


@dataclass(frozen=True)
class RigReading:
    """What the rig reported while the run waited on it (throttled; for live displays, not stored).

    Attributes:
        t_s: station clock time (s); roll_deg, pitch_deg, yaw_deg: measured angles (deg);
        rate_dps: measured table rate (deg/s); status: the status flags, e.g. 'MOVING|REMOTE';
        fault_code: latched fault code (0 = none).
    """

    run_id: str
    t_s: float
    roll_deg: float
    pitch_deg: float
    yaw_deg: float
    rate_dps: float
    status: str
    fault_code: int


@dataclass(frozen=True)
class PromptShown:
    """The station asks its operator to do something and waits (see :mod:`station.sequence.prompts`).

    Attributes:
        prompt_id: unique within the run (``'<run_id>/p<N>'``).
        kind: ``'load'``, ``'close-lid'``, ``'unload'`` or ``'confirm'``.
        text: what the operator reads; nests: the nests concerned (numbered from 1; empty: the fixture).
        timeout_s: how long the station waits for the answer (wall-clock s).
    """

    run_id: str
    prompt_id: str
    kind: str
    text: str
    nests: tuple[int, ...]
    timeout_s: float


@dataclass(frozen=True)
class PromptAnswered:
    """The prompt ``prompt_id`` was answered ``'confirmed'`` or ``'cancelled'``, or timed out (``'timeout'``);
    ``by``: who answered ('' if unknown); ``waited_s``: wall-clock seconds it waited."""

    run_id: str
    prompt_id: str
    answer: str
    by: str
    waited_s: float


Record = (RunStarted | StepStarted | StepFinished | Measured | UnitFinished | RunFinished | RigReading | PromptShown
          | PromptAnswered)
