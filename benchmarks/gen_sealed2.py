"""A second sealed generator of physics outside the diagnosis's library: the held-out final check.

Written apart from ``station/sim``, ``station/physics``, ``tests/indepgen.py``, ``benchmarks/gen_outside.py`` and
``benchmarks/gen_sealed.py`` (none of them imported or copied); only the session writer, the session model and
Table 1's ranges are the station's (to write a recording the station reads). Nobody changing the locator reads or
runs this file: it is run once, at the end, on fresh seeds.

**Rig: a minimum-jerk rig, attitude as rotation matrices.** Every rig step turns about one world axis fixed for
the step with a quintic minimum-jerk profile (``s(x) = 10 x^3 - 15 x^4 + 6 x^5``; tumbles rest to rest by an
angle, table-rate changes ``w0 -> w1``), whose angle is a polynomial in time; the attitude (body -> world) is
Rodrigues' matrix formula ``R(t) = Rot(a, theta(t)) R_start`` (3x3 matrices, no quaternions), the body rate
``R^T a theta'`` and the angular acceleration ``R^T a theta''``. A sample taken at a jittered time is the same
expressions' first-order Taylor step (the body-frame derivatives of the rate and of gravity are known exactly).

**Its own plan shape: faces, edges, corners, spins from zero.** A still rest of 60-180 s on a random face at a
random heading; then, in random order, 14 poses (the six faces, two *edge* poses per pair of axes with gravity
along ``(+-e_i +-e_j)/sqrt 2``, two *corner* poses along ``(+-1, +-1, +-1)/sqrt 3``), each reached by a tumble about
the horizontal axis (peak 50-150 deg/s), some followed by a table turn of 60-300 deg, held 3-10 s; between them,
at random places, the spin blocks: one per body axis (axis up or down) and one about a body diagonal (a corner up),
plus with probability 0.5 one about an edge diagonal. A block: the tumble, a pose, then for each of 3-4
magnitudes (2-3 on a diagonal; pool 10-450 deg/s, the top at least 250) in *shuffled* order, both signs in random
order, each from zero: a ramp (peak angular acceleration 120-400 deg/s^2), a hold of 4-9 s, a ramp back to zero,
a pose of 2-4 s. Last, the start face again. Sample rates 50, 64, 100, 128, 200, 256, 400, 512 or 800 Hz.
A climate chamber steps its set point (2-3 steps of 4-7 K up, then down, dwell 80-200 s) and the sensor follows
through two first-order lags (air 30-90 s, package 20-60 s), on top of self-heating (1-4 K, 100-400 s).

**Its own sensors.** Two classes within Table 1 (``station.kernel.sensor_class.TABLE1``): the middle half of
every range (``table1_mid``) and the full ranges (``table1_full``). Eq. (1) with the eq. (3) drift: ``b_drift
exp(-t/T_c)`` plus a Gauss-Markov part of stationary std 1 % of ``b_drift`` (started at 0), an AR(1) discretised
exactly at the sample rate; white noise; converters of +-8 g at 20 bit and +-2000 deg/s at 22 bit; a thermometer
of 1/64 K with 0.02 K noise. Random numbers: numpy's PCG64DXSM seeded by ``SeedSequence([seed, KEY, 0])`` for
plan and unit, ``[seed, KEY, 1 + index of the kind]`` for the kind's own draws: a kind's recording is the ``none``
recording of the same seed plus the planted physics only.

The kinds (:data:`SEALED2`, one axis per recording chosen by the seed, size random per seed 0.8-1.25 of
:data:`SIZE`, random sign where a sign means something):

``alias_tone``          accel: the gyro's drive (kHz) aliases into one accelerometer axis through the shared
                        converter clock, a tone ``c sin(2 pi int f dt)`` at 0.4-2.5 Hz whose frequency follows
                        the temperature (``df/dT`` 0.01-0.03 Hz/K: the drive frequency's temperature coefficient).
``temp_lut_steps``      gyro: the on-chip temperature compensation is a look-up table with cells of 1.5-3 K; a
                        linear tempco corrected by a constant per cell leaves a sawtooth ``c saw((T - T_r)/P)``.
``anisoinertia``        gyro: axis ``k`` sees ``c w_i w_j``, the product of the other two axes' rates (the
                        anisoinertia term of IEEE Std 1431/813): only where the rate has two components (spins
                        about a diagonal, tumbles about a non-body axis).
``accel_cross_coupling`` accel: the IEEE Std 1293 cross-coupling ``c f_k f_j / g`` on axis ``k`` (``j`` another
                        axis): zero on the faces, ``c g/2`` on an edge pose, ``c g/3`` on a corner.
``adc_crosstalk``       accel: channel crosstalk of a shared converter, ``c y_gyro,j`` added to accelerometer axis
                        ``k`` (``j`` any axis; odd in the rate, unlike a lever arm's ``w x (w x r)``).
``scale_jitter``        gyro: multiplicative noise of one axis, ``w_k (1 + e(t))``, ``e`` an AR(1) of 0.05-0.3 s
                        correlation (the drive amplitude's jitter): a noise that grows with the rate.
``motor_heating``       gyro: the table's motor heats the fixture on one side of the package (not the die's
                        thermometer): a bias ``c L[(|w|/w_top)^2]``, ``L`` a first-order lag of 40-150 s: it builds
                        up in the spins and decays in the poses after them.
``clock_jitter``        both: every sample taken at ``t + j(t)``, ``j`` an AR(1) of 3-30 ms correlation and
                        ~0.4 ms std (a polled data-ready line), time stamps nominal: an error ``j dy/dt``
                        (``LOCATION``: the gyro; the accelerometer's part is far below its noise).
``spin_stress_scale``   accel: the spin's centrifugal load on the board changes one axis's scale, ``f_k (1 + c
                        |w|^2)``: where the axis carries gravity during a spin (spins about it or a diagonal).

Nulls (:data:`NULLS`): ``none`` (base model only) and ``resonant_noise`` (the white noise replaced by 0.8 of it
plus a resonant part of 0.6 of it: white noise through a second-order band-pass at 0.15-0.35 of the sample rate,
Q 2-5, a structural mode of the package, on every axis of both sensors).

:data:`LOCATION` (sensors, segment kinds) and :data:`COVARIATE` (words one of which a right ``unexplained``
entry's covariate text names) were written with the kinds, before any recording was given to the diagnosis.

``python benchmarks/gen_sealed2.py SEED KIND OUT.csv`` writes one recording; ``--snr FIRST COUNT`` prints every
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
G0 = 9.80665
#: Second word of every SeedSequence of this generator (the first is the seed, the third the stream).
KEY = 0x5EA12002
#: Converters (own choice): +-8 g at 20 bit, +-2000 deg/s at 22 bit.
ACCEL_FULL = 8.0 * G0
GYRO_FULL = 2000.0 * DEG
ACCEL_LSB = 2.0 * ACCEL_FULL / 2**20
GYRO_LSB = 2.0 * GYRO_FULL / 2**22
#: Typical white-noise std of the classes (the middle of Table 1's ranges), for the design SNR.
SIGMA_TYPICAL = {"accel": 0.0225, "gyro": 0.0115 * DEG}
RATES_HZ = (50.0, 64.0, 100.0, 128.0, 200.0, 256.0, 400.0, 512.0, 800.0)

NULLS = ("none", "resonant_noise")
SEALED2 = ("alias_tone", "temp_lut_steps", "anisoinertia", "accel_cross_coupling", "adc_crosstalk",
           "scale_jitter", "motor_heating", "clock_jitter", "spin_stress_scale")
KINDS = (*NULLS, *SEALED2)
#: Kinds whose planted signal is random (a noise): their design SNR is a variance excess, not a matched filter.
NOISE_KINDS = ("scale_jitter", "clock_jitter")

# LOCATION and COVARIATE were written with the kinds, BEFORE any recording of this generator was given to the
# diagnosis. Do not edit them after seeing results.
#: Where each kind acts: (sensors, segment kinds); a right ``unexplained`` names one of the sensors and at least
#: one of the segment kinds.
LOCATION: dict[str, tuple[frozenset[str], frozenset[str]]] = {
    # a tone all the time
    "alias_tone": (frozenset({"accel"}), frozenset({"rest", "pose", "rate", "move"})),
    # follows the temperature wherever the unit is settled
    "temp_lut_steps": (frozenset({"gyro"}), frozenset({"rest", "pose", "rate"})),
    # the diagonal spins and the tumbles about non-body axes
    "anisoinertia": (frozenset({"gyro"}), frozenset({"rate", "move"})),
    # edge and corner poses, the diagonal spins (gravity on two axes), the tumbles
    "accel_cross_coupling": (frozenset({"accel"}), frozenset({"pose", "rate", "move"})),
    # wherever the gyro axis turns: the holds and the ramps
    "adc_crosstalk": (frozenset({"accel"}), frozenset({"rate", "move"})),
    "scale_jitter": (frozenset({"gyro"}), frozenset({"rate", "move"})),
    # builds up in the spins, decays in the poses between and after them
    "motor_heating": (frozenset({"gyro"}), frozenset({"rate", "pose"})),
    # only where the signal changes: the moves; the gyro only (the accelerometer's part, -j w x f, adds a variance
    # z of 0.06-0.17 at 50 Hz: present but not visible, so not a place a right report may name)
    "clock_jitter": (frozenset({"gyro"}), frozenset({"move"})),
    # spins with the axis carrying gravity (and the tumbles)
    "spin_stress_scale": (frozenset({"accel"}), frozenset({"rate", "move"})),
}
#: Words one of which a right ``unexplained`` entry's covariate text holds; for the nulls what an
#: ``unexplained`` on them may say (no covariate, the noise's colour).
COVARIATE: dict[str, tuple[str, ...]] = {
    "alias_tone": ("periodic", "oscillat", "tone", "sinus", "frequency"),
    "temp_lut_steps": ("temperature",),
    "anisoinertia": ("rate", "product"),
    "accel_cross_coupling": ("specific force", "force", "product", "orientation", "attitude"),
    "adc_crosstalk": ("rate",),
    "scale_jitter": ("rate", "noise", "scale", "variance", "dispersion"),
    "motor_heating": ("rate", "since the last", "history", "heating", "time"),
    "clock_jitter": ("angular acceleration", "jitter", "delay", "time", "noise"),
    "spin_stress_scale": ("rate", "specific force", "product", "force"),
    "none": ("none",),
    "resonant_noise": ("none", "colour", "color"),
}
#: Nominal size of each kind in its own unit, times a random 0.8-1.25 per recording. The design SNR from first
#: principles (:func:`design_snr`; ``python benchmarks/gen_sealed2.py --snr 300000 40``, 50 Hz, the smallest
#: plan rate) is stated per kind in docs/diagnosis-locator.md; the reasoning per kind:
SIZE = {
    # m/s^2 amplitude of the tone: ~0.9 sigma_a per sample, all the time: over N >= 25,000 samples a matched
    # filter of sqrt(N/2) * 0.9 >= 100 sigma; per 1,000-sample block a variance excess of ~0.4 sigma^2 (z ~ 9)
    "alias_tone": 0.02,
    # deg/s amplitude of the sawtooth (tempco x half a cell); per 4-9 s hold the mean's noise is <= 0.9 mdeg/s
    "temp_lut_steps": 0.03,
    # deg/s at 300 deg/s about an edge diagonal (w_i w_j = w^2/2; c = size / ((300 deg/s)^2 / 2) in s); a corner
    # spin has w^2/3: >= 0.02 deg/s in the top diagonal holds, >= 20 sigma of a hold's mean
    "anisoinertia": 0.05,
    # relative (c in c f_k f_j / g): 0.02-0.03 m/s^2 on an edge pose, >= 15 sigma of a 3 s pose's mean at 50 Hz
    "accel_cross_coupling": 5e-3,
    # m/s^2 per 100 deg/s of the gyro axis: 0.05-0.09 m/s^2 in the top holds about it, >= 2 sigma per sample
    "adc_crosstalk": 0.02,
    # relative std of e: 0.045 deg/s std at 300 deg/s (~4 sigma_g per sample); variance excess z >= 100
    "scale_jitter": 1.5e-4,
    # deg/s at full heating (a steady top rate); the plan's holds reach 0.2-0.6 of it: 0.02-0.06 deg/s, decaying
    # over 40-150 s in the poses after
    "motor_heating": 0.1,
    # ms std of the jitter; ramps of 120-400 deg/s^2 give 0.05-0.16 deg/s std in the gyro (4-14 sigma_g)
    "clock_jitter": 0.4,
    # relative scale change at 300 deg/s (c = size / (300 deg/s)^2 in s^2): 0.03 m/s^2 on +-g at 300 deg/s,
    # 0.02 m/s^2 at the smallest top rate (250 deg/s): >= 20 sigma of a 4 s hold's mean at 50 Hz
    "spin_stress_scale": 3e-3,
}

_UP = np.array([0.0, 0.0, 1.0])


# --- rotations (matrices, body -> world) ---------------------------------------------------------------------
def rodrigues(axis: np.ndarray, angle: np.ndarray | float) -> np.ndarray:
    """Rotation matrices (..., 3, 3) by ``angle`` about the unit ``axis``: I cos + sin [a]x + (1 - cos) a a^T."""
    a = np.asarray(axis, dtype=float)
    th = np.asarray(angle, dtype=float)[..., None, None]
    cross = np.array([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]])
    return np.cos(th) * np.eye(3) + np.sin(th) * cross + (1.0 - np.cos(th)) * np.outer(a, a)


def _orthonormal(r: np.ndarray) -> np.ndarray:
    u, _, vt = np.linalg.svd(r)
    return u @ vt


# --- the minimum-jerk profile --------------------------------------------------------------------------------
def _mj(x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Minimum-jerk s(x) = 10x^3 - 15x^4 + 6x^5 on [0, 1]: its integral, value, first and second derivative."""
    x = np.clip(x, 0.0, 1.0)
    big_s = x**4 * (2.5 - 3.0 * x + x**2)
    s = x**3 * (10.0 - 15.0 * x + 6.0 * x**2)
    ds = 30.0 * x**2 * (1.0 - x) ** 2
    dds = 60.0 * x * (1.0 - x) * (1.0 - 2.0 * x)
    return big_s, s, ds, dds


