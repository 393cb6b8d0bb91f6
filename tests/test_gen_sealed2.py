"""The second sealed outside-the-library generator (benchmarks/gen_sealed2.py) against its own truth: the rig's
kinematics against scipy's rotations, where each kind acts (its recording minus the same seed's ``none`` recording,
by sensor and segment kind: present where it acts, bit for bit zero where it does not), every kind's planted effect
re-derived here from its physics and the recording's reference columns, the design SNR, determinism, and loading
with the station's reader. Recordings at 50 Hz (``rate_hz``) to stay fast."""

from __future__ import annotations

import functools
import math
import subprocess
import sys
from pathlib import Path
from types import ModuleType

import numpy as np
import pytest
from benchmark_modules import load_benchmark, run_outside_bench_undiagnosed
from scipy.integrate import cumulative_trapezoid
from scipy.signal import welch
from scipy.spatial.transform import Rotation

from station.session.csv_v1 import read_session, write_session
from station.session.model import Kind

_BENCH = Path(__file__).resolve().parents[1] / "benchmarks"
_PATH = _BENCH / "gen_sealed2.py"
DEG = math.pi / 180.0
G0 = 9.80665
SEED = 300011
LABELS = {int(k): k.label for k in Kind}


@functools.cache
def _gen() -> ModuleType:
    return load_benchmark("gen_sealed2")


@functools.cache
def _rec(kind: str, seed: int = SEED):
    return _gen().generate(seed, kind, rate_hz=50.0)


def _col(sensor: str) -> str:
    return "accel_mps2" if sensor == "accel" else "gyro_radps"


def _diff(kind: str, sensor: str, seed: int = SEED) -> np.ndarray:
    a, b = _rec(kind, seed).session, _rec("none", seed).session
    return np.asarray(getattr(a, _col(sensor))) - np.asarray(getattr(b, _col(sensor)))


def _lsb(sensor: str) -> float:
    g = _gen()
    return float(g.ACCEL_LSB if sensor == "accel" else g.GYRO_LSB)


def _kinds(kind: str = "none") -> np.ndarray:
    return np.asarray(_rec(kind).session.kind)


def _ref(kind: str, name: str) -> np.ndarray:
    return np.asarray(getattr(_rec(kind).session, name))


#: Where each kind changes the output (sensor -> segment kinds), as the physics says; everywhere else its
#: recording is the ``none`` recording bit for bit (up to ``slack`` LSB: a quantization step may flip where the
#: planted part is below one LSB). LOCATION must be a subset of this.
ACTS = {
    "alias_tone": ({"accel": {"rest", "pose", "rate", "move"}}, 0),
    "temp_lut_steps": ({"gyro": {"rest", "pose", "rate", "move"}}, 0),
    "anisoinertia": ({"gyro": {"rate", "move"}}, 0),
    "accel_cross_coupling": ({"accel": {"pose", "rate", "move"}}, 0),
    "adc_crosstalk": ({"accel": {"rate", "move"}}, 2),
    "scale_jitter": ({"gyro": {"rate", "move"}}, 0),
    "motor_heating": ({"gyro": {"pose", "rate", "move"}}, 0),
    "clock_jitter": ({"gyro": {"move"}, "accel": {"move"}}, 0),
    "spin_stress_scale": ({"accel": {"rate", "move"}}, 0),
}


def test_kinds_are_new_and_located() -> None:
    g = _gen()
    used = "".join((_BENCH / f).read_text() for f in ("gen_outside.py", "gen_sealed.py"))
    used += (_BENCH.parent / "tests" / "indepgen.py").read_text()
    library = (_BENCH.parent / "station" / "diagnose" / "effect_registry.py").read_text()
    assert len(g.SEALED2) >= 8 and len(g.NULLS) == 2
    for kind in (*g.SEALED2, "resonant_noise"):
        assert f'"{kind}"' not in used and f'"{kind}"' not in library, kind
    for kind in g.SEALED2:
        sensors, segs = g.LOCATION[kind]
        assert sensors <= {"accel", "gyro"} and segs <= {"rest", "pose", "rate", "move"} and segs and sensors
        assert g.COVARIATE[kind] and "none" not in g.COVARIATE[kind]
        acts, _ = ACTS[kind]
        assert sensors <= set(acts), kind
        assert all(segs <= acts[s] for s in sensors), kind
    assert set(g.COVARIATE) == set(g.KINDS) and set(g.LOCATION) == set(g.SEALED2)


