"""A second independent recording generator: physics *outside* the diagnosis's library.

Written apart from ``station/sim``, ``station/physics`` and ``tests/indepgen.py`` (other numerics,
other plans):

* **Rig kinematics by numerical integration.** The rig is commanded as a world-frame angular-rate
  profile (trapezoidal ramps about a fixed world axis per move: 90/180 deg tumbles about horizontal
  axes, table spins about the vertical). The attitude is a unit quaternion integrated on a fixed
  2 kHz grid (independent of the sample rate) by the exponential map of each step's mid-point rate,
  and sampled by linear interpolation of the gravity direction and the body rate at any time (a
  sensor whose clock runs off is the motion at other times).
* **Its own noise**: a Philox bit generator; white noise plus, in the coloured-noise nulls, an AR(1)
  part (correlation time 30-400 ms) that the base model does not have; quantization to its own LSBs.
* **Its own plans**: 50-800 Hz, a still rest of 60-200 s, faces visited by tumbles in a random order
  (each hold 8-25 s), rate steps about each axis up or down at 3-5 rates of 20-400 deg/s (ascending,
  alternating sign, ramps of 60-250 deg/s^2), an optional climate program (up-down temperature).

The base sensor is the paper's eq. (1) with the eq. (3) drift (Table 1 ranges, via
``station.kernel.sensor_class.TABLE1``, its 1 % drift noise). On top of it one kind of physics
that no candidate of ``station.diagnose.registry`` has (:data:`OUTSIDE`), or none (:data:`NULLS`):

``telegraph``        gyro: a bias that jumps between two levels (+-A, exponential dwell 10-40 s), one axis.
``clock_rate``       both: the sample clock runs fast/slow by ``e`` ppm; time stamps are nominal.
``rate_norm_bias``   gyro: one axis's bias follows the total rate magnitude ``|w|`` (all spins).
``alpha_axial``      accel: an offset along the angular acceleration ``c alpha_k`` on the same axis
                     (a lever arm's ``alpha x r`` is perpendicular to alpha: not the library's).
``temp_hysteresis``  gyro: a bias following a play (backlash) operator of the temperature, width 1.5 K,
                     with an up-down climate program (the bias differs between heating and cooling).
``thermal_kick``     gyro: after every rate step, a bias kick ``c |dw|`` decaying with 8-25 s.
``cross_above``      gyro: a cross-axis term only above a rate: ``c (|w_k| - w0)+ sign(w_k)`` on axis j.
``vibration_rect``   accel: the spin's vibration rectified along the spin axis: ``c w_k^2`` on axis k.

A second set (:data:`OUTSIDE_NEW`), written later and before the locator's second round was changed:

``direction_bias``   gyro: one axis's bias is ``+-c`` by the direction of the last rotation about that axis
                     (faster than 5 deg/s), kept through the following holds (0 before any rotation).
``scale_settle``     gyro: the scale factor (every axis) is off by ``c exp(-(t - t_step)/tau)`` after each rate
                     step (tau 4-15 s): a scale that settles with the time since the last rate step.
``g2_sensitivity``   gyro: one axis's bias follows the square of one specific-force component, ``c (f_i/g)^2``
                     (even in g: the library's g sensitivity is linear).
``sample_hold``      both: sample-and-hold bursts of the shared converter; every 2-8 s (exponential) the
                     output repeats one sample for 30-150 ms; visible only where the signal changes.

A third set (:data:`UNANTICIPATED`), written before the locator's third round was changed and kept out of its
development: run only at the end, as the check on physics nobody anticipated (own random streams: Philox key
``[seed, 2729]``; not in :data:`KINDS`, so the first two sets' seed mapping is unchanged):

``alpha_sign_bias``  gyro: one axis's bias is ``+-c`` by the sign of the angular acceleration about it (while
                     ``|alpha_k|`` > 2 deg/s^2): a bias that exists only while the rate ramps, sign by direction.
``g_scale``          gyro: one axis's scale depends on the specific force along it, ``w_k (1 + c f_k/g)`` (a spin
                     with the axis up is read differently from one with it down).
``temp_misalign``    gyro: one cross-axis coupling changes with temperature, ``c (T - T_0) w_j`` on axis k
                     (climate program on).
``rate_deadband``    gyro: a soft dead band of the sensing element on one axis, ``w_k - c tanh(w_k / w0)``
                     (w0 2-5 deg/s): near zero the output is compressed, above it offset by ``-c sign(w_k)``.

Nulls: ``none`` (base model only) and ``ar1_noise`` (white + AR(1) coloured noise, no physics).

:data:`LOCATION`: per kind the sensors and segment kinds where it acts (what a right ``unexplained`` names).
``python benchmarks/gen_outside.py SEED KIND OUT.csv`` writes one recording.
"""

