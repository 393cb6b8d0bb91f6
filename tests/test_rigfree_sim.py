"""Rig-free fit on simulated hand-held multi-position recordings: recovery, importer, still
detector, exports, the RK4 integrator.

Seeds: these tests use 300.. (the development seeds were 100..139, the benchmark's report seeds 5000..).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation
from typer.testing import CliRunner

from station.cli import app
from station.fit.export import export_notes, imu_tk_terms, openaxes_coefficients
from station.fit.multipos import integrate_moves
from station.fit.rigfree_fit import RigFreeOptions, fit_rig_free, is_rig_free
from station.kernel.parameters import ParameterSet
from station.kernel.sensor_class import TABLE1
from station.session.model import Kind
from station.session.multipos_import import import_imu_tk
from station.session.still import detect_still
from station.sim.handheld import counts_with_offsets, simulate_handheld

TEST_SEEDS = range(300, 308)
TC_PRIOR = {"accel": TABLE1.accel_correlation_time_s, "gyro": TABLE1.gyro_correlation_time_s}
RUN = CliRunner()


def _truth_in_convention(m_a: np.ndarray, m_w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The truth in the fit's frame: M_a^-1 = Q' R (R upper-triangular, positive diagonal): M = R^-1, M_w Q'."""
    q, r = np.linalg.qr(np.linalg.inv(m_a))
    d = np.sign(np.diag(r))
    q, r = q * d, d[:, None] * r
    return np.linalg.inv(r), m_w @ q


def _write_imu_tk(folder: Path, seed: int) -> tuple[Path, Path, object, np.ndarray, np.ndarray, float, float]:
    res = simulate_handheld(seed)
    a_cnt, g_cnt, a_off, g_off, a_sens, g_sens = counts_with_offsets(res, np.random.default_rng(seed + 10**6))
    acc, gyr = folder / f"acc_{seed}.txt", folder / f"gyro_{seed}.txt"
    np.savetxt(acc, np.column_stack([res.t_s, a_cnt]), fmt=["%.6f", "%.0f", "%.0f", "%.0f"])
    np.savetxt(gyr, np.column_stack([res.t_s, g_cnt]), fmt=["%.6f", "%.0f", "%.0f", "%.0f"])
    return acc, gyr, res, a_off, g_off, a_sens, g_sens


@pytest.fixture(scope="module")
def study(tmp_path_factory: pytest.TempPathFactory) -> dict[str, np.ndarray]:
    folder = tmp_path_factory.mktemp("imutk")
    z: dict[str, list[np.ndarray]] = {}
    for seed in TEST_SEEDS:
        acc, gyr, res, a_off, g_off, a_sens, g_sens = _write_imu_tk(folder, seed)
        session = import_imu_tk(acc, gyr, accel_lsb_per_mps2=a_sens, gyro_lsb_per_radps=g_sens, gravity_mps2=9.8128)
        p = fit_rig_free(session, RigFreeOptions(cv_folds=0, tc_range_s=TC_PRIOR))
        m_a, m_w = _truth_in_convention(res.truth.accel.misalignment, res.truth.gyro.misalignment)
        up = np.triu_indices(3)
        z.setdefault("accel.M", []).append((p.accel.misalignment - m_a)[up] / p.accel.misalignment_std[up])
        z.setdefault("accel.b_stat", []).append(
            (p.accel.bias_static - res.truth.accel.bias_static - a_off / a_sens) / p.accel.bias_static_std)
        z.setdefault("gyro.M", []).append(((p.gyro.misalignment - m_w) / p.gyro.misalignment_std).ravel())
        z.setdefault("gyro.b_stat", []).append(
            (p.gyro.bias_static - res.truth.gyro.bias_static - g_off / g_sens) / p.gyro.bias_static_std)
        # below the diagonal the convention is exact
        assert np.all(p.accel.misalignment[np.tril_indices(3, -1)] == 0.0)
    return {k: np.concatenate(v) for k, v in z.items()}


@pytest.mark.parametrize("name", ["accel.M", "accel.b_stat", "gyro.M", "gyro.b_stat"])
def test_recovery_within_three_sigma(study: dict[str, np.ndarray], name: str) -> None:
    z = study[name]
    within = float(np.mean(np.abs(z) <= 3.0))
    assert within >= 0.95, f"{name}: {within:.1%} within 3 sigma (z std {np.std(z):.2f})"
    # honest uncertainties: the robust spread of z (1.4826 MAD; the tails are the 3-sigma share's business)
    spread = 1.4826 * float(np.median(np.abs(z - np.median(z))))
    assert 1 / 1.5 < spread < 1.5, f"{name}: uncertainties not honest, robust spread of z {spread:.2f}"


