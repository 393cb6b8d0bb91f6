"""An independent generator of a line unit's recordings: rack rest, rig part, full plan, validation.

Written apart from ``station/sim`` and ``station/physics`` (and from ``gen_outside.py``), with other numerical
choices, so that the line's accuracy is not measured only by the simulator its fit shares a model with:

* **Kinematics in closed form.** Every motion is a rotation about a fixed world axis with a raised-cosine rate
  profile (rate ``W (1 - cos(2 pi t / T)) / 2``, its angle integrated analytically); the attitude at a sample time
  is the composition of the rotations done so far (``scipy.spatial.transform.Rotation``), never integrated on a
  grid. A tumble turns the unit 90 deg about a horizontal world axis (180 deg where the next face is opposite);
  a rate step turns the table about the vertical: ramp up (raised-cosine acceleration), hold, ramp down.
* **Sampling by averaging.** Each output sample is the mean of 8 sub-samples of the true specific force and rate
  over the sample interval centred on its time stamp (an ADC with a boxcar filter); the references are the exact
  values at the sample time and are used only where they are constant (holds).
* **Its own unit and noise.** Parameters drawn uniformly in the Table 1 ranges (``TABLE1``'s numbers only) from a
  PCG64DXSM stream; eq. 3's Gauss-Markov drift (1 % of b_drift stationary) by exact discretization on the
  sub-sample grid over the whole power-on (rack, transfer, rig: one process); white noise per sub-sample scaled
  so that the averaged sample has the class's per-sample std; quantization to 16/20-bit LSBs. No Earth rate, no
  temperature effects (the model the line fits, by other code). Optionally (given, not drawn) a time offset of the
  sensor behind the rig and the gyro's IEEE 952 scale polynomial (:class:`Unit`).
* **Its own plans**, named as the station's: the rack's rest in a random orientation (tilts up to 25 deg), the
  line's rig part (:func:`station.kernel.line_plan.line_rig_plan`, a 2 s rest first), the full plan
  (``default_plan()``: 300 s rest, six 30 s poses, 18 rate steps of 12 s), and a one-hour rest. Tumble rate
  60 deg/s peak, table acceleration 150 deg/s^2 peak, 1.5 s of settling after each move (labelled MOVE).

``generate_unit(seed)`` returns the unit's truth and its recordings as station sessions.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np
from scipy.signal import lfilter
from scipy.spatial.transform import Rotation

from station.kernel.line_plan import line_rig_plan
from station.kernel.plan import RigPlan, default_plan
from station.kernel.sensor_class import TABLE1
from station.session.model import Kind, Session

DEG = math.pi / 180.0
SUB = 8  # sub-samples averaged into one sample
FACES = {"+x": (0, 1.0), "-x": (0, -1.0), "+y": (1, 1.0), "-y": (1, -1.0), "+z": (2, 1.0), "-z": (2, -1.0)}
UP = np.array([0.0, 0.0, 1.0])


@dataclass(frozen=True)
class Triad:
    m: np.ndarray
    b_stat: np.ndarray
    b_drift: np.ndarray
    tc: np.ndarray
    sigma: np.ndarray
    lsb: float


@dataclass(frozen=True)
class Unit:
    """The unit's truth; ``time_offset_s`` (the sample stamped t holds the motion at rig time t - tau) and the
    gyro's scale polynomial ``y_k = u_k + k2_k u_k^2 + k3_k u_k^3`` on ``u = M w`` (per sub-sample, before the
    averaging) are 0 unless given to :func:`generate_unit` (no random draw: the other numbers stay the same)."""

    accel: Triad
    gyro: Triad
    gravity: float
    time_offset_s: float = 0.0
    gyro_k2: np.ndarray = field(default_factory=lambda: np.zeros(3))
    gyro_k3: np.ndarray = field(default_factory=lambda: np.zeros(3))


def draw_unit(rng: np.random.Generator) -> Unit:
    c = TABLE1

    def triad(prefix: str, to_si: float, lsb: float) -> Triad:
        scale = getattr(c, f"{prefix}_scale")
        cross = getattr(c, f"{prefix}_cross_axis")
        unit_ = "dps" if prefix == "gyro" else "mps2"
        m = np.diag(rng.uniform(*scale, 3)) + (1.0 - np.eye(3)) * rng.uniform(*cross, (3, 3))
        return Triad(m, rng.uniform(*getattr(c, f"{prefix}_bias_static_{unit_}"), 3) * to_si,
                     rng.uniform(*getattr(c, f"{prefix}_bias_drift_{unit_}"), 3) * to_si,
                     rng.uniform(*getattr(c, f"{prefix}_correlation_time_s"), 3),
                     rng.uniform(*getattr(c, f"{prefix}_noise_std_{unit_}"), 3) * to_si, lsb)

    return Unit(triad("accel", 1.0, 16.0 * 9.80665 / 2**16), triad("gyro", DEG, 4000.0 * DEG / 2**20),
                float(rng.uniform(9.805, 9.82)))


@dataclass(frozen=True)
class Motion:
    """One piece of the timeline: ``duration`` s of rotation about world ``axis`` by a raised-cosine profile
    (``angle`` rad in total; or, for a ``spin``, ramp / hold / ramp at ``rate`` rad/s), labelled ``kind``."""

    kind: Kind
    duration: float
    axis: np.ndarray
    angle: float = 0.0  # raised-cosine turn (tumble)
    rate: float = 0.0  # spin: the hold's rate
    ramp: float = 0.0  # spin: the ramp's duration
    ref_up: np.ndarray | None = None  # the labelled reference (body frame) during a hold

    def theta(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Angle turned and rate at ``t`` (s from the piece's start)."""
        if self.angle:
            w_peak = 2.0 * self.angle / self.duration
            k = 2.0 * math.pi / self.duration
            return w_peak * (t / 2.0 - np.sin(k * t) / (2.0 * k)), w_peak * (1.0 - np.cos(k * t)) / 2.0
        if self.rate:
            r, tr, th = self.rate, self.ramp, self.duration - 2.0 * self.ramp
            k = 2.0 * math.pi / (2.0 * tr)  # raised-cosine acceleration over the ramp: rate r (1 - cos(pi t/tr)) / 2
            up = np.clip(t, 0.0, tr)
            a_up = r * (up / 2.0 - np.sin(k * up) / (2.0 * k))
            w_up = r * (1.0 - np.cos(k * up)) / 2.0
            hold = np.clip(t - tr, 0.0, th)
            down = np.clip(t - tr - th, 0.0, tr)
            a_down = r * down - r * (down / 2.0 - np.sin(k * down) / (2.0 * k))
            w = np.where(t < tr, w_up, np.where(t < tr + th, r, r - r * (1.0 - np.cos(k * down)) / 2.0))
            return a_up + r * hold + a_down, w
        return np.zeros_like(t), np.zeros_like(t)


