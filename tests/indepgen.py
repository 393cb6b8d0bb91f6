"""An independent recording generator for tests and benchmarks of ``station.diagnose``.

Written apart from ``station/sim`` and ``station/physics``: the rig's motion is a chain of
``scipy.spatial.transform`` rotations (``Slerp`` between poses with a cosine speed profile, a
rate table turning about a world axis), evaluated analytically at any time, so a sensor delay
is the motion evaluated at ``t - tau``; each effect acts on the physical input (rate, specific
force, temperature) before the sensor's matrix; white noise, quantization, sample rates
(100-400 Hz), pose orders and rate lists are chosen here, not by ``station.kernel.plan``. Shared
with the station: the session I/O (``station.session``), the paper's Table 1 ranges
(``station.kernel.sensor_class.TABLE1``) and the rig's rest-pose convention
(``station.kernel.geometry.POSE_ANGLES_DEG``), which the session format defines.

Two kinds of physics outside the station's candidate library (``OUTSIDE``):

* ``wobble`` (deg): the rate table's spin axis is tilted by a fraction of a degree while it turns;
  the accelerometer sees gravity's horizontal part rotate at the spin frequency (gyro unaffected).
* ``ripple`` (relative): the table's rate varies once per revolution, ``w (1 + r sin theta)``,
  while its controller reports the nominal rate: gyroscope and reference disagree periodically
  at the spin frequency.

Effect magnitudes are in engineering units (:data:`UNITS`). ``python tests/indepgen.py SEED
OUT.csv [effect=value ...]`` writes one recording.
"""

from __future__ import annotations

import math
import sys
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.signal import lfilter
from scipy.spatial.transform import Rotation, Slerp

from station.kernel.geometry import POSE_ANGLES_DEG
from station.kernel.sensor_class import TABLE1
from station.session.csv_v1 import write_session
from station.session.model import Kind, Session

G0 = 9.80665
DEG = math.pi / 180.0
EARTH_RATE = 7.2921159e-5
UP = np.array([0.0, 0.0, 1.0])

#: Engineering unit of each effect's magnitude.
UNITS = {
    "temperature_bias": "accel mg/K, gyro deg/s/K x 1e-3 (same number)",
    "temperature_scale": "ppm/K",
    "g_sensitivity": "deg/s per g",
    "scale_nonlinearity_even": "k2: relative scale error at 200 deg/s (gyro) / 1 g (accel), even in the input",
    "scale_nonlinearity_odd": "k3: relative scale error at 200 deg/s (gyro) / 1 g (accel), odd in the input",
    "scale_asymmetry": "relative (positive - negative scale)",
    "lever_arm": "mm",
    "earth_rotation": "multiple of the Earth rate",
    "time_offset": "ms (sensor late)",
    "bias_random_walk": "accel m/s^2/sqrt(s); gyro 0.1 x that in rad/s/sqrt(s)",
    "outliers": "probability per sample and axis",
    "pose_tilt": "deg rms per pose",
    "wobble": "deg (spin-axis tilt)",
    "ripple": "relative rate ripple once per revolution",
}
OUTSIDE = ("wobble", "ripple")
#: Where the outside-library physics shows (sensor, segment kinds, covariate).
OUTSIDE_LOCATION = {"wobble": ("accel", "spin"), "ripple": ("gyro", "spin")}
GYRO_REF = 200.0 * DEG


@dataclass(frozen=True)
class Plan:
    """What this generator's rig does."""

    rate_hz: float
    rest_s: float
    rest_pose: str
    poses: tuple[str, ...]
    hold_s: float
    move_s: float  # duration of a pose-to-pose slerp
    rates_dps: tuple[float, ...]  # magnitudes, each run with both signs about each axis
    axes: tuple[str, ...]
    spin_hold_s: float
    table_accel_dps2: float
    settle_s: float
    latitude_deg: float
    heading_deg: float
    gravity: float
    low_noise: bool


