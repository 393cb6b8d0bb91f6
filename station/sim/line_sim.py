"""A simulated unit through the line: its rack recording and its rig recording, seeded.

One unit, one power-on: the unit rests ``rack_s`` in the rack (a fixed orientation the station does
not know: the recording carries no reference), is carried to the rig still powered (``transfer_s``;
those samples are not recorded), and the rig runs its plan. Both recordings are cut from one
simulated session of the unit, so they share its drift realization and its sensor time since
power-on, as a real unit's two recordings do.

The rack's orientation: with the plan's ``rack_orientation`` ``"any"`` one of the six poses at random, level;
with a pose name (``"+z"``: every slot holds its unit that way up) that pose tilted by a random angle up to
``rack_tilt_deg`` about a random horizontal axis (a slot is never quite level; the station does not know the
tilt). Both drawn from the seed. ``simulate_line(..., any_tilt_deg=...)`` tilts the slots of a rack of any orientation
the same way against the face the unit lies on.

``power_cycled=True``: the unit loses power during the transfer; the rig recording is then a new
power-on of the same unit (its sensor time restarts at 0, its warm-up starts again).

Each recording carries ``wall_clock_at_start_s`` (POSIX seconds of its first sample, on the station's
clock) and ``boot_count`` (the sensor's power-on counter); :func:`station.fit.joint.check_power` reads them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from station.kernel.geometry import AXIS_INDEX, rotation_vector_matrix, up_vector
from station.kernel.line_plan import ANY_ORIENTATION, LinePlan, default_line_plan
from station.kernel.plan import RigPlan
from station.kernel.sensor_class import TABLE1, SensorClass
from station.physics.effects import Effects, EffectTruth
from station.physics.unit import UnitTruth
from station.session.model import Kind, Session
from station.sim.session_sim import SimResult, simulate_session

#: Wall clock (POSIX s) of the simulated units' power-on: a fixed date keeps the bytes deterministic.
POWER_ON_WALL_S = 1_790_000_000.0


@dataclass(frozen=True, eq=False)
class LineSim:
    """A unit's two recordings and what made them.

    Attributes:
        rack: the rack's rest from power-on, references NaN.
        rig: the rig's recording, sensor time since power-on.
        truth: the unit's true parameters.
        rack_up: the pose pointing up in the rack (not known to the station).
        rack_tilt_rad: the slot's tilt against ``rack_up`` (rotation vector, sensor frame; zeros when level).
        power_cycled: whether the unit lost power between rack and rig.
        source: the simulated session(s) the recordings were cut from.
    """

    rack: Session
    rig: Session
    truth: UnitTruth
    rack_up: str
    power_cycled: bool
    source: tuple[SimResult, ...]
    rack_tilt_rad: np.ndarray = field(default_factory=lambda: np.zeros(3))

    def rack_specific_force(self) -> np.ndarray:
        """The rack rest's true specific force in the sensor frame (m/s^2): gravity up the tilted ``rack_up``."""
        g = self.rig.gravity_mps2
        return np.asarray(rotation_vector_matrix(self.rack_tilt_rad).T @ (g * up_vector(self.rack_up)))


_POSES = ("+z", "-z", "+x", "-x", "+y", "-y")


def _cut(session: Session, sel: np.ndarray, **meta: str) -> Session:
    return Session(
        metadata={**session.metadata, **meta},
        t_s=session.t_s[sel],
        segment=session.segment[sel],
        kind=session.kind[sel],
        accel_mps2=session.accel_mps2[sel],
        gyro_radps=session.gyro_radps[sel],
        temp_degc=session.temp_degc[sel],
        ref_accel_mps2=session.ref_accel_mps2[sel],
        ref_gyro_radps=session.ref_gyro_radps[sel],
    )


def _unknown(session: Session) -> Session:
    """The rack's view: no reference, every sample one rest segment."""
    n = len(session)
    nan = np.full((n, 3), np.nan)
    return session.replace(segment=np.zeros(n, dtype=np.int64), kind=np.full(n, int(Kind.REST)),
                           ref_accel_mps2=nan, ref_gyro_radps=nan)


