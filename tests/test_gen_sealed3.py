"""The third sealed outside-the-library generator (benchmarks/gen_sealed3.py) against its own truth: the gimbal rig's
kinematics against scipy's rotations, where each kind acts (its recording minus the same seed's ``none`` recording,
the no-effect twin, by sensor and segment kind), every kind's planted effect re-derived here from its physics, its
stated size and the recording's reference columns, the design SNR, the truth recorded, determinism, and loading
with the station's reader. Recordings at 52 Hz (``rate_hz``) to stay fast."""

from __future__ import annotations

import functools
import math
import sys
from pathlib import Path
from types import ModuleType

import numpy as np
import pytest
from benchmark_modules import load_benchmark, run_outside_bench_undiagnosed
from scipy.signal import welch
from scipy.spatial.transform import Rotation

from station.fit.consistency import check_consistency
from station.session.csv_v1 import read_session, write_session
from station.session.model import Kind

_BENCH = Path(__file__).resolve().parents[1] / "benchmarks"
DEG = math.pi / 180.0
G0 = 9.80665
FS = 52.0
SEED = 400011
LABELS = {int(k): k.label for k in Kind}


@functools.cache
def _gen() -> ModuleType:
    return load_benchmark("gen_sealed3")


@functools.cache
def _rec(kind: str, seed: int = SEED):
    return _gen().generate(seed, kind, rate_hz=FS)


def _col(sensor: str) -> str:
    return "accel_mps2" if sensor == "accel" else "gyro_radps"


def _diff(kind: str, sensor: str, seed: int = SEED) -> np.ndarray:
    """The kind's recording minus its no-effect twin (the same seed's ``none``)."""
    a, b = _rec(kind, seed).session, _rec("none", seed).session
    return np.asarray(getattr(a, _col(sensor))) - np.asarray(getattr(b, _col(sensor)))


def _lsb(sensor: str) -> float:
    g = _gen()
    return float(g.ACCEL_LSB if sensor == "accel" else g.GYRO_LSB)


def _kinds(seed: int = SEED) -> np.ndarray:
    return np.asarray(_rec("none", seed).session.kind)


def _ref(name: str, seed: int = SEED) -> np.ndarray:
    return np.asarray(getattr(_rec("none", seed).session, name))


def _white_sigma(sensor: str) -> np.ndarray:
    """The none recording's white-noise std per axis from its rest (first differences; the drift is slow)."""
    y = np.asarray(getattr(_rec("none").session, _col(sensor)))[_kinds() == int(Kind.REST)]
    return np.std(np.diff(y, axis=0), axis=0) / math.sqrt(2.0)


#: Segment kinds where a kind may leak a little (not asserted either way): the pose after a ramp carries the end
#: of the supply regulator's lag.
MAY = {"supply_sag": {"accel": {"pose"}}}
#: Where each kind changes the output (sensor -> segment kinds) as its physics says; everywhere else its recording
#: is the ``none`` recording bit for bit. LOCATION must lie inside this. ``fifo_drop`` is checked apart (its last
#: samples of a hold already show the next move: the data are late).
ACTS = {
    "shock_steps": {"gyro": {"pose", "rate", "move"}},
    "supply_sag": {"accel": {"rate", "move"}},
    "warm_noise": {"gyro": {"rest", "pose", "rate", "move"}},
    "log_settling": {"accel": {"rest", "pose", "rate", "move"}},
    "scale_warmup": {"gyro": {"rate", "move"}},
    "stepper_rect": {"accel": {"move"}},
    "slew_limit": {"gyro": {"move"}},
    "alpha_cross": {"gyro": {"move"}},
}