def random_plan(rng: np.random.Generator) -> Plan:
    """A plan of this generator (other rates, orders and durations than the station's)."""
    poses = [str(p) for p in rng.permutation(list(POSE_ANGLES_DEG))]
    if rng.random() < 0.4:  # some plans repeat poses at the end (warm unit)
        poses += [str(p) for p in rng.choice(poses, size=2, replace=False)]
    n_rates = int(rng.choice([2, 3, 3, 4, 4, 5]))
    rates = tuple(sorted(float(r) for r in rng.choice([25.0, 40.0, 60.0, 90.0, 120.0, 180.0, 240.0, 320.0],
                                                       size=n_rates, replace=False)))
    return Plan(
        rate_hz=float(rng.choice([100.0, 125.0, 200.0, 250.0, 400.0])),
        rest_s=float(rng.uniform(90.0, 360.0)), rest_pose=str(rng.choice(list(POSE_ANGLES_DEG))),
        poses=tuple(poses), hold_s=float(rng.uniform(12.0, 35.0)), move_s=float(rng.uniform(2.0, 5.0)),
        rates_dps=rates, axes=tuple(str(a) for a in rng.permutation(["x", "y", "z"])),
        spin_hold_s=float(rng.uniform(6.0, 14.0)), table_accel_dps2=float(rng.choice([80.0, 150.0, 300.0])),
        settle_s=float(rng.uniform(0.7, 2.0)), latitude_deg=float(rng.uniform(-55.0, 65.0)),
        heading_deg=float(rng.uniform(0.0, 360.0)), gravity=float(rng.uniform(9.78, 9.832)),
        low_noise=bool(rng.random() < 0.35),
    )


#: Tilted poses a plan may name besides the session format's six (``random_plan`` never draws them): gravity along
#: a body diagonal, so that each axis sees +-g/sqrt(3), a second magnitude of specific force, in both directions.
CORNER_POSES = {"corner+++": (1.0, 1.0, 1.0), "corner--+": (-1.0, -1.0, 1.0), "corner-+-": (-1.0, 1.0, -1.0),
                "corner+--": (1.0, -1.0, -1.0)}


def _pose_rotation(pose: str, yaw_rad: float = 0.0) -> Rotation:
    if pose in CORNER_POSES:  # the sensor's diagonal up, then turned by yaw
        r, _ = Rotation.align_vectors([UP], [np.array(CORNER_POSES[pose]) / math.sqrt(3.0)])
        return Rotation.from_rotvec(yaw_rad * UP) * r
    roll, pitch = POSE_ANGLES_DEG[pose]
    return Rotation.from_euler("ZYX", [yaw_rad, pitch * DEG, roll * DEG])


def _up_rotation(axis: int, sign: float, yaw_rad: float) -> Rotation:
    """A sensor-to-world rotation with sensor axis ``sign * e_axis`` pointing up, then turned by yaw."""
    e = np.zeros(3)
    e[axis] = sign
    r, _ = Rotation.align_vectors([UP], [e])
    return Rotation.from_rotvec(yaw_rad * UP) * r


@dataclass
class _Piece:
    t0: float
    t1: float
    segment: int
    kind: Kind
    kind_until: float  # before this time the kind is MOVE (settling), then ``kind``
    what: str  # hold | slerp | spin
    a: Rotation
    b: Rotation | None = None
    # spin: theta(t) = th0 + w0 (t - t0) + 0.5 acc (t - t0)^2 about world z, rate about Ra^T z
    th0: float = 0.0
    w0: float = 0.0
    acc: float = 0.0
    spin_id: int = -1
    pose_a: str | None = None  # the rig pose at the start (hold: the pose held), None off the pose list
    pose_b: str | None = None  # the rig pose at the end of a slerp


