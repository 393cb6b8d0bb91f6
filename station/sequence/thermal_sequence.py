"""The thermal calibration sequence: the rig sequence under a climate chamber's temperature schedule.

:func:`thermal_steps` expands a :class:`~station.kernel.plan.ThermalPlan` (see
:mod:`station.kernel.thermal_plan`) into steps: the power-on rest at the room temperature, then per
plateau a chamber step (setpoint written, the air confirmed at it from the chamber's AT_SETPOINT bit
and readback), a soak (gate: every unit's own temperature slope over the last window within the stated
K/min) and the rig steps (poses, rate steps or a subset) named ``'pose +x @5C'``; in ramp mode a cold
soak and plateau, the ramp (the chamber ramps slowly while the rig cycles through the poses and, if
asked, rate steps) and a final soak and plateau; optionally a raw check plateau at the verification
temperature (``'check pose +z @35C'``), kept out of the fit's recording and assembled into a check
recording of its own (:attr:`ThermalSequence.check_sessions`).

:class:`ThermalSequence` is the :class:`~station.sequence.runner.RunSequence` for it: the
:class:`~station.sequence.runner.SequenceRunner` takes it (:func:`thermal_runner`) and calls its
hooks. Everything the runner guarantees holds (rig to rest in the teardown, outcomes, records, fits, limits, files). On
top: every chamber fault (no answer, alarm, setpoint not reached in time, a dropped link) is a station
ERROR, never a unit FAIL; after the fit each PASS unit's image is written and the unit power-cycled,
then the chamber goes to the verification temperature (one the fit did not use), the units soak, and
the corrected output is verified on the rig there (:class:`~station.sequence.verify.RigVerifier`): the
verdict uses those errors. The chamber is brought back to ambient at the end, also after a fault or an
abort. :attr:`ThermalSequence.timing` holds the batch's cycle time. Temperatures degC, times s.
"""

from __future__ import annotations

import contextlib
import logging
import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from station.chamber.protocol import Chamber, ChamberError, ChamberSetpointTimeout
from station.chamber.registers import AlarmCode
from station.fit.calibrate import FitOptions
from station.kernel.clock import Clock
from station.kernel.errors import HardwareError, StationError
from station.kernel.measurement import Measurement
from station.kernel.thermal_plan import ThermalPlan
from station.rig.protocol import Rig, RigFault
from station.sensor.protocol import Sensor, SensorTimeout
from station.sequence.capture import UnitChannel, build_session
from station.sequence.records import Measured, Outcome, StepFinished, StepStarted
from station.sequence.runner import (
    RigLinkError,
    RunResult,
    SequenceRunner,
    UnitResult,
    UnitVerdict,
)
from station.sequence.steps import (
    STEP_FUNCTIONS,
    Fixture,
    Step,
    StepReport,
    capture,
    drive_rig,
    plan_steps,
    position_rig,
)
from station.session import format_session
from station.session.model import Kind, Session

log = logging.getLogger(__name__)

CHECK_PREFIX = "check "


class ChamberLinkError(ChamberError):
    """The chamber link dropped and had to be re-established during the run."""


@dataclass(frozen=True)
class ChamberStep:
    """Set the chamber to ``degc`` (ramp ``ramp_k_per_min``, 0: as fast as it can) and confirm the air there."""

    index: int
    name: str
    degc: float
    ramp_k_per_min: float = 0.0
    kind: Kind = Kind.MOVE
    hold_s: float = 0.0


@dataclass(frozen=True)
class SoakStep:
    """Wait until every unit's temperature is stable (the soak gate) at plateau ``degc``."""

    index: int
    name: str
    degc: float
    kind: Kind = Kind.MOVE
    hold_s: float = 0.0


@dataclass(frozen=True)
class RampStep:
    """Ramp the chamber from ``from_degc`` to ``to_degc`` at ``k_per_min`` while the rig cycles through
    ``cycle`` (poses and rate steps, re-indexed as they run)."""

    index: int
    name: str
    from_degc: float
    to_degc: float
    k_per_min: float
    cycle: tuple[Step, ...]
    kind: Kind = Kind.MOVE
    hold_s: float = 0.0


ThermalItem = Step | ChamberStep | SoakStep | RampStep


def _label(degc: float) -> str:
    return f"@{degc:g}C"


