"""Run the calibration sequence for the N units of a fixture on one rig.

:class:`SequenceRunner` runs the steps of :mod:`station.sequence.steps` (power-on
rest, six gravity poses, rate steps about each axis) for every unit concurrently,
emits :mod:`~station.sequence.records` to its subscribers, and afterwards builds
each unit's :class:`~station.session.model.Session` from the captured frames,
fits it (:func:`station.fit.calibrate.fit_session`), checks the product limits
(:mod:`station.sequence.limits`) and saves the session CSV (and the parameter
JSON) of every unit that recorded anything.

Outcomes: a unit out of limits (or failing a physics gate) is FAIL; a station
fault (:class:`~station.kernel.errors.HardwareError`: rig timeout, rig fault, serial
fault, lost samples) is ERROR, for all units when it is the rig's and for one unit
when it is its sensor's; ``KeyboardInterrupt`` (Ctrl-C) or :meth:`SequenceRunner.abort`
is ABORTED. ``run()`` returns the result in every case and does not re-raise
``KeyboardInterrupt``.

Guaranteed teardown: whatever happens, the rig is told to stop and the runner
waits for it to report rest; streams are stopped. Nothing is written to any
sensor: the only path that writes is the optional :class:`Provisioner`, called
once per unit whose outcome is PASS, and only when the run was neither aborted
nor hit by a station fault.
"""

from __future__ import annotations

import logging
import threading
import time
import uuid
from collections.abc import Callable, Mapping, Sequence
from concurrent.futures import Future, wait
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any, Protocol, runtime_checkable

from threadpoolctl import threadpool_limits

from station.fit.calibrate import FitOptions, fit_session
from station.fit.determinability import assess
from station.fit.goodness import summary as goodness_summary
from station.kernel.clock import Clock
from station.kernel.errors import (
    FitError,
    HardwareError,
    RackOrientationError,
    StationError,
    TimeBaseError,
    UnitRejected,
)
from station.kernel.limits import ProductLimits, table1_limits
from station.kernel.measurement import Measurement, Verdict
from station.kernel.nest_frames import NestCalibration
from station.kernel.parameters import ParameterSet
from station.kernel.plan import RigPlan, default_plan
from station.kernel.virtual_clock import ActorPool, acting, busy
from station.rig.protocol import Rig, RigState
from station.sensor.protocol import Sensor
from station.sequence.capture import UnitChannel, build_session
from station.sequence.gates import station_fault_text
from station.sequence.limits import check_limits
from station.sequence.nest_correction import in_sensor_frame
from station.sequence.options import SequenceOptions
from station.sequence.prompts import Answer, Operator, Prompt, PromptPlan, fixture_prompts, unload_prompt
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
    worst,
)
from station.sequence.steps import STEP_FUNCTIONS, Fixture, Step, StepReport, bring_to_rest, plan_steps
from station.session import format_session, parse_session
from station.session.model import Session

log = logging.getLogger(__name__)

Subscriber = Callable[[Record], None]


def refusal_outcome(err: FitError) -> tuple[Outcome, str]:
    """The verdict for a recording the station captured and the fit refused.

    A time column that contradicts itself (:class:`TimeBaseError`: a gap inside a segment) means the station's
    link or clock did not keep up: a station fault, ERROR, which the retest policy does not count; so is a line
    unit's rack rest in another orientation than the line's plan holds its units in (:class:`RackOrientationError`).
    Any other refusal is about what the unit measured: FAIL.
    """
    if isinstance(err, TimeBaseError):
        return Outcome.ERROR, f"capture fault (station, not the unit): {err}"
    if isinstance(err, RackOrientationError):  # the line put the unit in its rack slot another way
        return Outcome.ERROR, f"line handling fault (not the unit): {err}"
    return Outcome.FAIL, f"fit refused the recording: {err}"


class RigLinkError(HardwareError):
    """The rig link dropped and had to be re-established during the run."""


@dataclass(frozen=True, eq=False)
class UnitResult:
    """One fixture slot's result.

    Attributes:
        slot: fixture slot; url: its sensor URL; serial: the unit's serial ('' if never identified).
        outcome, message: the verdict and its reason ('' for PASS).
        session: the recording (None if nothing was captured); params: the fit (None if not fitted).
        session_path, params_path: where they were saved (None if not saved).
        measurements: every gate and limit measurement of the unit.
    """

    slot: int
    url: str
    serial: str
    outcome: Outcome
    message: str
    session: Session | None = None
    params: ParameterSet | None = None
    session_path: Path | None = None
    params_path: Path | None = None
    measurements: tuple[Measured, ...] = ()


@dataclass(frozen=True, eq=False)
class RunResult:
    """A finished run.

    Attributes:
        run_id: unique id; outcome: the most severe unit outcome (or the run's own).
        units: per slot; records: everything emitted, in order.
        sequence_s: station clock time from start until the rig was confirmed at rest (s).
        duration_s: station clock time of the whole run incl. fit and saving (s).
        wall_s: wall-clock time of the whole run (s).
        post_wall_s: wall-clock time after the teardown: fits, limits, saving (s). On a fast
            simulated clock, ``sequence_s + post_wall_s`` is what the run takes on a real rig.
        message: why the run as a whole did not complete ('' if it did).
        rig_at_rest: teardown confirmed the rig at rest.
    """

    run_id: str
    outcome: Outcome
    units: tuple[UnitResult, ...]
    records: tuple[Record, ...]
    sequence_s: float
    duration_s: float
    wall_s: float
    post_wall_s: float = 0.0
    message: str = ""
    rig_at_rest: bool = True

    @property
    def cycle_time_per_unit_s(self) -> float:
        """Real-rig time per unit: (rig sequence + post-processing) / units (s)."""
        return (self.sequence_s + self.post_wall_s) / max(len(self.units), 1)

    def unit(self, slot: int) -> UnitResult:
        return self.units[slot]


