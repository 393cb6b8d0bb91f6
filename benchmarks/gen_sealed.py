"""A sealed generator of physics outside the diagnosis's library, kept out of every locator development.

Written apart from ``station/sim``, ``station/physics``, ``tests/indepgen.py`` and ``benchmarks/gen_outside.py``
(its rig and sensor code were not reused); only the session writer and Table 1's ranges are the station's.
It is meant to be run once, at the end, as the honest check of the locator on physics nobody tuning it saw.

**Rig kinematics in closed form.** Every rig step turns about one fixed world axis with a jerk-limited
raised-cosine profile (tumbles rest to rest, ``w = A/T (1 - cos 2 pi u/T)``; rate changes
``w = w0 + dw (u/T - sin(2 pi u/T) / 2 pi)``), whose angle has a closed form; the attitude at *any* time is
``exp(a theta(t) / 2) (x) q_start`` (a quaternion chain over the steps, no grid and no interpolation), the body
rate ``R^T a w(t)`` and the angular acceleration ``R^T a dw/dt``. A sensor axis sampled late is the same
expressions at another time.

**Its own plan shape.** A still rest of 90-240 s on a random face at a random heading; then for each body axis in
random order: a tumble that puts it up or down, a pose, a table-rate block about the vertical (3-5 magnitudes of
15-500 deg/s, the top at least 300 deg/s, ascending or descending; on most axes each magnitude at both signs,
reached by a direct step through zero, on the others one sign as a staircase), back to zero, and the pose again;
then the faces not yet visited, a table turn of 90-270 deg to a new heading, and the start face. Sample rates
50-800 Hz. A climate chamber runs the whole time: ramps of 1.5-3 K/min up and down with short holds (the sensor
follows through a 20-60 s lag, on top of self-heating).

**Its own sensors.** Two sensor classes within Table 1 (``station.kernel.sensor_class.TABLE1``): the lower and the
upper 60 % of every range. The base sensor is the paper's eq. (1) with the eq. (3) drift: ``b_drift exp(-t/T_c)``
plus its Gauss-Markov part (1 % of ``b_drift``, started at 0), drawn exactly on a 10 Hz grid and interpolated;
white noise; converters of +-4 g and +-1000 deg/s (16 and 20 bit). Random numbers: numpy's Philox with the key
``[seed, SEALED_KEY]`` for the plan and the unit, and ``[seed, SEALED_KEY + 1 + index of the kind]`` for the kind's
own draws, so a kind's recording is the ``none`` recording of the same seed plus the planted physics only.

The kinds (:data:`SEALED`, one axis per recording chosen by the seed, sizes random per seed, 0.8-1.25 of
:data:`SIZE`, random sign):

``dtdt_scale``         accel: one axis's scale follows the temperature *rate*, ``f_k (1 + c dT/dt)`` (a thermal
                       gradient across the proof mass while the chamber ramps; not ``T - T_0``).
``vibration_bias``     both: the table's bearing shakes the unit at ``m`` times the spin frequency with an amplitude
                       through a resonance (Q 3-6) of that frequency; the gyro's axis ``k`` rectifies it, a bias
                       ``kappa A^2 / 2`` following the accelerometer's vibration energy (largest at a mid rate).
``code_inl``           gyro: a periodic integral nonlinearity of a segmented converter on one axis,
                       ``y_k + c sin(2 pi y_k / P)`` (P 40-90 deg/s, redrawn until the axis's table-hold levels span
                       at least 0.6 of the sine's range): an error periodic in the output level.
``drive_limit_cycle``  gyro: a slow triangle (relay) limit cycle of the drive-amplitude loop, a bias
                       ``c tri(t / P + phase)`` on one axis, a period of 1.5-5 min; the temperature does not show it.
``heading_bias``       gyro: a magnetic-like bias from a field fixed in the world (horizontal), seen by one axis
                       through its cross sensitivity to another axis: ``c (R^T m)_j`` on axis ``k``; it follows the
                       heading in poses and the spin phase in table spins.
``accel_ratchet``      accel: the bias of one axis shifts by ``c`` (same sign, persistent, cumulative) at the end of
                       every table hold at 250 deg/s or more (the die attach slips under the centripetal load).
``rate_clip``          gyro: one axis saturates at ``+-R`` with ``R`` 88-96 % of its output at the plan's top rate
                       (a range below what the rig turns).
``axis_skew``          gyro: one axis is converted ``delta`` later than the other two (a multiplexed converter:
                       ``delta = m / (3 f_s)``, m 1 or 2, plus 0.55-0.9 ms of filter): a delay on one axis only.
``accel_creep``        accel: anelastic creep of one axis, ``(1 - c) f_k + c L[f_k]`` with ``L`` a first-order lag of
                       2-8 s: after every change of load (a tumble) the output creeps to its value.

Nulls (:data:`NULLS`): ``none`` (base model only) and ``pink_noise`` (the white noise replaced by 0.8 of it plus a
flicker-like part: five first-order processes, time constants 0.02-5 s log-spaced, 0.6 of the noise std).

:data:`LOCATION` (sensors, segment kinds) and :data:`COVARIATE` (words one of which a right ``unexplained``
entry's covariate names) were written with the kinds, before anything was run on them.

``python benchmarks/gen_sealed.py SEED KIND OUT.csv`` writes one recording; ``--snr FIRST COUNT`` prints every
kind's design SNR (:func:`design_snr`, no diagnosis) over COUNT seeds at 50 Hz.
"""

