"""The calibration sequence as plain functions that receive their hardware.

:func:`plan_steps` turns a :class:`~station.kernel.plan.RigPlan` into steps: the
power-on rest (drift and noise, eq. 3: the sensors are power-cycled at its start so
``g(0) = 1``), the six gravity poses, and the constant-rate steps about each sensor
axis. :func:`power_on_rest`, :func:`gravity_pose` and :func:`rate_step` each get a
:class:`Fixture` (the rig, the fixture's sensors, the clock, the options) and a
:class:`Step`; they position the rig, confirm it settled from its status bits and
readbacks, capture every active unit concurrently (one worker thread per sensor),
supervise the rig while capturing, and return a :class:`StepReport` with each
unit's gate results or error. Rig problems raise :class:`~station.kernel.errors.HardwareError`
(the whole run is an ERROR); a sensor problem only ends its own unit.
:func:`bring_to_rest` is the teardown. Angles deg, rates deg/s at the rig; SI inside.
"""

from __future__ import annotations

import math
import threading
from collections.abc import Callable
from concurrent.futures import FIRST_EXCEPTION, Future, ThreadPoolExecutor, wait
from dataclasses import dataclass, field

import numpy as np

from station.kernel.clock import Clock
from station.kernel.errors import HardwareError
from station.kernel.geometry import AXIS_INDEX, POSE_ANGLES_DEG, up_vector
from station.kernel.measurement import Measurement
from station.kernel.plan import RigPlan
from station.rig.protocol import Rig, RigFault, RigState
from station.rig.registers import FaultCode, angle_error_deg
from station.sequence.capture import CaptureStopped, UnitChannel, Window
from station.sequence.gates import clock_rate_gate, evaluate, frame_lateness_gate, rig_gate
from station.sequence.options import SequenceOptions
from station.session.model import Kind

_DEG = math.pi / 180.0


class RigNotHolding(HardwareError):
    """The rig left the confirmed pose or rate while a step was being captured."""


@dataclass(frozen=True)
class Step:
    """One step of the sequence.

    Attributes:
        index: position in the sequence; name: ``'rest'``, ``'pose -z'``, ``'rate x +50'``.
        kind: REST, POSE or RATE.
        pose: the pose whose nominal axis points up ('+x', '-z', ...).
        table_rate_dps: rate-table command (deg/s, counter-clockwise seen from above).
        rate_axis: for rate steps the nominal sensor axis turned about; rate_dps the rate about
            ``+rate_axis`` the sensor sees (deg/s).
        hold_s: capture duration (s).
    """

    index: int
    name: str
    kind: Kind
    pose: str
    table_rate_dps: float
    hold_s: float
    rate_axis: str | None = None
    rate_dps: float = 0.0

    def reference(self, gravity_mps2: float) -> tuple[np.ndarray, np.ndarray]:
        """What the rig imposes: (specific force m/s^2, angular rate rad/s) in the nominal sensor frame."""
        f = gravity_mps2 * up_vector(self.pose)
        w = np.zeros(3)
        if self.kind == Kind.RATE and self.rate_axis is not None:
            w[AXIS_INDEX[self.rate_axis]] = self.rate_dps * _DEG
        return f, w


def plan_steps(plan: RigPlan) -> list[Step]:
    """The steps of ``plan``: rest, poses, then rate steps (a flipped axis spins upside down, table reversed)."""
    steps = [Step(0, "rest", Kind.REST, plan.rest_pose, 0.0, plan.rest_s)]
    for pose in plan.poses:
        steps.append(Step(len(steps), f"pose {pose}", Kind.POSE, pose, 0.0, plan.pose_hold_s))
    for axis, rate in plan.rate_steps:
        sign = -1.0 if axis in plan.rate_flip else 1.0
        pose = ("-" if sign < 0 else "+") + axis
        steps.append(
            Step(len(steps), f"rate {axis} {rate:+g}", Kind.RATE, pose, sign * rate, plan.rate_hold_s, axis, rate)
        )
    return steps


@dataclass
class Fixture:
    """The hardware a step works with, and how.

    Attributes:
        rig: the rig (:class:`~station.rig.protocol.Rig`).
        units: every fixture slot's channel (inactive ones are skipped).
        clock: station clock (s).
        options: timeouts and gates.
        gravity_mps2: local gravity (m/s^2).
        sample_rate_hz: sensor sample rate (Hz).
        pool: worker threads for the concurrent captures (one per unit).
        abort: set to stop every capture (operator abort).
        first_sync: slot -> (station time s, sensor time s, half round trip s) of the unit's first clock sync
            in the run (the clock rate gate's origin).
    """

    rig: Rig
    units: list[UnitChannel]
    clock: Clock
    options: SequenceOptions
    gravity_mps2: float
    sample_rate_hz: int
    pool: ThreadPoolExecutor
    abort: threading.Event = field(default_factory=threading.Event)
    first_sync: dict[int, tuple[float, float, float]] = field(default_factory=dict)

    @property
    def active(self) -> list[UnitChannel]:
        return [u for u in self.units if u.active]

    @property
    def silence_wall_s(self) -> float:
        o = self.options
        return max(o.silence_timeout_s / self.clock.scale, o.silence_floor_wall_s)