@pytest.mark.parametrize("kind", sorted(ACTS))
def test_acts_where_it_says_and_nowhere_else(kind: str) -> None:
    """Per sensor and segment kind, the recording minus the same seed's ``none``: where the kind acts the
    difference is many LSB (and in some segment of the LOCATION segment kinds its energy is far above the noise:
    ``sqrt(sum d^2) / sigma > 5``); in every other sensor and segment kind it is zero (or ``slack`` LSB)."""
    acts, slack = ACTS[kind]
    rec = _rec(kind)
    kinds = _kinds(kind)
    sensors, segs = _gen().LOCATION[kind]
    best: dict[str, float] = {}
    for sensor in ("accel", "gyro"):
        d = _diff(kind, sensor)
        sigma = np.max(_gen().SIGMA_TYPICAL[sensor])
        for code, label in LABELS.items():
            sel = kinds == code
            if label in acts.get(sensor, set()):
                assert np.max(np.abs(d[sel])) > 20 * _lsb(sensor), (kind, sensor, label)
            else:
                assert np.max(np.abs(d[sel])) <= slack * _lsb(sensor) * 1.01, (kind, sensor, label)
        if sensor in sensors:  # some segment of a LOCATION kind carries it far above the noise (its energy)
            seg = np.asarray(rec.session.segment)
            there = np.unique(seg[np.isin(kinds, [c for c, lab in LABELS.items() if lab in segs])])
            best[sensor] = max(float(np.sqrt(np.max(np.sum(d[seg == s] ** 2, axis=0)))) / sigma for s in there)
    assert min(best.values()) > 5.0, (kind, best)
    assert rec.kind == kind


def test_rig_kinematics_against_scipy() -> None:
    rec = _gen().generate(SEED, "none", rate_hz=400.0)
    s = rec.session
    rot = Rotation.from_matrix(rec.attitude)
    np.testing.assert_allclose(np.linalg.det(rec.attitude), 1.0, atol=1e-9)
    up = rot.inv().apply([0.0, 0.0, 1.0])
    np.testing.assert_allclose(np.asarray(s.ref_accel_mps2), rec.plan.gravity * up, atol=1e-9)
    dt = 1.0 / rec.plan.rate_hz
    same = np.diff(np.asarray(s.segment)) == 0  # inside one step (a step's end is the next one's start)
    rel = (rot[:-1].inv() * rot[1:]).as_rotvec() / dt
    w = np.asarray(s.ref_gyro_radps)
    mean_w = 0.5 * (w[1:] + w[:-1])
    assert np.max(np.abs(rel - mean_w)[same]) < 0.02 * DEG
    # the angular acceleration is the rate's derivative (central difference of the rig's own motion, h = 1 us)
    t = np.asarray(s.t_s)
    h = 1e-6
    ahead, behind = _gen().motion(rec.plan, t + h), _gen().motion(rec.plan, t - h)
    inside = ahead.segment == behind.segment
    dw = (ahead.w - behind.w) / (2 * h)
    assert np.max(np.abs(dw - rec.alpha)[inside]) < 1e-3 * DEG
    assert np.max(np.abs(rec.alpha)) > 50 * DEG
    kind = np.asarray(s.kind)
    still = np.isin(kind, (int(Kind.REST), int(Kind.POSE)))
    assert np.all(np.abs(w[still]) == 0.0)
    # rate holds: about a body axis at the plan's magnitudes, or about a diagonal (two or three components)
    rate = kind == int(Kind.RATE)
    norms = np.round(np.linalg.norm(w[rate], axis=1) / DEG, 6)
    axial = np.max(np.abs(w[rate]), axis=1) / np.linalg.norm(w[rate], axis=1) > 0.999
    assert set(norms[axial]) == set(rec.plan.magnitudes_dps)
    assert max(rec.plan.magnitudes_dps) >= 250.0
    shares = np.sort(np.abs(w[rate][~axial]), axis=1) / np.linalg.norm(w[rate][~axial], axis=1, keepdims=True)
    assert np.any(np.all(np.abs(shares - 1 / math.sqrt(3.0)) < 1e-9, axis=1))  # a corner spin
    # every rate hold spins about the vertical: gravity stays along the rate
    f = np.asarray(s.ref_accel_mps2)[rate]
    np.testing.assert_allclose(np.abs(np.sum(f * w[rate], axis=1)),
                               np.linalg.norm(f, axis=1) * np.linalg.norm(w[rate], axis=1), rtol=1e-9)
    # the poses: six faces, edges of every pair of axes, corners
    poses = np.round(up[kind == int(Kind.POSE)], 6)
    count = np.sum(np.abs(poses) > 0.1, axis=1)
    faces = {(int(np.argmax(np.abs(u))), int(np.sign(u[np.argmax(np.abs(u))]))) for u in poses[count == 1]}
    assert len(faces) == 6
    pairs = {tuple(np.flatnonzero(np.abs(u) > 0.1)) for u in poses[count == 2]}
    assert pairs == {(0, 1), (0, 2), (1, 2)}
    assert np.any(count == 3)