from __future__ import annotations

import dataclasses
import math
import sys
from dataclasses import dataclass

import numpy as np
from scipy.signal import lfilter

from station.kernel.sensor_class import TABLE1, SensorClass
from station.session.model import Kind, Session

DEG = math.pi / 180.0
G_STD = 9.80665
#: Second word of every Philox key of this generator (the first is the seed).
SEALED_KEY = 0x5EA1ED27
#: Converter ranges and LSBs (own choice: +-4 g at 16 bit, +-1000 deg/s at 20 bit).
ACCEL_RANGE = 4.0 * G_STD
GYRO_RANGE = 1000.0 * DEG
ACCEL_LSB = 2.0 * ACCEL_RANGE / 2**16
GYRO_LSB = 2.0 * GYRO_RANGE / 2**20
#: Table holds at or above this rate (deg/s) shift the bias of ``accel_ratchet``.
RATCHET_DPS = 250.0

NULLS = ("none", "pink_noise")
SEALED = ("dtdt_scale", "vibration_bias", "code_inl", "drive_limit_cycle", "heading_bias", "accel_ratchet",
          "rate_clip", "axis_skew", "accel_creep")
KINDS = (*NULLS, *SEALED)

# LOCATION and COVARIATE below were written with the kinds, BEFORE this generator's recordings were given to the
# diagnosis (the only diagnosis run before the lead's final check: one smoke run of one recording, to see the CSV
# load). Do not edit them after seeing results.
#: Where each kind acts: (sensors, segment kinds); a right ``unexplained`` names one of the sensors and at least
#: one of the kinds.
LOCATION: dict[str, tuple[frozenset[str], frozenset[str]]] = {
    # scale * dT/dt where the axis carries gravity: holds during the chamber's ramps
    "dtdt_scale": (frozenset({"accel"}), frozenset({"rest", "pose", "rate"})),
    # bias only while the table spins; the vibration itself is an excess in the accelerometer there
    "vibration_bias": (frozenset({"gyro", "accel"}), frozenset({"rate"})),
    # periodic in the output level: at the table rates (and through the ramps)
    "code_inl": (frozenset({"gyro"}), frozenset({"rate", "move"})),
    "drive_limit_cycle": (frozenset({"gyro"}), frozenset({"rest", "pose", "rate"})),
    "heading_bias": (frozenset({"gyro"}), frozenset({"rest", "pose", "rate"})),
    # the shift is a bias difference between the holds before (the rest is before every shift) and after
    "accel_ratchet": (frozenset({"accel"}), frozenset({"rest", "pose", "rate"})),
    "rate_clip": (frozenset({"gyro"}), frozenset({"rate", "move"})),
    "axis_skew": (frozenset({"gyro"}), frozenset({"move"})),
    # after each tumble the output creeps for 2-8 s: the start of the poses, and the tumbles
    "accel_creep": (frozenset({"accel"}), frozenset({"pose", "move"})),
}
#: Words one of which a right ``unexplained`` entry's covariate text holds; for the nulls what an
#: ``unexplained`` on them may say (no covariate, the noise's colour).
COVARIATE: dict[str, tuple[str, ...]] = {
    "dtdt_scale": ("temperature",),
    "vibration_bias": ("vibration", "rate"),
    "code_inl": ("rate",),
    "drive_limit_cycle": ("periodic", "time", "oscillat"),
    "heading_bias": ("heading", "spin phase", "orientation", "attitude"),
    "accel_ratchet": ("since the last rate step", "step", "jump", "time"),
    "rate_clip": ("rate", "clip", "saturat"),
    "axis_skew": ("angular acceleration", "delay", "skew"),
    "accel_creep": ("since the last", "specific force", "creep"),
    "none": ("none",),
    "pink_noise": ("none", "colour"),
}
#: Nominal size of each kind (its engineering unit), times a random 0.8-1.25 per recording. The design SNR, from
#: first principles (white noise sigma per sample, N samples where it acts; the matched filter of a known signal
#: s has SNR sqrt(sum s^2) / sigma), is at least 20 for every kind on the smallest plan (50 Hz); the per-hold
#: figures in the comments use sigma_a <= 0.028 m/s^2, sigma_g <= 0.013 deg/s and holds of >= 4 s at 50 Hz.
SIZE = {
    # 1 / (K/s): at 1.5-3 K/min a scale change of 1.6e-3-5e-3, 16-50 mm/s^2 on +-g; per pose 6-18 s the mean's
    # noise is <= 1.6 mm/s^2 (>= 10 sigma per hold, several holds carry it)
    "dtdt_scale": 0.08,
    # deg/s at the resonance's peak (bias kappa A^2 / 2; A = 0.4-1.2 m/s^2 there); per 4-10 s hold noise of the
    # mean <= 0.9 mdeg/s: >= 30 sigma in the resonant hold
    "vibration_bias": 0.04,
    # deg/s amplitude of the periodic INL; every table hold carries c sin(2 pi w/P): >= 20 sigma per hold where
    # the sine is not near zero
    "code_inl": 0.04,
    # deg/s amplitude of the triangle; the mean of a 6 s pose has noise <= 0.8 mdeg/s; drift noise (1 % of
    # b_drift) <= 3.5 mdeg/s
    "drive_limit_cycle": 0.025,
    # deg/s, the bias with the field along axis j; in spins a sinusoid at the spin rate
    "heading_bias": 0.03,
    # m/s^2 per shift (3-6 shifts per plan); per pose noise of the mean <= 1.6 mm/s^2
    "accel_ratchet": 0.012,
    # fraction of the top rate where the axis saturates, drawn 0.88-0.96 (not scaled): 4-12 % of 300-500 deg/s
    # clipped, >= 12 deg/s in every top-rate hold
    "rate_clip": 0.92,
    # ms of added filter delay (plus m / (3 f_s)); at the tumbles' and ramps' 80-600 deg/s^2 an error of
    # >= 0.1 deg/s, >= 8 sigma per sample at the peaks
    "axis_skew": 0.7,
    # creep fraction c: after a tumble changing f_k by g or 2 g, an error c df of 0.04-0.12 m/s^2 decaying in
    # 2-8 s (>= 100 samples at 50 Hz)
    "accel_creep": 5e-3,
}

