"""A simulated hand-held multi-position recording (no rig): random orientations, hand moves between them.

``simulate_handheld(seed)`` draws a unit of the sensor class (Table 1 by default), a still rest at
power-on, then ``n_poses`` random orientations (uniform on SO(3)), each held still for a few seconds,
reached by a hand move: the rotation from one orientation to the next about its fixed axis with a
minimum-jerk time profile, plus a wobble about a random axis that starts and ends at zero (so the
rate's axis turns during the move, as a hand's does). The IMU model of :mod:`station.physics.imu`
renders the samples (eq. 1 with the drift of eq. 3, noise, outliers, ADC). Deterministic: the same
seed gives the same arrays.

The result carries the truth and the true still segments; the recording itself has no labels or
references (an import labels it with the still detector). :func:`counts_with_offsets` turns it into
raw ADC counts with large offsets, as imu_tk's text files hold them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from station.kernel.geometry import Kinematics
from station.kernel.sensor_class import TABLE1, SensorClass
from station.physics.effects import Effects
from station.physics.imu import ImuModel
from station.physics.unit import UnitTruth, draw_unit

__all__ = ["HandheldPlan", "HandheldResult", "counts_with_offsets", "simulate_handheld"]


@dataclass(frozen=True)
class HandheldPlan:
    """What the hand does (times in s, angles in deg, rates Hz, gravity m/s^2).

    Attributes:
        poses: number of still orientations after the rest; None draws 20..40.
        rest_s: still at power-on (the initial still).
        hold_s, move_s: ranges (low, high) of each pose's hold and each move's duration, uniform.
        wobble_deg: largest wobble amplitude during a move.
        sample_rate_hz, gravity_mps2: the recording's.
    """

    poses: int | None = None
    rest_s: float = 120.0
    hold_s: tuple[float, float] = (3.0, 6.0)
    move_s: tuple[float, float] = (1.5, 3.0)
    wobble_deg: float = 20.0
    sample_rate_hz: float = 100.0
    gravity_mps2: float = 9.8128


@dataclass(frozen=True, eq=False)
class HandheldResult:
    """The recording (SI: t_s, accel_mps2, gyro_radps), the unit, and the true still segments [start, stop)."""

    t_s: np.ndarray
    accel_mps2: np.ndarray
    gyro_radps: np.ndarray
    truth: UnitTruth
    still: tuple[tuple[int, int], ...]
    plan: HandheldPlan
    seed: int


def _min_jerk(tau: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """s(tau) = 10 tau^3 - 15 tau^4 + 6 tau^5 and its first two derivatives."""
    s = tau**3 * (10 - 15 * tau + 6 * tau**2)
    ds = 30 * tau**2 * (1 - tau) ** 2
    dds = 60 * tau * (1 - tau) * (1 - 2 * tau)
    return s, ds, dds


def _skew(v: np.ndarray) -> np.ndarray:
    return np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])


def simulate_handheld(
    seed: int,
    plan: HandheldPlan | None = None,
    *,
    sensor_class: SensorClass = TABLE1,
    unit: UnitTruth | None = None,
    effects: Effects | None = None,
    attitudes: np.ndarray | None = None,
    latitude_deg: float = 0.0,
) -> HandheldResult:
    """Simulate one hand-held multi-position recording (see the module docstring).

    ``attitudes``: the rest's and the poses' sensor-to-world rotations, (P + 1, 3, 3), instead of random ones
    (e.g. every pose a turn about one axis). ``latitude_deg``: the site, for an ``earth_rotation`` effect (the
    world frame's heading is the attitudes' own; random attitudes give every pose a random heading).
    """
    plan = plan or HandheldPlan()
    unit_seq, imu_seq, hand_seq = np.random.SeedSequence(seed).spawn(3)
    if unit is None:
        unit = draw_unit(sensor_class, np.random.default_rng(unit_seq))
    rng = np.random.default_rng(hand_seq)
    n_poses = int(plan.poses if plan.poses is not None else rng.integers(20, 41))
    if attitudes is None:
        attitudes = Rotation.random(n_poses + 1, random_state=rng).as_matrix()  # sensor-to-world
    else:
        attitudes = np.asarray(attitudes, dtype=float)
        n_poses = len(attitudes) - 1
    fs = plan.sample_rate_hz
    still: list[tuple[float, float]] = []
    t = 0.0

    def hold(r: np.ndarray, duration: float) -> None:
        nonlocal t
        still.append((t, t + duration))
        t += duration

    hold(attitudes[0], plan.rest_s)
    #: (start, end, kind, attitude at the start, a move's rotation and wobble vectors or None for a hold)
    segments: list[tuple[float, float, str, np.ndarray, tuple[np.ndarray, np.ndarray] | None]] = [
        (0.0, plan.rest_s, "hold", attitudes[0], None)]
    for i in range(1, n_poses + 1):
        duration = float(rng.uniform(*plan.move_s))
        phi = Rotation.from_matrix(attitudes[i - 1].T @ attitudes[i]).as_rotvec()  # body-frame rotation vector
        psi = np.radians(plan.wobble_deg) * rng.uniform(0.3, 1.0) * Rotation.random(random_state=rng).apply([1, 0, 0])
        segments.append((t, t + duration, "move", attitudes[i - 1], (phi, psi)))
        t += duration
        hold_s = float(rng.uniform(*plan.hold_s))
        segments.append((t, t + hold_s, "hold", attitudes[i], None))
        hold(attitudes[i], hold_s)
    n = math.floor(t * fs - 1e-9) + 1
    ts = np.arange(n) / fs
    rotation = np.empty((n, 3, 3))
    omega = np.zeros((n, 3))
    alpha = np.zeros((n, 3))
    for t0, t1, _kind, r0, move in segments:
        sel = np.flatnonzero((ts >= t0) & (ts < t1))
        if move is None:  # a hold
            rotation[sel] = r0
            continue
        phi, psi = move
        d = t1 - t0
        tau = (ts[sel] - t0) / d
        s, ds, dds = _min_jerk(tau)
        # wobble w(tau) = sin(pi tau)^2: zero at both ends with zero rate
        w = np.sin(np.pi * tau) ** 2
        dw = np.pi * np.sin(2 * np.pi * tau)
        ddw = 2 * np.pi**2 * np.cos(2 * np.pi * tau)
        e1 = Rotation.from_rotvec(s[:, None] * phi).as_matrix()
        e2 = Rotation.from_rotvec(w[:, None] * psi).as_matrix()
        rotation[sel] = r0 @ e1 @ e2
        w1 = (ds / d)[:, None] * phi  # body rate of E1 (fixed axis)
        w2 = (dw / d)[:, None] * psi
        e2t_w1 = np.einsum("nji,nj->ni", e2, w1)
        omega[sel] = e2t_w1 + w2
        alpha[sel] = (np.einsum("nji,nj->ni", e2, (dds / d**2)[:, None] * phi) - np.cross(w2, e2t_w1)
                      + (ddw / d**2)[:, None] * psi)
    model = ImuModel(unit, sensor_class, effects or Effects(), imu_seq, latitude_deg=latitude_deg)
    raw = model.render(Kinematics(ts, rotation, omega, alpha), plan.gravity_mps2)
    still_idx = tuple((int(np.ceil(a * fs - 1e-9)), min(n, int(np.ceil(b * fs - 1e-9)))) for a, b in still)
    return HandheldResult(ts, raw.accel_mps2, raw.gyro_radps, unit, still_idx, plan, seed)


def counts_with_offsets(
    result: HandheldResult, rng: np.random.Generator, *, offset_range_lsb: tuple[float, float] = (5000.0, 20000.0)
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, float, float]:
    """Raw counts as an ADC with an offset would give them: ``round(y / lsb) + offset``.

    Returns (accel counts, gyro counts, accel offset, gyro offset, accel LSB per m/s^2, gyro LSB per rad/s);
    each offset is drawn per axis, magnitude uniform in ``offset_range_lsb``, random sign.
    """
    a_sens, g_sens = 1.0 / result.truth.accel.lsb, 1.0 / result.truth.gyro.lsb

    def offset() -> np.ndarray:
        return np.round(rng.uniform(*offset_range_lsb, 3) * rng.choice([-1.0, 1.0], 3))

    a_off, g_off = offset(), offset()
    return (np.round(result.accel_mps2 * a_sens) + a_off, np.round(result.gyro_radps * g_sens) + g_off,
            a_off, g_off, a_sens, g_sens)