@dataclass
class StepReport:
    """What one step found, per fixture slot.

    Attributes:
        gates: slot -> gate results of the unit's capture.
        errors: slot -> the sensor fault that ended the unit in this step.
        rig_moved: the rig had to move or change rate for the step.
    """

    gates: dict[int, list[Measurement]] = field(default_factory=dict)
    errors: dict[int, HardwareError] = field(default_factory=dict)
    rig_moved: bool = False


# --- the rig ---------------------------------------------------------------------------------------


def _raise_if_faulted(st: RigState) -> None:
    if st.fault:
        raise RigFault(st.fault_code)


def _at_pose(st: RigState, pose: str, tol_deg: float) -> bool:
    roll, pitch = POSE_ANGLES_DEG[pose]
    return abs(angle_error_deg(st.roll_deg, roll)) <= tol_deg and abs(angle_error_deg(st.pitch_deg, pitch)) <= tol_deg


def clear_stale_watchdog(rig: Rig) -> bool:
    """Reset a latched WATCHDOG fault left by an earlier session; returns whether one was reset.

    A rig arms its watchdog with the first heartbeat after power-up, so every station
    session that ends (and stops beating) leaves it latched. Now that this session
    beats, its cause is gone. Any other latched fault is left for the operator
    (the step then raises :class:`~station.rig.protocol.RigFault`).
    """
    st = rig.state()
    if st.fault and st.fault_code == FaultCode.WATCHDOG:
        rig.reset_fault()
        return True
    return False


def position_rig(fx: Fixture, step: Step) -> bool:
    """Bring the fixture's rig to the step's pose and table rate (:func:`drive_rig`)."""
    return drive_rig(fx.rig, step, fx.options)


def drive_rig(rig: Rig, step: Step, o: SequenceOptions) -> bool:
    """Bring the rig to the step's pose and table rate, confirmed; returns whether it had to move.

    A tumble needs the table still: a spinning table is first ramped to 0. Every
    motion is confirmed by :meth:`Rig.wait_in_position` / :meth:`Rig.wait_rate_settled`
    (status bits and readbacks, never the setpoint). A latched rig fault raises
    :class:`~station.rig.protocol.RigFault` before anything moves.
    """
    st = rig.state()
    _raise_if_faulted(st)
    moved = False
    if not _at_pose(st, step.pose, o.angle_tol_deg):
        if not (st.at_rest and abs(st.rate_dps) <= o.rate_tol_dps):
            rig.spin(0.0)
            rig.wait_rate_settled(o.spin_timeout_s)
        rig.move_to(step.pose)
        rig.wait_in_position(o.move_timeout_s)
        moved = True
        st = rig.state()
    if abs(st.rate_dps - step.table_rate_dps) > o.rate_tol_dps or not st.rate_settled:
        rig.spin(step.table_rate_dps)
        rig.wait_rate_settled(o.spin_timeout_s)
        moved = True
    return moved


def check_rig_holding(st: RigState, step: Step, o: SequenceOptions) -> None:
    """Raise if the rig faulted or left the step's pose or table rate (readbacks within tolerance)."""
    _raise_if_faulted(st)
    if not _at_pose(st, step.pose, o.angle_tol_deg):
        raise RigNotHolding(f"rig left pose {step.pose} during step '{step.name}': {st.describe()}")
    if abs(st.rate_dps - step.table_rate_dps) > o.rate_tol_dps:
        raise RigNotHolding(f"rig table left {step.table_rate_dps:g} deg/s during step '{step.name}': {st.describe()}")


def bring_to_rest(rig: Rig, timeout_s: float) -> RigState:
    """Teardown: stop every axis and wait until the rig reports rest (works while a fault is latched)."""
    rig.stop()
    return rig.wait_at_rest(timeout_s)


# --- capture ---------------------------------------------------------------------------------------


def _synced(fx: Fixture, unit: UnitChannel) -> tuple[float, float, float]:
    """Sync the unit's clock: (station time s, the sensor time then s, half round trip s)."""
    unit.sync(fx.options.sync_tries)
    assert unit.offset_s is not None
    t = fx.clock.now()
    return t, t - unit.offset_s, unit.sync_halfwidth_s