def test_kinds_are_new_and_located() -> None:
    g = _gen()
    used = "".join((_BENCH / f).read_text() for f in ("gen_outside.py", "gen_sealed.py", "gen_sealed2.py"))
    used += (_BENCH.parent / "tests" / "indepgen.py").read_text()
    library = (_BENCH.parent / "station" / "diagnose" / "effect_registry.py").read_text()
    assert len(g.SEALED3) >= 8 and len(g.NULLS) >= 2 and g.NULLS[0] == "none"
    for kind in (*g.SEALED3, *g.NULLS[1:]):
        assert f'"{kind}"' not in used and f'"{kind}"' not in library, kind
    for kind in g.SEALED3:
        sensors, segs = g.LOCATION[kind]
        assert sensors <= {"accel", "gyro"} and segs <= {"rest", "pose", "rate", "move"} and segs and sensors
        assert g.COVARIATE[kind] and "none" not in g.COVARIATE[kind]
        if kind in ACTS:
            assert sensors <= set(ACTS[kind]) and all(segs <= ACTS[kind][s] for s in sensors), kind
    for kind in g.NULLS:
        assert "none" in g.COVARIATE[kind]
    assert set(g.COVARIATE) == set(g.KINDS) and set(g.LOCATION) == set(g.SEALED3) and set(g.SIZE) == set(g.SEALED3)


@pytest.mark.parametrize("kind", sorted(ACTS))
def test_acts_where_it_says_and_nowhere_else(kind: str) -> None:
    """Per sensor and segment kind, the recording minus its no-effect twin: where the kind acts (ACTS) it changes
    the output by many LSB, and in the LOCATION segment kinds its energy is far above the noise; in every other
    sensor and segment kind it is zero bit for bit."""
    acts = ACTS[kind]
    rec = _rec(kind)
    kinds = _kinds()
    sensors, segs = _gen().LOCATION[kind]
    for sensor in ("accel", "gyro"):
        d = _diff(kind, sensor)
        for code, label in LABELS.items():
            sel = kinds == code
            if label in acts.get(sensor, set()):
                assert np.max(np.abs(d[sel])) > 5 * _lsb(sensor), (kind, sensor, label)
            elif label not in MAY.get(kind, {}).get(sensor, set()):
                assert np.all(d[sel] == 0.0), (kind, sensor, label)
        if sensor in sensors:
            where = np.isin(kinds, [c for c, lab in LABELS.items() if lab in segs])
            energy = float(np.sqrt(np.max(np.sum(d[where] ** 2, axis=0)))) / _gen().SIGMA_TYPICAL[sensor]
            assert energy > 20.0, (kind, sensor, energy)
    assert rec.kind == kind


def test_fifo_drop_is_in_the_moves() -> None:
    """The late data change the output where the motion changes: >= 99 % of the planted energy in the moves (the
    rest in the last samples of holds, which already show the next move), none in the rest."""
    kinds = _kinds()
    for sensor in ("accel", "gyro"):
        d = _diff("fifo_drop", sensor)
        e = np.sum(d**2, axis=1)
        assert np.sum(e[kinds == int(Kind.MOVE)]) > 0.99 * np.sum(e), sensor
        assert np.all(d[kinds == int(Kind.REST)] == 0.0) or sensor == "gyro"
    assert np.max(np.abs(_diff("fifo_drop", "gyro")[kinds == int(Kind.MOVE)])) > 1.0 * DEG


def test_gimbal_attitude_against_scipy() -> None:
    rng = np.random.default_rng(5)
    a, b, c = rng.uniform(-math.pi, math.pi, (3, 50))
    np.testing.assert_allclose(_gen().gimbal_attitude(a, b, c),
                               Rotation.from_euler("ZYX", np.c_[a, b, c]).as_matrix(), atol=1e-12)