from __future__ import annotations

import math
import sys
from dataclasses import dataclass

import numpy as np
from scipy.signal import lfilter

from station.kernel.sensor_class import TABLE1
from station.session.model import Kind, Session

DEG = math.pi / 180.0
G_STD = 9.80665
#: Fixed integration grid of the rig's kinematics (Hz), independent of the sample rate.
GRID_HZ = 2000.0

OUTSIDE = ("telegraph", "clock_rate", "rate_norm_bias", "alpha_axial", "temp_hysteresis", "thermal_kick",
           "cross_above", "vibration_rect")
#: Kinds added in the second round (same recordings for the first kinds: their random draws are unchanged).
OUTSIDE_NEW = ("direction_bias", "scale_settle", "g2_sensitivity", "sample_hold")
NULLS = ("none", "ar1_noise")
KINDS = (*NULLS, *OUTSIDE, *OUTSIDE_NEW)
#: Kinds added in the third round, kept out of the locator's development (run only as the final check).
UNANTICIPATED = ("alpha_sign_bias", "g_scale", "temp_misalign", "rate_deadband")
#: Where each outside kind acts: (sensors, segment kinds); a right ``unexplained`` names one of the sensors and
#: at least one of the kinds.
LOCATION: dict[str, tuple[frozenset[str], frozenset[str]]] = {
    "telegraph": (frozenset({"gyro"}), frozenset({"rest", "pose", "rate"})),
    "clock_rate": (frozenset({"accel", "gyro"}), frozenset({"move"})),
    "rate_norm_bias": (frozenset({"gyro"}), frozenset({"rate"})),
    "alpha_axial": (frozenset({"accel"}), frozenset({"move"})),
    "temp_hysteresis": (frozenset({"gyro"}), frozenset({"rest", "pose", "rate"})),
    "thermal_kick": (frozenset({"gyro"}), frozenset({"rate", "move"})),
    "cross_above": (frozenset({"gyro"}), frozenset({"rate"})),
    "vibration_rect": (frozenset({"accel"}), frozenset({"rate"})),
    "direction_bias": (frozenset({"gyro"}), frozenset({"rest", "pose", "rate"})),
    "scale_settle": (frozenset({"gyro"}), frozenset({"rate"})),
    "g2_sensitivity": (frozenset({"gyro"}), frozenset({"rest", "pose", "rate"})),
    "sample_hold": (frozenset({"accel", "gyro"}), frozenset({"move"})),
    "alpha_sign_bias": (frozenset({"gyro"}), frozenset({"move"})),
    "g_scale": (frozenset({"gyro"}), frozenset({"rate"})),
    "temp_misalign": (frozenset({"gyro"}), frozenset({"rate"})),
    "rate_deadband": (frozenset({"gyro"}), frozenset({"rate", "move"})),
}
#: Words one of which a right ``unexplained`` entry's covariate text holds (the covariate the kind follows); for
#: the nulls: what an ``unexplained`` on them may say (no covariate, the noise's colour).
COVARIATE: dict[str, tuple[str, ...]] = {
    "telegraph": ("two-level",), "clock_rate": ("clock", "delay growing"), "rate_norm_bias": ("|rate|",),
    "alpha_axial": ("angular acceleration",), "temp_hysteresis": ("temperature",),
    "thermal_kick": ("since the last rate step",), "cross_above": ("rate",), "vibration_rect": ("rate",),
    "direction_bias": ("last rotation",), "scale_settle": ("since the last rate step",),
    "g2_sensitivity": ("specific force",), "sample_hold": ("hold",),
    "alpha_sign_bias": ("angular acceleration",), "g_scale": ("specific force", "rate"),
    "temp_misalign": ("temperature", "rate"), "rate_deadband": ("rate",),
    "none": ("none",), "ar1_noise": ("none", "colour"),
}
#: Size of each kind (engineering units), multiplied by a random 0.8-1.25 per recording.
SIZE = {
    "telegraph": 0.02,  # deg/s, half the level difference
    "clock_rate": 150.0,  # ppm
    "rate_norm_bias": 1.5e-4,  # deg/s per deg/s of |w|
    "alpha_axial": 6e-3,  # m/s^2 per rad/s^2
    "temp_hysteresis": 0.012,  # deg/s per K
    "thermal_kick": 1.5e-4,  # deg/s per deg/s of rate step
    "cross_above": 6e-4,  # deg/s per deg/s above the threshold
    "vibration_rect": 2.5e-3,  # m/s^2 per (rad/s)^2
    "direction_bias": 0.02,  # deg/s
    "scale_settle": 1.5e-3,  # relative scale at the step
    "g2_sensitivity": 0.03,  # deg/s per g^2
    "sample_hold": 1.0,  # (unused: bursts of held samples)
    "alpha_sign_bias": 0.03,  # deg/s while the rate ramps
    "g_scale": 2e-4,  # relative scale per g along the axis
    "temp_misalign": 5e-5,  # cross-axis coupling per K
    "rate_deadband": 0.03,  # deg/s (offset above the band)
}