def test_still_detector_finds_every_true_still_interval() -> None:
    res = simulate_handheld(310)
    iv = detect_still(res.accel_mps2, res.plan.sample_rate_hz, gyro_radps=res.gyro_radps)
    assert iv.rest and len(iv) == len(res.still)
    fs = res.plan.sample_rate_hz
    for (a, b), s0, s1 in zip(res.still, iv.starts, iv.stops, strict=True):
        # found inside the true interval, trimmed by at most the window (1 s) at each end
        assert a <= s0 <= a + fs and b - fs <= s1 <= b


def test_still_detector_keeps_a_pose_as_long_as_the_minimum() -> None:
    # 100 Hz: 20 s initial still, then moves of 2 s (a steady turn about a horizontal axis) around poses of
    # 1.4, 1.7, 2.0, 2.4 and 3 s. The centred 1 s window sees a pose as still only 0.5 s after it starts and
    # 0.5 s before it ends; the 1.5 s minimum is the quiet interval's, so 1.7 s and longer are found, 1.4 s not.
    fs, rng = 100.0, np.random.default_rng(320)
    lengths_s = (1.4, 1.7, 2.0, 2.4, 3.0)
    parts: list[tuple[np.ndarray, np.ndarray]] = []
    truth: list[tuple[int, int]] = []
    angle = 0.0
    rate = np.radians(45.0)  # rad/s about x

    def still(n: int, angle: float) -> None:
        g = 9.81 * np.array([0.0, np.sin(angle), np.cos(angle)])
        parts.append((np.tile(g, (n, 1)), np.zeros((n, 3))))

    def move(angle: float) -> float:
        a = angle + rate * np.arange(200) / fs
        acc = 9.81 * np.column_stack([np.zeros(200), np.sin(a), np.cos(a)])
        parts.append((acc, np.tile([rate, 0.0, 0.0], (200, 1))))
        return angle + rate * 2.0

    still(2000, angle)
    cursor = 2000
    for length in lengths_s:
        angle = move(angle)
        n = round(length * fs)
        still(n, angle)
        truth.append((cursor + 200, cursor + 200 + n))
        cursor += 200 + n
    move(angle)
    acc = np.concatenate([p[0] for p in parts]) + rng.normal(0, 0.01, (sum(len(p[0]) for p in parts), 3))
    gyro = np.concatenate([p[1] for p in parts]) + rng.normal(0, 0.002, acc.shape)
    iv = detect_still(acc, fs, gyro_radps=gyro)
    assert iv.rest
    found = list(zip(iv.starts[1:].tolist(), iv.stops[1:].tolist(), strict=True))
    expected = [(a, b) for (a, b), length in zip(truth, lengths_s, strict=True) if length >= 1.5]
    assert len(found) == len(expected), (found, truth)
    for (s0, s1), (a, b) in zip(found, expected, strict=True):
        assert a <= s0 <= a + fs and b - fs <= s1 <= b  # inside the true pose, trimmed by at most the window


def test_import_fit_export_on_the_command_line(tmp_path: Path) -> None:
    acc, gyr, res, a_off, _, a_sens, g_sens = _write_imu_tk(tmp_path, 311)
    out = tmp_path / "s.csv"
    r = RUN.invoke(app, ["import", "imu-tk", str(acc), str(gyr), "-o", str(out), "--accel-lsb-per-mps2", str(a_sens),
                         "--gyro-lsb-per-radps", str(g_sens), "--gravity", "9.8128"])
    assert r.exit_code == 0, r.output
    from station.session import read_session

    session = read_session(out)
    assert is_rig_free(session) and session.gravity_mps2 == 9.8128
    r = RUN.invoke(app, ["fit", str(out), "--json"])
    assert r.exit_code == 0, r.output
    params = ParameterSet.from_json(r.stdout)
    q = params.quality.rig_free
    assert q["cross_validation"]["folds"] == 5
    assert q["cross_validation"]["accel_norm_rms_mps2"] < 3 * q["accel_norm_rms_mps2"]
    m_a, _ = _truth_in_convention(res.truth.accel.misalignment, res.truth.gyro.misalignment)
    assert np.all(np.abs(params.accel.misalignment - m_a) <= 4 * params.accel.misalignment_std + 1e-12)
    assert np.allclose(params.accel.bias_static, res.truth.accel.bias_static + a_off / a_sens, atol=0.01)
    pj = tmp_path / "p.json"
    pj.write_text(params.to_json())
    r = RUN.invoke(app, ["export", str(pj), "--format", "openaxes"])
    assert r.exit_code == 0, r.output
    values = np.array([float(v) for v in r.stdout.split()])
    assert values.shape == (24,)
    # the list is (T K) column-major, bias after the matrix, gyro matrix column-major, gyro bias
    # the biases: the set's device values (an axis whose drift the recording cannot determine gets the bias at
    # the end of the recording, and the command says so on stderr)
    device = params.constant_bias_values()[0]
    assert all(f"note: {n}" in r.stderr for n in export_notes(params))
    tk = values[:9].reshape(3, 3, order="F")
    assert np.allclose(tk, np.linalg.inv(params.accel.misalignment), atol=1e-7)
    assert np.allclose(np.linalg.inv(tk) @ values[9:12], device.accel.bias_static, atol=1e-6)
    assert np.allclose(values[12:21].reshape(3, 3, order="F"), np.linalg.inv(params.gyro.misalignment), atol=1e-7)
    assert np.allclose(values[21:24], device.gyro.bias_static, atol=1e-9)
    r = RUN.invoke(app, ["export", str(pj), "--format", "imu-tk-json"])
    assert r.exit_code == 0 and '"format": "station-imutk/1"' in r.stdout


