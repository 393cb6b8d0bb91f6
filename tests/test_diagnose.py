"""station.diagnose: named physics at clearly visible magnitudes, nothing on base-model recordings."""

from __future__ import annotations

import json
import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from station.diagnose import FORMAT, NAMES, diagnose
from station.diagnose.candidates import attitude
from station.diagnose.effect_registry import LIBRARY
from station.diagnose.residuals import fit_baseline
from station.kernel.plan import RigPlan
from station.kernel.sensor_class import TABLE1
from station.physics.effects import Effects
from station.sim.session_sim import simulate_session

#: A short plan (~8 min at 100 Hz) with two rate magnitudes, so every candidate is identifiable.
PLAN = RigPlan(
    rest_s=120.0,
    pose_hold_s=15.0,
    rate_steps=tuple((a, s * r) for a in "xyz" for r in (50.0, 200.0) for s in (1.0, -1.0)),
    rate_hold_s=6.0,
)


def _run(effects: str, seed: int) -> dict:
    res = simulate_session(seed, plan=PLAN, effects=Effects.parse(effects))
    return diagnose(res.session).to_json()


def _named(report: dict) -> set[tuple[str, str]]:
    return {(f["effect"], f["sensor"]) for f in report["findings"]}


def test_library_has_the_required_names() -> None:
    assert NAMES[:10] == (
        "temperature_bias", "temperature_scale", "g_sensitivity", "scale_nonlinearity", "scale_asymmetry",
        "lever_arm", "earth_rotation", "time_offset", "bias_random_walk", "outliers",
    )
    assert NAMES[10:] == ("pose_tilt", "scale_nonlinearity_even", "scale_nonlinearity_odd")
    assert set(LIBRARY) <= set(NAMES)


def test_no_findings_on_base_model_recording() -> None:
    report = _run("", 3)
    assert report["format"] == FORMAT
    assert report["findings"] == []
    json.dumps(report)  # JSON-ready


def test_lever_arm_in_mm_with_temperature_scale() -> None:
    res = simulate_session(5, plan=PLAN, effects=Effects(lever_arm=30.0, temperature_scale=300.0))
    report = diagnose(res.session).to_json()
    assert "temperature_scale" in {f["effect"] for f in report["findings"]}
    finding = next(f for f in report["findings"] if f["effect"] == "lever_arm")
    assert finding["sensor"] == "accel"
    value = np.array(finding["parameters"]["value"])
    std = np.array(finding["parameters"]["std"])
    truth_mm = res.effect_truth.lever_arm_m * 1e3
    assert np.all(np.abs(value - truth_mm) < 5 * std + 1.0)
    assert finding["fit"]["after"]["bic"] < finding["fit"]["before"]["bic"]


def test_g_sensitivity_and_time_offset_in_engineering_units() -> None:
    res = simulate_session(7, plan=PLAN, effects=Effects(g_sensitivity=0.05, time_offset=3.0))
    report = diagnose(res.session).to_json()
    finding = next(f for f in report["findings"] if f["effect"] == "g_sensitivity")
    assert finding["sensor"] == "gyro"
    truth = res.effect_truth.g_sensitivity * 9.80665 * 180.0 / math.pi
    value = np.array(finding["parameters"]["value"])
    std = np.array(finding["parameters"]["std"])
    assert np.all(np.abs(value - truth) < 5 * std + 0.005)
    offsets = [f for f in report["findings"] if f["effect"] == "time_offset"]
    assert offsets
    for f in offsets:
        assert abs(f["parameters"]["value"][0] - 3.0) < 0.3


@pytest.mark.parametrize(("effects", "names"), [
    ("scale_asymmetry=0.003,earth_rotation=2", {"scale_asymmetry", "earth_rotation"}),
    ("outliers=0.002,bias_random_walk=0.002", {"outliers", "bias_random_walk"}),
])
def test_effects_named(effects: str, names: set[str]) -> None:
    report = _run(effects, 8)
    assert names <= {f["effect"] for f in report["findings"]}
    json.dumps(report)
    for f in report["findings"]:
        assert f["sensor"] in ("accel", "gyro")
        assert set(f) >= {"effect", "sensor", "axes", "parameters", "evidence", "fit"}