class Provisioner(Protocol):
    """Writes a passed unit's calibration into the sensor (EEPROM) and verifies it, in four phases.

    1. ``intend``: decide the write and record the intent before anything is written;
    2. ``write``: write, read back, record the write, power-cycle; a HardwareError when it fails (ERROR);
    3. ``verify``: check the corrected output (None: nothing to check); a HardwareError on a fault (ERROR);
    4. ``complete``: record the verification, or the ``fault`` that stopped it; returns the checks
       (recorded as measurements of step 'verify'), raises :class:`~station.kernel.errors.UnitRejected`
       when the unit misses them (FAIL).

    ``verifies``: whether ``verify`` checks anything (a sequence soaks or positions only then).
    See :class:`station.sequence.provision.EepromProvisioner`.
    """

    @property
    def verifies(self) -> bool: ...

    def intend(self, unit: UnitResult, sensor: Sensor, run_started_at: datetime | None = None) -> Any: ...

    def write(self, intent: Any, sensor: Sensor) -> Any: ...

    def verify(self, written: Any, sensor: Sensor) -> Any: ...

    def complete(self, written: Any, result: Any, fault: str = "") -> Sequence[Measurement] | None: ...


@runtime_checkable
class HoldSharingProvisioner(Provisioner, Protocol):
    """A provisioner that can verify every written unit of a batch in the same holds of the rig (one pose, one
    rate step whatever the number of units), phase 3 for all at once.

    ``shares_holds``: whether it does so now (its verifier can); ``verify_many``: per unit its result or its
    link's fault (a rig fault raises). See :meth:`station.sequence.provision.EepromProvisioner.verify_many`.
    """

    @property
    def shares_holds(self) -> bool: ...

    def verify_many(self, items: Sequence[tuple[Any, Sensor]]) -> Sequence[Any] | None: ...


class NamedStep(Protocol):
    """A step of a sequence as the runner's records need it: its name."""

    @property
    def name(self) -> str: ...


class RunSequence(Protocol):
    """What a run does on the rig and around its results: the steps, and hooks the runner calls.

    :class:`RigSequence` is the plain rig sequence; :class:`station.sequence.thermal_sequence.ThermalSequence`
    adds a climate chamber. The runner owns everything else (admission, teardown of the rig, records, fits,
    limits, files, provisioning).

    ``steps``: the named items, in order (their names go into ``RunStarted``).
    ``batch_verification``: write every PASS unit first, then :meth:`before_verification`, then verify each
    (False: write and verify one unit after the other, no preparation).
    """

    @property
    def steps(self) -> Sequence[Any]: ...

    @property
    def batch_verification(self) -> bool: ...

    def run_steps(self, run: SequenceRunner, fx: Fixture, verdicts: list[UnitVerdict], reconnects0: int) -> None:
        """Run the steps (raise KeyboardInterrupt on abort, HardwareError on a station fault)."""
        ...

    def after_teardown(self, run: SequenceRunner, failed: bool) -> None:
        """After the rig was brought to rest; ``failed``: the steps did not complete (fault, abort)."""
        ...

    def before_fits(self, run: SequenceRunner, channels: list[UnitChannel]) -> None:
        """Before the sessions are assembled and fitted."""
        ...

    def before_verification(self, run: SequenceRunner, units: list[UnitResult]) -> dict[int, str]:
        """Prepare the verification of the written ``units``; slot -> why for units that cannot be verified
        (they FAIL). Raises HardwareError or KeyboardInterrupt (every written unit ERROR / ABORTED)."""
        ...

    def after_run(self, run: SequenceRunner, result: RunResult | None) -> RunResult | None:
        """Called whenever :meth:`SequenceRunner.run` ends: the run's result, amended (e.g. by a teardown fault
        of the sequence's own equipment); ``result`` None: the run raised (the exception goes on)."""
        ...


class RigSequence:
    """The plain rig sequence: :func:`~station.sequence.steps.plan_steps` of the plan, nothing around it."""

    batch_verification = False

    def __init__(self, plan: RigPlan) -> None:
        self.steps: list[Step] = plan_steps(plan)

    def run_steps(self, run: SequenceRunner, fx: Fixture, verdicts: list[UnitVerdict], reconnects0: int) -> None:
        for step in self.steps:
            if not fx.active:
                log.warning("run %s: no unit left to measure; stopping before '%s'", run.run_id, step.name)
                return
            if fx.abort.is_set():
                raise KeyboardInterrupt
            t0 = run.clock.now()
            run.emit(StepStarted(run.run_id, step.index, step.name, step.kind.label, t0, step.hold_s))
            try:
                report = STEP_FUNCTIONS[step.kind](fx, step)
                reconnects = fx.rig.reconnects
                if run.options.rig_reconnect_is_error and reconnects > reconnects0:
                    raise RigLinkError(
                        f"the rig link dropped during the run and was re-established ({reconnects - reconnects0} "
                        f"reconnect(s)); the rig went unsupervised, the run is not trusted"
                    )
            except BaseException as exc:
                aborted = isinstance(exc, KeyboardInterrupt)
                why = run.abort_reason if aborted else f"{type(exc).__name__}: {exc}"
                run.emit(StepFinished(run.run_id, step.index, step.name, run.clock.now(),
                                      run.clock.now() - t0, False, len(fx.active), why))
                raise
            problems = run.apply_report(fx, step, report, verdicts)
            run.emit(StepFinished(run.run_id, step.index, step.name, run.clock.now(), run.clock.now() - t0,
                                  not problems, len(fx.active), "; ".join(problems)))

    def after_teardown(self, run: SequenceRunner, failed: bool) -> None:
        return None

    def before_fits(self, run: SequenceRunner, channels: list[UnitChannel]) -> None:
        return None

    def before_verification(self, run: SequenceRunner, units: list[UnitResult]) -> dict[int, str]:
        return {}

    def after_run(self, run: SequenceRunner, result: RunResult | None) -> RunResult | None:
        return result