def _plateau_rig_steps(tp: ThermalPlan, degc: float, prefix: str = "") -> list[Step]:
    plan = replace(tp.base, poses=tp.plateau_poses, rate_steps=tp.plateau_rate_steps)
    return [replace(s, name=f"{prefix}{s.name} {_label(degc)}") for s in plan_steps(plan)[1:]]


def thermal_steps(tp: ThermalPlan) -> list[ThermalItem]:
    """The steps of a thermal plan, indexed in order (see the module docstring)."""
    base = tp.base
    items: list[ThermalItem] = [Step(0, "rest", Kind.REST, base.rest_pose, 0.0, base.rest_s)]

    def plateau(degc: float, prefix: str = "") -> None:
        items.append(ChamberStep(0, f"{prefix}chamber {_label(degc)}", degc, tp.move_ramp_k_per_min))
        items.append(SoakStep(0, f"{prefix}soak {_label(degc)}", degc))
        items.extend(_plateau_rig_steps(tp, degc, prefix))

    if tp.mode == "plateaus":
        for degc in tp.plateaus_degc:
            plateau(degc)
    else:
        plateau(tp.ramp_from_degc)
        ramp_plan = replace(base, poses=tp.plateau_poses, rate_steps=tp.ramp_rate_steps)
        cycle = tuple(replace(s, name=f"ramp {s.name}") for s in plan_steps(ramp_plan)[1:])
        items.append(RampStep(0, f"ramp {_label(tp.ramp_from_degc)}->{_label(tp.ramp_to_degc)}",
                              tp.ramp_from_degc, tp.ramp_to_degc, tp.ramp_k_per_min, cycle))
        items.append(SoakStep(0, f"soak {_label(tp.ramp_to_degc)}", tp.ramp_to_degc))
        items.extend(_plateau_rig_steps(tp, tp.ramp_to_degc))
    if tp.raw_check and tp.verify_degc is not None:
        plateau(tp.verify_degc, CHECK_PREFIX)
    return [replace(item, index=k) for k, item in enumerate(items)]


def temperature_slope_k_per_min(t_s: np.ndarray, temp_degc: np.ndarray) -> float:
    """Least-squares slope of a temperature record (K/min); NaN with fewer than 3 samples."""
    if len(t_s) < 3:
        return math.nan
    tc = t_s - t_s.mean()
    denom = float(tc @ tc)
    if denom <= 0:
        return math.nan
    return float(tc @ (temp_degc - temp_degc.mean()) / denom) * 60.0


@dataclass(frozen=True)
class ThermalTiming:
    """Where a batch's time went (station clock s, except ``fit_wall_s``).

    ``cycle_s`` is what the batch takes on a real rig and chamber: the sequence (incl. soaks), the
    fits (wall time), the verification at its temperature, and the chamber's return to ambient.
    """

    sequence_s: float
    fit_wall_s: float
    verify_s: float
    ambient_s: float
    units: int

    @property
    def cycle_s(self) -> float:
        return self.sequence_s + self.fit_wall_s + self.verify_s + self.ambient_s

    @property
    def per_unit_s(self) -> float:
        return self.cycle_s / max(self.units, 1)