def test_attitude_reproduces_the_rig() -> None:
    res = simulate_session(9, plan=PLAN)
    rot = attitude(fit_baseline(res.session))
    assert rot is not None
    truth = res.trajectory.kinematics(res.session.t_s).rotation
    # the integrated rate reference keeps the attitude to a small fraction of a degree
    err = np.einsum("nij,nik->njk", rot, truth)
    angle = np.degrees(np.arccos(np.clip((np.trace(err, axis1=1, axis2=2) - 1.0) / 2.0, -1.0, 1.0)))
    assert angle.max() < 1.0


def test_eigen_likelihood_matches_cholesky() -> None:
    """The q profile's diagonalized likelihood equals the direct Cholesky one (same constant)."""
    from station.diagnose.likelihood import SensorProblem

    res = simulate_session(11, plan=PLAN)
    baseline = fit_baseline(res.session)
    prob = SensorProblem(baseline, baseline.gyro)
    for k in range(3):
        q0 = float(np.median(prob.white[:, k]))
        q, nll = prob._profile_q(k, 0.0, None)
        assert nll == pytest.approx(prob._axis_nll(k, q, 0.0, None), abs=1e-6)
        # the profile is a minimum over q
        for f in (0.0, 0.3, 3.0):
            assert nll <= prob._axis_nll(k, q * f if q > 0 else q0 * f, 0.0, None) + 1e-6


def test_random_walk_below_the_noise_is_found() -> None:
    """A bias random walk of 1e-4 m/s^2/sqrt(s) (gyro 5e-4 deg/s/sqrt(s)): ~3 mm/s^2 and 0.013 deg/s over
    the record, below one sample's noise; found on the gyro with its density, and nothing else named."""
    res = simulate_session(12, plan=PLAN, effects=Effects(bias_random_walk=1e-4))
    report = diagnose(res.session).to_json()
    walks = [f for f in report["findings"] if f["effect"] == "bias_random_walk"]
    assert {f["sensor"] for f in walks} >= {"gyro"}
    assert {f["effect"] for f in report["findings"]} == {"bias_random_walk"}
    gyro = next(f for f in walks if f["sensor"] == "gyro")
    density = gyro["parameters"]["density"]["value"]  # deg/s/sqrt(s)
    assert 0.3 * 5e-4 < density < 3.0 * 5e-4


def test_temperature_course_shaped_like_the_warmup_is_called_inseparable() -> None:
    """Self-heating is an exponential like eq. 3's warm-up: without a temperature bias, nothing is found,
    and the report says that this recording cannot tell the two apart, and which rig step would."""
    report = _run("", 13)
    assert report["findings"] == []
    pairs = [e for e in report["inseparable"] if "temperature_bias" in e["effects"]]
    assert pairs
    for e in pairs:
        assert e["evidence"]["r2_temperature_vs_warmup"] > 0.98
        assert e["rig_step"]


def test_temperature_bias_found_with_the_rig_step_the_report_names() -> None:
    """The separating step the report names (a climate-chamber cycle, +-2 K with a 5 min period) makes a temperature
    bias (2 mm/s^2/K, gyro 0.01 deg/s/K) that the plain recording cannot tell from the warm-up nameable on the
    gyro, with its coefficient; the same step without the effect names nothing. (The concealed magnitude
    with this step: benchmarks/bench_diagnose.py --chamber.)"""
    chamber = replace(TABLE1, ambient_cycle_k=2.0, ambient_cycle_period_s=300.0)
    res = simulate_session(14, plan=PLAN, sensor_class=chamber, effects=Effects(temperature_bias=2e-3))
    report = diagnose(res.session).to_json()
    found = [f for f in report["findings"] if f["effect"] == "temperature_bias" and f["sensor"] == "gyro"]
    assert found, report["findings"]
    value = np.array(found[0]["parameters"]["value"])  # deg/s/K
    std = np.array(found[0]["parameters"]["std"])
    truth = np.degrees(res.effect_truth.gyro_temp_bias)
    assert np.all(np.abs(value - truth) < 4 * std + 2e-4)
    clean = simulate_session(14, plan=PLAN, sensor_class=chamber)
    assert diagnose(clean.session).to_json()["findings"] == []