#: Peak of ds/dx of the minimum-jerk profile (at x = 1/2).
MJ_PEAK = 1.875


@dataclass(frozen=True)
class Step:
    """One rig step: a turn about the world ``axis`` (fixed for the step), then a settle at its final rate."""

    kind: Kind
    t0: float
    duration: float
    shape: str  # "hold" (constant rate w0), "tumble" (rest to rest by angle), "ramp" (w0 -> w1)
    axis: tuple[float, float, float]
    r_start: tuple[float, ...]  # 9 numbers, row-major
    w0: float = 0.0  # rad/s
    w1: float = 0.0  # rad/s
    angle: float = 0.0  # rad (tumbles)
    motion_s: float = 0.0

    def profile(self, u: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Angle (rad), rate (rad/s), angular acceleration (rad/s^2) about the axis at ``u`` s into the step."""
        if self.shape == "hold":
            return self.w0 * u, np.full_like(u, self.w0), np.zeros_like(u)
        big_t = self.motion_s
        x = u / big_t
        big_s, s, ds, dds = _mj(x)
        inside = (u < big_t).astype(float)
        if self.shape == "tumble":
            a = self.angle
            return a * s, a / big_t * ds * inside, a / big_t**2 * dds * inside
        dw = self.w1 - self.w0
        past = np.clip(u - big_t, 0.0, None)
        theta = self.w0 * np.minimum(u, big_t) + dw * big_t * big_s + self.w1 * past
        return theta, self.w0 + dw * s, dw / big_t * ds * inside


@dataclass(frozen=True)
class Plan:
    rate_hz: float
    sensor_class: str
    gravity: float
    magnitudes_dps: tuple[float, ...]  # of the body-axis spins
    steps: tuple[Step, ...]

    @property
    def end_s(self) -> float:
        return self.steps[-1].t0 + self.steps[-1].duration

    @property
    def top_dps(self) -> float:
        return max(self.magnitudes_dps)


def draw_plan(rng: np.random.Generator, rate_hz: float | None = None) -> Plan:
    """The plan of one recording (module docstring); ``rate_hz`` overrides the drawn sample rate."""
    fs = float(rng.choice(RATES_HZ))
    cls = "table1_mid" if rng.random() < 0.5 else "table1_full"
    gravity = float(rng.uniform(9.779, 9.832))
    tumble_peak = float(rng.uniform(50.0, 150.0)) * DEG
    alpha_peak = float(rng.uniform(120.0, 400.0)) * DEG
    settle = float(rng.uniform(0.3, 1.0))
    pool = np.array([10.0, 25.0, 50.0, 80.0, 120.0, 180.0, 250.0, 320.0, 400.0, 450.0])
    steps: list[Step] = []
    t = 0.0
    eye = np.eye(3)
    faces = [s * eye[k] for k in range(3) for s in (1.0, -1.0)]
    start = faces[int(rng.integers(6))]
    r = rodrigues(_UP, float(rng.uniform(0.0, 2 * math.pi))) @ _to_up(start)

    def add(kind: Kind, duration: float, shape: str, axis: np.ndarray, **kw: float) -> None:
        nonlocal t, r
        st = Step(kind, t, duration, shape, (float(axis[0]), float(axis[1]), float(axis[2])),
                  tuple(float(v) for v in r.ravel()), **kw)
        steps.append(st)
        theta, _, _ = st.profile(np.array([duration]))
        r = _orthonormal(rodrigues(axis, float(theta[0])) @ r)
        t += duration

    def hold(kind: Kind, duration: float, w: float = 0.0) -> None:
        add(kind, duration, "hold", _UP, w0=w, w1=w)

    def tumble_to(d: np.ndarray) -> None:
        v = r @ d
        c = float(np.clip(v @ _UP, -1.0, 1.0))
        if c > 1.0 - 1e-9:
            return
        ax = np.cross(v, _UP)
        if np.linalg.norm(ax) < 1e-6:
            h = float(rng.uniform(0.0, 2 * math.pi))
            ax = np.array([math.cos(h), math.sin(h), 0.0])
        ax = ax / np.linalg.norm(ax)
        ang = math.acos(c)
        dur = MJ_PEAK * ang / tumble_peak
        add(Kind.MOVE, dur + settle, "tumble", ax, angle=ang, motion_s=dur)

    def table_turn() -> None:
        turn = float(rng.uniform(60.0, 300.0)) * DEG
        dur = MJ_PEAK * turn / tumble_peak
        add(Kind.MOVE, dur + settle, "tumble", _UP if rng.random() < 0.5 else -_UP, angle=turn, motion_s=dur)

    def ramp(w0: float, w1: float) -> None:
        dur = max(MJ_PEAK * abs(w1 - w0) / alpha_peak, 0.05)
        add(Kind.MOVE, dur + settle, "ramp", _UP, w0=w0, w1=w1, motion_s=dur)

    def spin_block(d: np.ndarray, mags: list[float]) -> None:
        tumble_to(d)
        hold(Kind.POSE, float(rng.uniform(3.0, 6.0)))
        for m in mags:
            for sg in (1.0, -1.0) if rng.random() < 0.5 else (-1.0, 1.0):
                ramp(0.0, sg * m * DEG)
                hold(Kind.RATE, float(rng.uniform(4.0, 9.0)), sg * m * DEG)
                ramp(sg * m * DEG, 0.0)
                hold(Kind.POSE, float(rng.uniform(2.0, 4.0)))

    def axis_mags() -> list[float]:
        mags = [float(v) for v in rng.choice(pool, size=int(rng.integers(3, 5)), replace=False)]
        if max(mags) < 250.0:
            mags[int(np.argmax(mags))] = float(rng.choice(pool[pool >= 250.0]))
        return mags

    hold(Kind.REST, float(rng.uniform(60.0, 180.0)))
    poses: list[np.ndarray] = list(faces)
    for i, j in ((0, 1), (0, 2), (1, 2)):
        for _ in range(2):
            poses.append((rng.choice([-1.0, 1.0]) * eye[i] + rng.choice([-1.0, 1.0]) * eye[j]) / math.sqrt(2.0))
    for _ in range(2):
        poses.append(rng.choice([-1.0, 1.0], size=3) / math.sqrt(3.0))
    poses = [poses[int(i)] for i in rng.permutation(len(poses))]
    all_mags: list[float] = []
    blocks: list[tuple[np.ndarray, list[float]]] = []
    for k in (int(v) for v in rng.permutation(3)):
        mags = axis_mags()
        all_mags += mags
        blocks.append((float(rng.choice([-1.0, 1.0])) * eye[k], mags))
    diag_top = float(rng.choice(pool[(pool >= 200.0) & (pool <= 400.0)]))
    blocks.append((rng.choice([-1.0, 1.0], size=3) / math.sqrt(3.0),
                   [diag_top, *(float(v) for v in rng.choice(pool[pool < 200.0], size=int(rng.integers(1, 3)),
                                                              replace=False))]))
    if rng.random() < 0.5:
        i, j = (int(v) for v in rng.choice(3, size=2, replace=False))
        d = (rng.choice([-1.0, 1.0]) * eye[i] + rng.choice([-1.0, 1.0]) * eye[j]) / math.sqrt(2.0)
        blocks.append((d, [float(rng.choice(pool[(pool >= 120.0) & (pool <= 320.0)]))]))
    order = [blocks[int(i)] for i in rng.permutation(len(blocks))]
    where = sorted(int(v) for v in rng.choice(len(poses) + 1, size=len(order)))
    items: list[tuple[str, object]] = [("pose", p) for p in poses]
    for pos, blk in sorted(zip(where, order, strict=True), key=lambda z: -z[0]):
        items.insert(pos, ("spin", blk))
    for what, obj in items:
        if what == "pose":
            assert isinstance(obj, np.ndarray)
            tumble_to(obj)
            if rng.random() < 0.3:
                table_turn()
            hold(Kind.POSE, float(rng.uniform(3.0, 10.0)))
        else:
            d, mags = obj  # type: ignore[misc]
            spin_block(d, mags)
    tumble_to(start)
    hold(Kind.POSE, float(rng.uniform(3.0, 10.0)))
    return Plan(rate_hz=float(rate_hz) if rate_hz else fs, sensor_class=cls, gravity=gravity,
                magnitudes_dps=tuple(all_mags), steps=tuple(steps))


def _to_up(d: np.ndarray) -> np.ndarray:
    """A rotation (body -> world) that puts the body vector ``d`` along world up."""
    d = d / np.linalg.norm(d)
    c = float(d @ _UP)
    if c > 1.0 - 1e-12:
        return np.eye(3)
    if c < -1.0 + 1e-12:
        return rodrigues(np.array([1.0, 0.0, 0.0]), math.pi)
    ax = np.cross(d, _UP)
    return rodrigues(ax / np.linalg.norm(ax), math.acos(c))


@dataclass(frozen=True)
class Motion:
    """The rig at the sample times: attitude (body -> world), body rate and angular acceleration, labels."""

    rot: np.ndarray  # (n, 3, 3)
    w: np.ndarray  # (n, 3) rad/s, body
    alpha: np.ndarray  # (n, 3) rad/s^2, body
    up: np.ndarray  # (n, 3) world up in the body frame
    segment: np.ndarray
    kind: np.ndarray


def motion(plan: Plan, t: np.ndarray) -> Motion:
    """The rig's state at the times ``t`` (the step's polynomial angle, Rodrigues' matrices)."""
    starts = np.array([st.t0 for st in plan.steps])
    idx = np.clip(np.searchsorted(starts, t, side="right") - 1, 0, len(plan.steps) - 1)
    n = len(t)
    rot = np.empty((n, 3, 3))
    w = np.zeros((n, 3))
    al = np.zeros((n, 3))
    kind = np.empty(n, dtype=np.int64)
    for i, st in enumerate(plan.steps):
        sel = np.flatnonzero(idx == i)
        if not len(sel):
            continue
        u = np.clip(t[sel] - st.t0, 0.0, None)
        theta, rate, acc = st.profile(u)
        a = np.array(st.axis)
        ri = rodrigues(a, theta) @ np.array(st.r_start).reshape(3, 3)
        rot[sel] = ri
        w[sel] = np.einsum("nji,j->ni", ri, a) * rate[:, None]  # R^T a theta'
        al[sel] = np.einsum("nji,j->ni", ri, a) * acc[:, None]
        kind[sel] = int(st.kind)
    up = rot[:, 2, :]  # R^T e_z is the third row of R
    return Motion(rot=rot, w=w, alpha=al, up=up, segment=idx.astype(np.int64), kind=kind)


# --- temperature -------------------------------------------------------------------------------------------------
def temperature(t: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """True sensor temperature (degC): ambient, self-heating, a set-point staircase through two lags."""
    ambient = float(rng.uniform(20.0, 27.0))
    rise, tau_h = float(rng.uniform(1.0, 4.0)), float(rng.uniform(100.0, 400.0))
    n_up = int(rng.integers(2, 4))
    sizes = rng.uniform(4.0, 7.0, n_up)
    levels = np.concatenate([np.cumsum(sizes), np.cumsum(sizes)[::-1][1:], [0.0]])
    edges = [float(rng.uniform(10.0, 60.0))]
    for _ in levels[1:]:
        edges.append(edges[-1] + float(rng.uniform(80.0, 200.0)))
    setpoint = np.zeros_like(t)
    for e, lev in zip(edges, levels, strict=True):
        setpoint[t >= e] = lev
    dt = float(t[1] - t[0])
    out = setpoint
    for tau in (float(rng.uniform(30.0, 90.0)), float(rng.uniform(20.0, 60.0))):
        a = math.exp(-dt / tau)
        out = lfilter([1.0 - a], [1.0, -a], out)
    return ambient + rise * (1.0 - np.exp(-t / tau_h)) + out


# --- the unit --------------------------------------------------------------------------------------------------
def sensor_class(name: str) -> SensorClass:
    """``table1_mid``: the middle half of every Table 1 range; ``table1_full``: Table 1 itself."""
    if name == "table1_full":
        return dataclasses.replace(TABLE1, name=name)
    changes: dict[str, tuple[float, float]] = {}
    for f in dataclasses.fields(TABLE1):
        v = getattr(TABLE1, f.name)
        if isinstance(v, tuple):
            lo, hi = v
            changes[f.name] = (lo + 0.25 * (hi - lo), hi - 0.25 * (hi - lo))
    return dataclasses.replace(TABLE1, name=name, **changes)  # type: ignore[arg-type]


@dataclass(frozen=True)
class Triad:
    m: np.ndarray
    b_stat: np.ndarray
    b_drift: np.ndarray
    tc: np.ndarray
    sigma: np.ndarray


def draw_triad(rng: np.random.Generator, c: SensorClass, gyro: bool) -> Triad:
    unit = DEG if gyro else 1.0
    pre, ub = ("gyro", "dps") if gyro else ("accel", "mps2")

    def u(name: str, size: int | tuple[int, int]) -> np.ndarray:
        lo, hi = getattr(c, f"{pre}_{name}")
        return lo + (hi - lo) * rng.random(size)

    diag = u("scale", 3)
    cross = u("cross_axis", (3, 3))
    m = np.where(np.eye(3, dtype=bool), np.diag(diag), cross)
    return Triad(m=m, b_stat=u(f"bias_static_{ub}", 3) * unit, b_drift=u(f"bias_drift_{ub}", 3) * unit,
                 tc=u("correlation_time_s", 3), sigma=u(f"noise_std_{ub}", 3) * unit)


def ar1(n: int, fs: float, tau: float, std: float, rng: np.random.Generator, *, cols: int = 1,
        stationary: bool = True) -> np.ndarray:
    """AR(1) of correlation time ``tau`` and stationary std ``std``, exact at the sample rate; started from its
    stationary law (``stationary``) or from 0."""
    a = math.exp(-1.0 / (fs * tau))
    e = rng.standard_normal((n, cols)) * std * math.sqrt(1.0 - a * a)
    e[0] = rng.standard_normal(cols) * std if stationary else 0.0
    return lfilter([1.0], [1.0, -a], e, axis=0)


def drift(t: np.ndarray, fs: float, tr: Triad, rel: float, rng: np.random.Generator) -> np.ndarray:
    """eq. (3): b_drift (exp(-t/T_c) + x(t)), x Gauss-Markov of stationary std ``rel`` from x(0) = 0."""
    out = np.empty((len(t), 3))
    for k in range(3):
        x = ar1(len(t), fs, float(tr.tc[k]), rel, rng, stationary=False)[:, 0]
        out[:, k] = tr.b_drift[k] * (np.exp(-t / tr.tc[k]) + x)
    return out


def resonant(n: int, fs: float, f0: float, q: float, sigma: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """White noise through a second-order band-pass (RBJ biquad, centre ``f0``, quality ``q``), scaled to std
    ``sigma`` per axis (the filter's noise gain computed from its own impulse response)."""
    w0 = 2 * math.pi * f0 / fs
    alpha = math.sin(w0) / (2 * q)
    b = np.array([alpha, 0.0, -alpha])
    a = np.array([1 + alpha, -2 * math.cos(w0), 1 - alpha])
    imp = lfilter(b, a, np.r_[1.0, np.zeros(4096)])
    gain = math.sqrt(float(np.sum(imp**2)))
    warm = 2048  # start from the filter's stationary state: drop a run-in
    e = rng.standard_normal((n + warm, 3))
    return lfilter(b, a, e, axis=0)[warm:] / gain * sigma


def _saw(x: np.ndarray) -> np.ndarray:
    """Sawtooth of period 1 from -1 to 1."""
    return 2.0 * (x - np.floor(x)) - 1.0


# --- one recording ---------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Recording:
    session: Session
    plan: Plan
    kind: str
    size: float  # |size| in the unit of SIZE
    axis: int  # the axis it acts on (-1: every axis, or none)
    params: dict[str, float]
    planted: dict[str, np.ndarray]  # sensor -> (n, 3) what the kind added to the output (before quantization)
    temp_true: np.ndarray
    attitude: np.ndarray  # (n, 3, 3) body -> world
    alpha: np.ndarray  # (n, 3) body angular acceleration (rad/s^2)


def _streams(seed: int, kind: str) -> tuple[np.random.Generator, np.random.Generator]:
    base = np.random.Generator(np.random.PCG64DXSM(np.random.SeedSequence([seed, KEY, 0])))
    own = np.random.Generator(np.random.PCG64DXSM(np.random.SeedSequence([seed, KEY, 1 + KINDS.index(kind)])))
    return base, own


def generate(seed: int, kind: str, *, rate_hz: float | None = None) -> Recording:
    """One recording of ``kind`` (:data:`KINDS`): seed in, same session out. ``rate_hz`` overrides the drawn
    sample rate (tests only; the rest of the plan is the same)."""
    if kind not in KINDS:
        raise ValueError(f"unknown kind {kind!r} (one of {', '.join(KINDS)})")
    rng, kr = _streams(seed, kind)
    plan = draw_plan(rng, rate_hz)
    fs = plan.rate_hz
    n = int(plan.end_s * fs)
    t = np.arange(n) / fs
    mo = motion(plan, t)
    temp = temperature(t, rng)
    cls = sensor_class(plan.sensor_class)
    truth = {"accel": plan.gravity * mo.up, "gyro": mo.w}
    triads = {s: draw_triad(rng, cls, s == "gyro") for s in ("accel", "gyro")}
    clean = {s: truth[s] @ triads[s].m.T + triads[s].b_stat + drift(t, fs, triads[s], cls.drift_noise_rel, rng)
             for s in ("accel", "gyro")}  # eq. (1), (3)
    noise = {s: rng.standard_normal((n, 3)) * triads[s].sigma for s in ("accel", "gyro")}
    temp_read = np.round((temp + 0.02 * rng.standard_normal(n)) * 64.0) / 64.0

    axis = int(kr.integers(3))
    size = SIZE.get(kind, 0.0) * float(kr.uniform(0.8, 1.25))
    sgn = float(kr.choice([-1.0, 1.0]))
    if kind in ("scale_jitter", "clock_jitter"):  # a std: no sign
        sgn = 1.0
    params: dict[str, float] = {"c": sgn * size}
    add = {s: np.zeros((n, 3)) for s in ("accel", "gyro")}
    others = [j for j in range(3) if j != axis]
    if kind == "none":
        axis = -1
    if kind == "resonant_noise":
        f0 = float(kr.uniform(0.15, 0.35)) * fs
        q = float(kr.uniform(2.0, 5.0))
        for s in ("accel", "gyro"):
            add[s] = resonant(n, fs, f0, q, 0.6 * triads[s].sigma, kr) - 0.2 * noise[s]
        params.update(f0_hz=f0, q=q)
        axis = -1
    elif kind == "alias_tone":
        f0 = float(kr.uniform(0.4, 2.5))
        dfdt = float(kr.uniform(0.01, 0.03)) * float(kr.choice([-1.0, 1.0]))
        phase0 = float(kr.uniform(0.0, 2 * math.pi))
        freq = np.maximum(f0 + dfdt * (temp - temp[0]), 0.1)
        phase = phase0 + 2 * math.pi * np.concatenate([[0.0], np.cumsum(0.5 * (freq[1:] + freq[:-1]) / fs)])
        add["accel"][:, axis] = size * np.sin(phase)  # the sign is the phase's
        params.update(c=size, f0_hz=f0, dfdt_hz_per_k=dfdt, phase0=phase0)
    elif kind == "temp_lut_steps":
        cell = float(kr.uniform(1.5, 3.0))
        t_ref = float(kr.uniform(0.0, cell))
        add["gyro"][:, axis] = sgn * size * DEG * _saw((temp - t_ref) / cell)
        params.update(cell_k=cell, t_ref=t_ref)
    elif kind == "anisoinertia":
        c = sgn * size * DEG / ((300.0 * DEG) ** 2 / 2)
        add["gyro"][:, axis] = c * mo.w[:, others[0]] * mo.w[:, others[1]]
        params.update(c_s=c)
    elif kind == "accel_cross_coupling":
        j = others[int(kr.integers(2))]
        f = truth["accel"]
        add["accel"][:, axis] = sgn * size * f[:, axis] * f[:, j] / G0
        params.update(j=float(j))
    elif kind == "adc_crosstalk":
        j = int(kr.integers(3))
        y_gyro = clean["gyro"][:, j] + noise["gyro"][:, j]  # the gyro channel's voltage, noise and all
        c = sgn * size / (100.0 * DEG)
        add["accel"][:, axis] = c * y_gyro
        params.update(j=float(j), c_per_radps=c)
        # a crosstalk of the channel's constant part (its bias) is a constant: removed, what is left is the rate
        add["accel"][:, axis] -= c * float(np.mean(y_gyro[mo.kind == int(Kind.REST)]))
    elif kind == "scale_jitter":
        tau = float(kr.uniform(0.05, 0.3))
        e = ar1(n, fs, tau, size, kr)[:, 0]
        add["gyro"][:, axis] = (truth["gyro"] @ triads["gyro"].m.T)[:, axis] * e
        params.update(tau_s=tau)
    elif kind == "motor_heating":
        tau = float(kr.uniform(40.0, 150.0))
        a = math.exp(-1.0 / (fs * tau))
        load = (np.linalg.norm(mo.w, axis=1) / (plan.top_dps * DEG)) ** 2
        heat = lfilter([1.0 - a], [1.0, -a], load)
        add["gyro"][:, axis] = sgn * size * DEG * heat
        params.update(tau_s=tau, peak_heat=float(heat.max()))
    elif kind == "clock_jitter":
        tau = float(kr.uniform(3e-3, 30e-3))
        jit = ar1(n, fs, tau, size * 1e-3, kr)[:, 0]
        # y(t + j) ~ y(t) + j dy/dt: the gyro's rate changes by alpha, gravity in the body by -w x f
        add["gyro"] = (mo.alpha @ triads["gyro"].m.T) * jit[:, None]
        df = -np.cross(mo.w, truth["accel"])
        add["accel"] = (df @ triads["accel"].m.T) * jit[:, None]
        params.update(tau_s=tau, std_s=float(np.std(jit)))
        axis = -1
    elif kind == "spin_stress_scale":
        c = sgn * size / (300.0 * DEG) ** 2
        add["accel"][:, axis] = c * np.sum(mo.w**2, axis=1) * (truth["accel"] @ triads["accel"].m.T)[:, axis]
        params.update(c_s2=c)
    out: dict[str, np.ndarray] = {}
    for s, (full, lsb) in (("accel", (ACCEL_FULL, ACCEL_LSB)), ("gyro", (GYRO_FULL, GYRO_LSB))):
        y = clean[s] + noise[s] + add[s]
        out[s] = np.clip(np.round(y / lsb) * lsb, -full, full - lsb)
    meta = {"serial": f"SEAL2-{seed:06d}", "sample_rate_hz": f"{fs:g}", "gravity_mps2": f"{plan.gravity:.5f}",
            "station": "gen_sealed2", "rig": "gen_sealed2"}
    session = Session(metadata=meta, t_s=t, segment=mo.segment, kind=mo.kind, accel_mps2=out["accel"],
                      gyro_radps=out["gyro"], temp_degc=temp_read, ref_accel_mps2=truth["accel"],
                      ref_gyro_radps=mo.w)
    return Recording(session=session, plan=plan, kind=kind, size=size, axis=axis, params=params, planted=add,
                     temp_true=temp, attitude=mo.rot, alpha=mo.alpha)


def design_snr(rec: Recording) -> float:
    """The planted signal's size against the classes' typical white noise, over the sensor and axis where it is
    largest. A deterministic kind: the matched filter's SNR ``sqrt(sum (s - mean s)^2) / sigma`` (a constant is a
    bias the base fit takes). A random kind (:data:`NOISE_KINDS`, and the nulls): the z-score of the variance it
    adds where it acts, ``sum s^2 / sigma^2 / sqrt(2 N)``, N the samples with a non-zero s (0 when nothing is
    planted)."""
    best = 0.0
    for sensor, s in rec.planted.items():
        sigma = SIGMA_TYPICAL[sensor]
        for k in range(3):
            v = s[:, k]
            if rec.kind in NOISE_KINDS or rec.kind in NULLS:
                act = np.count_nonzero(v)
                z = float(np.sum(v**2)) / sigma**2 / math.sqrt(2.0 * act) if act else 0.0
            else:
                z = float(np.sqrt(np.sum((v - v.mean()) ** 2))) / sigma
            best = max(best, z)
    return best


def snr_table(first: int, count: int, rate_hz: float | None = 50.0) -> list[tuple[str, float, float]]:
    """(kind, min, median) of :func:`design_snr` over seeds ``first .. first + count - 1`` (no diagnosis run)."""
    rows = []
    for kind in SEALED2:
        v = sorted(design_snr(generate(s, kind, rate_hz=rate_hz)) for s in range(first, first + count))
        rows.append((kind, v[0], v[len(v) // 2]))
    return rows


if __name__ == "__main__":
    from station.session.csv_v1 import write_session

    argv = sys.argv[1:]
    if len(argv) == 3 and argv[0] == "--snr":
        for kind, lo, med in snr_table(int(argv[1]), int(argv[2])):
            print(f"{kind:22s} design SNR at 50 Hz: min {lo:9.1f}  median {med:9.1f}")
        sys.exit(0)
    if len(argv) != 3:
        sys.exit("usage: python benchmarks/gen_sealed2.py SEED KIND OUT.csv  |  --snr FIRST_SEED COUNT")
    rec = generate(int(argv[0]), argv[1])
    write_session(rec.session, argv[2])
    where = "every axis" if rec.axis < 0 else f"axis {'xyz'[rec.axis]}"
    print(f"{argv[2]}: {rec.kind} {len(rec.session)} samples at {rec.plan.rate_hz:g} Hz, "
          f"{rec.session.duration_s:.0f} s, {where}, design SNR {design_snr(rec):.0f}")