class ThermalSequence:
    """The steps of a :class:`ThermalPlan` and the chamber around them: a :class:`~station.sequence.runner.RunSequence`.

    The :class:`~station.sequence.runner.SequenceRunner` takes it (``sequence=``; :func:`thermal_runner`
    builds both) and calls its hooks; the runner's provisioner writes every PASS unit first
    (``batch_verification``), then :meth:`before_verification` brings the chamber to the verification
    temperature and soaks the units, then the provisioner verifies each.

    Args:
        chamber: the open chamber (:func:`station.chamber.open_chamber`).
        thermal: the thermal plan (its ``base`` is the rig plan).

    After a run: ``check_sessions`` (slot -> check recording), ``timing``, ``chamber_at_ambient``,
    ``chamber_message`` (why the chamber's teardown failed, '' if it did not).
    """

    batch_verification = True

    def __init__(self, chamber: Chamber, thermal: ThermalPlan) -> None:
        self.chamber = chamber
        self.thermal = thermal
        self.steps = thermal_steps(thermal)
        self.check_sessions: dict[int, Session] = {}
        self.timing: ThermalTiming | None = None
        self.chamber_at_ambient = False
        self.chamber_message = ""
        self._steps_failed = False
        self._fresh_start = False
        self._chamber_home_done = False
        self._next_index = len(self.steps)
        self._chamber_reconnects0 = 0
        self._ambient_s = 0.0
        self._run: SequenceRunner | None = None

    @property
    def verification_name(self) -> str:
        return f"verification at {self.verify_degc:g} degC"

    def _r(self) -> SequenceRunner:
        assert self._run is not None, "the sequence runs inside a SequenceRunner"
        return self._run

    # --- the run --------------------------------------------------------------------------------------

    def after_run(self, run: SequenceRunner, result: RunResult | None) -> RunResult | None:
        """The chamber back to ambient (also when the run raised), the batch's timing, a chamber teardown fault."""
        self._run = run
        self._chamber_home()
        if result is None:
            return None
        fit_wall_s = run.finish_wall_s - run.verify_s / run.clock.scale
        self.timing = ThermalTiming(result.sequence_s, fit_wall_s, run.verify_s, self._ambient_s, len(result.units))
        if self.chamber_message:
            message = f"{result.message}; {self.chamber_message}" if result.message else self.chamber_message
            outcome = Outcome.ERROR if result.outcome == Outcome.PASS else result.outcome
            result = replace(result, outcome=outcome, message=message)
        return result

    def run_steps(self, run: SequenceRunner, fx: Fixture, verdicts: list[UnitVerdict], reconnects0: int) -> None:
        self._run = run
        self.check_sessions, self.timing = {}, None
        self.chamber_at_ambient, self.chamber_message = False, ""
        self._steps_failed = self._fresh_start = self._chamber_home_done = False
        self._next_index, self._ambient_s = len(self.steps), 0.0
        self._chamber_reconnects0 = self.chamber.reconnects
        try:
            st = self.chamber.state()
            if st.alarm and st.alarm_code == AlarmCode.WATCHDOG:  # left by an earlier session that stopped beating
                self.chamber.acknowledge_alarm()
            self.chamber.check()
            for item in self.steps:
                if not fx.active:
                    log.warning("run %s: no unit left to measure; stopping before '%s'", self._r().run_id, item.name)
                    return
                self._do_step(fx, item, verdicts, reconnects0)
        except BaseException:
            self._steps_failed = True
            raise
        finally:
            self._t_steps_end = self._r().clock.now()

    def _do_step(self, fx: Fixture, item: ThermalItem, verdicts: list[UnitVerdict], reconnects0: int,
                 index: int | None = None) -> None:
        if fx.abort.is_set():
            raise KeyboardInterrupt
        index = item.index if index is None else index
        t0 = self._r().clock.now()
        self._r().emit(StepStarted(self._r().run_id, index, item.name, item.kind.label, t0, item.hold_s))
        try:
            if isinstance(item, Step) and item.kind != Kind.REST and self._fresh_start:
                # the rig waited for the chamber: the capture starts after this step's confirmation, never
                # right after the previous window
                moved = position_rig(fx, item)
                report = capture(fx, item, "settled")
                report.rig_moved = moved
                self._fresh_start = False
            elif isinstance(item, Step):
                report = STEP_FUNCTIONS[item.kind](fx, item)
            elif isinstance(item, ChamberStep):
                report = self._chamber_step(fx, item)
            elif isinstance(item, SoakStep):
                report = self._soak(fx, item)
            else:
                report = StepReport()
            if not isinstance(item, Step):
                self._fresh_start = True
            self._supervise(fx, reconnects0)
        except BaseException as exc:
            aborted = isinstance(exc, KeyboardInterrupt)
            why = self._r().abort_reason if aborted else f"{type(exc).__name__}: {exc}"
            now = self._r().clock.now()
            self._r().emit(StepFinished(self._r().run_id, index, item.name, now, now - t0, False, len(fx.active), why))
            raise
        problems = self._r().apply_report(fx, item, report, verdicts)
        now = self._r().clock.now()
        self._r().emit(StepFinished(self._r().run_id, index, item.name, now, now - t0, not problems, len(fx.active),
                                    "; ".join(problems)))
        if isinstance(item, RampStep):
            self._ramp(fx, item, verdicts, reconnects0)

    def _supervise(self, fx: Fixture, reconnects0: int) -> None:
        """After every step: the chamber has no alarm, neither link was re-established."""
        self.chamber.check()
        if self._r().options.rig_reconnect_is_error:
            if fx.rig.reconnects > reconnects0:
                raise RigLinkError(f"the rig link dropped during the run and was re-established "
                                   f"({fx.rig.reconnects - reconnects0} reconnect(s)); the run is not trusted")
            if self.chamber.reconnects > self._chamber_reconnects0:
                raise ChamberLinkError(f"the chamber link dropped during the run and was re-established "
                                       f"({self.chamber.reconnects - self._chamber_reconnects0} reconnect(s)); "
                                       f"the chamber went unsupervised, the run is not trusted")

    def _rest_step(self) -> Step:
        return Step(0, "rest pose", Kind.POSE, self.thermal.base.rest_pose, 0.0, 0.0)

    def _pull(self, fx: Fixture, progress: dict[int, float], report: StepReport) -> None:
        """Move every active unit's buffered samples into its record; a silent unit is a sensor fault."""
        now = time.monotonic()
        for unit in fx.active:
            if unit.slot in report.errors:
                continue
            try:
                if unit.pull():
                    progress[unit.slot] = now
            except HardwareError as exc:
                report.errors[unit.slot] = exc
                continue
            if now - progress.setdefault(unit.slot, now) > fx.silence_wall_s:
                report.errors[unit.slot] = SensorTimeout(
                    f"sensor {unit.serial or unit.url} went silent: no sample for {fx.silence_wall_s:.2f} s (wall)")

    def _chamber_step(self, fx: Fixture, item: ChamberStep) -> StepReport:
        """Rig still in the rest pose, setpoint written, RUN, the air confirmed at the setpoint."""
        report = StepReport(rig_moved=drive_rig(fx.rig, self._rest_step(), self._r().options))
        self.chamber.set_setpoint(item.degc, item.ramp_k_per_min)
        self.chamber.run()
        progress: dict[int, float] = {}
        deadline = self._r().clock.now() + self.thermal.setpoint_timeout_s
        poll = max(self.thermal.soak_poll_s, getattr(self.chamber, "poll_s", 1.0))
        while True:
            self._pull(fx, progress, report)
            st = self.chamber.check()
            if st.at_setpoint and st.running and abs(st.air_degc - item.degc) <= getattr(self.chamber,
                                                                                         "setpoint_tol_k", 0.5):
                return report
            if self._r().clock.now() > deadline:
                raise ChamberSetpointTimeout(f"chamber did not reach {item.degc:g} degC within "
                                             f"{self.thermal.setpoint_timeout_s:g} s: {st.describe()}", st)
            if fx.abort.is_set():
                raise KeyboardInterrupt
            _check_rig(fx.rig)
            self._r().clock.sleep(poll)

    def _soak(self, fx: Fixture, item: SoakStep) -> StepReport:
        """The soak gate: wait until every active unit's temperature slope over the last ``soak_window_s``
        is within ``soak_rate_k_per_min`` (or ``soak_timeout_s`` passed); one gate per unit."""
        tp = self.thermal
        report = StepReport(rig_moved=drive_rig(fx.rig, self._rest_step(), self._r().options))
        t_start = self._r().clock.now()
        deadline = t_start + tp.soak_timeout_s
        progress: dict[int, float] = {}
        slopes: dict[int, float] = {}
        temps: dict[int, float] = {}
        while True:
            self._pull(fx, progress, report)
            self.chamber.check()
            _check_rig(fx.rig)
            covered = self._r().clock.now() - t_start >= tp.soak_window_s
            for unit in fx.active:
                if unit.slot in report.errors:
                    continue
                t, temp = unit.recent_temperature(tp.soak_window_s)
                slopes[unit.slot] = temperature_slope_k_per_min(t, temp) if covered else math.nan
                temps[unit.slot] = float(np.mean(temp)) if len(temp) else math.nan
            waiting = [u for u in fx.active if u.slot not in report.errors
                       and not abs(slopes.get(u.slot, math.nan)) <= tp.soak_rate_k_per_min]
            if not waiting or self._r().clock.now() > deadline:
                break
            if fx.abort.is_set():
                raise KeyboardInterrupt
            self._r().clock.sleep(tp.soak_poll_s)
        for unit in fx.active:
            if unit.slot in report.errors:
                continue
            slope = slopes.get(unit.slot, math.nan)
            report.gates[unit.slot] = [
                Measurement.in_range("soak_rate", abs(slope) if math.isfinite(slope) else math.inf, 0.0,
                                     tp.soak_rate_k_per_min, "K/min"),
                Measurement.in_range("soak_temperature", temps.get(unit.slot, math.nan), -math.inf, math.inf, "degC"),
                Measurement.in_range("soak_time", self._r().clock.now() - t_start, 0.0, tp.soak_timeout_s, "s"),
            ]
        return report

    def _ramp(self, fx: Fixture, item: RampStep, verdicts: list[UnitVerdict], reconnects0: int) -> None:
        """Chamber ramp to ``to_degc``; the rig cycles through ``item.cycle`` until the air is there."""
        drive_rig(fx.rig, self._rest_step(), self._r().options)
        self.chamber.set_setpoint(item.to_degc, item.k_per_min)
        self.chamber.run()
        ramp_s = abs(item.to_degc - item.from_degc) / item.k_per_min * 60.0
        t_ramp0 = self._r().clock.now()
        deadline = t_ramp0 + ramp_s + self.thermal.setpoint_timeout_s
        k = 0
        while fx.active:
            st = self.chamber.check()
            if st.at_setpoint and st.running:
                return
            if self._r().clock.now() > deadline:
                raise ChamberSetpointTimeout(f"chamber ramp did not reach {item.to_degc:g} degC within "
                                             f"{deadline - t_ramp0:.0f} s: {st.describe()}", st)
            if not item.cycle:
                self._r().clock.sleep(self.thermal.soak_poll_s)
                continue
            step = item.cycle[k % len(item.cycle)]
            step = replace(step, name=f"{step.name} #{k // len(item.cycle) + 1}")
            self._do_step(fx, step, verdicts, reconnects0, index=self._next_index)
            self._next_index += 1
            k += 1

    # --- teardown and after the rig ----------------------------------------------------------------------

    def after_teardown(self, run: SequenceRunner, failed: bool) -> None:
        self._run = run
        if self._steps_failed or failed:
            self._chamber_home()  # nothing more to do at temperature

    def _chamber_home(self) -> None:
        """Bring the chamber back to ambient (command, then wait up to ``ambient_timeout_s``); once."""
        if self._chamber_home_done:
            return
        self._chamber_home_done = True
        tp = self.thermal
        t0 = self._r().clock.now()
        for _ in range(2):
            try:
                self.chamber.go_ambient(tp.ambient_degc)
                st = self.chamber.state()
                if st.alarm:
                    self.chamber_message = (f"chamber alarm {st.alarm_code} latched: conditioning stopped, the "
                                            f"chamber drifts to ambient by itself")
                elif tp.ambient_timeout_s > 0:
                    self.chamber.wait_at_setpoint(tp.ambient_timeout_s)
                    self.chamber_at_ambient = True
                break
            except KeyboardInterrupt:
                self.chamber_message = "chamber teardown interrupted; ambient was commanded again"
                continue
            except HardwareError as exc:
                self.chamber_message = f"could not bring the chamber back to ambient ({type(exc).__name__}: {exc})"
                log.error("run %s: %s", self._r().run_id, self.chamber_message)
                break
        self._ambient_s = self._r().clock.now() - t0

    def before_fits(self, run: SequenceRunner, channels: list[UnitChannel]) -> None:
        """Assemble each unit's check plateau into a check recording of its own, out of the fit's recording."""
        self._run = run
        for unit in channels:
            check = [w for w in unit.windows if w.step.startswith(CHECK_PREFIX)]
            if not check:
                continue
            calibration = [w for w in unit.windows if not w.step.startswith(CHECK_PREFIX)]
            unit.windows = check
            try:
                session = build_session(unit, run.plan.gravity_mps2, {**run.metadata(unit), "purpose": "check"})
            except StationError as exc:
                log.error("slot %d: could not assemble the check recording: %s", unit.slot, exc)
                session = None
            finally:
                unit.windows = calibration
            if session is not None:
                self.check_sessions[unit.slot] = session
                self._save_check(session)

    def _save_check(self, session: Session) -> None:
        out_dir = self._r().out_dir
        if out_dir is None:
            return
        try:
            out_dir.mkdir(parents=True, exist_ok=True)
            path = out_dir / f"{session.serial}_{self._r().run_id}.check.csv"
            path.write_bytes(format_session(session).encode("utf-8"))
        except (OSError, StationError) as exc:
            log.error("could not save the check recording of %s: %s", session.serial, exc)

    # --- writing and verification at the verification temperature -----------------------------------------

    @property
    def verify_degc(self) -> float:
        tp = self.thermal
        return tp.verify_degc if tp.verify_degc is not None else tp.calibration_degc[-1]

    def before_verification(self, run: SequenceRunner, units: list[UnitResult]) -> dict[int, str]:
        """Chamber to the verification temperature and the units soaked there (see :meth:`_verification_soak`)."""
        self._run = run
        return self._verification_soak(units)

    def _verification_soak(self, units: list[UnitResult]) -> dict[int, str]:
        """Chamber to the verification temperature, units streaming raw until their temperatures are
        stable; returns slot -> why for units that did not settle (they FAIL). Chamber faults raise."""
        tp, T = self.thermal, self.verify_degc
        drive_rig(self._r().rig, self._rest_step(), self._r().options)
        self.chamber.set_setpoint(T, tp.move_ramp_k_per_min)
        self.chamber.run()
        self.chamber.wait_at_setpoint(tp.setpoint_timeout_s)
        rate = int(self._r().plan.sample_rate_hz)
        records: dict[int, list] = {r.slot: [] for r in units}
        for r in units:
            self._r().sensors[r.slot].start_stream(rate)
        t_start = self._r().clock.now()
        slopes: dict[int, float] = {}
        temps: dict[int, float] = {}
        try:
            while True:
                self._r().clock.sleep(tp.soak_poll_s)
                self.chamber.check()
                for r in units:
                    block = self._r().sensors[r.slot].drain()
                    if len(block):
                        records[r.slot].append((block.t_s, block.temp_degc))
                    t = np.concatenate([b[0] for b in records[r.slot]]) if records[r.slot] else np.zeros(0)
                    temp = np.concatenate([b[1] for b in records[r.slot]]) if records[r.slot] else np.zeros(0)
                    if len(t):
                        keep = t >= t[-1] - tp.soak_window_s
                        t, temp = t[keep], temp[keep]
                        records[r.slot] = [(t, temp)]
                    covered = self._r().clock.now() - t_start >= tp.soak_window_s
                    slopes[r.slot] = temperature_slope_k_per_min(t, temp) if covered else math.nan
                    temps[r.slot] = float(np.mean(temp)) if len(temp) else math.nan
                if all(abs(slopes[r.slot]) <= tp.soak_rate_k_per_min for r in units):
                    break
                if self._r().clock.now() - t_start > tp.soak_timeout_s:
                    break
        finally:
            for r in units:
                with contextlib.suppress(HardwareError):
                    self._r().sensors[r.slot].stop_stream()
        unstable: dict[int, str] = {}
        for r in units:
            gates = [
                Measurement.in_range("soak_rate", abs(slopes[r.slot]) if math.isfinite(slopes[r.slot]) else math.inf,
                                     0.0, tp.soak_rate_k_per_min, "K/min"),
                Measurement.in_range("soak_temperature", temps[r.slot], -math.inf, math.inf, "degC"),
            ]
            for g in gates:
                self._r().emit(Measured(self._r().run_id, r.slot, r.serial, f"verify soak {_label(T)}", g))
            if not gates[0].passed:
                unstable[r.slot] = f"verification soak at {T:g} degC: {gates[0].describe()}"
        return unstable