def test_temperature_bias_found_with_the_sensor_class_tc_range() -> None:
    """A temperature bias (gyro ~0.01 deg/s/K) over the self-heating (time constant 200-600 s) is absorbed by the
    warm-up when the recording alone decides T_c: nothing is named, temperature and warm-up are listed as
    inseparable. With the sensor class's T_c range from the limits file (gyro 1030-3760 s) the diagnosis names
    it on the gyro with its coefficient; a clean recording with the same range names nothing."""
    from station.kernel.limits_file import load_limits

    tc_range = load_limits().correlation_time_s
    res = simulate_session(14, plan=PLAN, effects=Effects(temperature_bias=2e-3))
    alone = diagnose(res.session).to_json()
    assert alone["findings"] == [] and alone["warmup_tc_range_s"] is None
    assert any("temperature_bias" in e["effects"] for e in alone["inseparable"])
    report = diagnose(res.session, warmup_tc_s=tc_range).to_json()
    assert report["warmup_tc_range_s"] == {"accel": [50.0, 167.0], "gyro": [1030.0, 3760.0]}
    assert _named(report) == {("temperature_bias", "gyro")}
    par = report["findings"][0]["parameters"]
    value, std = np.array(par["value"]), np.array(par["std"])  # deg/s/K
    truth = np.degrees(res.effect_truth.gyro_temp_bias)
    assert np.all(np.abs(value - truth) < 3 * std)
    # the fit's own standard error is the recording's information; the stated one is the larger of it and the
    # bootstrap's spread over segments (here ~3.8x: the value depends on which segments are in), still a value
    fit_std = np.array(par.get("std_fit", par["std"]))
    assert np.all(fit_std < 0.1 * np.abs(truth))
    assert np.all(std >= fit_std) and np.all(std < 0.25 * np.abs(truth))
    clean = simulate_session(14, plan=PLAN)
    assert diagnose(clean.session, warmup_tc_s=tc_range).to_json()["findings"] == []


def test_temperature_scale_at_the_concealed_magnitude_with_its_coefficient() -> None:
    """100 ppm/K per axis (shape 0.5-1, random signs; the study's concealed magnitude, RMS over the recording
    below one sample's noise) is named on the gyro, and nothing else; each axis's coefficient in ppm/K lies within
    3 of its standard errors of the truth and is resolved to better than 25 %."""
    from station.kernel.limits_file import load_limits

    res = simulate_session(17, plan=PLAN, effects=Effects(temperature_scale=100.0))
    report = diagnose(res.session, warmup_tc_s=load_limits().correlation_time_s).to_json()
    assert _named(report) == {("temperature_scale", "gyro")}
    par = report["findings"][0]["parameters"]
    value, std = np.array(par["value"]), np.array(par["std"])  # ppm/K
    truth = res.effect_truth.gyro_temp_scale * 1e6
    assert np.all(np.abs(value - truth) < 3 * std)
    assert np.all(std < 0.25 * np.abs(truth))


def test_cli_diagnose_takes_the_tc_range_from_a_limits_file(tmp_path: Path) -> None:
    """``station diagnose --limits FILE``: the file's correlation_time_s ranges reach the diagnosis (the
    temperature bias of the test above is named); a malformed limits file is refused with exit code 2."""
    from typer.testing import CliRunner

    from station.cli import app
    from station.kernel.limits_file import DEFAULT_LIMITS_PATH
    from station.session import write_session

    path = tmp_path / "unit.csv"
    write_session(simulate_session(14, plan=PLAN, effects=Effects(temperature_bias=2e-3)).session, path)
    runner = CliRunner()
    r = runner.invoke(app, ["diagnose", str(path), "--json", "--limits", str(DEFAULT_LIMITS_PATH)])
    assert r.exit_code == 0, r.output
    doc = json.loads(r.stdout)
    assert doc["format"] == FORMAT
    assert {(f["effect"], f["sensor"]) for f in doc["findings"]} == {("temperature_bias", "gyro")}
    assert doc["warmup_tc_range_s"]["gyro"] == [1030.0, 3760.0]
    bad = tmp_path / "bad.toml"
    bad.write_text(DEFAULT_LIMITS_PATH.read_text().replace("correlation_time_s = [1030.0, 3760.0]",
                                                           "correlation_time_s = [3760.0, 1030.0]"))
    r = runner.invoke(app, ["diagnose", str(path), "--limits", str(bad)])
    assert r.exit_code == 2
    assert "correlation_time_s" in r.output