@dataclass
class UnitVerdict:
    """A unit's verdict while the run goes: None until something decides it."""

    outcome: Outcome | None = None
    message: str = ""
    measurements: list[Measured] = field(default_factory=list)


def _new_run_id() -> str:
    return datetime.now(UTC).strftime("%Y%m%dT%H%M%SZ") + "-" + uuid.uuid4().hex[:6]


class SequenceRunner:
    """Runs the sequence for the sensors of one fixture on one rig.

    Args:
        rig: an open rig (:func:`station.rig.open_rig`).
        sensors: open sensor clients, one per fixture slot (:func:`station.sensor.open_sensor`).
        clock: the station clock the rig and sensors were opened with.
        plan: steps and durations (default :func:`station.kernel.plan.default_plan`), site gravity.
        options: timeouts and capture gates.
        limits: product limits (default: Table 1 ranges).
        out_dir: where session CSVs and parameter JSONs go (None: not saved).
        fit_options: passed to :func:`fit_session`.
        provisioner: called for each PASS unit after a complete, fault-free run.
        admit: the retest policy, ``admit(serial, run_id) -> reason or None``, asked for each unit
            before anything moves (the unit is identified first); a refused unit is REFUSED, not tested.
        station, rig_name: names for records and session metadata.
        sensor_urls: for records and results (default ``slotN``).
        subscribers: called with every record, in order, from the thread calling :meth:`run`.
        nests: the rig's nest calibration: each unit's references are taken into its sensor frame before
            the session is saved and fitted (:mod:`station.sequence.nest_correction`); None: perfect nests.
        operator: answers the station's prompts (:mod:`station.sequence.prompts`; None: no prompts).
        prompts: which prompts (default with an operator: :func:`~station.sequence.prompts.fixture_prompts`,
            load the nests and close the lid before the rig moves, unload after the verdicts).
        expected_serials: fixture slot -> the serial the operator scanned for it; a unit that reports another
            serial is REFUSED before anything moves (the wrong unit, or the right one in the wrong nest).
        sequence: what runs on the rig and around it (default :class:`RigSequence` of ``plan``; a thermal
            plan: :class:`station.sequence.thermal_sequence.ThermalSequence`).
    """

    def __init__(
        self,
        rig: Rig,
        sensors: Sequence[Sensor],
        clock: Clock,
        *,
        plan: RigPlan | None = None,
        options: SequenceOptions | None = None,
        limits: ProductLimits | None = None,
        out_dir: Path | None = None,
        fit_options: FitOptions | None = None,
        provisioner: Provisioner | None = None,
        admit: Callable[[str, str], str | None] | None = None,
        station: str = "station",
        rig_name: str = "rig",
        sensor_urls: Sequence[str] | None = None,
        subscribers: Sequence[Subscriber] = (),
        nests: NestCalibration | None = None,
        operator: Operator | None = None,
        prompts: PromptPlan | None = None,
        expected_serials: Mapping[int, str] | None = None,
        sequence: RunSequence | None = None,
    ) -> None:
        if not sensors:
            raise ValueError("a run needs at least one sensor")
        self.rig = rig
        self.sensors = list(sensors)
        self.clock = clock
        self.plan = plan if plan is not None else default_plan()
        self.options = options if options is not None else SequenceOptions()
        self.limits = limits if limits is not None else table1_limits()
        self.out_dir = out_dir
        self.fit_options = fit_options
        self.provisioner = provisioner
        self.admit = admit
        self.station = station
        self.rig_name = rig_name
        self.sensor_urls = list(sensor_urls) if sensor_urls is not None else [f"slot{k}" for k in range(len(sensors))]
        self.nests = nests
        self.sequence: RunSequence = RigSequence(self.plan) if sequence is None else sequence
        self.steps = self.sequence.steps
        self.verification: dict[int, Any] = {}  # slot -> the provisioner's verification result
        self.verify_s = 0.0  # station clock s spent in the verification (incl. its preparation)
        self.finish_wall_s = 0.0  # wall s after the teardown: sessions, fits, limits, files, provisioning
        self._subscribers: list[Subscriber] = list(subscribers)
        self._records: list[Record] = []
        self._abort_requested = False
        self.abort_reason = "aborted by the operator"
        self._fixture: Fixture | None = None
        self.operator = operator
        self.prompts = prompts if prompts is not None or operator is None else fixture_prompts(len(self.sensors))
        self.expected_serials = dict(expected_serials or {})
        self._cancel = threading.Event()  # set by abort(): a prompt waiting for its answer gives up
        self._prompt_seq = 0
        self.run_id = _new_run_id()
        self.started_at = datetime.now(UTC)  # reset when the run starts; the run's images carry it

    # --- records ----------------------------------------------------------------------------------

    def subscribe(self, fn: Subscriber) -> None:
        """Call ``fn`` with every record emitted from now on."""
        self._subscribers.append(fn)

    def emit(self, record: Record) -> None:
        self._records.append(record)
        for fn in self._subscribers:
            try:
                fn(record)
            except Exception:  # a display or logger bug must not break the run
                log.exception("record subscriber %r failed", fn)

    def abort(self, reason: str = "aborted by the operator") -> None:
        """Ask the run to stop as soon as possible (thread-safe); the outcome becomes ABORTED with ``reason``.

        The first reason given is kept (e.g. ``'aborted by SIGTERM'``).
        """
        if not self._abort_requested:
            self.abort_reason = reason
        self._abort_requested = True
        self._cancel.set()
        if self._fixture is not None:
            self._fixture.abort.set()

    # --- the run ------------------------------------------------------------------------------------

    def run(self) -> RunResult:
        """Run every step, tear down, fit, check limits, save; see the module docstring."""
        result: RunResult | None = None
        try:
            with acting(self.clock, name="sequence-runner"):  # on a virtual clock the run owns time
                result = self._run()
        finally:
            amended = self.sequence.after_run(self, result)
        assert amended is not None
        return amended

    def _run(self) -> RunResult:
        self.started_at = datetime.now(UTC)
        clock = self.clock
        t_start, wall0 = clock.now(), time.monotonic()
        self._run_thread, self._last_reading = threading.current_thread(), 0.0
        channels = [
            UnitChannel(k, url, s, clock) for k, (url, s) in enumerate(zip(self.sensor_urls, self.sensors, strict=True))
        ]
        verdicts = [UnitVerdict() for _ in channels]
        self.emit(
            RunStarted(
                self.run_id, self.started_at.isoformat(), t_start, self.station, self.rig_name,
                tuple(self.sensor_urls), tuple(s.name for s in self.steps), tuple(s.hold_s for s in self.steps),
            )
        )
        aborted = self._abort_requested
        run_message = ""
        completed = False
        loaded = False  # the operator confirmed the prompts before the rig moves (or there were none)
        rig_at_rest = False
        pool = ActorPool(clock, max_workers=len(channels), thread_name_prefix="capture")
        fx = Fixture(
            self.rig, channels, clock, self.options, self.plan.gravity_mps2, int(self.plan.sample_rate_hz), pool
        )
        self._fixture = fx
        if aborted:
            fx.abort.set()
        reconnects0 = self.rig.reconnects
        self.rig.listeners.append(self._rig_reading)
        try:
            try:
                if not aborted:
                    self._ask_before()
                    loaded = True
                    self._admit_units(fx, verdicts)
                    self.sequence.run_steps(self, fx, verdicts, reconnects0)
                    completed = bool(fx.active)
            except KeyboardInterrupt:
                aborted = True
                run_message = self.abort_reason
            except HardwareError as exc:
                run_message = f"station fault: {exc}"
                log.warning("run %s: %s", self.run_id, run_message)
            finally:
                fx.abort.set()
                rig_at_rest, teardown_message, interrupted = self._teardown(channels)
                aborted = aborted or interrupted
                self.sequence.after_teardown(self, aborted or bool(run_message) or not completed)
                if teardown_message:
                    run_message = f"{run_message}; {teardown_message}" if run_message else teardown_message
            sequence_s = clock.now() - t_start
            post_wall0 = time.monotonic()
            self.sequence.before_fits(self, channels)
            # Fits run concurrently: each limits BLAS to one thread, but that limit is process-wide and each
            # fit restores what it found when it ends, so one fit's end would give the others' remaining BLAS
            # calls two threads (another order of summation: the last bits of a parameter set would depend on
            # timing). One limit held around all of them keeps every fit single-threaded.
            with busy(clock), threadpool_limits(limits=1, user_api="blas"):  # fits hold time: not a stall
                units = self._finish_units(channels, verdicts, aborted, run_message, completed)
            self.finish_wall_s = time.monotonic() - post_wall0
        finally:
            self.rig.listeners.remove(self._rig_reading)
            pool.shutdown(wait=True, cancel_futures=True)
            self._fixture = None
        outcome = worst(u.outcome for u in units)
        if aborted:
            outcome = Outcome.ABORTED
        elif run_message and outcome == Outcome.PASS:
            outcome = Outcome.ERROR
        finished = tuple(
            UnitFinished(self.run_id, u.slot, u.serial, u.outcome, u.message,
                         str(u.session_path) if u.session_path else None,
                         str(u.params_path) if u.params_path else None)
            for u in units
        )
        for rec in finished:
            self.emit(rec)
        note = self._ask_unload(units) if loaded and not aborted else ""
        if note:
            run_message = f"{run_message}; {note}" if run_message else note
        duration = clock.now() - t_start
        wall = time.monotonic() - wall0
        post_wall = time.monotonic() - post_wall0
        self.emit(RunFinished(self.run_id, outcome, clock.now(), duration, wall, finished, run_message, rig_at_rest))
        return RunResult(
            self.run_id, outcome, tuple(units), tuple(self._records), sequence_s, duration, wall, post_wall,
            run_message, rig_at_rest,
        )

    # --- prompts ----------------------------------------------------------------------------------

    def _ask(self, prompt: Prompt) -> Answer:
        """Show ``prompt`` (record), wait for the operator's answer, record it; the answer."""
        assert self.operator is not None
        self._prompt_seq += 1
        pid = f"{self.run_id}/p{self._prompt_seq}"
        self.emit(PromptShown(self.run_id, pid, prompt.kind.value, prompt.text, prompt.nests, prompt.timeout_s))
        t0 = time.monotonic()
        answer: Answer = "cancelled"
        by = ""
        try:
            answer, by = self.operator.ask(pid, prompt, self._cancel)
        finally:  # also on Ctrl-C or an operator that cannot be reached: the displays close the prompt
            self.emit(PromptAnswered(self.run_id, pid, answer, by, time.monotonic() - t0))
        return answer

    def _ask_before(self) -> None:
        """The prompts before the rig moves; a prompt not confirmed aborts the run (raises KeyboardInterrupt)."""
        if self.operator is None or self.prompts is None:
            return
        for prompt in self.prompts.before:
            answer = self._ask(prompt)
            if answer == "confirmed":
                continue
            if answer == "timeout":
                self.abort(f"aborted: no answer to the prompt '{prompt.kind.value}' within {prompt.timeout_s:g} s")
            else:
                self.abort(f"aborted by the operator at the prompt '{prompt.kind.value}'")
            raise KeyboardInterrupt

    def _ask_unload(self, units: Sequence[UnitResult]) -> str:
        """The unload prompt after the verdicts; '' when confirmed, else a note for the run's message (the
        verdicts stand either way)."""
        if self.operator is None or self.prompts is None or not self.prompts.unload:
            return ""
        prompt = unload_prompt([(u.slot + 1, u.outcome.value) for u in units], self.prompts.timeout_s)
        try:
            answer = self._ask(prompt)
        except KeyboardInterrupt:
            return f"unload not confirmed ({self.abort_reason})"
        except HardwareError as exc:
            return f"unload not confirmed ({exc})"
        return "" if answer == "confirmed" else f"unload not confirmed ({answer})"

    def _rig_reading(self, state: RigState) -> None:
        """Publish what the rig reports while the run waits on it: at most ~4 per wall second, and only
        from the thread running the sequence (subscribers are called from that thread)."""
        now = time.monotonic()
        if threading.current_thread() is not self._run_thread or now - self._last_reading < 0.25:
            return
        self._last_reading = now
        flags = "|".join(f.name or "" for f in type(state.status) if state.status & f)
        self.emit(RigReading(self.run_id, state.t_s, state.roll_deg, state.pitch_deg, state.yaw_deg, state.rate_dps,
                              flags, state.fault_code))

    def apply_report(self, fx: Fixture, step: NamedStep, report: StepReport, verdicts: list[UnitVerdict]) -> list[str]:
        """Emit the step's measurements; end units with a sensor fault (ERROR) or a failed gate.

        A failed link or timing gate (:mod:`station.sequence.gates`: samples, dropped frames, the sensor's clock
        rate, late frames, a rig that did not report itself settled) is the station's: ERROR, with the gate
        named. A physics gate that every measured unit of the step fails (two units or more) is a common cause,
        the rig or the station's timing, not the units: those units end ERROR too. The retest policy counts
        neither.
        """
        problems: list[str] = []
        common = common_cause(report)
        for unit in fx.units:
            v = verdicts[unit.slot]
            if unit.slot in report.errors:
                exc = report.errors[unit.slot]
                self._end_unit(fx, unit, v, Outcome.ERROR, f"step '{step.name}': {type(exc).__name__}: {exc}")
                problems.append(f"slot {unit.slot}: {exc}")
                continue
            gates = report.gates.get(unit.slot)
            if gates is None:
                continue
            for g in gates:
                m = Measured(self.run_id, unit.slot, unit.serial, step.name, g)
                v.measurements.append(m)
                self.emit(m)
            failed = [g for g in gates if not g.passed]
            if failed:
                link = [g for g in failed if g.link]
                outcome = Outcome.ERROR if link or common else Outcome.FAIL
                text = "; ".join(station_fault_text(g) for g in link) if link else "; ".join(
                    g.describe() for g in failed)
                if link:
                    text = f"station fault (not counted against the unit): {text}"
                elif common:
                    text = (f"station fault: every unit failed {', '.join(sorted(common))} in this step "
                            f"(the rig or the station's timing, not the unit): {text}")
                self._end_unit(fx, unit, v, outcome, f"step '{step.name}': {text}")
                problems.append(f"slot {unit.slot}: {text}")
        return problems

    def _admit_units(self, fx: Fixture, verdicts: list[UnitVerdict]) -> None:
        """The retest policy, before anything moves: identify every unit and end the ones it refuses.

        A refused unit is REFUSED (not tested, nothing written to it, not counted as an attempt); a
        sensor that does not answer is a station fault (ERROR) for its slot. With every unit refused
        the run ends without moving the rig.
        """
        if self.admit is None and not self.expected_serials and not self.routes_units:
            return
        for unit in list(fx.active):
            v = verdicts[unit.slot]
            try:
                ident = unit.sensor.identify()
            except HardwareError as exc:
                self._end_unit(fx, unit, v, Outcome.ERROR, f"could not identify the unit: {type(exc).__name__}: {exc}")
                continue
            scanned = self.expected_serials.get(unit.slot)
            if scanned and scanned != ident.serial:
                unit.identity = ident
                self._end_unit(fx, unit, v, Outcome.REFUSED,
                               f"nest {unit.slot + 1}: the scanned serial is {scanned} but the unit in the nest "
                               f"reports {ident.serial} (wrong unit, or the right unit in the wrong nest)")
                continue
            message = self.refusal(ident.serial)
            if message:
                unit.identity = ident
                self._end_unit(fx, unit, v, Outcome.REFUSED, message)

    #: Whether this runner decides per unit itself whether it runs (:meth:`refusal` adds its own reasons, as the
    #: line's rig role does): every unit is then identified before anything moves, even without a retest policy.
    routes_units: bool = False

    def refusal(self, serial: str) -> str | None:
        """Why ``serial`` is not run, as the unit's REFUSED message (None: run it). Here the retest policy
        (``admit``) decides; a runner that routes units itself (the line's rig role) adds its own reasons and
        sets :attr:`routes_units`."""
        reason = self.admit(serial, self.run_id) if self.admit is not None else None
        return f"refused by the retest policy: {reason}" if reason else None

    def _end_unit(self, fx: Fixture, unit: UnitChannel, v: UnitVerdict, outcome: Outcome, message: str) -> None:
        unit.active = False
        v.outcome, v.message = outcome, message
        fx.pool.submit(unit.stop_stream)  # not on the rig's critical path: a silent sensor takes a while

    # --- teardown -----------------------------------------------------------------------------------

    def _teardown(self, channels: list[UnitChannel]) -> tuple[bool, str, bool]:
        """Stop the rig and wait for rest (retried once after a Ctrl-C), stop the streams.

        Returns (rig confirmed at rest, message about a failed teardown, interrupted by Ctrl-C).
        """
        at_rest, message, interrupted = False, "", False
        for _ in range(2):
            try:
                bring_to_rest(self.rig, self.options.rest_timeout_s)
                at_rest, message = True, ""
                break
            except KeyboardInterrupt:
                interrupted = True
                message = "teardown interrupted; rig stop was retried"
            except HardwareError as exc:
                message = f"could not confirm the rig at rest ({type(exc).__name__}: {exc}); its watchdog must stop it"
                log.error("run %s: %s", self.run_id, message)
                break
        try:
            futures = [self._fixture.pool.submit(u.stop_stream) for u in channels] if self._fixture else []
            wait(futures)
        except KeyboardInterrupt:
            interrupted = True
        return at_rest, message, interrupted

    # --- after the rig: sessions, fits, limits, files -------------------------------------------------

    def metadata(self, unit: UnitChannel) -> dict[str, str]:
        p = self.plan
        return {
            "latitude_deg": repr(float(p.latitude_deg)),
            "heading_deg": repr(float(p.heading_deg)),
            "station": self.station,
            "rig": self.rig_name,
            "run_id": self.run_id,
            "slot": str(unit.slot),
        }

    def _fit_one(self, session: Session) -> ParameterSet:
        params = fit_session(session, self.fit_options)  # the b_stat rule of determinability needs the limits
        return assess(params, params.quality.record_end_s, self.limits)

    def _finish_units(
        self,
        channels: list[UnitChannel],
        verdicts: list[UnitVerdict],
        aborted: bool,
        run_message: str,
        completed: bool,
    ) -> list[UnitResult]:
        sessions: list[Session | None] = []
        texts: list[str | None] = []
        for unit, v in zip(channels, verdicts, strict=True):
            if v.outcome is None and unit.active:
                if aborted:
                    v.outcome, v.message = Outcome.ABORTED, run_message or self.abort_reason
                elif run_message:
                    v.outcome, v.message = Outcome.ERROR, run_message
                elif not completed:
                    v.outcome, v.message = Outcome.ERROR, "the sequence did not complete"
            elif v.outcome is None:
                v.outcome, v.message = Outcome.ERROR, run_message or "the unit was not measured"
            try:
                built = build_session(unit, self.plan.gravity_mps2, self.metadata(unit))
                if built is not None:
                    built = in_sensor_frame(built, self.nests, unit.slot)
                # fit exactly what is saved: re-fitting the CSV reproduces the parameter set
                text = format_session(built) if built is not None else None
                texts.append(text)
                sessions.append(parse_session(text) if text is not None else None)
            except StationError as exc:
                log.error("slot %d: could not assemble the session: %s", unit.slot, exc)
                texts.append(None)
                sessions.append(None)
        params: list[ParameterSet | None] = [None] * len(channels)
        to_fit = {k: s for k, (v, s) in enumerate(zip(verdicts, sessions, strict=True))
                  if v.outcome is None and s is not None}
        if to_fit:
            assert self._fixture is not None
            futures: dict[int, Future[ParameterSet]] = {
                k: self._fixture.pool.submit(self._fit_one, session) for k, session in to_fit.items()
            }
            try:
                wait(futures.values())
            except KeyboardInterrupt:
                aborted = True
            for k, fut in futures.items():
                v = verdicts[k]
                if aborted and not fut.done():
                    v.outcome, v.message = Outcome.ABORTED, f"{self.abort_reason} during the fit"
                    continue
                err = fut.exception()
                if isinstance(err, FitError):
                    v.outcome, v.message = refusal_outcome(err)
                elif err is not None:
                    raise err
                else:
                    fitted = fut.result()
                    params[k] = fitted
                    self._check_unit_limits(channels[k], v, fitted)
        results: list[UnitResult] = []
        for k, (unit, v) in enumerate(zip(channels, verdicts, strict=True)):
            if v.outcome is None:
                v.outcome = Outcome.ABORTED if aborted else Outcome.ERROR
                v.message = v.message or "not finished"
            session_path, params_path = self._save(unit, v, sessions[k], texts[k], params[k])
            results.append(
                UnitResult(unit.slot, unit.url, unit.serial, v.outcome, v.message, sessions[k], params[k],
                           session_path, params_path, tuple(v.measurements))
            )
        if self.provisioner is not None and not aborted and not run_message:
            results = self._provision(results)
        return results

    def _check_unit_limits(self, unit: UnitChannel, v: UnitVerdict, params: ParameterSet) -> None:
        checks = check_limits(params, self.limits)
        goodness = params.quality.goodness_of_fit
        if goodness is not None:
            checks.append(Measurement.in_range("fit.goodness_of_fit.failed_tests", len(goodness.failed),
                                               0.0, 0.0, "1"))
        for c in checks:
            m = Measured(self.run_id, unit.slot, unit.serial, "limits", c)
            v.measurements.append(m)
            self.emit(m)
        v.outcome, v.message = recording_verdict(params) or unit_verdict(checks, self.limits)

    def _save(
        self,
        unit: UnitChannel,
        v: UnitVerdict,
        session: Session | None,
        text: str | None,
        params: ParameterSet | None,
    ) -> tuple[Path | None, Path | None]:
        if self.out_dir is None or session is None or text is None:
            return None, None
        stem = f"{session.serial}_{self.run_id}"
        try:
            self.out_dir.mkdir(parents=True, exist_ok=True)
            session_path = self.out_dir / f"{stem}.csv"
            session_path.write_bytes(text.encode("utf-8"))
            params_path = None
            if params is not None:
                params_path = self.out_dir / f"{stem}.params.json"
                params_path.write_text(params.to_json() + "\n")
        except (OSError, StationError) as exc:
            if v.outcome in (Outcome.PASS, Outcome.FAIL):
                v.outcome, v.message = Outcome.ERROR, f"could not save the recording: {exc}"
            log.error("slot %d: could not save the recording: %s", unit.slot, exc)
            return None, None
        return session_path, params_path

    def _emit_verify(self, r: UnitResult, checks: Sequence[Measurement]) -> None:
        for c in checks:
            self.emit(Measured(self.run_id, r.slot, r.serial, "verify", c))

    def _provision(self, results: list[UnitResult]) -> list[UnitResult]:
        """The provisioner's phases for every PASS unit (see :class:`Provisioner`)."""
        p = self.provisioner
        assert p is not None
        t0 = self.clock.now()
        try:
            if not self.sequence.batch_verification and not self._shares_holds(p):
                return self._provision_each(p, results)
            return self._provision_batch(p, results)
        finally:
            self.verify_s = self.clock.now() - t0

    @staticmethod
    def _shares_holds(p: Provisioner) -> bool:
        """Whether the provisioner verifies every written unit in the same holds (:class:`HoldSharingProvisioner`)."""
        return p.verifies and isinstance(p, HoldSharingProvisioner) and p.shares_holds

    def _refused_now(self, r: UnitResult) -> UnitResult | None:
        """The retest policy asked again right before writing (e.g. scrapped while it was measured): REFUSED,
        and no image is written into it; None: go on."""
        reason = self.admit(r.serial, self.run_id) if self.admit is not None else None
        if not reason:
            return None
        return replace_outcome(r, Outcome.REFUSED, f"not provisioned, refused by the retest policy: {reason}")

    def _write(self, p: Provisioner, r: UnitResult) -> Any:
        sensor = self.sensors[r.slot]
        return p.write(p.intend(r, sensor, self.started_at), sensor)

    def _provision_each(self, p: Provisioner, results: list[UnitResult]) -> list[UnitResult]:
        out: list[UnitResult] = []
        stop = False
        for r in results:
            if r.outcome != Outcome.PASS or stop:
                out.append(r)
                continue
            refused = self._refused_now(r)
            if refused is not None:
                out.append(refused)
                continue
            try:
                written = self._write(p, r)
            except StationError as exc:  # a link fault, or an image the writer refused: the station's fault
                out.append(replace_outcome(r, Outcome.ERROR, f"provisioning failed: {exc}"))
                continue
            except KeyboardInterrupt:
                stop = True
                out.append(replace_outcome(r, Outcome.ABORTED, f"{self.abort_reason} during provisioning"))
                continue
            r, stop = self._verify_written(p, r, written, "verification")
            out.append(r)
        return out

    def _provision_batch(self, p: Provisioner, results: list[UnitResult]) -> list[UnitResult]:
        out = list(results)
        written: dict[int, Any] = {}
        for k, r in enumerate(results):
            if r.outcome != Outcome.PASS:
                continue
            refused = self._refused_now(r)
            if refused is not None:
                out[k] = refused
                continue
            try:
                written[k] = self._write(p, r)
            except StationError as exc:
                out[k] = replace_outcome(r, Outcome.ERROR, f"provisioning failed: {exc}")
            except KeyboardInterrupt:
                for j in range(k, len(results)):
                    if results[j].outcome == Outcome.PASS:
                        out[j] = replace_outcome(results[j], Outcome.ABORTED,
                                                 f"{self.abort_reason} during provisioning")
                self._complete_unverified(p, out, written, Outcome.ABORTED, self.abort_reason)
                return out
        if not written:
            return out
        if not p.verifies:
            for k, w in written.items():
                out[k], _ = self._verify_written(p, out[k], w, "verification")
            return out
        what = self.sequence_verification_name()
        try:
            unfit = self.sequence.before_verification(self, [out[k] for k in written])
        except (HardwareError, KeyboardInterrupt) as exc:
            aborted = isinstance(exc, KeyboardInterrupt)
            why = self.abort_reason if aborted else f"{type(exc).__name__}: {exc}"
            self._complete_unverified(p, out, written, Outcome.ABORTED if aborted else Outcome.ERROR,
                                      f"{what}: {why}")
            return out
        if self._shares_holds(p):
            for k, w in list(written.items()):
                if out[k].slot in unfit:
                    out[k] = self._complete(p, out[k], w, unfit[out[k].slot], Outcome.FAIL, unfit[out[k].slot])
                    del written[k]
            self._verify_together(p, out, written, what)
            return out
        for k, w in written.items():
            r = out[k]
            if r.slot in unfit:
                out[k] = self._complete(p, r, w, unfit[r.slot], Outcome.FAIL, unfit[r.slot])
                continue
            out[k], stop = self._verify_written(p, r, w, what)
            if stop:
                rest = {j: x for j, x in written.items() if j > k}
                self._complete_unverified(p, out, rest, Outcome.ABORTED, f"{self.abort_reason} during verification")
                break
        return out

    def sequence_verification_name(self) -> str:
        """How the verification is named in unit messages ('verification', or with its temperature)."""
        name = getattr(self.sequence, "verification_name", None)
        return name if isinstance(name, str) else "verification"

    def _complete(self, p: Provisioner, r: UnitResult, written: Any, fault: str, outcome: Outcome,
                  message: str) -> UnitResult:
        """Record a written unit that was not verified (``fault`` says why); the unit gets ``outcome``."""
        try:
            p.complete(written, None, fault)
        except StationError as exc:
            return replace_outcome(r, Outcome.ERROR, f"{message}; the write could not be recorded: {exc}")
        return replace_outcome(r, outcome, message)

    def _complete_unverified(self, p: Provisioner, out: list[UnitResult], written: dict[int, Any], outcome: Outcome,
                             why: str) -> None:
        for k, w in written.items():
            out[k] = self._complete(p, out[k], w, why, outcome, why)

    def _verify_together(self, p: Provisioner, out: list[UnitResult], written: dict[int, Any], what: str) -> None:
        """Every written unit verified in the same holds (one pose, one rate step for the whole fixture), then
        each completed as :meth:`_verify_written` does: a rig fault makes every unit ERROR, a unit's link fault
        that unit."""
        if not written:
            return
        keys = list(written)
        assert isinstance(p, HoldSharingProvisioner)
        try:
            results = p.verify_many([(written[k], self.sensors[out[k].slot]) for k in keys])
        except StationError as exc:
            self._complete_unverified(p, out, written, Outcome.ERROR, f"{what} fault: {type(exc).__name__}: {exc}")
            return
        except KeyboardInterrupt:
            self._complete_unverified(p, out, written, Outcome.ABORTED, f"{self.abort_reason} during {what}")
            return
        assert results is not None  # shares_holds: the verifier verifies together
        for k, result in zip(keys, results, strict=True):
            out[k], _ = self._verify_written(p, out[k], written[k], what, result)

    def _verify_written(self, p: Provisioner, r: UnitResult, written: Any, what: str,
                        done: Any = None) -> tuple[UnitResult, bool]:
        """Verify (unless ``done`` holds its result or its fault already) and complete one written unit; (its
        result, whether the operator aborted)."""
        sensor = self.sensors[r.slot]
        try:
            if isinstance(done, StationError):
                raise done
            result = p.verify(written, sensor) if done is None else done
        except StationError as exc:  # a rig or link fault during the verification: ERROR, the write recorded
            why = f"{what} fault: {type(exc).__name__}: {exc}"
            return self._complete(p, r, written, why, Outcome.ERROR, why), False
        except KeyboardInterrupt:
            why = f"{self.abort_reason} during {what}"
            return self._complete(p, r, written, why, Outcome.ABORTED, why), True
        if result is not None:
            self.verification[r.slot] = result
        try:
            checks = p.complete(written, result)
            self._emit_verify(r, checks or ())
        except UnitRejected as exc:
            self._emit_verify(r, exc.checks)
            return replace_outcome(r, Outcome.FAIL, f"{what} failed: {exc}"), False
        except StationError as exc:
            return replace_outcome(r, Outcome.ERROR, f"{what}: the result could not be recorded: {exc}"), False
        return r, False