def _capture_unit(
    fx: Fixture, unit: UnitChannel, step: Step, start: str, t_confirm: float, stop: threading.Event
) -> list[Measurement]:
    """One unit's capture of ``step`` (runs in a worker thread)."""
    o = fx.options
    first = fx.first_sync.setdefault(unit.slot, _synced(fx, unit))
    if start == "stream":
        t0 = unit.wait_first(stop, fx.silence_wall_s)
    elif start == "continue" and unit.windows:
        t0 = unit.windows[-1].t1_s
    else:
        t0 = unit.latest_sensor_time(t_confirm + o.settle_guard_s)
    if unit.windows:
        t0 = max(t0, unit.windows[-1].t1_s)
    t1 = t0 + step.hold_s
    unit.collect_until(t1, stop, fx.silence_wall_s)
    assert unit.offset_s is not None
    lateness = fx.clock.now() - (unit.t_last_s + unit.offset_s)
    late = frame_lateness_gate(lateness, 2.0 * o.silence_floor_wall_s * fx.clock.scale, o)
    rate = clock_rate_gate(first, _synced(fx, unit), o)
    timing = [late] if rate is None else [rate, late]
    block = unit.window_samples(t0, t1)
    ref_f, ref_w = step.reference(fx.gravity_mps2)
    unit.windows.append(Window(step.name, step.kind, t0, t1, ref_f, ref_w))
    return timing + evaluate(
        block, step.kind, t0, t1, unit.rate_hz, fx.gravity_mps2, o, step.rate_axis, step.rate_dps * _DEG
    )


def capture(fx: Fixture, step: Step, start: str) -> StepReport:
    """Capture ``step`` on every active unit concurrently while supervising the rig.

    ``start``: ``'stream'`` (the window starts at the first sample of the stream),
    ``'continue'`` (right after the unit's previous window: the rig did not move) or
    ``'settled'`` (the settle guard after now, the rig's confirmation). Sensor faults end
    only their unit (``StepReport.errors``); a rig fault or the rig leaving the step stops
    every capture and raises.
    """
    o, clock = fx.options, fx.clock
    t_confirm = clock.now()
    stop = threading.Event()
    futures: dict[Future[list[Measurement]], UnitChannel] = {
        fx.pool.submit(_capture_unit, fx, u, step, start, t_confirm, stop): u for u in fx.active
    }
    report = StepReport()
    readings: list[RigState] = []

    def supervise() -> None:
        st = fx.rig.state()
        readings.append(st)
        check_rig_holding(st, step, o)

    try:
        pending = set(futures)
        while pending:
            if fx.abort.is_set():
                raise KeyboardInterrupt
            _, pending = wait(pending, timeout=o.supervise_period_s / clock.scale, return_when=FIRST_EXCEPTION)
            if pending:
                supervise()
        supervise()
    finally:
        stop.set()
        wait(futures)
    for fut, unit in futures.items():
        exc = fut.exception()
        if exc is None:
            settled = rig_gate(readings, step.pose, step.table_rate_dps, o)
            report.gates[unit.slot] = ([settled] if settled is not None else []) + fut.result()
        elif isinstance(exc, HardwareError):
            report.errors[unit.slot] = exc
        elif isinstance(exc, CaptureStopped):
            continue
        else:
            raise exc
    return report


def _power_on_unit(unit: UnitChannel, rate_hz: int) -> None:
    unit.power_on(rate_hz)


def power_on_rest(fx: Fixture, step: Step) -> StepReport:
    """Rig to the rest pose and still; power-cycle and start every sensor; capture the rest from power-on."""
    clear_stale_watchdog(fx.rig)
    moved = position_rig(fx, step)
    futures = {fx.pool.submit(_power_on_unit, u, fx.sample_rate_hz): u for u in fx.active}
    wait(futures)
    errors: dict[int, HardwareError] = {}
    for fut, unit in futures.items():
        exc = fut.exception()
        if isinstance(exc, HardwareError):
            errors[unit.slot] = exc
            unit.active = False
        elif exc is not None:
            raise exc
    report = capture(fx, step, "stream")
    report.errors.update(errors)
    report.rig_moved = moved
    return report


def gravity_pose(fx: Fixture, step: Step) -> StepReport:
    """Tumble to a gravity pose (table still), confirm, capture the static pose."""
    moved = position_rig(fx, step)
    report = capture(fx, step, "settled" if moved else "continue")
    report.rig_moved = moved
    return report


def rate_step(fx: Fixture, step: Step) -> StepReport:
    """Tumble the rate axis up (or down when flipped), spin the table, confirm settled, capture."""
    moved = position_rig(fx, step)
    report = capture(fx, step, "settled" if moved else "continue")
    report.rig_moved = moved
    return report


STEP_FUNCTIONS: dict[Kind, Callable[[Fixture, Step], StepReport]] = {
    Kind.REST: power_on_rest,
    Kind.POSE: gravity_pose,
    Kind.RATE: rate_step,
}