@dataclass
class Motion:
    """The rig motion as pieces; :meth:`state` evaluates it anywhere."""

    pieces: list[_Piece] = field(default_factory=list)
    wobble_rad: float = 0.0
    ripple: float = 0.0
    tilt: dict[str, Rotation] = field(default_factory=dict)  # the rig's error per pose (every visit, rest too)

    @property
    def end(self) -> float:
        return self.pieces[-1].t1

    def state(self, t: np.ndarray, *, true: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(R sensor-to-world (n, 3, 3), body rate (n, 3) rad/s, body angular acceleration (n, 3)) at times
        ``t``; ``true``: the motion that happens (wobble, ripple, pose tilt), else what the rig reports."""
        t = np.clip(np.asarray(t, dtype=float), 0.0, self.end)
        n = len(t)
        rot = np.zeros((n, 3, 3))
        w = np.zeros((n, 3))
        al = np.zeros((n, 3))
        starts = np.array([p.t0 for p in self.pieces])
        idx = np.clip(np.searchsorted(starts, t, side="right") - 1, 0, len(self.pieces) - 1)
        for i in np.unique(idx):
            p = self.pieces[i]
            sel = idx == i
            tt = t[sel] - p.t0
            if p.what == "hold":
                r = p.a
                if true and p.pose_a in self.tilt:
                    r = self.tilt[p.pose_a] * r
                rot[sel] = r.as_matrix()
            elif p.what == "slerp":
                dur = p.t1 - p.t0
                u = np.clip(tt / dur, 0.0, 1.0)
                s = 0.5 - 0.5 * np.cos(math.pi * u)
                ds = 0.5 * math.pi / dur * np.sin(math.pi * u)
                dds = 0.5 * (math.pi / dur) ** 2 * np.cos(math.pi * u)
                slerp = Slerp([0.0, 1.0], Rotation.concatenate([p.a, p.b]))
                r_nom = slerp(s)
                phi = (p.a.inv() * p.b).as_rotvec()
                w[sel] = ds[:, None] * phi
                al[sel] = dds[:, None] * phi
                if self.tilt:
                    # the rate reference comes from the rig's encoders and includes the moves between the tilted
                    # poses; its attitude (the specific-force reference) is the nominal pose
                    # the rig moves between the poses where they really are: the world tilt T(s) = slerp of the
                    # two poses' tilts on top of the nominal path, body rate + s' R^T psi
                    ta = self.tilt.get(p.pose_a, Rotation.identity())
                    tb = self.tilt.get(p.pose_b, Rotation.identity())
                    tilt = Slerp([0.0, 1.0], Rotation.concatenate([ta, tb]))(s)
                    psi = (ta.inv() * tb).as_rotvec()
                    rot[sel] = (tilt * r_nom).as_matrix() if true else r_nom.as_matrix()
                    w[sel] += ds[:, None] * r_nom.inv().apply(np.tile(psi, (len(s), 1)))
                else:
                    rot[sel] = r_nom.as_matrix()
            else:  # spin about the table axis
                th = p.th0 + p.w0 * tt + 0.5 * p.acc * tt**2
                dth = p.w0 + p.acc * tt
                ddth = np.full_like(tt, p.acc)
                if true and self.ripple:
                    # theta = nominal + r (1 - cos nominal): rate w (1 + r sin nominal)
                    th, dth, ddth = (th + self.ripple * (1.0 - np.cos(th)), dth * (1.0 + self.ripple * np.sin(th)),
                                     ddth * (1.0 + self.ripple * np.sin(th)) + self.ripple * dth**2 * np.cos(th))
                r = Rotation.from_rotvec(th[:, None] * UP) * p.a
                if true and self.wobble_rad:
                    r = Rotation.from_rotvec([self.wobble_rad, 0.0, 0.0]) * r
                rot[sel] = r.as_matrix()
                axis_body = p.a.inv().apply(UP)
                w[sel] = dth[:, None] * axis_body
                al[sel] = ddth[:, None] * axis_body
        return rot, w, al

    def labels(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        starts = np.array([p.t0 for p in self.pieces])
        idx = np.clip(np.searchsorted(starts, t, side="right") - 1, 0, len(self.pieces) - 1)
        seg = np.array([p.segment for p in self.pieces])[idx]
        until = np.array([p.kind_until for p in self.pieces])[idx]
        kind = np.array([int(p.kind) for p in self.pieces])[idx]
        kind = np.where(t < until, int(Kind.MOVE), kind)
        return seg, kind


def build_motion(plan: Plan, rng: np.random.Generator) -> Motion:
    """The rig's motion for ``plan``: rest, poses (slerp moves), rate steps about each axis (table spin)."""
    m = Motion()
    seg = 0
    cur = _pose_rotation(plan.rest_pose)
    t = 0.0

    def add(p: _Piece) -> None:
        nonlocal t
        m.pieces.append(p)
        t = p.t1

    add(_Piece(0.0, plan.rest_s, seg, Kind.REST, 0.0, "hold", cur, pose_a=plan.rest_pose))
    cur_pose: str | None = plan.rest_pose
    for pose in plan.poses:
        seg += 1
        target = _pose_rotation(pose)
        add(_Piece(t, t + plan.move_s, seg, Kind.MOVE, t + plan.move_s, "slerp", cur, target, pose_a=cur_pose,
                   pose_b=pose))
        seg += 1
        add(_Piece(t, t + plan.hold_s, seg, Kind.POSE, t + plan.settle_s, "hold", target, pose_a=pose))
        cur, cur_pose = target, pose
    acc = plan.table_accel_dps2 * DEG
    for spin_id, axis in enumerate(plan.axes):
        k = "xyz".index(axis)
        flip = rng.random() < 0.5
        start = _up_rotation(k, -1.0 if flip else 1.0, float(rng.uniform(0, 2 * math.pi)))
        seg += 1
        add(_Piece(t, t + plan.move_s, seg, Kind.MOVE, t + plan.move_s, "slerp", cur, start, pose_a=cur_pose))
        cur, cur_pose = start, None
        steps = []
        for r in plan.rates_dps:
            signs = (1.0, -1.0) if rng.random() < 0.5 else (-1.0, 1.0)
            steps += [s * r * DEG for s in signs]
        th, w = 0.0, 0.0
        # the body sees +rate about +axis: with the axis down the table turns the other way
        for target_w in [*steps, 0.0]:
            table_w = -target_w if flip else target_w
            dur = abs(table_w - w) / acc
            a = math.copysign(acc, table_w - w) if dur > 0 else 0.0
            seg += 1
            add(_Piece(t, t + dur, seg, Kind.MOVE, t + dur, "spin", start, th0=th, w0=w, acc=a, spin_id=spin_id))
            th += w * dur + 0.5 * a * dur**2
            w = table_w
            if target_w == 0.0:
                break
            seg += 1
            add(_Piece(t, t + plan.spin_hold_s, seg, Kind.RATE, t + plan.settle_s, "spin", start, th0=th, w0=w,
                       spin_id=spin_id))
            th += w * plan.spin_hold_s
        cur = Rotation.from_rotvec(th * UP) * start
        seg += 1
        add(_Piece(t, t + 1.0, seg, Kind.MOVE, t + 1.0, "hold", cur))
    seg += 1
    home = _pose_rotation(plan.rest_pose)
    add(_Piece(t, t + plan.move_s, seg, Kind.MOVE, t + plan.move_s, "slerp", cur, home, pose_b=plan.rest_pose))
    seg += 1
    add(_Piece(t, t + plan.hold_s, seg, Kind.POSE, t + plan.settle_s, "hold", home, pose_a=plan.rest_pose))
    return m


@dataclass(frozen=True)
class Recording:
    session: Session
    plan: Plan
    effects: dict[str, float]
    #: Drawn coefficients some benchmarks score against: per sensor the polynomial's k2, k3 on the physical input
    #: (1/U, 1/U^2) and M; the time offset (s). And, keyed ``"<effect> <sensor>"``, the drawn parameters of each
    #: effect in the diagnosis's candidate forms (SI, per axis or per matrix element; the IEEE scale terms as
    #: coefficients of the powers of ``M x``, the diagnosis's modelled input). The draws are the same as without.
    #: Per sensor the stochastic model an oracle knows: ``<sensor>_drift_noise_var`` (eq. 3's drift noise, stationary
    #: variance, started at 0), ``<sensor>_tc``, ``<sensor>_white_var`` (noise and ADC), and
    #: ``<sensor>_deterministic`` (n, 3): the output without drift noise, walk, white noise and ADC.
    truth: dict[str, np.ndarray | float] = field(default_factory=dict)

    def write(self, path: str | Path) -> None:
        write_session(self.session, path)


def _uniform(rng: np.random.Generator, rng_pair: tuple[float, float], n: int = 3) -> np.ndarray:
    return rng.uniform(*rng_pair, size=n)


def _triad(rng: np.random.Generator, scale: tuple[float, float], cross: tuple[float, float]) -> np.ndarray:
    m = np.diag(_uniform(rng, scale))
    off = ~np.eye(3, dtype=bool)
    m[off] = rng.uniform(*cross, size=6)
    return m


def generate(seed: int, effects: dict[str, float] | None = None, plan: Plan | None = None) -> Recording:
    """One recording: seed in, same session out. ``effects``: name -> magnitude (:data:`UNITS`)."""
    eff = dict(effects or {})
    unknown = set(eff) - set(UNITS)
    if unknown:
        raise ValueError(f"unknown effect(s) {sorted(unknown)}")
    rng = np.random.default_rng([seed, 16])
    plan = plan or random_plan(rng)
    motion = build_motion(plan, rng)
    motion.wobble_rad = eff.get("wobble", 0.0) * DEG
    motion.ripple = eff.get("ripple", 0.0)
    if eff.get("pose_tilt"):
        for pose in POSE_ANGLES_DEG:  # a horizontal tilt axis per pose, fixed for every visit
            motion.tilt[pose] = Rotation.from_rotvec(rng.normal(0.0, eff["pose_tilt"] * DEG / math.sqrt(2), 3)
                                                     * np.array([1.0, 1.0, 0.0]))
    fs = plan.rate_hz
    n = int(motion.end * fs)
    t = np.arange(n) / fs
    seg, kind = motion.labels(t)
    c = TABLE1
    quiet = 0.25 if plan.low_noise else 1.0

    # --- what the rig reports (at the sensor's time stamps) ---
    r_ref, w_ref, _ = motion.state(t, true=False)
    ref_f = plan.gravity * r_ref[:, 2, :]  # R^T g up
    # --- what happens at the sensor, at rig time t - delay ---
    tau = eff.get("time_offset", 0.0) * 1e-3
    r_true, w_true, al_true = motion.state(t - tau, true=True)
    f_true = plan.gravity * r_true[:, 2, :]
    truth: dict[str, np.ndarray | float] = {"time_offset_s": tau}
    if eff.get("lever_arm"):
        arm = rng.normal(size=3)
        arm *= eff["lever_arm"] * 1e-3 / np.linalg.norm(arm)
        truth["lever_arm accel"] = arm.copy()
        f_true = f_true + np.cross(w_true, np.cross(w_true, arm)) + np.cross(al_true, arm)
    w_in = w_true.copy()
    if eff.get("earth_rotation"):
        lat, head = plan.latitude_deg * DEG, plan.heading_deg * DEG
        north = np.array([-math.sin(head), math.cos(head), 0.0])  # the rig's y axis at heading_deg from north
        e_world = EARTH_RATE * (math.cos(lat) * north + np.array([0.0, 0.0, math.sin(lat)]))
        w_in = w_in + eff["earth_rotation"] * np.einsum("nji,j->ni", r_true, e_world)

    # --- temperature (K): self-heating, room drift; sensor reading quantized ---
    amb = rng.uniform(19.0, 26.0)
    heat, tau_h = rng.uniform(2.0, 7.0), rng.uniform(150.0, 700.0)
    temp = amb + heat * -np.expm1(-t / tau_h) + rng.uniform(-0.8, 0.8) * t / 3600.0
    d_temp = temp - temp[0]
    temp_read = np.round((temp + rng.normal(0.0, 0.03, n)) * 16.0) / 16.0

    out = {}
    for sensor in ("accel", "gyro"):
        gyro = sensor == "gyro"
        x = (w_in if gyro else f_true).copy()
        ref_scale = GYRO_REF if gyro else G0
        # IEEE polynomial scale model on the physical input, per axis
        k2 = eff.get("scale_nonlinearity_even", 0.0) * rng.choice([-1.0, 1.0], 3) * rng.uniform(0.7, 1.0, 3)
        k3 = eff.get("scale_nonlinearity_odd", 0.0) * rng.choice([-1.0, 1.0], 3) * rng.uniform(0.7, 1.0, 3)
        x = x + k2 * x**2 / ref_scale + k3 * x**3 / ref_scale**2
        truth[f"{sensor}_k2"], truth[f"{sensor}_k3"] = k2 / ref_scale, k3 / ref_scale**2
        truth[f"scale_nonlinearity_even {sensor}"] = k2 / ref_scale
        truth[f"scale_nonlinearity_odd {sensor}"] = k3 / ref_scale**2
        if eff.get("scale_asymmetry"):
            asym = eff["scale_asymmetry"] * rng.choice([-1.0, 1.0], 3)
            truth[f"scale_asymmetry {sensor}"] = asym
            x = x * (1.0 + 0.5 * asym * np.sign(x))
        if eff.get("temperature_scale"):
            ts = eff["temperature_scale"] * 1e-6 * rng.choice([-1.0, 1.0], 3)
            truth[f"temperature_scale {sensor}"] = ts
            x = x * (1.0 + ts * d_temp[:, None])
        if gyro:
            m = _triad(rng, c.gyro_scale, c.gyro_cross_axis)
            b_stat = _uniform(rng, c.gyro_bias_static_dps) * DEG
            b_drift = _uniform(rng, c.gyro_bias_drift_dps) * DEG * quiet
            tc = _uniform(rng, c.gyro_correlation_time_s)
            sigma = _uniform(rng, c.gyro_noise_std_dps) * DEG * quiet
            lsb = 2000.0 * DEG / 2**19
        else:
            m = _triad(rng, c.accel_scale, c.accel_cross_axis)
            b_stat = _uniform(rng, c.accel_bias_static_mps2)
            b_drift = _uniform(rng, c.accel_bias_drift_mps2) * quiet
            tc = _uniform(rng, c.accel_correlation_time_s)
            sigma = _uniform(rng, c.accel_noise_std_mps2) * quiet
            lsb = 4.0 * G0 / 2**17
        truth[f"{sensor}_m"] = m
        y = x @ m.T + b_stat
        # the diagnosis's scale terms are powers of u = M x (its modelled input through M): M (k2 x^2) = (k2 / M) u^2,
        # M (k3 x^3) = (k3 / M^2) u^3 per axis (M's diagonal; the asymmetry and the temperature scale are as drawn)
        for name, power in (("scale_nonlinearity_even", 1), ("scale_nonlinearity_odd", 2)):
            truth[f"{name} {sensor}"] = truth[f"{name} {sensor}"] / np.diag(m) ** power
        # eq. 3 drift: warm-up plus a small stationary Gauss-Markov part (AR(1), exact discretization)
        phi = np.exp(-1.0 / (fs * tc))
        gm = np.stack([lfilter([math.sqrt(1 - phi[k] ** 2) * 0.01 * abs(b_drift[k])], [1.0, -phi[k]],
                               rng.standard_normal(n)) for k in range(3)], axis=1)
        y = y + b_drift * np.exp(-t[:, None] / tc)
        # the stochastic model of the output (an oracle's knowledge, e.g. benchmarks/bench_gyro_walk_power.py):
        # eq. 3's drift noise variance (stationary, started at 0 at power-on), its T_c, the white variance
        truth[f"{sensor}_drift_noise_var"] = (0.01 * b_drift) ** 2
        truth[f"{sensor}_tc"] = tc.copy()
        truth[f"{sensor}_white_var"] = sigma**2 + lsb**2 / 12.0
        y = y + gm
        stochastic = gm.copy()
        if gyro and eff.get("g_sensitivity"):
            gs = rng.normal(size=(3, 3))
            gs *= eff["g_sensitivity"] * DEG / G0 / np.abs(gs).max()
            truth["g_sensitivity gyro"] = gs.copy()
            y = y + f_true @ gs.T
        if eff.get("temperature_bias"):
            coef = eff["temperature_bias"] * (1e-6 * G0 * 1e3 if not gyro else 1e-3 * DEG)
            tb = coef * rng.choice([-1.0, 1.0], 3)
            truth[f"temperature_bias {sensor}"] = tb
            y = y + tb * d_temp[:, None]
        if eff.get("bias_random_walk"):
            k = eff["bias_random_walk"] * (0.1 * DEG if gyro else 1.0)
            truth[f"bias_random_walk {sensor}"] = np.array([k])
            walk = np.cumsum(rng.standard_normal((n, 3)), axis=0) * k / math.sqrt(fs)
            y = y + walk
            stochastic += walk
        white = rng.standard_normal((n, 3)) * sigma
        y = y + white
        stochastic += white
        #: everything but the drift noise, the walk, the white noise and the ADC: y - this is their sum
        truth[f"{sensor}_deterministic"] = y - stochastic
        if eff.get("outliers") and not gyro:
            hit = rng.random((n, 3)) < eff["outliers"]
            y = y + hit * rng.choice([-1.0, 1.0], (n, 3)) * rng.uniform(6.0, 12.0, (n, 3)) * sigma
        out[sensor] = np.round(y / lsb) * lsb
    meta = {
        "serial": f"INDEP-{seed:06d}", "sample_rate_hz": f"{fs:g}", "gravity_mps2": f"{plan.gravity:.5f}",
        "latitude_deg": f"{plan.latitude_deg:.3f}", "heading_deg": f"{plan.heading_deg:.2f}",
        "station": "indepgen", "rig": "indepgen",
    }
    session = Session(
        metadata=meta, t_s=t, segment=seg, kind=kind, accel_mps2=out["accel"], gyro_radps=out["gyro"],
        temp_degc=temp_read, ref_accel_mps2=ref_f, ref_gyro_radps=w_ref,
    )
    if eff.get("earth_rotation"):
        truth["earth_rotation gyro"] = np.array([eff["earth_rotation"]])
    if eff.get("time_offset"):
        truth["time_offset accel"] = truth["time_offset gyro"] = np.array([tau])
    return Recording(session=session, plan=plan, effects=eff, truth=truth)


if __name__ == "__main__":
    args = sys.argv[1:]
    rec = generate(int(args[0]), {k: float(v) for k, v in (a.split("=") for a in args[2:])})
    rec.write(args[1])
    print(f"{args[1]}: {len(rec.session)} samples at {rec.plan.rate_hz:g} Hz, {rec.session.duration_s:.0f} s")