def test_rig_kinematics() -> None:
    g = _gen()
    rec = g.generate(SEED, "none", rate_hz=416.0)
    s = rec.session
    rot = Rotation.from_matrix(rec.attitude)
    np.testing.assert_allclose(np.linalg.det(rec.attitude), 1.0, atol=1e-9)
    up = rot.inv().apply([0.0, 0.0, 1.0])
    np.testing.assert_allclose(np.asarray(s.ref_accel_mps2), rec.plan.gravity * up, atol=1e-9)
    same = np.diff(np.asarray(s.segment)) == 0
    rel = (rot[:-1].inv() * rot[1:]).as_rotvec() * 416.0  # body rotation between samples / dt
    w = np.asarray(s.ref_gyro_radps)
    assert np.max(np.abs(rel - 0.5 * (w[1:] + w[:-1]))[same]) < 0.02 * DEG
    t = np.asarray(s.t_s)
    h = 1e-6
    ahead, behind = g.motion(rec.plan, t + h), g.motion(rec.plan, t - h)
    inside = ahead.segment == behind.segment
    assert np.max(np.abs((ahead.w - behind.w) / (2 * h) - rec.alpha)[inside]) < 1e-3 * DEG
    assert np.max(np.abs(rec.alpha)) > 50 * DEG
    kind = np.asarray(s.kind)
    still = np.isin(kind, (int(Kind.REST), int(Kind.POSE)))
    assert np.all(np.abs(w[still]) < 1e-12)
    rate = kind == int(Kind.RATE)
    f = np.asarray(s.ref_accel_mps2)
    np.testing.assert_allclose(np.abs(np.sum(f[rate] * w[rate], axis=1)),  # every spin about the vertical
                               np.linalg.norm(f[rate], axis=1) * np.linalg.norm(w[rate], axis=1), rtol=1e-9)
    assert max(rec.plan.magnitudes_dps) >= 300.0
    # each of the six faces spun once; each body axis spun early and late (before and after the oblique block)
    axial = np.max(np.abs(up[rate]), axis=1) > 1 - 1e-9
    faces = {(int(np.argmax(np.abs(u))), int(np.sign(u[np.argmax(np.abs(u))]))) for u in up[rate][axial]}
    assert len(faces) == 6
    assert np.any(~axial)  # the oblique block: a spin about no body axis
    t_oblique = t[rate][~axial].mean()
    for k in range(3):
        tk = t[rate][axial & (np.argmax(np.abs(up[rate]), axis=1) == k)]
        assert tk.min() < t_oblique < tk.max(), k
    # poses: the six faces and random attitudes, reached by moves that turn several gimbals at once
    pose = np.round(up[kind == int(Kind.POSE)], 6)
    count = np.sum(np.abs(pose) > 1e-3, axis=1)
    assert np.any(count >= 2)
    moving = kind == int(Kind.MOVE)
    dirs = w[moving] / np.maximum(np.linalg.norm(w[moving], axis=1, keepdims=True), 1e-12)
    seg = np.asarray(s.segment)[moving]
    turning = [np.ptp(dirs[(seg == sg) & (np.linalg.norm(w[moving], axis=1) > 5 * DEG)], axis=0).max()
               for sg in np.unique(seg)]
    assert max(turning) > 0.2  # the rotation axis changes within a move (not a fixed-axis turn)


def test_design_snr_of_every_kind() -> None:
    g = _gen()
    for kind in g.SEALED3:
        snr = g.design_snr(_rec(kind))
        assert snr.snr >= 20.0 and snr.n > 40, (kind, snr)
    assert g.design_snr(_rec("none")).snr == 0.0