def common_cause(report: StepReport) -> set[str]:
    """Physics gates that every unit measured in a step failed (empty below two measured units)."""
    measured = [gates for gates in report.gates.values() if gates]
    if len(measured) < 2:
        return set()
    failed = [{g.name for g in gates if not g.passed and not g.link} for gates in measured]
    return set.intersection(*failed)


def recording_verdict(params: ParameterSet) -> tuple[Outcome, str] | None:
    """RETEST when the fit's goodness-of-fit test failed, else None (then the limits decide).

    Residuals far beyond the noise the fit itself estimated mean the result is not a calibration: the
    limit verdicts are meaningless, and it is not the unit's failure either (a disturbed recording, a
    rig that did not hold): the recording is repeated, and no failed attempt is counted.
    """
    goodness = params.quality.goodness_of_fit
    if goodness is not None and not goodness.passed:
        return Outcome.RETEST, f"the recording contradicts its own fit, retest: {goodness_summary(goodness)}"
    return None


def unit_verdict(checks: Sequence[Measurement], limits: ProductLimits) -> tuple[Outcome, str]:
    """A unit's outcome and message from its limit checks.

    Any FAIL makes the unit FAIL. Otherwise an INCONCLUSIVE check (its ``value +- k u`` straddles
    a limit) makes it FAIL or RETEST, as the limits file's ``inconclusive`` says; else PASS.
    """

    def shown(cs: list[Measurement]) -> str:
        more = f" (+{len(cs) - 3} more)" if len(cs) > 3 else ""
        return "; ".join(c.describe() for c in cs[:3]) + more

    failed = [c for c in checks if c.verdict == Verdict.FAIL]
    if failed:
        return Outcome.FAIL, f"out of limits ({limits.name}): {shown(failed)}"
    unsure = [c for c in checks if c.verdict == Verdict.INCONCLUSIVE]
    if unsure:
        outcome = Outcome.RETEST if limits.inconclusive == "retest" else Outcome.FAIL
        return outcome, f"inconclusive ({limits.name}, k = {limits.k_sigma:g}): {shown(unsure)}"
    return Outcome.PASS, ""


def replace_outcome(r: UnitResult, outcome: Outcome, message: str) -> UnitResult:
    return UnitResult(r.slot, r.url, r.serial, outcome, message, r.session, r.params, r.session_path, r.params_path,
                      r.measurements)