def test_design_snr_of_every_kind() -> None:
    g = _gen()
    for kind in g.SEALED2:
        assert g.design_snr(_rec(kind)) >= 20.0, kind
    assert g.design_snr(_rec("none")) == 0.0


def test_nulls() -> None:
    g = _gen()
    for sensor in ("accel", "gyro"):
        assert np.all(_diff("none", sensor) == 0.0)
    rec = _rec("resonant_noise")
    for sensor in ("accel", "gyro"):
        d = _diff("resonant_noise", sensor)
        base = np.asarray(getattr(_rec("none").session, _col(sensor)))[_kinds() == int(Kind.REST)]
        sigma = np.std(np.diff(base, axis=0), axis=0) / math.sqrt(2.0)  # white noise std (drift is slow)
        ratio = np.std(d, axis=0) / sigma
        assert np.all((ratio > 0.5) & (ratio < 0.78)), ratio  # sqrt(0.6^2 + 0.2^2) = 0.63
        # the resonant part's power peaks at its centre frequency
        y = np.asarray(getattr(rec.session, _col(sensor)))[_kinds() == int(Kind.REST)]
        freq, p = welch(y - y.mean(axis=0), fs=50.0, nperseg=512, axis=0)
        peak = freq[np.argmax(p.mean(axis=1))]
        assert abs(peak - rec.params["f0_hz"]) < 0.1 * rec.params["f0_hz"] + 0.3, (peak, rec.params["f0_hz"])
    assert g.NULLS == ("none", "resonant_noise")


def test_alias_tone() -> None:
    rec = _rec("alias_tone")
    k, p = rec.axis, rec.params
    t = np.asarray(rec.session.t_s)
    freq = np.maximum(p["f0_hz"] + p["dfdt_hz_per_k"] * (rec.temp_true - rec.temp_true[0]), 0.1)
    expected = p["c"] * np.sin(p["phase0"] + 2 * math.pi * cumulative_trapezoid(freq, t, initial=0.0))
    d = _diff("alias_tone", "accel")[:, k]
    assert np.max(np.abs(d - expected)) <= 1.01 * _lsb("accel") + 1e-9 * len(t)
    assert 0.4 <= p["f0_hz"] <= 2.5 and np.ptp(d) > 1.9 * p["c"]
    assert np.all(_diff("alias_tone", "accel")[:, [j for j in range(3) if j != k]] == 0.0)


def test_temp_lut_steps() -> None:
    rec = _rec("temp_lut_steps")
    k, p = rec.axis, rec.params
    x = (rec.temp_true - p["t_ref"]) / p["cell_k"]
    expected = p["c"] * DEG * (2.0 * np.mod(x, 1.0) - 1.0)
    d = _diff("temp_lut_steps", "gyro")[:, k]
    assert np.max(np.abs(d - expected)) <= 1.01 * _lsb("gyro")
    assert np.ptp(rec.temp_true) >= 2 * p["cell_k"]  # the chamber crosses two cells at least
    assert np.ptp(d) > 1.8 * abs(p["c"]) * DEG


def test_anisoinertia() -> None:
    rec = _rec("anisoinertia")
    k, c = rec.axis, rec.params["c_s"]
    w = _ref("anisoinertia", "ref_gyro_radps")
    i, j = (a for a in range(3) if a != k)
    d = _diff("anisoinertia", "gyro")[:, k]
    assert np.max(np.abs(d - c * w[:, i] * w[:, j])) <= 1.01 * _lsb("gyro")
    assert np.max(np.abs(d[_kinds() == int(Kind.RATE)])) > 0.3 * rec.size * DEG  # a diagonal spin


