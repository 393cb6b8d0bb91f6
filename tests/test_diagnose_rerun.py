"""station.diagnose.rerun: the simulator re-run with the fitted effects matches the recording better.

End to end through :func:`station.diagnose.diagnose` on a recording with a clearly visible
lever arm and on a clean one; with the simulator's own truth as the "fitted" parameters, every
effect mapping (SI theta -> EffectTruth, time offset, temperature course, Earth rate) must bring
the re-run down to the noise; and the simulator extensions the re-run needs keep old outputs.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from station.diagnose import diagnose
from station.diagnose.rerun import Drive, FittedEffect, rerun, run_model
from station.diagnose.residuals import SensorData, fit_baseline
from station.diagnose.results import load_report
from station.kernel.plan import RigPlan
from station.kernel.sensor_class import TABLE1
from station.physics.effects import Effects
from station.physics.imu import Environment, ImuModel
from station.physics.trajectory import build_trajectory
from station.physics.unit import draw_unit
from station.sim.session_sim import simulate_session

#: The short plan of tests/test_diagnose.py (~8 min at 100 Hz), two rate magnitudes per axis.
PLAN = RigPlan(
    rest_s=120.0,
    pose_hold_s=15.0,
    rate_steps=tuple((a, s * r) for a in "xyz" for r in (50.0, 200.0) for s in (1.0, -1.0)),
    rate_hold_s=6.0,
)


def _chi2(run_residual: np.ndarray, sd: SensorData) -> np.ndarray:
    return np.mean(run_residual**2 * sd.count[:, None] / sd.sigma**2, axis=0)


def test_lever_arm_rerun_matches_the_recording_better() -> None:
    res = simulate_session(5, plan=PLAN, effects=Effects(lever_arm=30.0, temperature_scale=300.0))
    d = diagnose(res.session)
    report = d.to_json()
    # the one JSON form, and read back into the types unchanged (findings with re-run, calibration, bootstrap)
    text = json.dumps(report)
    assert json.dumps(load_report(json.loads(text)).to_json()) == text
    lever_arm = next(f for f in d.report.findings if f.effect == "lever_arm")
    assert lever_arm.rerun is not None and lever_arm.calibration is not None and lever_arm.fit is not None
    assert d.report.of_sensor("accel").findings[0].sensor == "accel"
    rr = report["rerun"]
    assert set(rr) >= {"method", "effects", "not_simulated", "base", "extended", "improvement"}
    assert {"effect": "lever_arm", "sensor": "accel"} in rr["effects"]
    base, ext = rr["base"]["accel"], rr["extended"]["accel"]
    assert base["unit"] == "m/s^2" and set(base["per_kind"]) == {"rest", "pose", "rate", "move"}
    # the lever arm (w x (w x r) + alpha x r) is huge in the rate steps and moves: the base model misses it
    # on every axis, the extended simulation is down to the noise of the block means
    assert min(base["chi2"]) > 20.0
    assert max(ext["chi2"]) < 2.0
    assert max(ext["per_kind"]["rate"]["chi2"]) < 3.0
    np.testing.assert_array_less(ext["rms"], 1.3 * np.array(ext["noise_rms"]))
    assert min(rr["improvement"]["accel"]["rms_ratio"]) > 5.0
    lever = next(f for f in report["findings"] if f["effect"] == "lever_arm")
    part = lever["rerun"]
    assert part["unit"] == "m/s^2"
    np.testing.assert_array_less(np.array(part["rms_with_this_effect"]) * 5.0, part["rms_base"])
    # every simulated finding helps its own sensor on its own axes
    for f in report["findings"]:
        if "rerun" in f:
            ax = ["xyz".index(a) for a in f["axes"]]
            assert np.all(np.array(f["rerun"]["rms_extended"])[ax] < np.array(f["rerun"]["rms_base"])[ax])
    # the figure data: recording minus base / extended simulation per block
    assert d.rerun is not None
    assert d.rerun.base.block_residual["accel"].shape == d.baseline.accel.y.shape


def test_clean_recording_rerun_is_at_the_noise() -> None:
    res = simulate_session(3, plan=PLAN)
    d = diagnose(res.session)
    assert d.to_json()["findings"] == []
    rr = d.to_json()["rerun"]
    assert rr["effects"] == [] and rr["not_simulated"] == []
    assert rr["extended"] == rr["base"]
    for sensor in ("accel", "gyro"):
        stats = rr["base"][sensor]
        # white noise alone gives chi^2 = 1 (std ~ sqrt(2 / blocks) = 0.08 here)
        assert all(0.6 < c < 1.6 for c in stats["chi2"]), stats["chi2"]
        np.testing.assert_allclose(stats["rms"], stats["noise_rms"], rtol=0.3)
        assert rr["improvement"][sensor]["rms_ratio"] == [1.0, 1.0, 1.0]


#: Every mean effect at a visible magnitude, for the mapping test.
ALL_MEAN = Effects(lever_arm=30.0, g_sensitivity=0.05, temperature_scale=300.0, temperature_bias=0.001,
                   scale_nonlinearity=0.002, scale_asymmetry=0.002, earth_rotation=2.0, time_offset=3.0)


@pytest.fixture(scope="module")
def all_effects() -> tuple:
    res = simulate_session(11, plan=PLAN, effects=ALL_MEAN)
    et = res.effect_truth
    effects = []
    for s in ("accel", "gyro"):
        effects += [
            FittedEffect("temperature_bias", s, getattr(et, f"{s}_temp_bias")),
            FittedEffect("temperature_scale", s, getattr(et, f"{s}_temp_scale")),
            FittedEffect("scale_nonlinearity", s, getattr(et, f"{s}_nonlinearity")),
            FittedEffect("scale_asymmetry", s, getattr(et, f"{s}_asymmetry")),
            FittedEffect("time_offset", s, np.array([et.time_offset_s])),
        ]
    effects += [
        FittedEffect("lever_arm", "accel", et.lever_arm_m),
        FittedEffect("g_sensitivity", "gyro", et.g_sensitivity.ravel()),
        FittedEffect("earth_rotation", "gyro", np.array([ALL_MEAN.earth_rotation])),
    ]
    return fit_baseline(res.session), effects


def test_true_effects_bring_the_rerun_to_the_noise(all_effects: tuple) -> None:
    baseline, effects = all_effects
    rr = rerun(baseline, [*effects, FittedEffect("outliers", "accel", np.zeros(0))])
    summary = rr.summary().to_json()
    json.dumps(summary, allow_nan=False)
    assert summary["not_simulated"][0]["effect"] == "outliers"
    for sensor in ("accel", "gyro"):
        assert min(summary["base"][sensor]["chi2"]) > 50.0
        assert max(summary["extended"][sensor]["chi2"]) < 1.6, summary["extended"][sensor]["chi2"]
    # the simulator's noise-free output is deterministic
    again = rerun(baseline, effects)
    for sensor in ("accel", "gyro"):
        np.testing.assert_array_equal(again.extended.output[sensor], rr.extended.output[sensor])


def test_chunked_render_is_bit_identical(all_effects: tuple, monkeypatch: pytest.MonkeyPatch) -> None:
    """The re-run renders in chunks cut between blocks: small chunks give the very numbers of one render."""
    import station.diagnose.rerun as rerun_module

    baseline, effects = all_effects
    tilt = FittedEffect("pose_tilt", "accel", 1e-3 * np.arange(12) / 12)
    whole = rerun(baseline, [*effects, tilt])
    assert Drive(baseline).cuts() == [0, len(baseline.session)]
    monkeypatch.setattr(rerun_module, "CHUNK", 3000)
    cuts = Drive(baseline).cuts()
    assert len(cuts) > 5
    for sd in (baseline.accel, baseline.gyro):  # no block of either sensor crosses a cut
        lab = sd.label
        for c in cuts[1:-1]:
            before, after = lab[:c][lab[:c] >= 0], lab[c:][lab[c:] >= 0]
            assert len(before) == 0 or len(after) == 0 or before[-1] != after[0]
    chunked = rerun(baseline, [*effects, tilt])
    for a, b in zip((whole.base, whole.extended, *whole.alone), (chunked.base, chunked.extended, *chunked.alone),
                    strict=True):
        for sensor in a.block_residual:
            np.testing.assert_array_equal(a.block_residual[sensor], b.block_residual[sensor])
    assert whole.summary().to_json() == chunked.summary().to_json()


@pytest.mark.parametrize(("effect", "sensor"), [
    ("lever_arm", "accel"), ("time_offset", "accel"), ("scale_asymmetry", "accel"), ("g_sensitivity", "gyro"),
    ("time_offset", "gyro"), ("scale_asymmetry", "gyro"), ("scale_nonlinearity", "gyro"), ("earth_rotation", "gyro"),
])
def test_leaving_out_one_true_effect_shows(all_effects: tuple, effect: str, sensor: str) -> None:
    baseline, effects = all_effects
    drive = Drive(baseline)
    rest = [e for e in effects if not (e.effect == effect and e.sensor == sensor)]
    assert len(rest) == len(effects) - 1
    sd = baseline.sensor(sensor)
    full = _chi2(run_model(drive, "all", effects).block_residual[sensor], sd)
    without = _chi2(run_model(drive, "without", rest).block_residual[sensor], sd)
    assert without.max() > 1.5 * full.max() + 0.5, (without, full)


def test_base_rerun_is_the_base_fit_mean_model() -> None:
    """Driven by the recording's references, the simulated base model is the fit's eq. (1) + eq. (3) mean."""
    baseline = fit_baseline(simulate_session(4, plan=PLAN, effects=Effects(g_sensitivity=0.05)).session)
    run = run_model(Drive(baseline), "base", [], refit=False)
    for sensor in ("accel", "gyro"):
        np.testing.assert_allclose(run.block_residual[sensor], baseline.sensor(sensor).y, rtol=0, atol=1e-12)


# --- the simulator extensions the re-run uses -------------------------------------------------
def _short() -> tuple:
    plan = RigPlan(rest_s=5.0, poses=("+x",), pose_hold_s=2.0, rate_steps=(("z", 100.0),), rate_hold_s=2.0)
    traj = build_trajectory(plan)
    t = traj.sample_times()
    return plan, traj.kinematics(t)


def test_explicit_effect_truth_and_specific_force_keep_the_bytes() -> None:
    plan, kin = _short()
    unit = draw_unit(TABLE1, np.random.default_rng(1))
    effects = Effects(lever_arm=20.0, temperature_scale=200.0, g_sensitivity=0.1)
    a = ImuModel(unit, effects=effects, seed=3).render(kin, plan.gravity_mps2)
    et = effects.realize(unit.shapes)
    b = ImuModel(unit, effect_truth=et, seed=3).render(kin, plan.gravity_mps2,
                                                       specific_force_mps2=kin.specific_force(plan.gravity_mps2))
    for name in ("accel_mps2", "gyro_radps", "temp_degc"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))


def test_temperature_course_drives_the_temperature_effects() -> None:
    plan, kin = _short()
    unit = draw_unit(TABLE1, np.random.default_rng(2)).noiseless()
    et = Effects(temperature_bias=0.01).realize(unit.shapes)
    env = Environment(ambient_degc=20.0)
    cold = ImuModel(unit, effect_truth=et, environment=env, temperature_degc=lambda t: np.full(len(t), 20.0))
    warm = ImuModel(unit, effect_truth=et, environment=env, temperature_degc=lambda t: 20.0 + 0.01 * t)
    rc, rw = cold.render(kin, plan.gravity_mps2), warm.render(kin, plan.gravity_mps2)
    expected = et.accel_temp_bias * (0.01 * kin.t_s)[:, None]
    np.testing.assert_allclose(rw.accel_mps2 - rc.accel_mps2, expected, atol=unit.accel.lsb)
    assert rw.temp_degc[-1] == pytest.approx(20.0 + 0.01 * kin.t_s[-1], abs=unit.temp_lsb_k)
    assert math.isclose(float(rc.temp_degc[0]), 20.0, abs_tol=unit.temp_lsb_k)