@dataclass(frozen=True)
class RigPlan:
    rate_hz: float
    rest_s: float
    hold_s: float
    settle_s: float
    tumble_dps: float  # peak rate of a tumble
    tumble_acc_dps2: float
    spin_acc_dps2: float
    spin_hold_s: float
    rates_dps: tuple[float, ...]
    axis_order: tuple[int, ...]
    axis_down: tuple[bool, ...]
    faces: tuple[tuple[int, int], ...]  # (body axis, sign) pointing up, in visiting order
    gravity: float
    climate: bool


def draw_plan(rng: np.random.Generator, *, climate: bool | None = None) -> RigPlan:
    faces = [(k, s) for k in range(3) for s in (1, -1)]
    order = [faces[i] for i in rng.permutation(6)]
    n_rates = int(rng.integers(3, 6))
    rates = tuple(sorted(float(r) for r in rng.choice([20.0, 35.0, 50.0, 75.0, 110.0, 150.0, 200.0, 260.0, 330.0,
                                                         400.0], size=n_rates, replace=False)))
    if rates[-1] < 200.0:  # a step above the cross-axis threshold in every plan
        rates = (*rates[:-1], float(rng.choice([260.0, 330.0, 400.0])))
    return RigPlan(
        rate_hz=float(rng.choice([50.0, 80.0, 100.0, 160.0, 320.0, 500.0, 800.0])),
        rest_s=float(rng.uniform(60.0, 200.0)), hold_s=float(rng.uniform(8.0, 25.0)),
        settle_s=float(rng.uniform(0.5, 1.5)), tumble_dps=float(rng.uniform(30.0, 90.0)),
        tumble_acc_dps2=float(rng.uniform(60.0, 250.0)), spin_acc_dps2=float(rng.uniform(60.0, 250.0)),
        spin_hold_s=float(rng.uniform(5.0, 12.0)), rates_dps=rates,
        axis_order=tuple(int(a) for a in rng.permutation(3)), axis_down=tuple(bool(b) for b in rng.random(3) < 0.5),
        faces=tuple(order), gravity=float(rng.uniform(9.79, 9.83)),
        climate=bool(rng.random() < 0.5) if climate is None else climate,
    )


# --- quaternions (w, x, y, z), body -> world ----------------------------------------------------------------
def _qmul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    aw, ax, ay, az = a
    bw, bx, by, bz = b
    return np.array([aw * bw - ax * bx - ay * by - az * bz, aw * bx + ax * bw + ay * bz - az * by,
                     aw * by - ax * bz + ay * bw + az * bx, aw * bz + ax * by - ay * bx + az * bw])


def _qexp(v: np.ndarray) -> np.ndarray:
    """Quaternion of the rotation vector v (rad)."""
    a = float(np.linalg.norm(v))
    if a < 1e-15:
        return np.array([1.0, 0.5 * v[0], 0.5 * v[1], 0.5 * v[2]])
    s = math.sin(0.5 * a) / a
    return np.array([math.cos(0.5 * a), s * v[0], s * v[1], s * v[2]])