def test_nulls() -> None:
    g = _gen()
    for sensor in ("accel", "gyro"):
        assert np.all(_diff("none", sensor) == 0.0)
    rest = _kinds() == int(Kind.REST)
    for sensor in ("accel", "gyro"):
        sigma = _white_sigma(sensor)
        # shaped: std 0.8 white + 0.6 first-difference-shaped: the same total; the power rises with frequency
        y = np.asarray(getattr(_rec("shaped_noise").session, _col(sensor)))[rest]
        d = y - np.asarray(getattr(_rec("none").session, _col(sensor)))[rest]
        ratio = np.std(d, axis=0) / sigma
        assert np.all((ratio > 0.55) & (ratio < 0.72)), ratio  # sqrt(0.6^2 + 0.2^2) = 0.63
        freq, p = welch(y - y.mean(axis=0), fs=FS, nperseg=512, axis=0)
        low, high = p[(freq > 0.5) & (freq < FS / 8)].mean(axis=0), p[freq > 3 * FS / 8].mean(axis=0)
        assert np.all(high > 1.3 * low), (high / low)
        # dither: white, the same std, light tails (kurtosis 2.18 instead of 3)
        y = np.asarray(getattr(_rec("dither_noise").session, _col(sensor)))[rest]
        v = np.diff(y, axis=0) / math.sqrt(2.0)
        assert np.all(np.abs(np.std(v, axis=0) / sigma - 1.0) < 0.08)
        box = np.ones(105) / 105.0  # the slow drift removed by a 2 s moving mean
        x = np.stack([y[:, i] - np.convolve(y[:, i], box, mode="same") for i in range(3)], axis=1)[60:-60]
        kurt = np.mean(x**4, axis=0) / np.mean(x**2, axis=0) ** 2
        assert np.all(kurt < 2.5), kurt  # Gaussian: 3
    assert g.NULLS == ("none", "shaped_noise", "dither_noise")


def test_shock_steps() -> None:
    g = _gen()
    rec = _rec("shock_steps")
    k, size = rec.axis, rec.size
    d = _diff("shock_steps", "gyro")[:, k]
    t = np.asarray(rec.session.t_s)
    ends = g.tilt_ends(rec.plan)
    assert len(ends) == rec.params["n_steps"] >= 8 and np.array_equal(ends, rec.events)
    level = np.searchsorted(ends, t, side="right")
    assert np.all(d[level == 0] == 0.0)
    means = np.array([d[level == i].mean() for i in range(len(ends) + 1) if np.any(level == i)])
    for i in range(len(ends) + 1):
        there = level == i
        if np.any(there):
            assert np.ptp(d[there]) <= 1.01 * _lsb("gyro")  # constant between the events
    steps = np.abs(np.diff(means))
    assert np.all((steps > 0.6 * size * DEG - 2 * _lsb("gyro")) & (steps < 1.4 * size * DEG + 2 * _lsb("gyro")))
    assert np.all(_diff("shock_steps", "gyro")[:, [j for j in range(3) if j != k]] == 0.0)


def test_supply_sag() -> None:
    rec = _rec("supply_sag")
    size, tau = rec.size, rec.params["tau_s"]
    d = _diff("supply_sag", "accel")
    w = _ref("ref_gyro_radps")
    seg, kinds = np.asarray(rec.session.segment), _kinds()
    assert np.all(d[kinds == int(Kind.REST)] == 0.0)
    checked = 0
    for sg in np.unique(seg[kinds == int(Kind.RATE)]):
        there = np.flatnonzero(seg == sg)
        settled = there[there >= there[0] + int(5 * tau * FS)]  # the regulator's lag has settled
        if len(settled) < 20:
            continue
        sag = size * np.linalg.norm(w[settled[0]]) / (300.0 * DEG)
        ratio = -d[settled].mean(axis=0) / sag / G0  # 5 k_i (k_i 0.9-1.1) plus the axis's own reading in g
        assert np.all((ratio > 3.4) & (ratio < 6.7)), ratio
        checked += 1
    assert checked >= 10


def test_warm_noise() -> None:
    rec = _rec("warm_noise")
    d = _diff("warm_noise", "gyro")
    sigma = _white_sigma("gyro")
    expected = (1.0 + rec.size * (rec.temp_true - rec.params["t_min"]) / 10.0) ** 2 - 1.0  # extra var / sigma^2
    warm = expected > np.quantile(expected, 0.8)
    cool = expected < np.quantile(expected, 0.2)
    for k in range(3):
        got_warm = np.var(d[warm, k]) / sigma[k] ** 2
        assert 0.85 * expected[warm].mean() < got_warm < 1.15 * expected[warm].mean(), (k, got_warm)
        assert np.var(d[cool, k]) < 0.5 * np.var(d[warm, k])
    assert rec.params["peak_factor"] > 1.25
    assert np.all(_diff("warm_noise", "accel") == 0.0)