def test_accel_cross_coupling() -> None:
    rec = _rec("accel_cross_coupling")
    k, j, c = rec.axis, int(rec.params["j"]), rec.params["c"]
    f = _ref("accel_cross_coupling", "ref_accel_mps2")
    d = _diff("accel_cross_coupling", "accel")[:, k]
    assert np.max(np.abs(d - c * f[:, k] * f[:, j] / G0)) <= 1.01 * _lsb("accel")
    pose = _kinds() == int(Kind.POSE)
    edge = pose & (np.abs(np.abs(f[:, k]) - np.abs(f[:, j])) < 1e-6) & (np.abs(f[:, k]) > 0.5)
    assert np.any(edge)
    assert np.allclose(np.abs(d[edge]), abs(c) * rec.plan.gravity**2 / G0 * np.where(
        np.abs(f[edge, 3 - k - j]) > 0.5, 1 / 3, 1 / 2), atol=1.01 * _lsb("accel"))


def test_adc_crosstalk() -> None:
    rec = _rec("adc_crosstalk")
    k, j, c = rec.axis, int(rec.params["j"]), rec.params["c_per_radps"]
    y = np.asarray(_rec("none").session.gyro_radps)[:, j]
    rest = _kinds() == int(Kind.REST)
    d = _diff("adc_crosstalk", "accel")[:, k]
    assert np.max(np.abs(d - c * (y - y[rest].mean()))) <= 2.01 * _lsb("accel")
    w = _ref("adc_crosstalk", "ref_gyro_radps")[:, j]
    top = _kinds() == int(Kind.RATE)
    assert np.max(np.abs(d[top])) > 0.5 * abs(c) * np.max(np.abs(w))
    # odd in the rate: the holds at +w and -w about the axis give opposite offsets
    seg = np.asarray(rec.session.segment)
    means = {round(float(w[seg == s][0]), 9): float(d[seg == s].mean()) for s in np.unique(seg[top])}
    pairs = [(means[v], means[-v]) for v in means if v > 0.1 and -v in means]
    assert pairs and all(a * b < 0 for a, b in pairs)


def test_scale_jitter() -> None:
    rec = _rec("scale_jitter")
    k, size, tau = rec.axis, rec.size, rec.params["tau_s"]
    w = _ref("scale_jitter", "ref_gyro_radps")[:, k]
    d = _diff("scale_jitter", "gyro")[:, k]
    big = np.abs(w) > 200 * DEG
    assert np.sum(big) > 200
    e = d[big] / w[big]  # the relative jitter (the scale factor within 3 %)
    assert 0.8 * size < np.std(e) < 1.25 * size
    lag1 = np.corrcoef(e[:-1], e[1:])[0, 1]
    assert lag1 > 0.5 * math.exp(-1.0 / (50.0 * tau))  # coloured (its correlation time), not white
    still = np.all(_ref("scale_jitter", "ref_gyro_radps") == 0.0, axis=1)
    assert np.all(d[still] == 0.0)


def test_motor_heating() -> None:
    rec = _rec("motor_heating")
    k, c, tau = rec.axis, rec.params["c"], rec.params["tau_s"]
    w = _ref("motor_heating", "ref_gyro_radps")
    load = np.sum(w**2, axis=1) / (rec.plan.top_dps * DEG) ** 2
    a = math.exp(-1.0 / (50.0 * tau))
    heat = np.empty_like(load)
    acc = 0.0
    for i, v in enumerate(load):  # first-order lag, its own loop
        acc = a * acc + (1 - a) * v
        heat[i] = acc
    d = _diff("motor_heating", "gyro")[:, k]
    assert np.max(np.abs(d - c * DEG * heat)) <= 1.01 * _lsb("gyro")
    assert np.max(np.abs(d)) > 0.1 * abs(c) * DEG
    # it decays in the poses after the spins: a pose after a spin still carries it
    pose = _kinds() == int(Kind.POSE)
    assert np.max(np.abs(d[pose])) > 0.5 * np.max(np.abs(d))


def test_clock_jitter() -> None:
    rec = _rec("clock_jitter")
    alpha = rec.alpha
    dg = _diff("clock_jitter", "gyro")
    da = _diff("clock_jitter", "accel")
    move = _kinds() == int(Kind.MOVE)
    strong = move & (np.max(np.abs(alpha), axis=1) > 50 * DEG)
    # one jitter per sample for all axes: estimated from the gyro, it predicts the accelerometer
    j = np.sum(dg[strong] * alpha[strong], axis=1) / np.sum(alpha[strong] ** 2, axis=1)
    std = rec.params["std_s"]
    assert 0.8 * std < np.std(j) < 1.25 * std
    w = _ref("clock_jitter", "ref_gyro_radps")[strong]
    f = _ref("clock_jitter", "ref_accel_mps2")[strong]
    pred = -np.cross(w, f) * j[:, None]
    big = np.linalg.norm(pred, axis=1) > 3e-3
    assert np.sum(big) > 20
    r = np.corrcoef(pred[big].ravel(), da[strong][big].ravel())[0, 1]
    assert r > 0.95


