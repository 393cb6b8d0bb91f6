"""A whole simulated calibration session: a drawn unit on the simulated rig, seeded.

``simulate_session(seed)`` draws a unit of the sensor class (unless one is given),
drives the rig through the plan, renders the IMU and returns the :class:`Session`
together with the truth. The same seed gives the same arrays and, written out, the
same CSV bytes.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from station.kernel.plan import RigPlan, default_plan
from station.kernel.sensor_class import TABLE1, SensorClass
from station.physics.effects import Effects, EffectTruth
from station.physics.imu import Environment, ImuModel
from station.physics.plateau_course import PlateauCourse
from station.physics.trajectory import RigTrajectory, build_plateau_trajectory, build_trajectory
from station.physics.unit import UnitTruth, draw_unit
from station.session.model import Session


@dataclass(frozen=True, eq=False)
class SimResult:
    """A simulated session and everything that made it.

    Attributes:
        session: the recording (SI inside, see :class:`Session`).
        truth: the unit's true parameters.
        plan: the rig plan that was run.
        effects: the effect magnitudes; effect_truth: their SI coefficients for this unit.
        environment: the room (ambient temperature at power-on = ``T_ref``, ambient drift).
        trajectory: the rig trajectory and segment table.
        temperature: the unit's true temperature course when the session ran at temperature
            plateaus (:class:`~station.physics.plateau_course.PlateauCourse`), else None.
    """

    session: Session
    truth: UnitTruth
    plan: RigPlan
    effects: Effects
    effect_truth: EffectTruth
    environment: Environment
    trajectory: RigTrajectory
    temperature: PlateauCourse | None = None


def _num(x: float) -> str:
    """Shortest round-trip text of a float, without a trailing ``.0``."""
    s = repr(float(x))
    return s[:-2] if s.endswith(".0") else s


def simulate_session(
    seed: int,
    *,
    plan: RigPlan | None = None,
    sensor_class: SensorClass = TABLE1,
    effects: Effects | None = None,
    unit: UnitTruth | None = None,
    temperature_plateaus_degc: Sequence[float] | None = None,
    soak_s: float = 600.0,
    thermal_lag_s: float = 150.0,
    effect_truth: EffectTruth | None = None,
    rest_tilt: tuple[np.ndarray, float] | None = None,
) -> SimResult:
    """Simulate one session of a unit (drawn from ``sensor_class`` with ``seed`` unless given).

    The seed's first spawned stream draws the unit, the second seeds the IMU model (noise,
    drift, outliers, temperature, environment). ``t`` starts at 0 (power-on); samples are
    at ``k / sample_rate_hz``.

    ``temperature_plateaus_degc`` (e.g. ``(25, 45, 5, 25)``): a climate-chamber session instead. The
    plan's rest, poses and rate steps run once per plateau (:func:`build_plateau_trajectory`; every
    plateau after the first begins with a ``soak_s`` rest while the chamber moves), and the unit's
    temperature follows the setpoints with a first-order lag ``thermal_lag_s`` plus its own
    self-heating (:class:`~station.physics.plateau_course.PlateauCourse`). The unit is powered on soaked at
    the first plateau, which is therefore the temperature effects' ``T_ref``. Without it, nothing
    changes (same seed, same bytes).

    ``effect_truth``: explicit SI effect coefficients instead of realizing ``effects`` (e.g. the IEEE 952
    polynomial, which no :class:`Effects` magnitude realizes).

    ``rest_tilt`` = ``(phi, until_s)``: the unit's attitude in the rest before ``until_s`` is tilted by the
    rotation vector ``phi`` (rad, sensor frame) against the commanded pose, the reference is not (a soak rack's
    slot: :func:`station.sim.line_sim.simulate_line`). None: nothing changes (same seed, same bytes).
    """
    plan = plan if plan is not None else default_plan()
    effects = effects if effects is not None else Effects()
    unit_seq, imu_seq = np.random.SeedSequence(seed).spawn(2)
    if unit is None:
        unit = draw_unit(sensor_class, np.random.default_rng(unit_seq), serial=plan.serial)
    course: PlateauCourse | None = None
    if temperature_plateaus_degc is None:
        model = ImuModel(
            unit, sensor_class, effects, imu_seq, latitude_deg=plan.latitude_deg, heading_deg=plan.heading_deg,
            effect_truth=effect_truth,
        )
        traj = build_trajectory(plan)
    else:
        plateaus = tuple(float(p) for p in temperature_plateaus_degc)
        traj, starts = build_plateau_trajectory(plan, len(plateaus), soak_s)
        course = PlateauCourse(plateaus, starts, thermal_lag_s, unit.self_heating_k, unit.self_heating_tau_s)
        model = ImuModel(
            unit, sensor_class, effects, imu_seq, latitude_deg=plan.latitude_deg, heading_deg=plan.heading_deg,
            environment=Environment(ambient_degc=plateaus[0]), temperature_degc=course, effect_truth=effect_truth,
        )
    t = traj.sample_times()
    kin = traj.kinematics(t, time_offset_s=model.time_offset_s, pose_tilt_rad=model.effect_truth.pose_tilts(),
                          rest_tilt=rest_tilt)
    raw = model.render(kin, plan.gravity_mps2)
    segment, kind = traj.labels(t)
    ref_f, ref_w = traj.reference(t)
    metadata = {
        "serial": plan.serial if plan.serial is not None else unit.serial,
        "sample_rate_hz": _num(plan.sample_rate_hz),
        "gravity_mps2": _num(plan.gravity_mps2),
        "latitude_deg": _num(plan.latitude_deg),
        "heading_deg": _num(plan.heading_deg),
        "station": "sim",
        "rig": "sim",
        "sim_seed": str(seed),
        "sim_class": sensor_class.name,
        "sim_effects": effects.describe(),
    }
    if course is not None:
        metadata["sim_temperature_plateaus_degc"] = " ".join(_num(p) for p in course.plateaus_degc)
        metadata["sim_soak_s"] = _num(soak_s)
    session = Session(
        metadata=metadata,
        t_s=t,
        segment=segment,
        kind=kind,
        accel_mps2=raw.accel_mps2,
        gyro_radps=raw.gyro_radps,
        temp_degc=raw.temp_degc,
        ref_accel_mps2=ref_f,
        ref_gyro_radps=ref_w,
    )
    return SimResult(session, unit, plan, effects, model.effect_truth, model.environment, traj, course)
