"""A third sealed generator of physics outside the diagnosis's library: a held-out final check.

Written apart from ``station/sim``, ``station/physics``, ``station/fit``, ``station/diagnose``, ``tests/indepgen.py``,
``benchmarks/gen_outside.py``, ``benchmarks/gen_sealed.py`` and ``benchmarks/gen_sealed2.py`` (none of them imported
or copied); only the session model (``station.session.model``) and Table 1's ranges
(``station.kernel.sensor_class.TABLE1``) are the station's, to write a recording the station reads. Nobody
changing the locator reads or runs this file: it is run once, at the end, on fresh seeds.

**Rig: a three-axis gimbal table.** The unit sits on the inner gimbal of a three-axis rate table: the outer gimbal
turns about world ``z`` (angle ``a``), the middle about its own ``y`` (``b``), the inner about its own ``x``
(``c``), so the attitude (body -> world) is ``R = Rz(a) Ry(b) Rx(c)`` (Z-Y-X Euler angles, matrices). Every step moves
the three gimbals *together* (not about one fixed axis, unlike a single-axis tumble) with a minimum-snap profile
``s(x) = 35 x^4 - 84 x^5 + 70 x^6 - 20 x^7`` per gimbal; the gimbal angles are polynomials in time, the world rate
``sum theta_g' u_g`` (``u_g`` the gimbal axes), the body rate ``R^T`` of it and the angular acceleration
``R^T (sum theta_g'' u_g + sum theta_g' (omega_outer x u_g))``, all in closed form at any time.

**Its own plan shape.** A still rest of 60-200 s at a random face and heading. Then two halves: each holds one
rate block per body axis (the first half with the axis up or down, the second with the other face, so each face is
spun once: an axis is spun early *and* late) and half of the poses (the six faces and 4-6 *random attitudes*): the
first half its three rate blocks in random order and then its poses, the second all shuffled; between the halves a
rate block at a random tilted attitude (a rate about no body axis). A rate block: the pose held 3-6 s, then a
*zig-zag* of 3-4 outer-gimbal rates of alternating sign (magnitudes from 8-600 deg/s, at least one of 110 or
more, ascending or descending, the plan's top at least 300 deg/s), each reached by a ramp straight through zero
from the one before (peak angular acceleration 100-400 deg/s^2) and held 3-8 s; a ramp to zero and the pose
again. Every pose is reached by a move of all three gimbals to the new angles (peak gimbal rate 60-150 deg/s) with
a new random heading, held 4-12 s. Sample rates 52, 104, 208, 416 or 833 Hz (the output data rates of a common
MEMS family). A climate chamber: a hold, a ramp of 10-18 K up at 2-4 K/min, a soak, a ramp back down; the unit
follows through a two-node thermal network (board and die, time constants 60-180 s and 10-40 s, self-heating of
2-5 K of the die), integrated exactly (matrix exponential) on a 0.5 s grid.

**Its own sensors.** A "lot" class within Table 1 (``table1_lot``): for every Table 1 range a window of half its
width at a random place, drawn per recording. Eq. (1) with the eq. (3) drift: ``b_drift exp(-t/T_c)`` plus a
Gauss-Markov part of stationary std 1 % of ``b_drift`` started at 0, drawn exactly on a 1 s grid and joined by a
cubic spline; white noise; converters of +-6 g at 18 bit and +-1250 deg/s at 21 bit; a thermometer of 1/32 K with
0.03 K noise. Random numbers: numpy's SFC64 seeded by ``SeedSequence([seed, KEY, 0])`` for the plan and the unit
and ``[seed, KEY, 1 + index of the kind]`` for the kind's own draws: a kind's recording is the same seed's ``none``
recording plus the planted physics only (what the tests use).

The kinds (:data:`SEALED3`; an axis chosen by the seed where the kind has one; size random per seed 0.8-1.25 of
:data:`SIZE`, random sign where a sign means something):

``shock_steps``      gyro: at the end of every move that tilts the unit (middle or inner gimbal moving) the bias of
                     one axis steps by ``+-c u`` (random sign, u 0.6-1.4): the mechanical shock releases package
                     stress (a bias that changes at known events and stays).
``supply_sag``       accel, all axes: a ratiometric accelerometer powered from the rig's supply, which sags with
                     the outer motor's load (``|w|/300 deg/s + |alpha|/300 deg/s^2``) through the regulator's lag
                     (0.3-1 s): ``y (1 + dV/V) + 5 g k_i dV/V`` (the zero-g level is half the supply: 5 g at a
                     sensitivity of a tenth of the supply per g; k_i 0.9-1.1 per axis).
``warm_noise``       gyro, all axes: the white noise grows with the die temperature (the drive loop's Q falls),
                     ``sigma (1 + k (T - T_min) / 10 K)``: a noise following the temperature.
``log_settling``     accel: one axis's bias settles after power-on as ``c ln(1 + t/tau0)`` (tau0 1-5 s; stress
                     relaxation of the die attach: logarithmic, not the exponential of eq. 3).
``scale_warmup``     gyro: one axis's scale factor settles after power-on, ``(1 + c exp(-t/tau)) (M w)_k`` (tau
                     200-500 s; the drive amplitude's control loop settling): the early spins read differently
                     from the late ones.
``stepper_rect``     accel: the middle and inner gimbals are stepper driven; their vibration through a mount
                     resonance (30-80 deg/s of gimbal speed, Q 2-4) is rectified by one accelerometer axis:
                     a DC shift ``c sum_g P(|theta_g'|)`` only while they move.
``fifo_drop``        both: the sensor's FIFO drops whole samples (a full buffer) at random times; the time stamps
                     are a nominal counter, so after ``m`` drops every sample is the motion ``m/f_s`` later (drops
                     summing to about 30 ms over the recording, at least 2).
``slew_limit``       gyro: one axis's force-rebalance loop has a slew-rate limit: its output follows the rate at
                     most at ``S`` (deg/s^2), S 0.45-0.75 of the plan's largest angular acceleration about that
                     axis (the strongest moves exceed it; the output catches up before the move ends).
``alpha_cross``      gyro: axis ``k`` senses the angular acceleration about another axis ``j``, ``c alpha_j``
                     (an angular-acceleration cross sensitivity of the proof mass; not a delay, which acts on
                     ``alpha_k`` of the same axis).

Nulls (:data:`NULLS`): ``none`` (base model only); ``shaped_noise`` (the white noise replaced by 0.8 of it plus
0.6 of it shaped by a first difference, ``(e_n - e_{n-1}) / sqrt 2``: a sigma-delta converter's noise shaping, a
noise rising with frequency); ``dither_noise`` (the white noise replaced by a light-tailed white noise of the same
std: 0.6 of it Gaussian plus a +-0.8 sigma binary dither).

:data:`LOCATION` (sensors, segment kinds) and :data:`COVARIATE` (words one of which a right ``unexplained`` entry's
covariate text names) were written with the kinds, before any recording of a kind was given to the diagnosis.

``python benchmarks/gen_sealed3.py SEED KIND OUT.csv`` writes one recording; ``--snr FIRST COUNT`` prints every
kind's design SNR (:func:`design_snr`, no diagnosis) over COUNT seeds at 52 Hz.
"""