def _world_to_body(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """R(q)^T v."""
    w, x, y, z = q
    r = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                  [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                  [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])
    return r.T @ v


@dataclass
class _Step:
    """One commanded piece: rate profile about a fixed world axis, trapezoid to ``angle`` (or a hold)."""

    kind: Kind
    duration: float
    axis: np.ndarray  # world axis (unit), zeros for a hold
    rate0: float = 0.0  # rad/s at start (spins)
    rate1: float = 0.0  # rad/s at end of the ramp (spins)
    tumble_angle: float = 0.0  # rad (tumbles)
    settle: float = 0.0


def _trapezoid(angle: float, peak: float, acc: float) -> tuple[float, float]:
    """(duration, peak) of a rest-to-rest trapezoid over ``angle`` (rad) at most ``peak`` (rad/s), ``acc``."""
    t_acc = peak / acc
    if acc * t_acc**2 >= angle:  # triangle
        t_acc = math.sqrt(angle / acc)
        return 2 * t_acc, acc * t_acc
    return 2 * t_acc + (angle - acc * t_acc**2) / peak, peak


class Rig:
    """The rig's motion: planned as steps, integrated on a fixed grid; :meth:`at` samples it at any times."""

    def __init__(self, plan: RigPlan, rng: np.random.Generator) -> None:
        self.plan = plan
        up = np.array([0.0, 0.0, 1.0])
        k0, s0 = plan.faces[0]
        q0 = _qmul(_qexp(up * rng.uniform(0, 2 * math.pi)), self._face_up(k0, s0))
        steps: list[_Step] = [_Step(Kind.REST, plan.rest_s, np.zeros(3))]
        cur = q0.copy()  # the planned attitude (exact), to aim the tumbles

        def tumble_to(k: int, s: int) -> None:
            nonlocal cur
            axis_world = _body_to_world(cur, np.eye(3)[k] * s)
            c = float(np.clip(axis_world @ up, -1.0, 1.0))
            if c > 1 - 1e-9:
                return
            ax = np.cross(axis_world, up)
            if np.linalg.norm(ax) < 1e-9:  # upside down: 180 deg about a horizontal axis
                ax = np.array([1.0, 0.0, 0.0]) if rng.random() < 0.5 else np.array([0.0, 1.0, 0.0])
            ax = ax / np.linalg.norm(ax)
            ang = math.acos(c)
            dur, _ = _trapezoid(ang, plan.tumble_dps * DEG, plan.tumble_acc_dps2 * DEG)
            steps.append(_Step(Kind.MOVE, dur, ax, tumble_angle=ang))
            cur = _qmul(_qexp(ax * ang), cur)

        for k, s in plan.faces[1:]:
            tumble_to(k, s)
            steps.append(_Step(Kind.POSE, plan.hold_s, np.zeros(3), settle=plan.settle_s))
        for k, down in zip(plan.axis_order, plan.axis_down, strict=True):
            tumble_to(k, -1 if down else 1)
            steps.append(_Step(Kind.MOVE, 1.0, np.zeros(3)))
            sign_table = -1.0 if down else 1.0  # body rate about +k = table rate * sign
            w, turned = 0.0, 0.0
            seq: list[float] = []
            for r in plan.rates_dps:
                first = 1.0 if rng.random() < 0.5 else -1.0
                seq += [first * r * DEG, -first * r * DEG]
            for target in [*seq, 0.0]:
                table = target * sign_table
                dur = abs(table - w) / (plan.spin_acc_dps2 * DEG)
                steps.append(_Step(Kind.MOVE, dur, up.copy(), rate0=w, rate1=table))
                turned += 0.5 * (w + table) * dur
                w = table
                if target == 0.0:
                    break
                steps.append(_Step(Kind.RATE, plan.spin_hold_s, up.copy(), rate0=w, rate1=w, settle=plan.settle_s))
                turned += w * plan.spin_hold_s
            steps.append(_Step(Kind.MOVE, 1.0, np.zeros(3)))
            cur = _qmul(_qexp(up * turned), cur)
        tumble_to(*plan.faces[0])
        steps.append(_Step(Kind.POSE, plan.hold_s, np.zeros(3), settle=plan.settle_s))
        self.steps = steps
        self.q0 = q0
        self._integrate()

    @staticmethod
    def _face_up(k: int, s: int) -> np.ndarray:
        """A quaternion with body axis ``s e_k`` along world up."""
        e = np.eye(3)[k] * s
        up = np.array([0.0, 0.0, 1.0])
        c = float(e @ up)
        if c > 1 - 1e-12:
            return np.array([1.0, 0.0, 0.0, 0.0])
        if c < -1 + 1e-12:
            return _qexp(np.array([math.pi, 0.0, 0.0]))
        ax = np.cross(e, up)
        return _qexp(ax / np.linalg.norm(ax) * math.acos(c))

    def _step_rate(self, st: _Step, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Commanded rate (rad/s) and angular acceleration about the step's world axis at times u into it."""
        if st.tumble_angle:
            dur, peak = _trapezoid(st.tumble_angle, self.plan.tumble_dps * DEG, self.plan.tumble_acc_dps2 * DEG)
            acc = self.plan.tumble_acc_dps2 * DEG
            ta = peak / acc
            r = np.clip(np.minimum(np.minimum(acc * u, peak), acc * (dur - u)), 0.0, None)
            return r, np.where(u < ta, acc, np.where(u > dur - ta, -acc, 0.0))
        if np.any(st.axis):
            dur = max(st.duration, 1e-9)
            return st.rate0 + (st.rate1 - st.rate0) * u / dur, np.full_like(u, (st.rate1 - st.rate0) / dur)
        return np.zeros_like(u), np.zeros_like(u)

    def _labels(self, tt: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        seg = np.zeros(len(tt), dtype=np.int64)
        kind = np.full(len(tt), int(Kind.MOVE), dtype=np.int64)
        for i, (st, t0) in enumerate(zip(self.steps, self.starts, strict=True)):
            sel = (tt >= t0) & (tt < t0 + st.duration) if i < len(self.steps) - 1 else (tt >= t0)
            seg[sel] = i
            if st.kind != Kind.MOVE:
                kind[sel] = np.where(tt[sel] - t0 < st.settle, int(Kind.MOVE), int(st.kind))
        return seg, kind

    def _integrate(self) -> None:
        """Attitude on the grid: per step, the angle about its fixed world axis by the trapezoidal rule on the
        grid, composed onto the attitude the previous step ended in (a quaternion chain)."""
        self.starts = np.concatenate([[0.0], np.cumsum([st.duration for st in self.steps])[:-1]])
        self.end = float(self.starts[-1] + self.steps[-1].duration)
        g = np.arange(0.0, self.end + 2.0 / GRID_HZ, 1.0 / GRID_HZ)
        qs = np.empty((len(g), 4))
        w = np.zeros((len(g), 3))
        a = np.zeros((len(g), 3))
        q = self.q0.copy()
        for i, (st, t0) in enumerate(zip(self.steps, self.starts, strict=True)):
            t1 = t0 + st.duration
            idx = np.flatnonzero((g >= t0) & (g < t1)) if i < len(self.steps) - 1 else np.flatnonzero(g >= t0)
            u = np.concatenate([[0.0], g[idx] - t0, [st.duration]])
            r, al = self._step_rate(st, u)
            theta = np.concatenate([[0.0], np.cumsum(0.5 * (r[1:] + r[:-1]) * np.diff(u))])
            half = 0.5 * theta[1:]
            dq = np.column_stack([np.cos(half), np.sin(half)[:, None] * st.axis[None, :]])
            qq = _batch_qmul(dq, q)
            qs[idx] = qq[:-1]
            w[idx] = r[1:-1, None] * st.axis
            a[idx] = al[1:-1, None] * st.axis
            q = qq[-1] / np.linalg.norm(qq[-1])
        self.grid = g
        self.up_b = _batch_rot_T(qs, np.tile([0.0, 0.0, 1.0], (len(g), 1)))
        self.w_b = _batch_rot_T(qs, w)
        self.a_b = _batch_rot_T(qs, a)

    def at(self, t: np.ndarray) -> dict[str, np.ndarray]:
        """Body gravity direction, body rate (rad/s), body angular acceleration (rad/s^2), labels at times t."""
        t = np.clip(t, 0.0, self.grid[-1])
        up = np.stack([np.interp(t, self.grid, self.up_b[:, j]) for j in range(3)], axis=1)
        up /= np.linalg.norm(up, axis=1, keepdims=True)
        w = np.stack([np.interp(t, self.grid, self.w_b[:, j]) for j in range(3)], axis=1)
        al = np.stack([np.interp(t, self.grid, self.a_b[:, j]) for j in range(3)], axis=1)
        seg, kind = self._labels(t)
        return {"up": up, "w": w, "alpha": al, "segment": seg, "kind": kind}


def _qconj(q: np.ndarray) -> np.ndarray:
    return np.array([q[0], -q[1], -q[2], -q[3]])


def _body_to_world(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    return _world_to_body(_qconj(q), v)


def _batch_qmul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Rows of ``a`` (n, 4) times the quaternion ``b`` (4,)."""
    aw, ax, ay, az = a.T
    bw, bx, by, bz = b
    return np.column_stack([aw * bw - ax * bx - ay * by - az * bz, aw * bx + ax * bw + ay * bz - az * by,
                            aw * by - ax * bz + ay * bw + az * bx, aw * bz + ax * by - ay * bx + az * bw])


def _batch_rot_T(qs: np.ndarray, v: np.ndarray) -> np.ndarray:
    """R(q_i)^T v_i for every row."""
    w, x, y, z = qs.T
    r00, r01, r02 = 1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)
    r10, r11, r12 = 2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)
    r20, r21, r22 = 2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)
    return np.stack([r00 * v[:, 0] + r10 * v[:, 1] + r20 * v[:, 2], r01 * v[:, 0] + r11 * v[:, 1] + r21 * v[:, 2],
                     r02 * v[:, 0] + r12 * v[:, 1] + r22 * v[:, 2]], axis=1)


def _temperature(t: np.ndarray, plan: RigPlan, rng: np.random.Generator, force_climate: bool) -> np.ndarray:
    """Sensor temperature (degC): self-heating, and with a climate program an up-down triangle."""
    amb = rng.uniform(20.0, 27.0)
    rise, tau = rng.uniform(2.0, 6.0), rng.uniform(120.0, 500.0)
    temp = amb + rise * -np.expm1(-t / tau)
    if plan.climate or force_climate:
        amp = rng.uniform(2.5, 4.0)
        period = t[-1] * rng.uniform(0.6, 0.9)
        phase = (t / period) % 1.0
        tri = np.where(phase < 0.5, 4 * phase - 1, 3 - 4 * phase)  # -1..1..-1
        temp = temp + amp * (tri + 1.0) * 0.5
    return temp


def _play(x: np.ndarray, width: float) -> np.ndarray:
    """Play (backlash) operator: the output follows x only once x leaves a band of ``width`` around it."""
    out = np.empty_like(x)
    y = x[0]
    h = 0.5 * width
    for i, v in enumerate(x):
        if v > y + h:
            y = v - h
        elif v < y - h:
            y = v + h
        out[i] = y
    return out


def _unanticipated(kind: str, size: float, axis: int, true: dict[str, np.ndarray], temp: np.ndarray, plan: RigPlan,
                   rng: np.random.Generator) -> np.ndarray:
    """The gyro's added output (rad/s, n x 3) of one :data:`UNANTICIPATED` kind on ``axis``."""
    w = true["w"]
    add = np.zeros_like(w)
    if kind == "alpha_sign_bias":
        a_dps2 = true["alpha"][:, axis] / DEG
        add[:, axis] = size * DEG * np.where(np.abs(a_dps2) > 2.0, np.sign(a_dps2), 0.0)
    elif kind == "g_scale":
        add[:, axis] = size * w[:, axis] * plan.gravity * true["up"][:, axis] / G_STD
    elif kind == "temp_misalign":
        src = (axis + 1 + int(rng.integers(2))) % 3
        add[:, axis] = size * (temp - temp[0]) * w[:, src]
    elif kind == "rate_deadband":
        w0 = float(rng.uniform(2.0, 5.0)) * DEG
        add[:, axis] = -size * DEG * np.tanh(w[:, axis] / w0)
    return add


@dataclass(frozen=True)
class Outside:
    session: Session
    plan: RigPlan
    kind: str
    size: float
    axis: int  # the axis it acts on (where it acts on one)


def generate(seed: int, kind: str) -> Outside:
    """One recording of ``kind`` (:data:`KINDS`): seed in, same session out."""
    if kind not in KINDS and kind not in UNANTICIPATED:
        raise ValueError(f"unknown kind {kind!r} (one of {', '.join((*KINDS, *UNANTICIPATED))})")
    rng = np.random.Generator(np.random.Philox(key=[seed, 2729 if kind in UNANTICIPATED else 2727]))
    plan = draw_plan(rng, climate=True if kind in ("temp_hysteresis", "temp_misalign") else None)
    rig = Rig(plan, rng)
    fs = plan.rate_hz
    n = int(rig.end * fs)
    t = np.arange(n) / fs  # nominal time stamps
    size = SIZE.get(kind, 0.0) * float(rng.uniform(0.8, 1.25)) * (1.0 if rng.random() < 0.5 else -1.0)
    axis = int(rng.integers(3))
    ref = rig.at(t)
    ppm = size * 1e-6 if kind == "clock_rate" else 0.0
    true = rig.at(t / (1.0 + ppm)) if ppm else ref  # a fast clock samples earlier than its stamps say
    temp = _temperature(t, plan, rng, kind in ("temp_hysteresis", "temp_misalign"))
    d_temp = temp - temp[0]
    c = TABLE1
    out: dict[str, np.ndarray] = {}
    for sensor in ("accel", "gyro"):
        gyro = sensor == "gyro"
        x = true["w"].copy() if gyro else plan.gravity * true["up"]
        if gyro:
            m = np.diag(rng.uniform(*c.gyro_scale, 3)) + (1 - np.eye(3)) * rng.uniform(*c.gyro_cross_axis, (3, 3))
            b_stat = rng.uniform(*c.gyro_bias_static_dps, 3) * DEG
            b_drift = rng.uniform(*c.gyro_bias_drift_dps, 3) * DEG
            tc = rng.uniform(*c.gyro_correlation_time_s, 3)
            sigma = rng.uniform(*c.gyro_noise_std_dps, 3) * DEG
            lsb = 4000.0 * DEG / 2**20
        else:
            m = np.diag(rng.uniform(*c.accel_scale, 3)) + (1 - np.eye(3)) * rng.uniform(*c.accel_cross_axis, (3, 3))
            b_stat = rng.uniform(*c.accel_bias_static_mps2, 3)
            b_drift = rng.uniform(*c.accel_bias_drift_mps2, 3)
            tc = rng.uniform(*c.accel_correlation_time_s, 3)
            sigma = rng.uniform(*c.accel_noise_std_mps2, 3)
            lsb = 16.0 * G_STD / 2**16
        y = x @ m.T + b_stat
        # eq. 3: warm-up b_drift exp(-t/T_c) and its 1 % Gauss-Markov part (started at 0), exact AR(1) steps
        phi = np.exp(-1.0 / (fs * tc))
        e = rng.standard_normal((n, 3)) * np.sqrt(1 - phi**2) * c.drift_noise_rel * np.abs(b_drift)
        gm = np.stack([lfilter([1.0], [1.0, -phi[k]], e[:, k]) for k in range(3)], axis=1)
        y += b_drift * np.exp(-t[:, None] / tc) + gm
        w_dps = true["w"] / DEG
        if gyro and kind == "telegraph":
            dwell = rng.uniform(10.0, 40.0)
            flips = np.cumsum(rng.exponential(dwell, size=int(4 * t[-1] / dwell) + 8))
            level = np.where(np.searchsorted(flips, t) % 2 == 0, 1.0, -1.0)
            y[:, axis] += size * DEG * level
        if gyro and kind == "rate_norm_bias":
            y[:, axis] += size * DEG * np.linalg.norm(w_dps, axis=1)
        if gyro and kind == "temp_hysteresis":
            y[:, axis] += size * DEG * _play(d_temp, 1.5)
        if gyro and kind == "thermal_kick":
            tau_k = rng.uniform(8.0, 25.0)
            # every rate step (a spin ramp's end) kicks the bias by size * |dw|, decaying with tau_k
            kick = np.zeros(n)
            steps_t, t0 = [], 0.0
            for st in rig.steps:
                t1 = t0 + st.duration
                if st.kind == Kind.MOVE and np.any(st.axis) and not st.tumble_angle and st.rate0 != st.rate1:
                    steps_t.append((t1, abs(st.rate1 - st.rate0) / DEG))
                t0 = t1
            for ts, dw in steps_t:
                after = t >= ts
                kick[after] += dw * np.exp(-(t[after] - ts) / tau_k)
            y[:, axis] += size * DEG * kick
        if gyro and kind == "cross_above":
            src = (axis + 1 + int(rng.integers(2))) % 3
            over = np.maximum(np.abs(w_dps[:, src]) - 150.0, 0.0) * np.sign(w_dps[:, src])
            y[:, axis] += size * DEG * over
        if not gyro and kind == "alpha_axial":
            y += size * true["alpha"]
        if not gyro and kind == "vibration_rect":
            y += size * true["w"] ** 2
        if gyro and kind == "direction_bias":
            wk = w_dps[:, axis]
            moving = np.abs(wk) > 5.0
            idx = np.where(moving, np.arange(n), -1)
            last = np.maximum.accumulate(idx)
            y[:, axis] += size * DEG * np.where(last >= 0, np.sign(wk[np.maximum(last, 0)]), 0.0)
        if gyro and kind == "scale_settle":
            tau_s = rng.uniform(4.0, 15.0)
            ends, t0 = [], 0.0
            for st in rig.steps:
                t1 = t0 + st.duration
                if st.kind == Kind.MOVE and np.any(st.axis) and not st.tumble_angle and st.rate0 != st.rate1:
                    ends.append(t1)
                t0 = t1
            j = np.searchsorted(np.asarray(ends), t, side="right") - 1
            since = np.where(j >= 0, t - np.asarray([*ends, 0.0])[np.maximum(j, 0)], np.inf)
            y += size * (true["w"] @ m.T) * np.exp(-since / tau_s)[:, None]
        if gyro and kind == "g2_sensitivity":
            src = int(rng.integers(3))
            y[:, axis] += size * DEG * (true["up"][:, src] * plan.gravity / G_STD) ** 2
        if gyro and kind in UNANTICIPATED:
            y += _unanticipated(kind, size, axis, true, temp, plan, rng)
        if kind == "ar1_noise":
            tau_n = rng.uniform(0.03, 0.4)
            a1 = math.exp(-1.0 / (fs * tau_n))
            drive = rng.standard_normal((n, 3)) * math.sqrt(1 - a1**2) * sigma
            col = lfilter([1.0], [1.0, -a1], drive, axis=0)
            y += col
            y += rng.standard_normal((n, 3)) * sigma * 0.7
        else:
            y += rng.standard_normal((n, 3)) * sigma
        out[sensor] = np.round(y / lsb) * lsb
    if kind == "sample_hold":  # the shared converter repeats one sample in bursts (both sensors)
        held = np.arange(n)
        tb = float(rng.exponential(5.0))
        while tb < t[-1]:
            i0 = int(tb * fs)
            i1 = min(n, i0 + max(2, int(rng.uniform(0.03, 0.15) * fs)))
            held[i0:i1] = i0
            tb += float(rng.uniform(2.0, 8.0))
        out = {k: v[held] for k, v in out.items()}
    temp_read = np.round((temp + rng.normal(0.0, 0.04, n)) * 32.0) / 32.0
    meta = {"serial": f"OUT-{seed:06d}", "sample_rate_hz": f"{fs:g}", "gravity_mps2": f"{plan.gravity:.5f}",
            "station": "gen_outside", "rig": "gen_outside"}
    session = Session(metadata=meta, t_s=t, segment=ref["segment"], kind=ref["kind"], accel_mps2=out["accel"],
                      gyro_radps=out["gyro"], temp_degc=temp_read, ref_accel_mps2=plan.gravity * ref["up"],
                      ref_gyro_radps=ref["w"])
    return Outside(session=session, plan=plan, kind=kind, size=abs(size), axis=axis)


if __name__ == "__main__":
    from station.session.csv_v1 import write_session

    a = sys.argv[1:]
    rec = generate(int(a[0]), a[1])
    write_session(rec.session, a[2])
    print(f"{a[2]}: {rec.kind} {len(rec.session)} samples at {rec.plan.rate_hz:g} Hz, {rec.session.duration_s:.0f} s")