def test_log_settling() -> None:
    rec = _rec("log_settling")
    k, c, tau0 = rec.axis, rec.params["c"], rec.params["tau0_s"]
    t = np.asarray(rec.session.t_s)
    d = _diff("log_settling", "accel")[:, k]
    assert np.max(np.abs(d - c * np.log1p(t / tau0))) <= 1.01 * _lsb("accel")
    assert 0.8 * 0.035 <= abs(c) <= 1.25 * 0.035 and 1.0 <= tau0 <= 5.0


def test_scale_warmup() -> None:
    rec = _rec("scale_warmup")
    k, c, tau = rec.axis, rec.params["c"], rec.params["tau_s"]
    t = np.asarray(rec.session.t_s)
    w = _ref("ref_gyro_radps")
    d = _diff("scale_warmup", "gyro")[:, k]
    expected = c * np.exp(-t / tau) * w[:, k]
    # the unit's M (scale 0.97-1.003, cross-axis 1e-3) against the reference's w_k
    assert np.max(np.abs(d - expected)) <= 0.035 * np.max(np.abs(expected)) + 0.0011 * np.max(np.abs(c * w)) \
        + 1.01 * _lsb("gyro")
    # in the spins about the axis the relative error decays as c exp(-t/tau): early spins read differently from late
    rate = _kinds() == int(Kind.RATE)
    about = rate & (np.abs(w[:, k]) > 100 * DEG)
    model = c * np.exp(-t[about] / tau) * w[about, k]
    assert np.all(np.abs(d[about] - model) <= 0.035 * np.abs(model) + 1.01 * _lsb("gyro"))
    decay = np.exp(-t[about] / tau)
    assert decay.max() > 1.3 * decay.min()  # spun early and late: the scale error differs by 30 % at least


def test_stepper_rect() -> None:
    g = _gen()
    rec = _rec("stepper_rect")
    k, c = rec.axis, rec.params["c"]
    d = _diff("stepper_rect", "accel")[:, k]
    t = np.asarray(rec.session.t_s)
    tilting = np.zeros(len(t), dtype=bool)
    for st in rec.plan.steps:
        if st.kind == Kind.MOVE and st.tilts:
            tilting |= (t > st.t0) & (t < st.t0 + st.motion_s)
    assert np.all(d[~tilting] == 0.0)  # nothing while only the outer gimbal turns, nothing when still
    assert np.max(np.abs(d)) > 0.85 * abs(c) and np.max(np.abs(d)) < 2.3 * abs(c)  # the resonance is crossed
    assert np.all(np.sign(d[np.abs(d) > 10 * _lsb("accel")]) == np.sign(c))  # a rectified (one-sign) shift
    r = np.linspace(0.0, 3.0, 3001)
    p = g.stepper_power(r, 1.0, rec.params["q"])
    assert abs(p[1000] - 1.0) < 1e-12 and p[0] == 0.0


def test_fifo_drop() -> None:
    """The data of every move are the rig's motion a whole number of samples later (the drops so far): that number
    never falls, and reaches the recorded drops by the end."""
    g = _gen()
    rec = _rec("fifo_drop")
    drops = int(rec.params["drops"])
    assert drops == max(2, round(rec.size * 1e-3 * FS)) and rec.params["slip_s"] == pytest.approx(drops / FS)
    d = _diff("fifo_drop", "gyro")
    t = np.asarray(rec.session.t_s)
    seg, kinds = np.asarray(rec.session.segment), _kinds()
    w = _ref("ref_gyro_radps")
    late = [g.motion(rec.plan, t + m / FS).w - w for m in range(drops + 1)]
    drop_t = np.array(rec.events)
    assert len(drop_t) == drops and np.all(np.diff(drop_t) >= 0)
    exact = 0
    moves = np.unique(seg[kinds == int(Kind.MOVE)])
    for sg in moves:
        there = seg == sg
        err = [float(np.max(np.abs(d[there] - lt[there]))) for lt in late]  # M within 3 % of I
        m = int(np.argmin(err))
        if err[m] <= 0.035 * float(np.max(np.abs(late[m][there]))) + 3 * _lsb("gyro"):
            exact += 1
            assert m == int(np.sum(drop_t <= t[there][0])), sg  # the drops so far
    assert exact >= len(moves) - drops  # a move with a drop inside it fits no single slip