def thermal_runner(
    rig: Rig,
    sensors: Sequence[Sensor],
    clock: Clock,
    chamber: Chamber,
    thermal: ThermalPlan,
    **kwargs: Any,
) -> SequenceRunner:
    """A :class:`~station.sequence.runner.SequenceRunner` for ``thermal`` in ``chamber`` (``runner.sequence`` is
    the :class:`ThermalSequence`).

    ``kwargs``: the runner's other arguments (``plan`` is the thermal plan's base); the provisioner's
    verifier verifies at the verification temperature. Without ``fit_options`` the fit adds the temperature
    polynomials where the recording separates them (``thermal="auto"``): the plan moves the temperature.
    """
    kwargs.pop("plan", None)
    if kwargs.get("fit_options") is None:
        kwargs["fit_options"] = FitOptions(thermal="auto")
    return SequenceRunner(rig, sensors, clock, plan=thermal.base, sequence=ThermalSequence(chamber, thermal), **kwargs)


def _check_rig(rig: Rig) -> None:
    st = rig.state()
    if st.fault:
        raise RigFault(st.fault_code)


__all__ = [
    "CHECK_PREFIX",
    "ChamberLinkError",
    "ChamberStep",
    "RampStep",
    "SoakStep",
    "ThermalSequence",
    "ThermalTiming",
    "temperature_slope_k_per_min",
    "thermal_runner",
    "thermal_steps",
]
