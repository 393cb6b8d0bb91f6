"""The rig's calibration plan: what the rig does, in what order, for how long.

A :class:`RigPlan` says what the rig does: a still rest from power-on, the six gravity
poses reached by tumbling, then constant-rate steps about each sensor axis (the rig
tumbles that axis up, then spins the rate table about the vertical). :func:`build_trajectory`
turns it into the three axis trajectories (roll, pitch, yaw; :mod:`station.physics.motion`)
and a segment table with the rig's reference (spec session-csv-v1: what the rig knows).

Angles in the plan are degrees, rates deg/s, accelerations deg/s^2, times s; inside the
trajectory everything is rad, rad/s, rad/s^2.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from station.kernel.errors import StationError
from station.kernel.geometry import AXIS_INDEX, POSE_ANGLES_DEG

_DEG = math.pi / 180.0


class PlanError(StationError):
    """A rig plan that cannot be run (unknown pose or axis, non-positive duration, ...)."""


@dataclass(frozen=True)
class RigPlan:
    """What the rig does during one session.

    Attributes:
        sample_rate_hz: sensor sample rate (Hz).
        rest_s: still period from power-on (s), in ``rest_pose``.
        rest_pose: orientation during the rest ('+z' = z axis up), also the rig's home.
        poses: gravity poses in order ('+x', '-x', ...), each held ``pose_hold_s`` (s).
        tumble_rate_dps, tumble_accel_dps2: max rate (deg/s) and acceleration (deg/s^2) of
            the roll and pitch gimbal axes while tumbling.
        rate_steps: (axis, rate_dps) constant-rate steps, rate about the sensor's nominal
            axis 'x'|'y'|'z' in deg/s; consecutive steps about the same axis share one
            tumble. Each is held ``rate_hold_s`` (s) after the ramp and a settle.
        rate_flip: axes for which the rig puts the negative axis up before spinning (the
            table then spins the other way so the sensor still sees ``rate_dps``).
        table_accel_dps2: rate-table acceleration for rate ramps (deg/s^2).
        settle_s: settling time after every tumble and ramp (s), part of the ``move``.
        gravity_mps2: local gravity (m/s^2).
        latitude_deg: site latitude (deg); heading_deg: azimuth of the rig's world y axis
            (yaw = 0) from true north, clockwise (deg).
        serial: serial number for the session, None to use the simulated unit's.
    """

    sample_rate_hz: float = 100.0
    rest_s: float = 300.0
    rest_pose: str = "+z"
    poses: tuple[str, ...] = ("+z", "-z", "+x", "-x", "+y", "-y")
    pose_hold_s: float = 30.0
    tumble_rate_dps: float = 60.0
    tumble_accel_dps2: float = 120.0
    rate_steps: tuple[tuple[str, float], ...] = tuple(
        (axis, sign * rate) for axis in "xyz" for rate in (50.0, 100.0, 200.0) for sign in (1.0, -1.0)
    )
    rate_flip: tuple[str, ...] = ()
    rate_hold_s: float = 12.0
    table_accel_dps2: float = 100.0
    settle_s: float = 2.0
    gravity_mps2: float = 9.8128
    latitude_deg: float = 52.61
    heading_deg: float = 0.0
    serial: str | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "poses", tuple(self.poses))
        object.__setattr__(self, "rate_steps", tuple((str(a), float(r)) for a, r in self.rate_steps))
        object.__setattr__(self, "rate_flip", tuple(self.rate_flip))
        for pose in (self.rest_pose, *self.poses):
            if pose not in POSE_ANGLES_DEG:
                raise PlanError(f"unknown pose {pose!r}; poses are {', '.join(POSE_ANGLES_DEG)}")
        for axis, _ in self.rate_steps:
            if axis not in AXIS_INDEX:
                raise PlanError(f"unknown rate axis {axis!r}; axes are x, y, z")
        for axis in self.rate_flip:
            if axis not in AXIS_INDEX:
                raise PlanError(f"unknown rate_flip axis {axis!r}; axes are x, y, z")
        for name in ("sample_rate_hz", "tumble_rate_dps", "tumble_accel_dps2", "table_accel_dps2", "gravity_mps2"):
            if not getattr(self, name) > 0:
                raise PlanError(f"plan: {name} must be > 0, got {getattr(self, name)!r}")
        for name in ("rest_s", "pose_hold_s", "rate_hold_s", "settle_s"):
            if not getattr(self, name) >= 0:
                raise PlanError(f"plan: {name} must be >= 0, got {getattr(self, name)!r}")


def with_move_time_scale(plan: RigPlan, factor: float) -> RigPlan:
    """``plan`` on a rig whose moves take ``factor`` times as long (a slower or faster rig, a busier host).

    Tumbles (trapezoids) scale by ``factor`` with the rate divided by it and the acceleration by its
    square; table ramps with the acceleration divided by it; the settle time with it. Holds are unchanged.
    """
    if not factor > 0:
        raise PlanError(f"move time factor must be > 0, got {factor!r}")
    return replace(
        plan,
        tumble_rate_dps=plan.tumble_rate_dps / factor,
        tumble_accel_dps2=plan.tumble_accel_dps2 / factor**2,
        table_accel_dps2=plan.table_accel_dps2 / factor,
        settle_s=plan.settle_s * factor,
    )


def default_plan() -> RigPlan:
    """A ~14-minute session at 100 Hz: 300 s rest, six 30 s poses, +-50/100/200 deg/s about each axis."""
    return RigPlan()


def random_plan(rng: np.random.Generator) -> RigPlan:
    """A plan with random pose order, rates, durations and sample rate, for robustness tests."""
    poses = tuple(str(p) for p in rng.permutation(list(POSE_ANGLES_DEG)))
    rates = sorted(rng.choice([20.0, 50.0, 100.0, 150.0, 200.0, 300.0], size=int(rng.integers(1, 4)), replace=False))
    axes = [str(a) for a in rng.permutation(["x", "y", "z"])]
    steps: list[tuple[str, float]] = []
    for axis in axes:
        for rate in rates:
            signs = (1.0, -1.0) if rng.random() < 0.5 else (-1.0, 1.0)
            steps.extend((axis, s * float(rate)) for s in signs)
    flip = tuple(a for a in "xyz" if rng.random() < 0.5)
    return RigPlan(
        sample_rate_hz=float(rng.choice([100.0, 200.0, 400.0])),
        rest_s=float(np.round(rng.uniform(60.0, 400.0), 1)),
        rest_pose=str(rng.choice(list(POSE_ANGLES_DEG))),
        poses=poses,
        pose_hold_s=float(np.round(rng.uniform(10.0, 40.0), 1)),
        tumble_rate_dps=float(rng.choice([30.0, 60.0, 90.0])),
        tumble_accel_dps2=float(rng.choice([60.0, 120.0, 240.0])),
        rate_steps=tuple(steps),
        rate_flip=flip,
        rate_hold_s=float(np.round(rng.uniform(5.0, 15.0), 1)),
        table_accel_dps2=float(rng.choice([50.0, 100.0, 200.0])),
        settle_s=float(np.round(rng.uniform(0.5, 3.0), 1)),
        gravity_mps2=float(np.round(rng.uniform(9.78, 9.83), 4)),
        latitude_deg=float(np.round(rng.uniform(-60.0, 70.0), 2)),
        heading_deg=float(np.round(rng.uniform(0.0, 360.0), 1)),
    )