def test_slew_limit() -> None:
    rec = _rec("slew_limit")
    k, limit = rec.axis, rec.params["limit_dps2"] * DEG
    w = _ref("ref_gyro_radps")[:, k]
    alpha_ref = np.gradient(w, 1.0 / FS)
    assert 0.4 * np.max(np.abs(alpha_ref)) < limit < 0.8 * np.max(np.abs(alpha_ref))
    planted = rec.planted["gyro"][:, k]
    y0 = np.asarray(_rec("none").session.gyro_radps)[:, k]
    # the limited output's steps are at most limit/fs (the noise of two samples on top)
    steps = np.abs(np.diff(y0 + planted))
    assert np.max(steps[np.abs(planted[1:]) > 0]) < limit / FS + 8 * 0.013 * DEG
    assert np.max(np.abs(planted)) > 1.0 * DEG


def test_alpha_cross() -> None:
    rec = _rec("alpha_cross")
    k, j, c = rec.axis, int(rec.params["j"]), rec.params["c_s"]
    assert j != k and abs(c) == pytest.approx(rec.size * DEG)
    d = _diff("alpha_cross", "gyro")[:, k]
    expected = c * rec.alpha[:, j]
    assert np.max(np.abs(d - expected)) <= 1.01 * _lsb("gyro")
    # the body angular acceleration is the reference rate's derivative (independent of the generator's formula; the
    # same plan at 416 Hz, where a central difference is accurate)
    fine = _gen().generate(SEED, "alpha_cross", rate_hz=416.0)
    w = np.asarray(fine.session.ref_gyro_radps)[:, j]
    seg = np.asarray(fine.session.segment)
    inner = np.r_[False, (seg[2:] == seg[:-2]), False]
    fd = np.gradient(w, 1.0 / 416.0)
    assert np.max(np.abs(fd - fine.alpha[:, j])[inner]) < 0.01 * np.max(np.abs(fine.alpha[:, j]))
    assert np.max(np.abs(fine.planted["gyro"][:, k] - c * fd)[inner]) < 0.01 * np.max(np.abs(c * fd))


def test_truth_recorded() -> None:
    g = _gen()
    own = {"shock_steps": {"n_steps"}, "supply_sag": {"tau_s", "peak_sag"}, "warm_noise": {"t_min", "peak_factor"},
           "log_settling": {"tau0_s"}, "scale_warmup": {"tau_s"}, "stepper_rect": {"v_res_dps", "q"},
           "fifo_drop": {"drops", "slip_s"}, "slew_limit": {"limit_dps2"}, "alpha_cross": {"j", "c_s"}}
    assert set(own) == set(g.SEALED3)
    for kind in g.SEALED3:
        rec = _rec(kind)
        assert rec.kind == kind and set(rec.params) == {"c", *own[kind]}, kind
        assert abs(rec.params["c"]) == pytest.approx(rec.size)
        if kind != "slew_limit":
            assert 0.8 * g.SIZE[kind] <= rec.size <= 1.25 * g.SIZE[kind]
        assert set(rec.planted) == {"accel", "gyro"} and rec.planted["gyro"].shape == (len(rec.session), 3)
        assert rec.axis in (-1, 0, 1, 2)
        assert rec.sensor_class.name == "table1_lot"