_UP = np.array([0.0, 0.0, 1.0])


# --- quaternions (w, x, y, z), body -> world ----------------------------------------------------------------------
def _qmul(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Hamilton product of rows (..., 4)."""
    pw, px, py, pz = np.moveaxis(p, -1, 0)
    qw, qx, qy, qz = np.moveaxis(q, -1, 0)
    return np.stack([pw * qw - px * qx - py * qy - pz * qz, pw * qx + px * qw + py * qz - pz * qy,
                     pw * qy - px * qz + py * qw + pz * qx, pw * qz + px * qy - py * qx + pz * qw], axis=-1)


def _axis_angle(axis: np.ndarray, angle: np.ndarray | float) -> np.ndarray:
    a = np.asarray(angle, dtype=float)[..., None]
    return np.concatenate([np.cos(0.5 * a), np.sin(0.5 * a) * axis], axis=-1)


def _rotate(q: np.ndarray, v: np.ndarray, *, inverse: bool = False) -> np.ndarray:
    """R(q) v, or R(q)^T v with ``inverse`` (rows of q and v broadcast): v + 2 w (u x v) + 2 u x (u x v)."""
    w = q[..., :1]
    u = -q[..., 1:] if inverse else q[..., 1:]
    uv = np.cross(u, v)
    return v + 2.0 * w * uv + 2.0 * np.cross(u, uv)


# --- the plan --------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class SealedStep:
    """One rig step: a turn about the fixed world ``axis`` (or none), then a settle at its final rate."""

    kind: Kind
    t0: float
    duration: float
    shape: str  # "hold" (constant rate0), "tumble" (rest to rest by angle), "ramp" (rate0 -> rate1)
    axis: tuple[float, float, float]
    q_start: tuple[float, float, float, float]
    rate0: float = 0.0  # rad/s
    rate1: float = 0.0  # rad/s
    angle: float = 0.0  # rad (tumbles)
    motion_s: float = 0.0  # length of the turn (the rest of the step is a settle)
    table: bool = False  # a turn of the table (about the vertical): the bearing runs

    def theta_rate_acc(self, u: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Angle (rad), rate (rad/s), angular acceleration (rad/s^2) about the axis at times ``u`` into the step."""
        if self.shape == "hold":
            return self.rate0 * u, np.full_like(u, self.rate0), np.zeros_like(u)
        big_t = self.motion_s
        x = np.clip(u / big_t, 0.0, 1.0)
        c2, s2 = np.cos(2 * math.pi * x), np.sin(2 * math.pi * x)
        inside = u < big_t
        if self.shape == "tumble":
            a = self.angle
            theta = a * (x - s2 / (2 * math.pi))
            rate = np.where(inside, a / big_t * (1 - c2), 0.0)
            acc = np.where(inside, a / big_t * (2 * math.pi / big_t) * s2, 0.0)
            return theta, rate, acc
        dw = self.rate1 - self.rate0
        theta_in = self.rate0 * u + dw * big_t * (x**2 / 2 + (c2 - 1) / (4 * math.pi**2))
        theta_end = self.rate0 * big_t + dw * big_t / 2
        theta = np.where(inside, theta_in, theta_end + self.rate1 * (u - big_t))
        rate = np.where(inside, self.rate0 + dw * (x - s2 / (2 * math.pi)), self.rate1)
        acc = np.where(inside, dw / big_t * (1 - c2), 0.0)
        return theta, rate, acc


@dataclass(frozen=True)
class SealedPlan:
    rate_hz: float
    sensor_class: str
    gravity: float
    magnitudes_dps: tuple[float, ...]
    steps: tuple[SealedStep, ...]

    @property
    def end_s(self) -> float:
        return self.steps[-1].t0 + self.steps[-1].duration

    @property
    def top_dps(self) -> float:
        return max(self.magnitudes_dps)


def _face_quat(k: int, s: int) -> np.ndarray:
    """An attitude with body axis ``s e_k`` along world up."""
    e = np.eye(3)[k] * s
    c = float(e @ _UP)
    if c > 1 - 1e-12:
        return np.array([1.0, 0.0, 0.0, 0.0])
    if c < -1 + 1e-12:
        return _axis_angle(np.array([0.0, 1.0, 0.0]), math.pi)
    ax = np.cross(e, _UP)
    return _axis_angle(ax / np.linalg.norm(ax), math.acos(c))


def draw_plan(rng: np.random.Generator, rate_hz: float | None = None) -> SealedPlan:
    """The plan of one recording (see the module docstring); ``rate_hz`` overrides the drawn sample rate."""
    fs = float(rng.choice([50.0, 100.0, 125.0, 200.0, 250.0, 400.0, 500.0, 800.0]))
    cls = "table1_lower" if rng.random() < 0.5 else "table1_upper"
    gravity = float(rng.uniform(9.78, 9.83))
    pool = [15.0, 30.0, 60.0, 100.0, 150.0, 220.0, 300.0, 400.0, 500.0]
    mags = sorted(float(m) for m in rng.choice(pool, size=int(rng.integers(3, 6)), replace=False))
    if mags[-1] < 300.0:
        mags[-1] = float(rng.choice([300.0, 400.0, 500.0]))
    tumble_peak = rng.uniform(40.0, 120.0) * DEG
    ramp_acc = rng.uniform(80.0, 300.0) * DEG
    settle = rng.uniform(0.4, 1.2)
    faces = [(k, s) for k in range(3) for s in (1, -1)]
    k0, s0 = faces[int(rng.integers(6))]
    q = _qmul(_axis_angle(_UP, rng.uniform(0.0, 2 * math.pi)), _face_quat(k0, s0))
    steps: list[SealedStep] = []
    t = 0.0

    def add(kind: Kind, duration: float, shape: str, axis: np.ndarray, **kw: float | bool) -> None:
        nonlocal t, q
        st = SealedStep(kind, t, duration, shape, (float(axis[0]), float(axis[1]), float(axis[2])),
                  (float(q[0]), float(q[1]), float(q[2]), float(q[3])), **kw)  # type: ignore[arg-type]
        steps.append(st)
        theta, _, _ = st.theta_rate_acc(np.array([duration]))
        q = _qmul(_axis_angle(axis, float(theta[0])), q)
        q = q / np.linalg.norm(q)
        t += duration

    def hold(kind: Kind, duration: float, rate: float = 0.0) -> None:
        add(kind, duration, "hold", _UP if rate else np.zeros(3), rate0=rate, rate1=rate, table=bool(rate))

    def tumble_to(k: int, s: int) -> None:
        v = _rotate(q, np.eye(3)[k] * s)
        c = float(np.clip(v @ _UP, -1.0, 1.0))
        if c > 1 - 1e-9:
            return
        ax = np.cross(v, _UP)
        if np.linalg.norm(ax) < 1e-6:  # upside down: half a turn about a horizontal axis
            h = float(rng.uniform(0.0, math.pi))
            ax = np.array([math.cos(h), math.sin(h), 0.0])
        ax = ax / np.linalg.norm(ax)
        ang = math.acos(c)
        dur = 2 * ang / tumble_peak  # raised cosine: peak rate 2 A / T
        add(Kind.MOVE, dur + settle, "tumble", ax, angle=ang, motion_s=dur)

    def ramp(w0: float, w1: float) -> None:
        dur = max(2 * abs(w1 - w0) / ramp_acc, 0.05)  # raised cosine: peak acceleration 2 dw / T
        add(Kind.MOVE, dur + settle, "ramp", _UP, rate0=w0, rate1=w1, motion_s=dur, table=True)

    hold(Kind.REST, float(rng.uniform(90.0, 240.0)))
    visited = {(k0, s0)}
    for k in (int(a) for a in rng.permutation(3)):
        s = 1 if rng.random() < 0.5 else -1
        tumble_to(k, s)
        visited.add((k, s))
        hold(Kind.POSE, float(rng.uniform(6.0, 18.0)))
        order = mags if rng.random() < 0.5 else mags[::-1]
        both = rng.random() < 0.7
        sign = 1.0 if rng.random() < 0.5 else -1.0
        targets = [sg * sign * m for m in order for sg in ((1.0, -1.0) if both else (1.0,))]
        w = 0.0
        for target in targets:
            ramp(w, target * DEG)
            w = target * DEG
            hold(Kind.RATE, float(rng.uniform(4.0, 10.0)), w)
        ramp(w, 0.0)
        hold(Kind.POSE, float(rng.uniform(6.0, 18.0)))
    rest = [f for f in faces if f not in visited]
    for i in rng.permutation(len(rest)):
        tumble_to(*rest[int(i)])
        hold(Kind.POSE, float(rng.uniform(6.0, 18.0)))
    turn = float(rng.uniform(90.0, 270.0)) * DEG * (1.0 if rng.random() < 0.5 else -1.0)
    dur = 2 * abs(turn) / tumble_peak
    add(Kind.MOVE, dur + settle, "tumble", _UP if turn > 0 else -_UP, angle=abs(turn), motion_s=dur, table=True)
    hold(Kind.POSE, float(rng.uniform(6.0, 18.0)))
    tumble_to(k0, s0)
    hold(Kind.POSE, float(rng.uniform(6.0, 18.0)))
    return SealedPlan(rate_hz=float(rate_hz) if rate_hz else fs, sensor_class=cls, gravity=gravity,
                magnitudes_dps=tuple(mags), steps=tuple(steps))


@dataclass(frozen=True)
class SealedMotion:
    """The rig at sample times: attitude (body -> world), body rate, body angular acceleration, labels."""

    q: np.ndarray  # (n, 4)
    w: np.ndarray  # (n, 3) rad/s, body
    alpha: np.ndarray  # (n, 3) rad/s^2, body
    segment: np.ndarray
    kind: np.ndarray
    table_angle: np.ndarray  # (n,) rad, the table's angle within its step (the bearing's phase), 0 off the table
    table_rate: np.ndarray  # (n,) rad/s, 0 off the table


def motion(plan: SealedPlan, t: np.ndarray) -> SealedMotion:
    """The rig's state at any times ``t`` (closed form per step)."""
    starts = np.array([st.t0 for st in plan.steps])
    idx = np.clip(np.searchsorted(starts, t, side="right") - 1, 0, len(plan.steps) - 1)
    n = len(t)
    q = np.empty((n, 4))
    w = np.zeros((n, 3))
    al = np.zeros((n, 3))
    kind = np.empty(n, dtype=np.int64)
    tab_a = np.zeros(n)
    tab_w = np.zeros(n)
    for i, st in enumerate(plan.steps):
        sel = np.flatnonzero(idx == i)
        if not len(sel):
            continue
        u = np.clip(t[sel] - st.t0, 0.0, None)
        theta, rate, acc = st.theta_rate_acc(u)
        axis = np.array(st.axis)
        qi = _qmul(_axis_angle(axis, theta), np.array(st.q_start)[None, :])
        q[sel] = qi
        w[sel] = _rotate(qi, rate[:, None] * axis, inverse=True)
        al[sel] = _rotate(qi, acc[:, None] * axis, inverse=True)
        kind[sel] = int(st.kind)
        if st.table:
            tab_a[sel] = theta
            tab_w[sel] = rate
    return SealedMotion(q=q, w=w, alpha=al, segment=idx.astype(np.int64), kind=kind, table_angle=tab_a,
                        table_rate=tab_w)


# --- temperature ---------------------------------------------------------------------------------------------
def temperature(t: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """True sensor temperature (degC): ambient, self-heating, and a chamber program through a first-order lag."""
    amb = rng.uniform(19.0, 28.0)
    rise, tau_s = rng.uniform(1.5, 5.0), rng.uniform(150.0, 600.0)
    rho = rng.uniform(1.5, 3.0) / 60.0  # K/s
    knots_t, knots_v = [0.0, float(rng.uniform(20.0, 100.0))], [0.0, 0.0]
    sign = 1.0 if rng.random() < 0.5 else -1.0
    while knots_t[-1] < t[-1]:
        ramp = rng.uniform(100.0, 200.0)
        knots_t.append(knots_t[-1] + ramp)
        knots_v.append(knots_v[-1] + sign * rho * ramp)
        knots_t.append(knots_t[-1] + rng.uniform(20.0, 60.0))
        knots_v.append(knots_v[-1])
        sign = -sign
    chamber = np.interp(t, knots_t, knots_v)
    lag = rng.uniform(20.0, 60.0)
    a = math.exp(-float(t[1] - t[0]) / lag)
    sensed = lfilter([1 - a], [1.0, -a], chamber)
    return amb + rise * -np.expm1(-t / tau_s) + sensed


# --- the unit --------------------------------------------------------------------------------------------------
def sensor_class(name: str) -> SensorClass:
    """The lower or upper 60 % of every Table 1 range (a class within Table 1)."""
    changes: dict[str, tuple[float, float]] = {}
    for f in dataclasses.fields(TABLE1):
        v = getattr(TABLE1, f.name)
        if isinstance(v, tuple):
            lo, hi = v
            changes[f.name] = (lo, lo + 0.6 * (hi - lo)) if name == "table1_lower" else (lo + 0.4 * (hi - lo), hi)
    return dataclasses.replace(TABLE1, name=name, **changes)  # type: ignore[arg-type]


@dataclass(frozen=True)
class SealedTriad:
    m: np.ndarray
    b_stat: np.ndarray
    b_drift: np.ndarray
    tc: np.ndarray
    sigma: np.ndarray


def draw_triad(rng: np.random.Generator, c: SensorClass, gyro: bool) -> SealedTriad:
    u = DEG if gyro else 1.0
    pre = "gyro" if gyro else "accel"
    unit_bias = "dps" if gyro else "mps2"

    def draw(name: str, size: int | tuple[int, int]) -> np.ndarray:
        lo, hi = getattr(c, f"{pre}_{name}")
        return rng.uniform(float(lo), float(hi), size)

    m = np.diag(draw("scale", 3)) + (1 - np.eye(3)) * draw("cross_axis", (3, 3))
    return SealedTriad(m=m, b_stat=draw(f"bias_static_{unit_bias}", 3) * u,
                       b_drift=draw(f"bias_drift_{unit_bias}", 3) * u, tc=draw("correlation_time_s", 3),
                       sigma=draw(f"noise_std_{unit_bias}", 3) * u)


def drift(t: np.ndarray, tr: SealedTriad, rel: float, rng: np.random.Generator) -> np.ndarray:
    """eq. (3): b_drift (exp(-t/T_c) + x(t)), x Gauss-Markov of stationary std ``rel`` from x(0) = 0, drawn exactly
    on a 10 Hz grid (T_c >= 50 s: the interpolation changes nothing measurable)."""
    grid = np.arange(0.0, t[-1] + 0.2, 0.1)
    out = np.empty((len(t), 3))
    for k in range(3):
        phi = math.exp(-0.1 / tr.tc[k])
        e = rng.standard_normal(len(grid)) * math.sqrt(1 - phi**2) * rel
        e[0] = 0.0
        x = lfilter([1.0], [1.0, -phi], e)
        out[:, k] = tr.b_drift[k] * (np.exp(-t / tr.tc[k]) + np.interp(t, grid, x))
    return out


def pink(n: int, fs: float, sigma: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Flicker-like noise: five first-order processes, time constants 0.02-5 s log-spaced, equal variance, total std
    ``sigma`` per axis (each stationary from the start)."""
    out = np.zeros((n, 3))
    taus = np.geomspace(0.02, 5.0, 5)
    for tau in taus:
        a = math.exp(-1.0 / (fs * tau))
        e = rng.standard_normal((n, 3)) * math.sqrt(1 - a**2)
        e[0] = rng.standard_normal(3)
        out += lfilter([1.0], [1.0, -a], e, axis=0)
    return out * sigma / math.sqrt(len(taus))


def _tri(x: np.ndarray) -> np.ndarray:
    """Triangle wave of period 1, amplitude 1."""
    f = x % 1.0
    return np.where(f < 0.5, 4 * f - 1, 3 - 4 * f)


def high_holds_ended(plan: SealedPlan, t: np.ndarray) -> np.ndarray:
    """Number of table holds at ``RATCHET_DPS`` or more that ended before each time."""
    ends = np.array([st.t0 + st.duration for st in plan.steps
                     if st.kind == Kind.RATE and abs(st.rate0) >= RATCHET_DPS * DEG - 1e-9])
    return np.searchsorted(ends, t, side="right").astype(float)


# --- one recording ---------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Sealed:
    session: Session
    plan: SealedPlan
    kind: str
    size: float  # |size| in the unit of SIZE
    axis: int  # the axis it acts on
    params: dict[str, float]  # the kind's other draws
    planted: dict[str, np.ndarray]  # sensor -> (n, 3) what the kind added to the output (before quantization)
    temp_true: np.ndarray  # (n,) the sensor's true temperature (degC)
    attitude: np.ndarray  # (n, 4) body -> world quaternion (w, x, y, z)


def generate(seed: int, kind: str, *, rate_hz: float | None = None) -> Sealed:
    """One recording of ``kind`` (:data:`KINDS`): seed in, same session out. ``rate_hz`` overrides the drawn sample
    rate (tests only; the rest of the plan is the same)."""
    if kind not in KINDS:
        raise ValueError(f"unknown kind {kind!r} (one of {', '.join(KINDS)})")
    rng = np.random.Generator(np.random.Philox(key=[seed, SEALED_KEY]))
    kr = np.random.Generator(np.random.Philox(key=[seed, SEALED_KEY + 1 + KINDS.index(kind)]))
    plan = draw_plan(rng, rate_hz)
    fs = plan.rate_hz
    n = int(plan.end_s * fs)
    t = np.arange(n) / fs
    mo = motion(plan, t)
    up = _rotate(mo.q, np.broadcast_to(_UP, (n, 3)), inverse=True)
    temp = temperature(t, rng)
    cls = sensor_class(plan.sensor_class)
    x = {"accel": plan.gravity * up, "gyro": mo.w}
    clean: dict[str, np.ndarray] = {}
    noise: dict[str, np.ndarray] = {}
    triads: dict[str, SealedTriad] = {}
    for sensor in ("accel", "gyro"):
        tr = draw_triad(rng, cls, sensor == "gyro")
        triads[sensor] = tr
        clean[sensor] = x[sensor] @ tr.m.T + tr.b_stat + drift(t, tr, cls.drift_noise_rel, rng)  # eq. (1), (3)
        noise[sensor] = rng.standard_normal((n, 3)) * tr.sigma
    temp_read = np.round((temp + rng.normal(0.0, 0.03, n)) * 128.0) / 128.0

    axis = int(kr.integers(3))
    size = SIZE.get(kind, 0.0) * float(kr.uniform(0.8, 1.25))
    if kind == "rate_clip":  # a fraction of the top rate: its own range
        size = float(kr.uniform(0.88, 0.96))
    sgn = 1.0 if kr.random() < 0.5 else -1.0
    if kind in ("rate_clip", "axis_skew", "accel_creep"):  # no sign: a range, a delay, a creep fraction
        sgn = 1.0
    params: dict[str, float] = {"c": sgn * size}
    add = {s: np.zeros((n, 3)) for s in ("accel", "gyro")}
    if kind == "pink_noise":
        for sensor in ("accel", "gyro"):
            sig = triads[sensor].sigma
            add[sensor] = pink(n, fs, 0.6 * sig, kr) - 0.2 * noise[sensor]  # white 0.8 sigma + pink 0.6 sigma
    elif kind == "dtdt_scale":
        dtdt = np.gradient(temp, t)
        add["accel"][:, axis] = sgn * size * dtdt * x["accel"][:, axis]
    elif kind == "vibration_bias":
        m_ball = float(kr.integers(6, 11))
        mids = plan.magnitudes_dps[len(plan.magnitudes_dps) // 2: len(plan.magnitudes_dps) // 2 + 1]
        f0 = m_ball * mids[0] / 360.0 * float(kr.uniform(0.9, 1.1))
        q_fac = float(kr.uniform(3.0, 6.0))
        a_peak = float(kr.uniform(0.4, 1.2))
        fb = m_ball * np.abs(mo.table_rate) / (2 * math.pi)
        r = fb / f0
        amp = a_peak / q_fac / np.sqrt((1 - r**2) ** 2 + (r / q_fac) ** 2) * np.minimum(r, 1.0) ** 2
        d = kr.standard_normal(3)
        d /= np.linalg.norm(d)
        add["accel"] = (amp * np.sin(m_ball * mo.table_angle))[:, None] * d
        kappa = size * DEG / (a_peak**2 / 2)
        add["gyro"][:, axis] = sgn * kappa * amp**2 / 2
        params.update(m=m_ball, f0_hz=f0, q=q_fac, a_peak=a_peak, kappa=sgn * kappa)
    elif kind == "drive_limit_cycle":
        period = float(kr.uniform(90.0, 300.0))
        phase = float(kr.uniform(0.0, 1.0))
        add["gyro"][:, axis] = sgn * size * DEG * _tri(t / period + phase)
        params.update(period_s=period, phase=phase)
    elif kind == "heading_bias":
        j = (axis + 1 + int(kr.integers(2))) % 3
        beta = float(kr.uniform(0.0, 2 * math.pi))
        field = np.array([math.cos(beta), math.sin(beta), 0.0])
        add["gyro"][:, axis] = sgn * size * DEG * _rotate(mo.q, np.broadcast_to(field, (n, 3)), inverse=True)[:, j]
        params.update(j=float(j), beta=beta)
    elif kind == "accel_ratchet":
        add["accel"][:, axis] = sgn * size * high_holds_ended(plan, t)
    elif kind == "axis_skew":
        delta = float(kr.integers(1, 3)) / (3 * fs) + size * 1e-3
        late = motion(plan, t - delta).w
        add["gyro"][:, axis] = ((late - mo.w) @ triads["gyro"].m.T)[:, axis]
        params.update(delta_s=delta)
    elif kind == "accel_creep":
        tau = float(kr.uniform(2.0, 8.0))
        a = math.exp(-1.0 / (fs * tau))
        f = x["accel"][:, axis]
        lagged = lfilter([1 - a], [1.0, -a], f - f[0]) + f[0]
        add["accel"][:, axis] = size * (lagged - f)
        params.update(tau_s=tau)
    out: dict[str, np.ndarray] = {}
    for sensor in ("accel", "gyro"):
        y = clean[sensor] + noise[sensor] + add[sensor]
        if sensor == "gyro" and kind == "code_inl":
            tr = triads["gyro"]  # the axis's output levels in the table holds (all blocks: 0 in the others')
            levels = np.unique(np.round(mo.w[mo.kind == int(Kind.RATE), axis], 9)) * tr.m[axis, axis]
            levels += tr.b_stat[axis] + tr.b_drift[axis]
            for _ in range(50):  # a period that the plan's rates resolve: the INL spans >= 0.6 c over the holds
                period = float(kr.uniform(40.0, 90.0)) * DEG
                if np.ptp(np.sin(2 * math.pi * levels / period)) >= 1.2:
                    break
            inl = sgn * size * DEG * np.sin(2 * math.pi * y[:, axis] / period)
            y[:, axis] += inl
            add[sensor][:, axis] = inl
            params.update(period_dps=period / DEG)
        if sensor == "gyro" and kind == "rate_clip":
            rail = size * plan.top_dps * DEG * triads["gyro"].m[axis, axis]  # a fraction of the axis's top output
            clipped = np.clip(y[:, axis], -rail, rail)
            add[sensor][:, axis] = clipped - y[:, axis]
            y[:, axis] = clipped
            params.update(rail_dps=rail / DEG)
        rng_, lsb = (ACCEL_RANGE, ACCEL_LSB) if sensor == "accel" else (GYRO_RANGE, GYRO_LSB)
        out[sensor] = np.clip(np.round(y / lsb) * lsb, -rng_, rng_ - lsb)
    meta = {"serial": f"SEAL-{seed:06d}", "sample_rate_hz": f"{fs:g}", "gravity_mps2": f"{plan.gravity:.5f}",
            "station": "gen_sealed", "rig": "gen_sealed"}
    session = Session(metadata=meta, t_s=t, segment=mo.segment, kind=mo.kind, accel_mps2=out["accel"],
                      gyro_radps=out["gyro"], temp_degc=temp_read, ref_accel_mps2=x["accel"], ref_gyro_radps=mo.w)
    return Sealed(session=session, plan=plan, kind=kind, size=size, axis=axis, params=params, planted=add,
                  temp_true=temp, attitude=mo.q)


def design_snr(rec: Sealed) -> float:
    """The planted signal's matched-filter SNR against the white noise: sqrt(sum s^2) / sigma over the sensor and
    axis where it is largest, after removing its mean (a constant is a bias the base fit takes)."""
    best = 0.0
    for sensor, s in rec.planted.items():
        sigma = (0.0125 * DEG) if sensor == "gyro" else 0.025  # the classes' typical noise std
        for k in range(3):
            v = s[:, k] - s[:, k].mean()
            best = max(best, float(np.sqrt(np.sum(v**2))) / sigma)
    return best


def snr_table(first: int, count: int, rate_hz: float | None = 50.0) -> list[tuple[str, float, float]]:
    """(kind, min, median) of :func:`design_snr` over seeds ``first .. first + count - 1`` (no diagnosis run)."""
    rows = []
    for kind in SEALED:
        v = sorted(design_snr(generate(s, kind, rate_hz=rate_hz)) for s in range(first, first + count))
        rows.append((kind, v[0], v[len(v) // 2]))
    return rows


if __name__ == "__main__":
    from station.session.csv_v1 import write_session

    a = sys.argv[1:]
    if len(a) == 3 and a[0] == "--snr":
        for kind, lo, med in snr_table(int(a[1]), int(a[2])):
            print(f"{kind:18s} design SNR at 50 Hz: min {lo:9.1f}  median {med:9.1f}")
        sys.exit(0)
    if len(a) != 3:
        sys.exit("usage: python benchmarks/gen_sealed.py SEED KIND OUT.csv  |  --snr FIRST_SEED COUNT")
    rec = generate(int(a[0]), a[1])
    write_session(rec.session, a[2])
    print(f"{a[2]}: {rec.kind} {len(rec.session)} samples at {rec.plan.rate_hz:g} Hz, {rec.session.duration_s:.0f} s, "
          f"axis {'xyz'[rec.axis]}, design SNR {design_snr(rec):.0f}")