from __future__ import annotations

import math
import sys
from dataclasses import dataclass, fields, replace

import numpy as np
from scipy.interpolate import CubicSpline
from scipy.linalg import expm

from station.kernel.sensor_class import TABLE1, SensorClass
from station.session.model import Kind, Session

G0 = 9.80665  # standard gravity (m/s^2): the converter's g
DEG = math.pi / 180.0  # rad per degree
#: This generator's word in its seed sequences ``[seed, KEY, stream]`` (stream 0: plan and unit; 1 + i: kind i).
KEY = 0x5EA13003
#: The converters (own choice): accelerometer +-6 g at 18 bit, gyro +-1250 deg/s at 21 bit.
ACCEL_FULL = 6.0 * G0
GYRO_FULL = 1250.0 * DEG
ACCEL_BITS, GYRO_BITS = 18, 21
ACCEL_LSB = 2.0 * ACCEL_FULL / 2**ACCEL_BITS
GYRO_LSB = 2.0 * GYRO_FULL / 2**GYRO_BITS
#: Thermometer resolution (K) and noise (K).
TEMP_LSB = 1.0 / 32.0
TEMP_NOISE = 0.03
#: Typical white-noise std (the middle of Table 1's ranges), for the design SNR.
SIGMA_TYPICAL = {"accel": 0.0225, "gyro": 0.0115 * DEG}
RATES_HZ = (52.0, 104.0, 208.0, 416.0, 833.0)

NULLS = ("none", "shaped_noise", "dither_noise")
SEALED3 = ("shock_steps", "supply_sag", "warm_noise", "log_settling", "scale_warmup", "stepper_rect", "fifo_drop",
           "slew_limit", "alpha_cross")
KINDS = (*NULLS, *SEALED3)
#: Kinds whose planted signal is random (a noise): their design SNR is a variance excess, not a matched filter.
NOISE_KINDS = ("warm_noise",)

# LOCATION and COVARIATE were written with the kinds, BEFORE any recording of a kind was given to the diagnosis
# (the only diagnosis run before the lead's check: the nulls, a smoke test). Do not edit them after seeing results.
#: Where each kind acts: (sensors, segment kinds); a right ``unexplained`` names one of the sensors and at least one
#: of the segment kinds.
LOCATION: dict[str, tuple[frozenset[str], frozenset[str]]] = {
    # the steps are differences between the still and spin levels after the tilting moves (none before the first)
    "shock_steps": (frozenset({"gyro"}), frozenset({"pose", "rate"})),
    # the outer motor's load: the spins (viscous part) and the ramps (inertial part)
    "supply_sag": (frozenset({"accel"}), frozenset({"rate", "move"})),
    # wherever the die is warm: the poses and spins during and after the chamber's ramp
    "warm_noise": (frozenset({"gyro"}), frozenset({"pose", "rate"})),
    # everywhere the unit is settled: the bias keeps moving long after eq. 3's T_c
    "log_settling": (frozenset({"accel"}), frozenset({"rest", "pose", "rate"})),
    # the spins (and the ramps) about the axis, early against late
    "scale_warmup": (frozenset({"gyro"}), frozenset({"rate", "move"})),
    # only while the middle/inner gimbals move
    "stepper_rect": (frozenset({"accel"}), frozenset({"move"})),
    # only where the signal changes: the moves (gyro: angular acceleration; accel: gravity turning in the body)
    "fifo_drop": (frozenset({"gyro", "accel"}), frozenset({"move"})),
    # only where the angular acceleration exceeds the limit: the moves
    "slew_limit": (frozenset({"gyro"}), frozenset({"move"})),
    # only where there is angular acceleration: the moves
    "alpha_cross": (frozenset({"gyro"}), frozenset({"move"})),
}
#: Words one of which a right ``unexplained`` entry's covariate text holds; for the nulls what an ``unexplained``
#: on them may say (no covariate, the noise's colour).
COVARIATE: dict[str, tuple[str, ...]] = {
    "shock_steps": ("step", "jump", "level", "since the last"),
    "supply_sag": ("rate", "angular acceleration", "supply", "voltage"),
    "warm_noise": ("temperature", "noise", "variance", "dispersion"),
    "log_settling": ("power-on", "time"),
    "scale_warmup": ("power-on", "time"),
    "stepper_rect": ("rate", "vibration"),
    "fifo_drop": ("angular acceleration", "delay", "clock", "time", "drop"),
    "slew_limit": ("angular acceleration", "slew", "delay"),
    "alpha_cross": ("angular acceleration",),
    "none": ("none",),
    "shaped_noise": ("none", "colour", "color"),
    "dither_noise": ("none",),
}
#: Nominal size of each kind in its own unit, times a random 0.8-1.25 per recording. The design SNR from first
#: principles is :func:`design_snr` (``python benchmarks/gen_sealed3.py --snr FIRST COUNT``, all at 52 Hz, the
#: smallest plan rate); the reasoning per kind (sigma_a ~ 0.0225 m/s^2, sigma_g ~ 0.0115 deg/s per sample, holds
#: of >= 3 s = 156 samples at 52 Hz, so the noise of a hold's mean is <= 1.8 mm/s^2 and 0.9 mdeg/s):
SIZE = {
    # deg/s per step (times 0.6-1.4, random sign); ~12-16 tilting moves: each step >= 0.012 deg/s, >= 13 sigma of a
    # hold's mean; the bias after n steps is a walk of ~0.02 sqrt(n) deg/s
    "shock_steps": 0.02,
    # relative supply sag dV/V at the reference load (300 deg/s, or 300 deg/s^2): zero-g shift 5 g dV/V = 0.049
    # m/s^2 (2 sigma_a per sample) on every axis at the top rates, >= 25 sigma of a 3 s hold's mean at 300 deg/s
    "supply_sag": 1e-3,
    # relative noise growth per 10 K (k): at a 10-18 K excursion (plus self-heating) the std grows 1.3-1.6x,
    # a variance excess of 0.7-1.6 sigma^2 per sample over ~10^4 samples at 52 Hz (z >= 50)
    "warm_noise": 0.3,
    # m/s^2 per e-fold of (1 + t/tau0): the bias moves by ~2.2 c (0.08 m/s^2, 8 mg: a consumer part's turn-on
    # settling) between t = 60 s and 600 s; an exponential of T_c <= 167 s follows most of it, what is left (the
    # design SNR after the base terms and two exponentials are projected out) is ~0.1-0.25 sigma_a over ~3e4 samples
    "log_settling": 0.035,
    # relative scale change at power-on (c): at the first spins (t ~ 60-300 s, tau 200-500 s: factor 0.5-0.85)
    # 0.3-0.5 deg/s at 300 deg/s (25-45 sigma_g per sample); at the late spins (t ~ 400-700 s) 0.25-0.6 of that
    "scale_warmup": 2e-3,
    # m/s^2 of DC shift at the resonance (per gimbal); ~12-16 tilting moves of 1-3 s cross it: per move ~0.5 s near
    # the peak, 26 samples at 52 Hz: 0.05 sqrt(26) / 0.0225 = 11 sigma per move
    "stepper_rect": 0.05,
    # ms of total slip over the recording (round(slip f_s) drops, at least 2); at the moves' 100-400 deg/s^2 one
    # drop at 52 Hz (19 ms) is an error of 2-8 deg/s, at 833 Hz (1.2 ms) 0.1-0.5 deg/s
    "fifo_drop": 30.0,
    # the limit as a fraction of the plan's largest |alpha_k| (drawn 0.45-0.75, not scaled): in the strongest moves
    # the output lags by the integral of (alpha - S): 1-20 deg/s for a while, caught up before the move ends
    "slew_limit": 0.6,
    # (deg/s) per (rad/s^2): at the moves' 1.5-7 rad/s^2 of peak angular acceleration 0.02-0.1 deg/s (2-9 sigma_g
    # per sample at the peaks), over ~1-3 s per move and ~30 moves
    "alpha_cross": 0.015,
}