def test_spin_stress_scale() -> None:
    rec = _rec("spin_stress_scale")
    k, c = rec.axis, rec.params["c_s2"]
    w = _ref("spin_stress_scale", "ref_gyro_radps")
    f = _ref("spin_stress_scale", "ref_accel_mps2")[:, k]
    d = _diff("spin_stress_scale", "accel")[:, k]
    expected = c * np.sum(w**2, axis=1) * f
    assert np.max(np.abs(d - expected)) <= 0.04 * np.max(np.abs(expected)) + 1.01 * _lsb("accel")  # M, not I
    rate = _kinds() == int(Kind.RATE)
    assert np.max(np.abs(d[rate])) > 0.5 * rec.size * G0 * (250.0 / 300.0) ** 2


def test_seed_in_same_bytes_out(tmp_path: Path) -> None:
    """The same seed writes the same file byte for byte (every random draw, the plan, the float formatting);
    another seed another file; the planted kind on its own stream leaves the base draws alone."""
    g = _gen()
    files = {}
    for name, seed, kind in (("a", 300003, "clock_jitter"), ("b", 300003, "clock_jitter"),
                             ("c", 300004, "clock_jitter"), ("d", 300003, "none")):
        files[name] = tmp_path / f"{name}.csv"
        write_session(g.generate(seed, kind, rate_hz=50.0).session, files[name])
    data = {k: v.read_bytes() for k, v in files.items()}
    assert data["a"] == data["b"] and data["a"] != data["c"] and data["a"] != data["d"]
    a, d = read_session(files["a"]), read_session(files["d"])
    assert np.array_equal(a.t_s, d.t_s) and np.array_equal(a.temp_degc, d.temp_degc)
    assert np.array_equal(a.ref_gyro_radps, d.ref_gyro_radps)


@pytest.mark.parametrize("kind", ["none", "resonant_noise", *sorted(ACTS)])
def test_every_kind_loads(kind: str, tmp_path: Path) -> None:
    """Every kind's recording goes through the station's writer and reader unchanged."""
    rec = _rec(kind)
    path = tmp_path / f"{kind}.csv"
    write_session(rec.session, path)
    back = read_session(path)
    assert len(back) == len(rec.session) and back.sample_rate_hz == 50.0
    np.testing.assert_allclose(back.gyro_radps, rec.session.gyro_radps, atol=1e-6 * DEG)
    np.testing.assert_allclose(back.accel_mps2, rec.session.accel_mps2, atol=1e-6)


def test_cli_writes_the_same_file_twice(tmp_path: Path) -> None:
    g = _gen()
    seed = next(s for s in range(300000, 300100)
                if g.draw_plan(g._streams(s, "none")[0]).rate_hz == 50.0)
    outs = []
    for name in ("a.csv", "b.csv"):
        out = tmp_path / name
        subprocess.run([sys.executable, str(_PATH), str(seed), "motor_heating", str(out)], check=True,
                       capture_output=True, text=True)
        outs.append(out.read_bytes())
    assert outs[0] == outs[1]
    assert len(read_session(tmp_path / "a.csv")) == len(g.generate(seed, "motor_heating").session)


def test_unknown_kind_refused() -> None:
    with pytest.raises(ValueError, match="unknown kind"):
        _gen().generate(300000, "heading_bias")


def test_bench_runs_the_second_sealed_generator(monkeypatch: pytest.MonkeyPatch,
                                                capsys: pytest.CaptureFixture[str]) -> None:
    """``bench_diagnose_outside.py --generator sealed2`` draws its recordings from gen_sealed2 (seed mapping,
    places); the diagnosis is replaced by an empty report here: the kinds are not diagnosed before the final
    check."""
    run_outside_bench_undiagnosed(monkeypatch, ["--generator", "sealed2", "--base", "300082", "--per", "1",
                                                "--kinds", "none,clock_jitter"])
    out = capsys.readouterr().out
    g = _gen()
    assert "benchmarks/gen_sealed2.py" in out
    assert f"clock_jitter     seed {300082 + g.KINDS.index('clock_jitter')}:" in out
    assert "axis all" in out
    assert "gyro in move" in out