def test_temperature_bias_is_not_taken_for_a_random_walk() -> None:
    """A temperature bias of 2 mm/s^2/K (gyro ~0.01 deg/s/K) on a random plan (seeds of the concealed-data study,
    benchmarks/bench_diagnose.py --chamber). From the recording alone the warm-up absorbs most of it (T_c pulled to
    the self-heating's time constant); what eq. 3's slower drift then leaves is not a random walk: the walk's null
    re-fits T_c with the temperature term. With a climate-chamber cycle the bias is named on both sensors, and
    what the accel's warm-up amplitude cannot exclude bounds its drift noise: again no random walk."""
    from station.kernel.plan import random_plan

    def plan(seed: int) -> RigPlan:
        return random_plan(np.random.default_rng(10_000 + seed))

    alone = simulate_session(107, plan=plan(107), effects=Effects(temperature_bias=2e-3))
    report = diagnose(alone.session).to_json()
    assert {f["effect"] for f in report["findings"]} <= {"temperature_bias"}  # no random walk
    for f in report["findings"]:  # where named at all (the gyro's z here, marginally), with the true coefficient
        truth = np.degrees(alone.effect_truth.gyro_temp_bias) if f["sensor"] == "gyro" else (
            alone.effect_truth.accel_temp_bias / 9.80665e-3)  # deg/s/K, mg/K
        value, std = np.array(f["parameters"]["value"]), np.array(f["parameters"]["std"])
        assert np.all(np.abs(value - truth) < 3 * std)
    assert any("temperature_bias" in e["effects"] for e in report["inseparable"])
    chamber = replace(TABLE1, ambient_cycle_k=2.0, ambient_cycle_period_s=300.0)
    cycled = simulate_session(105, plan=plan(105), sensor_class=chamber, effects=Effects(temperature_bias=2e-3))
    assert _named(diagnose(cycled.session).to_json()) == {("temperature_bias", "accel"), ("temperature_bias", "gyro")}


def test_warmup_tc_range_is_checked() -> None:
    res = simulate_session(14, plan=PLAN)
    with pytest.raises(ValueError, match="0 < low <= high"):
        fit_baseline(res.session, warmup_tc_s={"gyro": (3000.0, 1000.0)})
    with pytest.raises(ValueError, match="unknown sensor"):
        fit_baseline(res.session, warmup_tc_s={"mag": (1.0, 2.0)})


def test_nonlinearity_that_distorts_the_base_warmup_names_no_temperature_bias() -> None:
    """A gyro scale nonlinearity (1e-3 at 200 deg/s) pulls the base fit's warm-up to T_c ~ 44 s on y (truth ~1700 s).
    The diagnosis re-fits the drift with the whole b_drift, not as a correction on top of the base fit's: the
    nonlinearity is found with its coefficient and the leftover warm-up is not taken for a temperature bias."""
    res = simulate_session(23, plan=PLAN, effects=Effects(scale_nonlinearity=1e-3))
    report = diagnose(res.session).to_json()
    assert _named(report) == {("scale_nonlinearity", "gyro")}
    finding = report["findings"][0]
    value = np.array(finding["parameters"]["value"])  # relative scale error at 200 deg/s
    std = np.array(finding["parameters"]["std"])
    truth = res.effect_truth.gyro_nonlinearity * math.radians(200.0)
    assert np.all(np.abs(value - truth) < 4 * std)


def test_block_data_do_not_depend_on_the_base_fit_warmup() -> None:
    """The diagnosis's block data are the recording minus the base fit's M ref + b_stat only: changing the base
    fit's b_drift and T_c (eq. 3) leaves them unchanged."""
    from station.diagnose.likelihood import SensorProblem
    from station.diagnose.residuals import _sensor_data

    res = simulate_session(11, plan=PLAN)
    baseline = fit_baseline(res.session)
    p = baseline.gyro.params
    other = replace(p, bias_drift=np.array([3e-3, -2e-3, 1e-3]), correlation_time_s=np.array([40.0, 900.0, np.nan]))
    sd = _sensor_data(res.session, "gyro", other, res.session.gyro_radps, baseline.gyro.ref, 150)
    assert not np.allclose(sd.y, baseline.gyro.y)  # the base fit's residual does change
    a = SensorProblem(baseline, baseline.gyro).y
    b = SensorProblem(replace(baseline, gyro=sd), sd).y
    assert np.allclose(a, b, rtol=0.0, atol=1e-12)