_EZ = np.array([0.0, 0.0, 1.0])


# --- elementary rotations (matrices, vectorised over angles) -----------------------------------------------------
def _rz(a: np.ndarray) -> np.ndarray:
    a = np.asarray(a, dtype=float)
    c, s = np.cos(a), np.sin(a)
    o, z = np.ones_like(a), np.zeros_like(a)
    return np.stack([np.stack([c, -s, z], -1), np.stack([s, c, z], -1), np.stack([z, z, o], -1)], -2)


def _ry(b: np.ndarray) -> np.ndarray:
    b = np.asarray(b, dtype=float)
    c, s = np.cos(b), np.sin(b)
    o, z = np.ones_like(b), np.zeros_like(b)
    return np.stack([np.stack([c, z, s], -1), np.stack([z, o, z], -1), np.stack([-s, z, c], -1)], -2)


def _rx(c_: np.ndarray) -> np.ndarray:
    c_ = np.asarray(c_, dtype=float)
    c, s = np.cos(c_), np.sin(c_)
    o, z = np.ones_like(c_), np.zeros_like(c_)
    return np.stack([np.stack([o, z, z], -1), np.stack([z, c, -s], -1), np.stack([z, s, c], -1)], -2)


def gimbal_attitude(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """Body -> world matrices ``Rz(a) Ry(b) Rx(c)`` (..., 3, 3)."""
    return _rz(a) @ _ry(b) @ _rx(c)


# --- the minimum-snap profile --------------------------------------------------------------------------------
def _ms(x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Minimum-snap s(x) = 35x^4 - 84x^5 + 70x^6 - 20x^7 on [0, 1]: its integral, value, first, second derivative."""
    x = np.clip(x, 0.0, 1.0)
    big_s = x**5 * (7.0 - 14.0 * x + 10.0 * x**2 - 2.5 * x**3)
    s = x**4 * (35.0 - 84.0 * x + 70.0 * x**2 - 20.0 * x**3)
    ds = 140.0 * x**3 * (1.0 - x) ** 3
    dds = 420.0 * x**2 * (1.0 - x) ** 2 * (1.0 - 2.0 * x)
    return big_s, s, ds, dds


#: Peak of ds/dx of the minimum-snap profile (at x = 1/2): 140/64.
MS_PEAK = 2.1875


@dataclass(frozen=True)
class Step:
    """One rig step: the three gimbals (a, b, c) move together over ``motion_s`` from ``theta0`` by ``delta`` while
    their rates go ``w0 -> w1`` (the rate part only on the outer gimbal), then settle at ``w1``."""

    kind: Kind
    t0: float
    duration: float
    motion_s: float
    theta0: tuple[float, float, float]
    delta: tuple[float, float, float] = (0.0, 0.0, 0.0)
    w0: tuple[float, float, float] = (0.0, 0.0, 0.0)
    w1: tuple[float, float, float] = (0.0, 0.0, 0.0)

    @property
    def tilts(self) -> bool:
        """The middle or inner gimbal moves (the unit is tilted, not only turned about the vertical)."""
        return abs(self.delta[1]) > 1e-12 or abs(self.delta[2]) > 1e-12

    def gimbals(self, u: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Angles, rates and accelerations of the gimbals, each (len(u), 3), ``u`` s into the step."""
        th0, d = np.array(self.theta0), np.array(self.delta)
        w0, w1 = np.array(self.w0), np.array(self.w1)
        big_t = self.motion_s
        if big_t <= 0.0:
            return th0 + np.outer(u, w1), np.tile(w1, (len(u), 1)), np.zeros((len(u), 3))
        x = u / big_t
        big_s, s, ds, dds = (v[:, None] for v in _ms(x))
        inside = (u < big_t).astype(float)[:, None]
        dw = w1 - w0
        uu = u[:, None]
        theta = th0 + w0 * np.minimum(uu, big_t) + dw * big_t * big_s + w1 * np.clip(uu - big_t, 0.0, None) + d * s
        rate = w0 + dw * s + d / big_t * ds * inside
        acc = (dw / big_t * ds + d / big_t**2 * dds) * inside
        return theta, rate, acc

    def end_angles(self) -> np.ndarray:
        theta, _, _ = self.gimbals(np.array([self.duration]))
        return theta[0]


@dataclass(frozen=True)
class Plan:
    rate_hz: float
    gravity: float
    magnitudes_dps: tuple[float, ...]  # every spin magnitude of the plan
    steps: tuple[Step, ...]

    @property
    def end_s(self) -> float:
        return self.steps[-1].t0 + self.steps[-1].duration

    @property
    def top_dps(self) -> float:
        return max(self.magnitudes_dps)


def _face_angles(k: int, s: int) -> tuple[float, float]:
    """Middle and inner gimbal angles (b, c) that put the body axis ``s e_k`` up: up_body = (-sin b, cos b sin c,
    cos b cos c)."""
    if k == 0:
        return (-s * math.pi / 2, 0.0)
    if k == 1:
        return (0.0, s * math.pi / 2)
    return (0.0, 0.0 if s > 0 else math.pi)


def _wrap(x: float) -> float:
    """An angle difference brought into (-pi, pi]."""
    return -((-x + math.pi) % (2 * math.pi) - math.pi)


def draw_plan(rng: np.random.Generator, rate_hz: float | None = None) -> Plan:
    """The plan of one recording (module docstring); ``rate_hz`` overrides the drawn sample rate."""
    fs = float(rng.choice(RATES_HZ))
    gravity = float(rng.uniform(9.778, 9.833))
    gimbal_peak = float(rng.uniform(60.0, 150.0)) * DEG
    alpha_peak = float(rng.uniform(100.0, 400.0)) * DEG
    settle = float(rng.uniform(0.3, 1.0))
    pool = np.array([8.0, 15.0, 30.0, 50.0, 75.0, 110.0, 160.0, 230.0, 300.0, 380.0, 480.0, 600.0])
    steps: list[Step] = []
    t = 0.0
    k0, s0 = int(rng.integers(3)), int(rng.choice([-1, 1]))
    b0, c0 = _face_angles(k0, s0)
    ang = np.array([float(rng.uniform(-math.pi, math.pi)), b0, c0])
    mags_all: list[float] = []

    def add(kind: Kind, duration: float, motion_s: float = 0.0, delta: tuple[float, float, float] = (0, 0, 0),
            w0: float = 0.0, w1: float = 0.0) -> None:
        nonlocal t, ang
        st = Step(kind, t, duration, motion_s, (float(ang[0]), float(ang[1]), float(ang[2])),
                  (float(delta[0]), float(delta[1]), float(delta[2])), (w0, 0.0, 0.0), (w1, 0.0, 0.0))
        steps.append(st)
        ang = st.end_angles()
        t += duration

    def hold(kind: Kind, duration: float, w: float = 0.0) -> None:
        add(kind, duration, w0=w, w1=w)

    def move_to(b: float, c: float) -> None:
        """All three gimbals together: the tilt (b, c) and a new random heading."""
        d = (_wrap(float(rng.uniform(-math.pi, math.pi)) - ang[0]), _wrap(b - ang[1]), _wrap(c - ang[2]))
        dur = max(MS_PEAK * max(abs(v) for v in d) / gimbal_peak, 0.5)
        add(Kind.MOVE, dur + settle, dur, d)

    def ramp(w0: float, w1: float) -> None:
        dur = max(MS_PEAK * abs(w1 - w0) / alpha_peak, 0.1)
        add(Kind.MOVE, dur + settle, dur, w0=w0, w1=w1)

    def rate_block(b: float, c: float, mags: list[float]) -> None:
        move_to(b, c)
        hold(Kind.POSE, float(rng.uniform(3.0, 6.0)))
        sign = float(rng.choice([-1.0, 1.0]))
        w = 0.0
        for m in mags:
            ramp(w, sign * m * DEG)
            w = sign * m * DEG
            hold(Kind.RATE, float(rng.uniform(3.0, 8.0)), w)
            sign = -sign
        ramp(w, 0.0)
        hold(Kind.POSE, float(rng.uniform(3.0, 6.0)))

    def zigzag() -> list[float]:
        mags = sorted(float(v) for v in rng.choice(pool, size=int(rng.integers(3, 5)), replace=False))
        if mags[-1] < 110.0:  # every block reaches 110 deg/s at least
            mags[-1] = float(rng.choice(pool[pool >= 110.0]))
            mags.sort()
        mags_all.extend(mags)
        return mags if rng.random() < 0.5 else mags[::-1]

    hold(Kind.REST, float(rng.uniform(60.0, 200.0)))
    poses: list[tuple[float, float]] = [_face_angles(k, s) for k in range(3) for s in (1, -1)]
    for _ in range(int(rng.integers(4, 7))):  # random attitudes
        poses.append((float(rng.uniform(-80.0, 80.0)) * DEG, float(rng.uniform(-180.0, 180.0)) * DEG))
    poses = [poses[int(i)] for i in rng.permutation(len(poses))]
    first_sign = {k: int(rng.choice([-1, 1])) for k in range(3)}
    halves: list[list[tuple[str, tuple[float, float], int]]] = []
    for half in range(2):
        items: list[tuple[str, tuple[float, float], int]] = [
            ("pose", p, -1) for p in poses[half * len(poses) // 2: (half + 1) * len(poses) // 2]]
        for k in range(3):
            items.append(("spin", _face_angles(k, first_sign[k] * (1 if half == 0 else -1)), k))
        order = [items[int(i)] for i in rng.permutation(len(items))]
        if half == 0:  # the first half spins every axis first (an early spin per axis), then its poses
            order = [it for it in order if it[0] == "spin"] + [it for it in order if it[0] == "pose"]
        halves.append(order)
    tilt = (float(rng.uniform(-70.0, 70.0)) * DEG, float(rng.uniform(-180.0, 180.0)) * DEG)
    for n_half, items in enumerate(halves):
        for what, (b, c), _k in items:
            if what == "pose":
                move_to(b, c)
                hold(Kind.POSE, float(rng.uniform(4.0, 12.0)))
            else:
                rate_block(b, c, zigzag())
        if n_half == 0:  # the oblique spin between the halves
            rate_block(*tilt, sorted(float(v) for v in rng.choice(pool[4:10], size=2, replace=False)))
    if max(mags_all) < 300.0:  # the top of the plan at least 300 deg/s: one more block on the start face
        top = float(rng.choice(pool[pool >= 300.0]))
        mags_all.append(top)
        rate_block(b0, c0, [top])
    move_to(b0, c0)
    hold(Kind.POSE, float(rng.uniform(4.0, 12.0)))
    return Plan(rate_hz=float(rate_hz) if rate_hz else fs, gravity=gravity, magnitudes_dps=tuple(mags_all),
                steps=tuple(steps))


@dataclass(frozen=True)
class Motion:
    """The rig at the sample times: attitude (body -> world), body rate and angular acceleration, labels."""

    rot: np.ndarray  # (n, 3, 3)
    w: np.ndarray  # (n, 3) rad/s, body
    alpha: np.ndarray  # (n, 3) rad/s^2, body
    up: np.ndarray  # (n, 3) world up in the body frame
    gimbal_rate: np.ndarray  # (n, 3) rad/s, the gimbals' own rates (a, b, c)
    segment: np.ndarray
    kind: np.ndarray


def motion(plan: Plan, t: np.ndarray) -> Motion:
    """The rig's state at the times ``t`` (the steps' polynomial gimbal angles, closed form)."""
    starts = np.array([st.t0 for st in plan.steps])
    idx = np.clip(np.searchsorted(starts, t, side="right") - 1, 0, len(plan.steps) - 1)
    n = len(t)
    th = np.empty((n, 3))
    rt = np.empty((n, 3))
    ac = np.empty((n, 3))
    kind = np.empty(n, dtype=np.int64)
    for i, st in enumerate(plan.steps):
        sel = np.flatnonzero(idx == i)
        if len(sel):
            th[sel], rt[sel], ac[sel] = st.gimbals(np.clip(t[sel] - st.t0, 0.0, None))
            kind[sel] = int(st.kind)
    rz, ry, rx = _rz(th[:, 0]), _ry(th[:, 1]), _rx(th[:, 2])
    rot = rz @ ry @ rx
    # gimbal axes in the world: outer e_z, middle Rz(a) e_y, inner Rz(a) Ry(b) e_x
    u_a = np.broadcast_to(_EZ, (n, 3))
    u_b = rz[:, :, 1]
    u_c = (rz @ ry)[:, :, 0]
    w_world = rt[:, :1] * u_a + rt[:, 1:2] * u_b + rt[:, 2:3] * u_c
    w_out = rt[:, :1] * u_a  # the rate of the frame that carries the middle gimbal's axis
    w_mid = w_out + rt[:, 1:2] * u_b  # ... and the inner gimbal's axis
    a_world = (ac[:, :1] * u_a + ac[:, 1:2] * u_b + ac[:, 2:3] * u_c
               + rt[:, 1:2] * np.cross(w_out, u_b) + rt[:, 2:3] * np.cross(w_mid, u_c))
    w = np.einsum("nji,nj->ni", rot, w_world)  # R^T w
    alpha = np.einsum("nji,nj->ni", rot, a_world)  # d/dt (R^T w_world) = R^T dw_world/dt
    up = rot[:, 2, :]
    return Motion(rot=rot, w=w, alpha=alpha, up=up, gimbal_rate=rt, segment=idx.astype(np.int64), kind=kind)


# --- temperature ---------------------------------------------------------------------------------------------
def temperature(t: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """The die's true temperature (degC): a chamber program (hold, ramp up, soak, ramp down) through a two-node
    network, board ``dT_b/dt = (T_air - T_b)/tau_ba + mu (T_d - T_b)/tau_ba`` and die ``dT_d/dt = (T_b - T_d +
    h)/tau_db`` (h the die's self-heating), integrated exactly for a piecewise-constant air temperature on a 0.5 s
    grid (the matrix exponential of the augmented system)."""
    ambient = float(rng.uniform(19.0, 27.0))
    tau_ba, tau_db = float(rng.uniform(60.0, 180.0)), float(rng.uniform(10.0, 40.0))
    mu, heat = float(rng.uniform(0.1, 0.4)), float(rng.uniform(2.0, 5.0))
    rise = float(rng.uniform(10.0, 18.0))
    slope = float(rng.uniform(2.0, 4.0)) / 60.0
    end = float(t[-1])
    t_up = float(rng.uniform(0.1, 0.3)) * end
    soak = float(rng.uniform(60.0, 200.0))
    back = float(rng.uniform(0.0, 5.0))
    knots_t = [0.0, t_up, t_up + rise / slope, t_up + rise / slope + soak,
               t_up + rise / slope + soak + (rise - back) / slope]
    knots_v = [0.0, 0.0, rise, rise, back]
    dt = 0.5
    grid = np.arange(0.0, end + 2 * dt, dt)
    air = ambient + np.interp(grid + dt / 2, knots_t, knots_v)
    a = np.array([[-(1 + mu) / tau_ba, mu / tau_ba], [1 / tau_db, -1 / tau_db]])
    b = np.array([[1 / tau_ba, 0.0], [0.0, 1 / tau_db]])
    aug = np.zeros((4, 4))
    aug[:2, :2], aug[:2, 2:] = a, b
    phi = expm(aug * dt)
    ad, bd = phi[:2, :2], phi[:2, 2:]
    x = np.array([ambient, ambient])
    die = np.empty(len(grid))
    for i, air_i in enumerate(air):
        die[i] = x[1]
        x = ad @ x + bd @ np.array([air_i, heat])
    return np.interp(t, grid, die)


# --- the unit --------------------------------------------------------------------------------------------------
def lot_class(rng: np.random.Generator) -> SensorClass:
    """``table1_lot``: every Table 1 range cut to a window of half its width at a random place."""
    changes: dict[str, tuple[float, float]] = {}
    for f in fields(TABLE1):
        v = getattr(TABLE1, f.name)
        if isinstance(v, tuple):
            lo, hi = v
            start = lo + float(rng.random()) * 0.5 * (hi - lo)
            changes[f.name] = (start, start + 0.5 * (hi - lo))
    return replace(TABLE1, name="table1_lot", **changes)  # type: ignore[arg-type]


@dataclass(frozen=True)
class Unit:
    """One triad of the unit (SI): eq. (1)'s ``gain`` matrix M and ``offset`` b_stat, eq. (3)'s ``drift_amp``
    b_drift and ``drift_tc`` T_c, and the ``white`` noise std per axis."""

    gain: np.ndarray
    offset: np.ndarray
    drift_amp: np.ndarray
    drift_tc: np.ndarray
    white: np.ndarray


def draw_unit(rng: np.random.Generator, cls: SensorClass, sensor: str) -> Unit:
    """One triad drawn uniformly from the class's ranges (deg/s ranges converted to rad/s)."""
    to_si = DEG if sensor == "gyro" else 1.0
    suffix = "dps" if sensor == "gyro" else "mps2"

    def draw(param: str, count: int) -> np.ndarray:
        low, high = getattr(cls, f"{sensor}_{param}")
        return np.array([low + (high - low) * float(rng.random()) for _ in range(count)])

    gain = np.empty((3, 3))
    for i, j in np.ndindex(3, 3):
        gain[i, j] = draw("scale" if i == j else "cross_axis", 1)[0]
    return Unit(gain=gain, offset=draw(f"bias_static_{suffix}", 3) * to_si,
                drift_amp=draw(f"bias_drift_{suffix}", 3) * to_si, drift_tc=draw("correlation_time_s", 3),
                white=draw(f"noise_std_{suffix}", 3) * to_si)


def drift(t: np.ndarray, unit: Unit, rel: float, rng: np.random.Generator) -> np.ndarray:
    """eq. (3): b_drift (exp(-t/T_c) + x(t)), x Gauss-Markov of stationary std ``rel`` from x(0) = 0, exact on a 1 s
    grid, a cubic spline between (T_c >= 50 s: nothing of it is lost)."""
    grid = np.arange(0.0, t[-1] + 2.0, 1.0)
    columns = []
    for amp, tc in zip(unit.drift_amp, unit.drift_tc, strict=True):
        phi = math.exp(-1.0 / tc)
        x = np.zeros(len(grid))
        e = rng.standard_normal(len(grid)) * rel * math.sqrt(1.0 - phi * phi)
        for i in range(1, len(grid)):
            x[i] = phi * x[i - 1] + e[i]
        columns.append(amp * (np.exp(-t / tc) + CubicSpline(grid, x)(t)))
    return np.column_stack(columns)


def convert(y: np.ndarray, full: float, bits: int) -> np.ndarray:
    """The converter: ``bits`` over +-``full``, rounded to the nearest code, clipped to the codes that exist."""
    lsb = 2.0 * full / 2**bits
    codes = np.clip(np.rint(y / lsb), -(2 ** (bits - 1)), 2 ** (bits - 1) - 1)
    return codes * lsb


def first_lag(x: np.ndarray, fs: float, tau: float) -> np.ndarray:
    """First-order lag of time constant ``tau`` started at 0, exact for an input held over each sample (an explicit
    loop)."""
    a = math.exp(-1.0 / (fs * tau))
    out = np.empty(len(x))
    acc = 0.0
    for i, v in enumerate(x):
        acc = a * acc + (1.0 - a) * v
        out[i] = acc
    return out


def slew_limited(x: np.ndarray, fs: float, limit: float) -> np.ndarray:
    """``x`` followed at a rate of at most ``limit`` per second (a slew-rate limit), from ``x[0]``."""
    step = limit / fs
    out = np.empty(len(x))
    y = float(x[0])
    for i, v in enumerate(x):
        y += min(max(v - y, -step), step)
        out[i] = y
    return out


def stepper_power(speed: np.ndarray, v_res: float, q: float) -> np.ndarray:
    """The mount's vibration power at a gimbal speed (rad/s): a second-order resonance at ``v_res`` driven by a
    step rate proportional to the speed, squared and normalised to 1 at the resonance."""
    r = np.abs(speed) / v_res
    amp = r**2 / np.sqrt((1.0 - r**2) ** 2 + (r / q) ** 2)
    return (amp / q) ** 2


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
    sensor_class: SensorClass
    events: tuple[float, ...] = ()  # the kind's event times (s): fifo_drop's drops, shock_steps' steps


def _streams(seed: int, kind: str) -> tuple[np.random.Generator, np.random.Generator]:
    base = np.random.Generator(np.random.SFC64(np.random.SeedSequence([seed, KEY, 0])))
    own = np.random.Generator(np.random.SFC64(np.random.SeedSequence([seed, KEY, 1 + KINDS.index(kind)])))
    return base, own


def tilt_ends(plan: Plan) -> np.ndarray:
    """End times of the motion of every move that tilts the unit (middle or inner gimbal moving)."""
    return np.array([st.t0 + st.motion_s for st in plan.steps if st.kind == Kind.MOVE and st.tilts])


def generate(seed: int, kind: str, *, rate_hz: float | None = None) -> Recording:
    """The recording of ``kind`` (one of :data:`KINDS`) for ``seed``; the same seed gives the same bytes. With
    ``rate_hz`` the plan is drawn as usual but sampled at that rate (for the tests)."""
    if kind not in KINDS:
        raise ValueError(f"unknown kind {kind!r} (one of {', '.join(KINDS)})")
    rng, kr = _streams(seed, kind)
    plan = draw_plan(rng, rate_hz)
    fs = plan.rate_hz
    n = int(plan.end_s * fs)
    t = np.arange(n) / fs
    mo = motion(plan, t)
    temp = temperature(t, rng)
    cls = lot_class(rng)
    truth = {"accel": plan.gravity * mo.up, "gyro": mo.w}
    units = {s: draw_unit(rng, cls, s) for s in ("accel", "gyro")}
    clean: dict[str, np.ndarray] = {}
    noise: dict[str, np.ndarray] = {}
    for s, u in units.items():  # eq. (1) with the bias of eq. (3)
        clean[s] = np.einsum("ij,nj->ni", u.gain, truth[s]) + u.offset + drift(t, u, cls.drift_noise_rel, rng)
        noise[s] = rng.standard_normal((n, 3)) * u.white
    temp_read = np.round((temp + TEMP_NOISE * rng.standard_normal(n)) / TEMP_LSB) * TEMP_LSB

    axis = int(kr.integers(3))
    size = SIZE.get(kind, 0.0) * float(kr.uniform(0.8, 1.25))
    sgn = float(kr.choice([-1.0, 1.0]))
    if kind in ("supply_sag", "warm_noise", "fifo_drop", "slew_limit"):  # a sag, a std, a slip, a limit: no sign
        sgn = 1.0
    if kind == "slew_limit":  # a fraction of the plan's largest angular acceleration: its own range
        size = float(kr.uniform(0.45, 0.75))
    params: dict[str, float] = {"c": sgn * size}
    add = {s: np.zeros((n, 3)) for s in ("accel", "gyro")}
    events: tuple[float, ...] = ()
    if kind in NULLS or kind in ("supply_sag", "warm_noise", "fifo_drop"):
        axis = -1
    if kind == "shaped_noise":
        for s in ("accel", "gyro"):
            e = kr.standard_normal((n + 1, 3))
            add[s] = 0.6 * units[s].white * (e[1:] - e[:-1]) / math.sqrt(2.0) - 0.2 * noise[s]
    elif kind == "dither_noise":
        for s in ("accel", "gyro"):
            dith = 0.8 * kr.choice([-1.0, 1.0], size=(n, 3)) + 0.6 * kr.standard_normal((n, 3))
            add[s] = dith * units[s].white - noise[s]
    elif kind == "shock_steps":
        ends = tilt_ends(plan)
        steps = kr.choice([-1.0, 1.0], size=len(ends)) * kr.uniform(0.6, 1.4, len(ends)) * size * DEG
        level = np.concatenate([[0.0], np.cumsum(steps)])
        add["gyro"][:, axis] = level[np.searchsorted(ends, t, side="right")]
        params.update(n_steps=float(len(ends)))
        events = tuple(float(v) for v in ends)
    elif kind == "supply_sag":
        tau = float(kr.uniform(0.3, 1.0))
        load = np.abs(mo.gimbal_rate[:, 0]) / (300.0 * DEG) + np.abs(_outer_acc(plan, t)) / (300.0 * DEG)
        sag = size * first_lag(load, fs, tau)  # dV/V, a drop
        zero_g = 5.0 * G0 * kr.uniform(0.9, 1.1, 3)
        add["accel"] = -sag[:, None] * (clean["accel"] + zero_g)
        params.update(tau_s=tau, peak_sag=float(sag.max()))
    elif kind == "warm_noise":
        t_min = float(temp.min())
        factor = 1.0 + size * (temp - t_min) / 10.0
        extra = np.sqrt(factor**2 - 1.0)
        add["gyro"] = kr.standard_normal((n, 3)) * units["gyro"].white * extra[:, None]
        params.update(t_min=t_min, peak_factor=float(factor.max()))
    elif kind == "log_settling":
        tau0 = float(kr.uniform(1.0, 5.0))
        add["accel"][:, axis] = sgn * size * np.log1p(t / tau0)
        params.update(tau0_s=tau0)
    elif kind == "scale_warmup":
        tau = float(kr.uniform(200.0, 500.0))
        add["gyro"][:, axis] = sgn * size * np.exp(-t / tau) * (truth["gyro"] @ units["gyro"].gain[axis])
        params.update(tau_s=tau)
    elif kind == "stepper_rect":
        v_res = float(kr.uniform(30.0, 80.0)) * DEG
        q = float(kr.uniform(2.0, 4.0))
        power = stepper_power(mo.gimbal_rate[:, 1], v_res, q) + stepper_power(mo.gimbal_rate[:, 2], v_res, q)
        add["accel"][:, axis] = sgn * size * power
        params.update(v_res_dps=v_res / DEG, q=q)
    elif kind == "fifo_drop":
        drops = max(2, round(size * 1e-3 * fs))
        when = np.sort(kr.uniform(0.0, float(t[-1]), drops))
        slip = np.searchsorted(when, t, side="right") / fs
        late = motion(plan, t + slip)
        for s, x in (("accel", plan.gravity * late.up), ("gyro", late.w)):
            add[s] = np.einsum("ij,nj->ni", units[s].gain, x - truth[s])
        params.update(drops=float(drops), slip_s=drops / fs)
        events = tuple(float(v) for v in when)
    elif kind == "slew_limit":
        limit = size * float(np.max(np.abs(mo.alpha[:, axis])))
        y = clean["gyro"][:, axis]
        add["gyro"][:, axis] = slew_limited(y, fs, limit) - y
        params.update(limit_dps2=limit / DEG)
    elif kind == "alpha_cross":
        j = [v for v in range(3) if v != axis][int(kr.integers(2))]
        c = sgn * size * DEG  # (rad/s) per (rad/s^2)
        add["gyro"][:, axis] = c * mo.alpha[:, j]
        params.update(j=float(j), c_s=c)
    out = {"accel": convert(clean["accel"] + noise["accel"] + add["accel"], ACCEL_FULL, ACCEL_BITS),
           "gyro": convert(clean["gyro"] + noise["gyro"] + add["gyro"], GYRO_FULL, GYRO_BITS)}
    meta = {"serial": f"SEAL3-{seed:06d}", "sample_rate_hz": f"{fs:g}", "gravity_mps2": f"{plan.gravity:.5f}",
            "station": "gen_sealed3", "rig": "gen_sealed3 three-axis table"}
    session = Session(metadata=meta, t_s=t, segment=mo.segment, kind=mo.kind, accel_mps2=out["accel"],
                      gyro_radps=out["gyro"], temp_degc=temp_read, ref_accel_mps2=truth["accel"],
                      ref_gyro_radps=mo.w)
    return Recording(session=session, plan=plan, kind=kind, size=size, axis=axis, params=params, planted=add,
                     temp_true=temp, attitude=mo.rot, alpha=mo.alpha, sensor_class=cls, events=events)


def _outer_acc(plan: Plan, t: np.ndarray) -> np.ndarray:
    """The outer gimbal's angular acceleration (rad/s^2) at ``t``."""
    starts = np.array([st.t0 for st in plan.steps])
    idx = np.clip(np.searchsorted(starts, t, side="right") - 1, 0, len(plan.steps) - 1)
    out = np.zeros(len(t))
    for i, st in enumerate(plan.steps):
        sel = np.flatnonzero(idx == i)
        if len(sel):
            out[sel] = st.gimbals(np.clip(t[sel] - st.t0, 0.0, None))[2][:, 0]
    return out


@dataclass(frozen=True)
class Snr:
    """The planted signal's size where it acts, on the sensor and axis where it is largest: ``rms_sigma`` its RMS
    in units of the single-sample noise over the ``n`` samples where it is non-zero; ``snr`` the matched-filter SNR
    ``rms_sigma sqrt(n)`` (a deterministic kind) or the z-score of the variance it adds, ``sum s^2 / sigma^2 /
    sqrt(2 n)`` (a random kind or a null)."""

    sensor: str
    rms_sigma: float
    n: int
    snr: float


def base_projection_residual(rec: Recording, sensor: str, s: np.ndarray) -> np.ndarray:
    """``s`` (n,) minus its least-squares projection on what eq. (1) and (3) take without any new term: a constant,
    the three reference components (a scale and cross-axis row of M) and the drift's exponential at the two ends of
    the class's T_c range. What is left is what the base model cannot imitate (its drift noise aside)."""
    t = np.asarray(rec.session.t_s)
    x = np.asarray(rec.session.ref_gyro_radps if sensor == "gyro" else rec.session.ref_accel_mps2)
    lo, hi = getattr(rec.sensor_class, f"{sensor}_correlation_time_s")
    basis = np.column_stack([np.ones(len(t)), x, np.exp(-t / lo), np.exp(-t / hi)])
    coef, *_ = np.linalg.lstsq(basis, s, rcond=None)
    return s - basis @ coef


def design_snr(rec: Recording) -> Snr:
    """:class:`Snr` of the recording's planted signal against the classes' typical white noise. A deterministic
    kind: what is left of it after :func:`base_projection_residual`, its RMS over the samples where it acts and the
    matched filter's SNR. A random kind or a null: the variance z-score of what it adds (0 when nothing is
    planted)."""
    best = Snr("-", 0.0, 0, 0.0)
    for sensor, s in rec.planted.items():
        sigma = SIGMA_TYPICAL[sensor]
        for k in range(3):
            v = s[:, k]
            act = v != 0.0
            n = int(np.count_nonzero(act))
            if not n:
                continue
            if rec.kind in NOISE_KINDS or rec.kind in NULLS:
                rms = float(np.sqrt(np.mean(v[act] ** 2))) / sigma
                z = float(np.sum(v[act] ** 2)) / sigma**2 / math.sqrt(2.0 * n)
            else:
                r = base_projection_residual(rec, sensor, v)
                z = float(np.sqrt(np.sum(r**2))) / sigma
                rms = z / math.sqrt(n)
            if z > best.snr:
                best = Snr(sensor, rms, n, z)
    return best


def snr_table(first: int, count: int, rate_hz: float | None = 52.0) -> dict[str, tuple[Snr, Snr]]:
    """Per kind the smallest and the median :class:`Snr` over seeds ``first .. first + count - 1`` (no diagnosis)."""
    table: dict[str, tuple[Snr, Snr]] = {}
    for kind in SEALED3:
        ranked = sorted((design_snr(generate(seed, kind, rate_hz=rate_hz)) for seed in range(first, first + count)),
                        key=lambda x: x.snr)
        table[kind] = (ranked[0], ranked[count // 2])
    return table


def _main(argv: list[str]) -> int:
    from station.session.csv_v1 import write_session

    if len(argv) == 3 and argv[0] == "--snr":
        print(f"{'kind':14s} {'sensor':6s} {'min SNR':>9s} {'rms/sigma':>9s} {'n':>7s}   "
              f"{'median SNR':>10s} {'rms/sigma':>9s} {'n':>7s}   (52 Hz)")
        for kind, (low, mid) in snr_table(int(argv[1]), int(argv[2])).items():
            print(f"{kind:14s} {low.sensor:6s} {low.snr:9.1f} {low.rms_sigma:9.3f} {low.n:7d}   "
                  f"{mid.snr:10.1f} {mid.rms_sigma:9.3f} {mid.n:7d}")
        return 0
    if len(argv) != 3:
        print("usage: python benchmarks/gen_sealed3.py SEED KIND OUT.csv  |  --snr FIRST_SEED COUNT", file=sys.stderr)
        return 2
    rec = generate(int(argv[0]), argv[1])
    write_session(rec.session, argv[2])
    axis = "every axis" if rec.axis < 0 else "axis " + "xyz"[rec.axis]
    print(f"{argv[2]}: {rec.kind}, {rec.plan.rate_hz:g} Hz, {rec.session.duration_s:.0f} s "
          f"({len(rec.session)} samples), {axis}, design SNR {design_snr(rec).snr:.0f}")
    return 0


if __name__ == "__main__":
    sys.exit(_main(sys.argv[1:]))