class Timeline:
    """Motions one after the other from an initial attitude (body -> world)."""

    def __init__(self, start: Rotation) -> None:
        self.start = start
        self.pieces: list[tuple[float, Motion, Rotation]] = []
        self.end = 0.0
        self.att = start

    def add(self, m: Motion) -> None:
        self.pieces.append((self.end, m, self.att))
        total, _ = m.theta(np.array([m.duration]))
        self.att = Rotation.from_rotvec(m.axis * float(total[0])) * self.att
        self.end += m.duration

    def hold(self, kind: Kind, s: float) -> None:
        up_body = self.att.inv().apply(UP)
        self.add(Motion(kind, s, UP, ref_up=up_body))

    def tumble_to(self, face: str, settle_s: float, tumble_dps: float = 60.0) -> None:
        k, sign = FACES[face]
        body_axis = np.eye(3)[k] * sign
        now_up = self.att.apply(body_axis)  # where the face points in the world now
        c = float(np.clip(now_up @ UP, -1.0, 1.0))
        if c > 1 - 1e-12:
            return
        axis = np.cross(now_up, UP)
        if np.linalg.norm(axis) < 1e-9:  # opposite: any horizontal axis
            axis = np.cross(now_up, np.array([1.0, 0.0, 0.0]))
            if np.linalg.norm(axis) < 1e-9:
                axis = np.cross(now_up, np.array([0.0, 1.0, 0.0]))
        axis /= np.linalg.norm(axis)
        angle = math.acos(c)
        self.add(Motion(Kind.MOVE, 2.0 * angle / (tumble_dps * DEG), axis, angle=angle))
        if settle_s:
            self.add(Motion(Kind.MOVE, settle_s, UP))

    def spin(self, rate_dps: float, hold_s: float, settle_s: float, acc_dps2: float = 150.0) -> None:
        """Turn the table about the vertical: ramp up and settle (MOVE), hold (RATE), ramp down (MOVE)."""
        r = rate_dps * DEG
        ramp = math.pi * abs(r) / (2.0 * acc_dps2 * DEG)  # raised-cosine ramp whose peak acceleration is acc_dps2
        spin = Motion(Kind.RATE, 2.0 * ramp + settle_s + hold_s, UP, rate=r, ramp=ramp)
        start, att0, t0 = self.end, self.att, 0.0
        for kind, dur in ((Kind.MOVE, ramp + settle_s), (Kind.RATE, hold_s), (Kind.MOVE, ramp)):
            self.pieces.append((start + t0, _Window(spin, t0, kind, dur), att0))
            t0 += dur
        self.end = start + t0
        total, _ = spin.theta(np.array([spin.duration]))
        self.att = Rotation.from_rotvec(UP * float(total[0])) * att0

    def sample(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """True up direction (body) and body rate (rad/s) at times ``t``."""
        up = np.empty((len(t), 3))
        w = np.empty((len(t), 3))
        starts = np.array([p[0] for p in self.pieces])
        idx = np.clip(np.searchsorted(starts, t, side="right") - 1, 0, len(self.pieces) - 1)
        for i in np.unique(idx):
            sel = idx == i
            t0, m, att0 = self.pieces[i]
            ang, rate = m.theta(np.clip(t[sel] - t0, 0.0, m.duration))
            att = Rotation.from_rotvec(np.outer(ang, m.axis)) * att0
            up[sel] = att.inv().apply(UP)
            w[sel] = att.inv().apply(np.outer(rate, m.axis))
        return up, w

    def labels(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Segment index (a new one where the piece changes) and kind per sample."""
        starts = np.array([p[0] for p in self.pieces])
        idx = np.clip(np.searchsorted(starts, t, side="right") - 1, 0, len(self.pieces) - 1)
        kind = np.array([int(self.pieces[i][1].kind) for i in idx], dtype=np.int64)
        seg = np.concatenate([[0], np.cumsum(np.diff(idx) != 0)]).astype(np.int64)
        return seg, kind


@dataclass(frozen=True)
class _Window:
    """A labelled time window of a longer motion (a spin's ramp, hold, ramp)."""

    motion: Motion
    offset: float
    kind: Kind
    duration: float

    @property
    def axis(self) -> np.ndarray:
        return self.motion.axis

    def theta(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Angle since the whole spin's start (its pieces keep the spin's starting attitude) and rate."""
        return self.motion.theta(t + self.offset)


# --- plans -------------------------------------------------------------------------------------------------


def rig_timeline(plan: RigPlan, rng: np.random.Generator, settle_s: float = 1.5) -> Timeline:
    """A station rig plan on this generator's kinematics: rest in ``rest_pose``, the poses, the rate steps
    (each about its body axis, that axis turned up first)."""
    k, sign = FACES[plan.rest_pose]
    yaw = Rotation.from_rotvec(UP * rng.uniform(0.0, 2.0 * math.pi))
    tl = Timeline(yaw * _face_up(k, sign))
    if plan.rest_s:
        tl.hold(Kind.REST, plan.rest_s)
    for pose in plan.poses:
        tl.tumble_to(pose, settle_s)
        tl.hold(Kind.POSE, plan.pose_hold_s)
    for axis, rate in plan.rate_steps:
        tl.tumble_to(f"+{axis}", settle_s)
        tl.spin(rate, plan.rate_hold_s, settle_s)
    return tl


def _face_up(k: int, sign: float) -> Rotation:
    """An attitude (body -> world) with body axis ``k`` (sign) pointing up."""
    body = np.eye(3)[k] * sign
    axis = np.cross(body, UP)
    if np.linalg.norm(axis) < 1e-12:
        return Rotation.identity() if body @ UP > 0 else Rotation.from_rotvec(np.array([math.pi, 0.0, 0.0]))
    return Rotation.from_rotvec(axis / np.linalg.norm(axis) * math.acos(float(np.clip(body @ UP, -1, 1))))


# --- the sensor ----------------------------------------------------------------------------------------------


class Drift:
    """eq. 3's Gauss-Markov part of one triad over one power-on, drawn forward in time by exact steps."""

    def __init__(self, tri: Triad, rng: np.random.Generator) -> None:
        self.tri, self.rng = tri, rng
        self.t = 0.0
        self.x = np.zeros(3)  # started at 0 at power-on
        self.q = TABLE1.drift_noise_rel * np.abs(tri.b_drift)  # stationary std

    def at(self, times: np.ndarray) -> np.ndarray:
        """The process at ``times`` (uniformly spaced, after the last call's): an exact step from the last time
        (any gap), then exact AR(1) steps (``scipy.signal.lfilter``)."""
        gap = max(float(times[0]) - self.t, 0.0)
        step = float(times[1] - times[0]) if len(times) > 1 else 0.0
        out = np.empty((len(times), 3))
        for k in range(3):
            phi0 = math.exp(-gap / self.tri.tc[k])
            x0 = phi0 * self.x[k] + self.rng.standard_normal() * math.sqrt(1.0 - phi0**2) * self.q[k]
            phi = math.exp(-step / self.tri.tc[k])
            e = self.rng.standard_normal(len(times) - 1) * math.sqrt(1.0 - phi**2) * self.q[k]
            rest = lfilter([1.0], [1.0, -phi], e, zi=[phi * x0])[0] if len(e) else np.empty(0)
            out[:, k] = np.concatenate([[x0], rest])
        self.x, self.t = out[-1].copy(), float(times[-1])
        return out


def record(tl: Timeline, unit: Unit, drifts: tuple[Drift, Drift], t0: float, n: int, fs: float,
           rng: np.random.Generator, meta: dict[str, str], known: bool = True) -> Session:
    """``n`` samples at ``fs`` from sensor time ``t0`` (the timeline's time 0); each sample the mean of
    :data:`SUB` sub-samples over its interval."""
    t_local = np.arange(n) / fs
    # the sub-samples: centred on the sample time, uniformly spaced (the first ones of a power-on are clipped to 0
    # for the motion and the warm-up; the drift process starts at the first)
    sub = (t_local[:, None] + (np.arange(SUB) - (SUB - 1) / 2.0)[None, :] / (fs * SUB)).reshape(-1)
    up, w = tl.sample(np.maximum(sub - unit.time_offset_s, 0.0))  # the motion at rig time t - tau
    outs = []
    for tri, x, drift in ((unit.accel, unit.gravity * up, drifts[0]), (unit.gyro, w, drifts[1])):
        t_abs = t0 + sub
        warm = tri.b_drift * np.exp(-np.maximum(t_abs, 0.0)[:, None] / tri.tc)
        u = x @ tri.m.T
        if tri is unit.gyro and (np.any(unit.gyro_k2) or np.any(unit.gyro_k3)):
            u = u + unit.gyro_k2 * u * u + unit.gyro_k3 * u * u * u
        y = u + tri.b_stat + warm + drift.at(t_abs)
        y += rng.standard_normal(y.shape) * tri.sigma * math.sqrt(SUB)
        y = y.reshape(n, SUB, 3).mean(axis=1)
        outs.append(np.round(y / tri.lsb) * tri.lsb)
    seg, kind = tl.labels(t_local)
    ref_up, ref_w = tl.sample(t_local)
    nan = np.full((n, 3), np.nan)
    return Session(metadata={**meta, "sample_rate_hz": f"{fs:g}", "gravity_mps2": f"{unit.gravity:.5f}"},
                   t_s=t0 + t_local, segment=seg if known else np.zeros(n, dtype=np.int64),
                   kind=kind if known else np.full(n, int(Kind.REST), dtype=np.int64), accel_mps2=outs[0],
                   gyro_radps=outs[1], temp_degc=np.full(n, np.nan),
                   ref_accel_mps2=unit.gravity * ref_up if known else nan, ref_gyro_radps=ref_w if known else nan)


@dataclass(frozen=True)
class LineUnit:
    unit: Unit
    rack: Session
    rig: Session
    full: Session
    val_full: Session
    val_hour: Session


WALL0 = 1_800_000_000.0


def generate_unit(seed: int, rack_s: float = 3600.0, transfer_s: float = 45.0, rig: RigPlan | None = None,
                  fs: float = 100.0, hour_s: float = 3600.0, rack_tilt_deg: float = 25.0, time_offset_s: float = 0.0,
                  gyro_k2: np.ndarray | None = None, gyro_k3: np.ndarray | None = None) -> LineUnit:
    """One unit (seed in, same recordings out): rack + rig of one power-on, a full-plan recording of another
    power-on, and two validation power-ons (full plan; ``hour_s`` at rest). The rack holds the unit +z up,
    tilted by a rotation vector whose components are uniform in +-``rack_tilt_deg`` (25: about any attitude
    near +z; 3: a rack that holds its units on their base, tilts up to 4.2 deg). ``time_offset_s`` (s) and the
    gyro's ``gyro_k2`` (1/(rad/s)), ``gyro_k3`` (1/(rad/s)^2) per axis: see :class:`Unit` (all power-ons)."""
    rng = np.random.Generator(np.random.PCG64DXSM(np.random.SeedSequence([seed, 4242])))
    unit = replace(draw_unit(rng), time_offset_s=float(time_offset_s),
                   gyro_k2=np.zeros(3) if gyro_k2 is None else np.asarray(gyro_k2, dtype=float),
                   gyro_k3=np.zeros(3) if gyro_k3 is None else np.asarray(gyro_k3, dtype=float))
    serial = f"IND-{seed:07d}"
    rig_plan = rig if rig is not None else replace(line_rig_plan(), rest_s=2.0, sample_rate_hz=fs)

    def power_on(boot: int) -> tuple[Drift, Drift]:
        return Drift(unit.accel, rng), Drift(unit.gyro, rng)

    # one power-on: the rack (a fixed random tilt, nobody measures it), the transfer, the rig
    drifts = power_on(1)
    tilt = Rotation.from_rotvec(rng.uniform(-rack_tilt_deg, rack_tilt_deg, 3) * DEG)
    rack_tl = Timeline(tilt)
    rack_tl.hold(Kind.REST, rack_s + 1.0)
    n_rack = round(rack_s * fs)
    meta = {"serial": serial, "station": "gen_line_indep", "rig": "gen_line_indep", "boot_count": "1"}
    rack = record(rack_tl, unit, drifts, 0.0, n_rack, fs, rng, {**meta, "wall_clock_at_start_s": repr(WALL0)},
                  known=False)
    t_rig = rack_s + transfer_s
    tl = rig_timeline(rig_plan, rng)
    rig_s = record(tl, unit, drifts, t_rig, round(tl.end * fs), fs, rng,
                   {**meta, "wall_clock_at_start_s": repr(WALL0 + t_rig)})

    def whole(plan: RigPlan, boot: int) -> Session:
        d = power_on(boot)
        tl_ = rig_timeline(replace(plan, sample_rate_hz=fs), rng)
        return record(tl_, unit, d, 0.0, round(tl_.end * fs), fs, rng,
                      {**meta, "boot_count": str(boot), "wall_clock_at_start_s": repr(WALL0 + 1e5 * boot)})

    full = whole(default_plan(), 2)
    val_full = whole(default_plan(), 3)
    val_hour = whole(replace(default_plan(), rest_s=hour_s, poses=(), rate_steps=()), 4)
    return LineUnit(unit, rack, rig_s, full, val_full, val_hour)