def test_sensor_class_within_table1() -> None:
    import dataclasses

    from station.kernel.sensor_class import TABLE1

    cls = _rec("none").sensor_class
    for f in dataclasses.fields(TABLE1):
        v = getattr(TABLE1, f.name)
        if isinstance(v, tuple):
            lo, hi = getattr(cls, f.name)
            assert v[0] <= lo < hi <= v[1] and hi - lo == pytest.approx(0.5 * (v[1] - v[0])), f.name


def test_seed_in_same_bytes_out(tmp_path: Path) -> None:
    """The same seed writes the same file byte for byte; another seed another file; the planted kind on its own
    stream leaves the base draws alone."""
    g = _gen()
    files = {}
    for name, seed, kind in (("a", 400003, "fifo_drop"), ("b", 400003, "fifo_drop"),
                             ("c", 400004, "fifo_drop"), ("d", 400003, "none")):
        files[name] = tmp_path / f"{name}.csv"
        write_session(g.generate(seed, kind, rate_hz=FS).session, files[name])
    data = {k: v.read_bytes() for k, v in files.items()}
    assert data["a"] == data["b"] and data["a"] != data["c"] and data["a"] != data["d"]
    a, d = read_session(files["a"]), read_session(files["d"])
    assert np.array_equal(a.t_s, d.t_s) and np.array_equal(a.temp_degc, d.temp_degc)
    assert np.array_equal(a.ref_gyro_radps, d.ref_gyro_radps)


@pytest.mark.parametrize("kind", ["none", "shaped_noise", "dither_noise", *sorted(ACTS), "fifo_drop"])
def test_every_kind_loads(kind: str, tmp_path: Path) -> None:
    """Every kind's recording goes through the station's writer and reader unchanged, and passes its input checks."""
    rec = _rec(kind)
    path = tmp_path / f"{kind}.csv"
    write_session(rec.session, path)
    back = read_session(path)
    assert len(back) == len(rec.session) and back.sample_rate_hz == FS
    np.testing.assert_allclose(back.gyro_radps, rec.session.gyro_radps, atol=1e-6 * DEG)
    np.testing.assert_allclose(back.accel_mps2, rec.session.accel_mps2, atol=1e-6)
    check_consistency(back)  # the station's input checks (no fit) accept it


def test_unknown_kind_refused() -> None:
    with pytest.raises(ValueError, match="unknown kind"):
        _gen().generate(400000, "anisoinertia")


def test_bench_runs_the_third_sealed_generator(monkeypatch: pytest.MonkeyPatch,
                                               capsys: pytest.CaptureFixture[str]) -> None:
    """``bench_diagnose_outside.py --generator sealed3`` draws its recordings from gen_sealed3 (seed mapping,
    places), with no diagnosis run."""
    run_outside_bench_undiagnosed(monkeypatch, ["--generator", "sealed3", "--base", "400200", "--per", "1",
                                                "--kinds", "none,alpha_cross"])
    out = capsys.readouterr().out
    assert "benchmarks/gen_sealed3.py" in out
    assert f"alpha_cross      seed {400200 + _gen().KINDS.index('alpha_cross')}:" in out
    assert "gyro in move" in out and "nulls with a (false) finding: 0/1" in out


def test_cli_writes_the_same_file_twice(tmp_path: Path) -> None:
    import subprocess

    g = _gen()
    seed = next(s for s in range(400000, 400100) if g.draw_plan(g._streams(s, "none")[0]).rate_hz == FS)
    outs = []
    for name in ("a.csv", "b.csv"):
        out = tmp_path / name
        subprocess.run([sys.executable, str(_BENCH / "gen_sealed3.py"), str(seed), "shock_steps", str(out)],
                       check=True, capture_output=True, text=True)
        outs.append(out.read_bytes())
    assert outs[0] == outs[1]
    assert len(read_session(tmp_path / "a.csv")) == len(g.generate(seed, "shock_steps").session)
    bad = subprocess.run([sys.executable, str(_BENCH / "gen_sealed3.py"), "1"], capture_output=True, text=True)
    assert bad.returncode == 2 and "usage" in bad.stderr