def test_export_terms_follow_the_stated_convention() -> None:
    res = simulate_handheld(312)
    m = res.truth.as_parameter_set(0.01)
    t = imu_tk_terms(m)
    assert np.allclose(t["accel"]["TK"], np.linalg.inv(m.accel.misalignment))
    assert np.allclose(t["accel"]["T"] @ np.diag(t["accel"]["K"]), t["accel"]["TK"])
    assert np.allclose(np.diag(t["accel"]["T"]), 1.0)
    # calibrated = TK raw - b_after reproduces the specific force from raw = M f + b
    f = np.array([1.0, -2.0, 9.0])
    raw = m.accel.misalignment @ f + m.accel.bias_static
    assert np.allclose(t["accel"]["TK"] @ raw - t["accel"]["bias_after_matrix"], f)
    w = np.array([0.3, -0.1, 2.0])
    raw_w = m.gyro.misalignment @ w + m.gyro.bias_static
    assert np.allclose(t["gyro"]["TK"] @ (raw_w - t["gyro"]["bias_before_matrix"]), w)
    values, stds = openaxes_coefficients([m, m])
    assert values.shape == stds.shape == (36,)


def test_rk4_turns_a_constant_rate_exactly_and_a_coning_motion_closely() -> None:
    dt = 0.01
    w = np.array([0.4, -1.1, 2.3])
    rot = integrate_moves(np.tile(w, (201, 1, 1)).reshape(201, 1, 3), dt)[0]
    assert np.allclose(rot, Rotation.from_rotvec(w * 2.0).as_matrix(), atol=1e-12)
    # a wobble whose axis turns: compare with a fine integration of the same sampled rate
    t = np.arange(0, 2.0 + dt / 2, dt)
    rate = np.column_stack([np.cos(3 * t), np.sin(3 * t), 0.5 + 0 * t]) * 2.0
    coarse = integrate_moves(rate[:, None, :], dt)[0]
    tf = np.arange(0, 2.0 + dt / 20, dt / 10)
    fine_rate = np.column_stack([np.cos(3 * tf), np.sin(3 * tf), 0.5 + 0 * tf]) * 2.0
    fine = integrate_moves(fine_rate[:, None, :], dt / 10)[0]
    angle = np.degrees(Rotation.from_matrix(coarse.T @ fine).magnitude())
    assert angle < 0.01


def test_not_rig_free_when_poses_have_references() -> None:
    from station.sim.session_sim import simulate_session

    session = simulate_session(1).session
    assert not is_rig_free(session)
    assert session.segments_of(Kind.POSE)


def test_normal_gravity_from_latitude() -> None:
    from station.session.multipos_import import normal_gravity_mps2

    # WGS 84: 9.7803253359 at the equator, 9.8321849378 at the poles; free air -3.086e-6 per m
    assert normal_gravity_mps2(0.0) == pytest.approx(9.7803253359, abs=1e-9)
    assert normal_gravity_mps2(-90.0) == pytest.approx(9.8321849378, abs=1e-9)
    assert normal_gravity_mps2(45.0, 1000.0) == pytest.approx(9.8061977694 - 3.086e-3, abs=1e-8)