def test_drift_refit_reaches_its_optimum() -> None:
    """The drift's T_c re-fit runs to convergence: another re-fit moves nothing. (A nested test re-fits the null
    and then the alternative from the null's T_c; a null left short of its optimum hands the alternative's extra
    improvement to the candidate.)"""
    from station.diagnose.likelihood import SensorProblem

    baseline = fit_baseline(simulate_session(5, plan=PLAN).session)
    for sd in (baseline.accel, baseline.gyro):
        prob = SensorProblem(baseline, sd)
        nll, tc = prob.total_nll(), prob.tc.copy()
        prob.refit_drift()
        assert prob.total_nll() == pytest.approx(nll, abs=1e-9)
        assert np.array_equal(prob.tc, tc)


def test_detectable_from_is_the_size_at_the_quoted_power() -> None:
    """A rejected candidate's ``detectable_from``: per parameter the size whose noncentrality (with the marginal
    std) gives the test the quoted power; on the recording itself, an effect at twice that size on every axis is
    found, one at a fifth of the smallest is not."""
    from scipy import stats

    from station.diagnose.likelihood import Test
    from station.diagnose.reporting import DETECT_POWER, detectable_from

    cov = np.diag([1e-10, 4e-10, 9e-10])
    t = Test(effect="temperature_scale", sensor="gyro", gain=3.0, params=3, bic_gain=3.0 - 3 * math.log(900.0),
             critical=float(stats.chi2.isf(1e-5, 3)), theta=np.zeros(3), cov=cov)
    d = detectable_from(t)
    assert d is not None and d.unit == "ppm/K" and d.power == DETECT_POWER
    threshold = max(t.critical, 3 * math.log(900.0))
    for k, value in enumerate(d.value):
        lam = (value * 1e-6) ** 2 / cov[k, k]
        assert stats.ncx2.sf(threshold, 3, lam) == pytest.approx(DETECT_POWER, abs=0.005)
    assert detectable_from(replace(t, params=2)) is None  # not every parameter determined

    clean = diagnose(simulate_session(21, plan=PLAN).session).to_json()
    rejected = next(r for r in clean["rejected"] if (r["effect"], r["sensor"]) == ("temperature_scale", "gyro"))
    sizes = np.abs(rejected["detectable_from"]["value"])  # ppm/K
    # the simulator's per-axis coefficients are the magnitude times 0.5-1
    big = simulate_session(21, plan=PLAN, effects=Effects(temperature_scale=2.0 * sizes.max() / 0.5))
    assert ("temperature_scale", "gyro") in _named(diagnose(big.session).to_json())
    small = simulate_session(21, plan=PLAN, effects=Effects(temperature_scale=0.2 * sizes.min()))
    assert "temperature_scale" not in {f["effect"] for f in diagnose(small.session).to_json()["findings"]}


def test_odd_scale_forms_a_plan_cannot_tell_apart_give_one_finding() -> None:
    """A plan with a single rate magnitude (+-100 deg/s, the station study's seed 401): u|u| and u^3 are the same
    signal there (both odd in the rate), so the scale nonlinearity is found and named by the better-fitting form,
    with the other form and the rig step that separates them in its evidence, instead of naming nothing."""
    from station.kernel.plan import random_plan

    plan = random_plan(np.random.default_rng(10_000 + 401))
    assert {abs(r) for _, r in plan.rate_steps} == {100.0}
    res = simulate_session(401, plan=plan, effects=Effects(scale_nonlinearity=2e-4))
    report = diagnose(res.session, warmup_tc_s={"accel": (50.0, 167.0), "gyro": (1030.0, 3760.0)}).to_json()
    assert [(f["effect"], f["sensor"]) for f in report["findings"]] == [("scale_nonlinearity", "gyro")]
    form = report["findings"][0]["evidence"]["form_inseparable_from"]
    assert set(form["effects"]) == {"scale_nonlinearity_odd"}
    assert "magnitude" in form["rig_step"]
    assert not any("scale_nonlinearity" in e for i in report["inseparable"] for e in i["effects"])