def simulate_line(
    seed: int,
    *,
    plan: LinePlan | None = None,
    transfer_s: float = 60.0,
    sensor_class: SensorClass = TABLE1,
    unit: UnitTruth | None = None,
    power_cycled: bool = False,
    rack_tilt_deg: float = 3.0,
    any_tilt_deg: float = 0.0,
    effects: Effects | None = None,
    effect_truth: EffectTruth | None = None,
) -> LineSim:
    """Simulate a unit's rack and rig recordings (the unit drawn with ``seed`` unless given); ``rack_tilt_deg``:
    the largest tilt of a slot when the plan's rack holds its units in one orientation; ``any_tilt_deg``: the same
    for a rack of any orientation (its unit on one of its faces at random, tilted up to that; 0: level); ``effects`` and
    ``effect_truth`` as :func:`~station.sim.session_sim.simulate_session` takes them (e.g. a time offset, the gyro's
    IEEE 952 polynomial), the same in the rack and on the rig."""
    plan = plan if plan is not None else default_line_plan()
    rig: RigPlan = plan.rig
    tilt = np.zeros(3)
    if plan.rack_orientation == ANY_ORIENTATION:
        rack_up = _POSES[int(np.random.default_rng(np.random.SeedSequence([seed, 7])).integers(len(_POSES)))]
    else:
        rack_up = plan.rack_orientation
    if plan.rack_orientation != ANY_ORIENTATION or any_tilt_deg > 0.0:
        rack_tilt_deg = rack_tilt_deg if plan.rack_orientation != ANY_ORIENTATION else any_tilt_deg
        u = np.random.default_rng(np.random.SeedSequence([seed, 8])).uniform(size=2)
        k = AXIS_INDEX[rack_up[1]]
        axis = np.zeros(3)
        axis[(k + 1) % 3], axis[(k + 2) % 3] = math.cos(2.0 * math.pi * u[0]), math.sin(2.0 * math.pi * u[0])
        tilt = math.radians(rack_tilt_deg) * float(u[1]) * axis  # about a horizontal axis of the slot
    rest_tilt = (tilt, plan.rack_s + transfer_s) if np.any(tilt) else None
    if not power_cycled:
        whole = replace(rig, rest_pose=rack_up, rest_s=plan.rack_s + transfer_s + rig.rest_s)
        res = simulate_session(seed, plan=whole, sensor_class=sensor_class, unit=unit, rest_tilt=rest_tilt,
                               effects=effects, effect_truth=effect_truth)
        s = res.session
        t0_rig = plan.rack_s + transfer_s
        rack = _cut(s, s.t_s < plan.rack_s, wall_clock_at_start_s=repr(POWER_ON_WALL_S), boot_count="1")
        # the rig's own short rest (if any) keeps its reference; its segment index stays that of the long rest
        rig_s = _cut(s, s.t_s >= t0_rig, wall_clock_at_start_s=repr(POWER_ON_WALL_S + t0_rig), boot_count="1")
        return LineSim(_unknown(rack), rig_s, res.truth, rack_up, False, (res,), tilt)
    first = simulate_session(seed, plan=replace(rig, rest_pose=rack_up, rest_s=plan.rack_s, poses=(),
                                                rate_steps=()), sensor_class=sensor_class, unit=unit,
                             rest_tilt=rest_tilt, effects=effects, effect_truth=effect_truth)
    second = simulate_session(seed + 1_000_003, plan=rig, sensor_class=sensor_class, unit=first.truth,
                              effects=effects, effect_truth=effect_truth)
    s1 = first.session
    rack = _cut(s1, s1.t_s < plan.rack_s, wall_clock_at_start_s=repr(POWER_ON_WALL_S), boot_count="1")
    rig_s = _cut(second.session, np.ones(len(second.session), dtype=bool), serial=s1.serial,
                 wall_clock_at_start_s=repr(POWER_ON_WALL_S + plan.rack_s + transfer_s), boot_count="2")
    return LineSim(_unknown(rack), rig_s, first.truth, rack_up, True, (first, second), tilt)


__all__ = ["POWER_ON_WALL_S", "LineSim", "simulate_line"]
