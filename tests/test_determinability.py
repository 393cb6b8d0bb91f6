"""Parameters the recording cannot determine are flagged, not printed as results (the fit, the JSON, the CLI,
exports and the EEPROM image), and the typed fit quality survives its JSON round trip."""

from __future__ import annotations

import json
import math
from dataclasses import replace
from datetime import UTC, datetime
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from station.cli import app
from station.eeprom.image import CalibrationImage, image_notes
from station.fit.calibrate import fit_session
from station.fit.determinability import RULE, assess, undetermined
from station.fit.export import export_notes, imu_tk_terms
from station.kernel.errors import FormatError, UnsupportedVersionError
from station.kernel.parameters import (
    AllanCoefficients,
    FitQuality,
    GoodnessOfFit,
    ParameterSet,
    TriadParams,
    Undetermined,
)
from station.kernel.sensor_class import TABLE1
from station.physics.unit import draw_unit
from station.session.csv_v1 import write_session
from station.sim.session_sim import simulate_session

Z3 = np.zeros(3)


def _triad(b_stat: list[float], b_drift: list[float], tc: list[float], tc_std: list[float],
           b_std: list[float] | None = None) -> TriadParams:
    return TriadParams(
        misalignment=np.eye(3), misalignment_std=np.zeros((3, 3)),
        bias_static=b_stat, bias_static_std=b_std if b_std is not None else [0.001] * 3,
        bias_drift=b_drift, bias_drift_std=[0.001] * 3,
        correlation_time_s=tc, correlation_time_s_std=tc_std,
        drift_noise=Z3, drift_noise_std=Z3, noise_std=Z3, noise_std_std=Z3,
        allan=AllanCoefficients(Z3, Z3, Z3, Z3, Z3, Z3), residual_rms=Z3,
    )


def _params(accel: TriadParams, gyro: TriadParams | None = None) -> ParameterSet:
    gyro = gyro if gyro is not None else _triad([0.0] * 3, [0.0] * 3, [math.nan] * 3, [math.nan] * 3)
    return ParameterSet(serial="DET-1", sample_period_s=0.01, accel=accel, gyro=gyro)


# --- the rule on made-up numbers ----------------------------------------------------------------------------------


def test_the_rule_on_made_up_numbers() -> None:
    # x: T_c 60 +- 5 s in a 600 s record: determined; y: T_c 1392 s > 237 s record: T_c, b_drift, b_stat flagged;
    # z: T_c 40 +- 55 s: T_c and b_drift flagged, b_stat (settled within the record) kept
    tri = _triad([0.1, -0.155, 0.2], [0.02, 0.187, 0.01], [60.0, 1392.0, 40.0], [5.0, 400.0, 55.0])
    flags = {(u.parameter, u.axis) for u in undetermined("accel", tri, 237.0)}
    assert flags == {("correlation_time_s", 1), ("bias_drift", 1), ("bias_static", 1),
                     ("correlation_time_s", 2), ("bias_drift", 2)}
    # with a prior range, T_c beyond the record is the class's statement: only its uncertainty decides
    assert {(u.parameter, u.axis) for u in undetermined("accel", tri, 237.0, prior=True)} == {
        ("correlation_time_s", 2), ("bias_drift", 2)}
    # an unresolved T_c (NaN: no drift fitted) is not flagged: b_drift is then 0 by the fit's choice
    assert undetermined("accel", _triad([0.0] * 3, [0.0] * 3, [math.nan] * 3, [math.nan] * 3), 100.0) == []
    # b_stat's uncertainty against its limit range's width
    wide = _triad([0.0] * 3, [0.0] * 3, [math.nan] * 3, [math.nan] * 3, b_std=[0.01, 0.5, 0.2])
    assert [(u.parameter, u.axis) for u in undetermined("accel", wide, 100.0, bias_limit_width=0.4)] == [
        ("bias_static", 1)]


def test_an_export_falls_back_to_the_bias_at_the_end_of_the_recording() -> None:
    tri = _triad([0.1, -0.155, 0.2], [0.02, 0.187, 0.01], [60.0, 1392.0, 40.0], [5.0, 400.0, 55.0])
    params = assess(_params(tri), 237.0)
    assert params.quality.determinability_rule == RULE and params.quality.record_end_s == 237.0
    const, notes = params.constant_bias_values()
    # y (b_stat not determined): constant bias b_stat + b_drift exp(-t_end/T_c), no drift, T_c unresolved,
    # uncertainty not stated; x and z (b_stat determined) unchanged
    assert const.accel.bias_static[1] == pytest.approx(-0.155 + 0.187 * math.exp(-237.0 / 1392.0), rel=1e-12)
    assert math.isnan(const.accel.bias_static_std[1]) and const.accel.bias_drift[1] == 0.0
    assert math.isnan(const.accel.correlation_time_s[1])
    for k in (0, 2):
        assert const.accel.bias_static[k] == tri.bias_static[k] and const.accel.correlation_time_s[k] == \
            tri.correlation_time_s[k]
    end = -0.155 + 0.187 * math.exp(-237.0 / 1392.0)
    assert notes == (f"accel y: the bias at the end of the recording (t = 237.0 s), {end:.6g}, instead of "
                     "b_stat -0.155 (not determined)",)
    assert export_notes(params) == notes
    # the set's own numbers are unchanged (flagged, not replaced)
    assert params.accel.bias_static[1] == -0.155
    # no end time stated: refused rather than guessed
    no_end = replace(params, quality=replace(params.quality, record_end_s=math.nan))
    with pytest.raises(FormatError, match="no recording end time"):
        no_end.constant_bias_values()
    # nothing undetermined: the set itself
    clean = assess(_params(_triad([0.1] * 3, [0.01] * 3, [60.0] * 3, [5.0] * 3)), 600.0)
    assert clean.quality.undetermined == () and clean.constant_bias_values() == (clean, ())
    assert image_notes(clean) == ()


def test_the_image_keeps_the_fitted_curve_and_says_so_and_the_exports_use_the_rule() -> None:
    tri = _triad([0.1, -0.155, 0.2], [0.02, 0.187, 0.01], [60.0, 1392.0, 40.0], [5.0, 400.0, 55.0])
    params = assess(_params(tri), 237.0)
    img = CalibrationImage.from_params(params, "st-1", datetime(2026, 1, 1, tzinfo=UTC))
    # the image: the fitted warm-up curve (what the recording determines over its length), every axis
    assert np.array_equal(img.accel.bias_static, tri.bias_static)
    assert np.array_equal(img.accel.correlation_time_s, tri.correlation_time_s)
    assert np.array_equal(img.accel.bias_drift, tri.bias_drift)
    notes = image_notes(params)
    assert [n.split(":")[0] for n in notes] == ["accel y", "accel z"]
    assert "the image holds the fitted warm-up curve, determined over the recording's 237.0 s" in notes[0]
    # the exports: the bias at the end of the recording on y, its uncertainty not stated
    terms = imu_tk_terms(params)["accel"]
    assert terms["bias_after_matrix"][1] == pytest.approx(params.constant_bias_values()[0].accel.bias_static[1])
    assert np.isnan(terms["bias_after_matrix_std"][1])


# --- JSON: typed quality round trip, old files, unknown versions --------------------------------------------------


def test_quality_round_trip_and_old_files() -> None:
    tri = _triad([0.1, -0.155, 0.2], [0.02, 0.187, 0.01], [60.0, 1392.0, 40.0], [5.0, 400.0, 55.0])
    params = assess(replace(_params(tri), quality=FitQuality(
        goodness_of_fit=GoodnessOfFit(passed=False, failed=("accel pose",), report={"format": "station-goodness/1"}),
        extra={"future_section": {"a": 1}})), 237.0)
    text = params.to_json()
    back = ParameterSet.from_json(text)
    assert back.to_json() == text
    assert back.quality.why_undetermined("accel", "correlation_time_s", 1) is not None
    assert back.quality.is_determined("accel", "correlation_time_s", 0)
    assert back.quality.goodness_of_fit is not None and back.quality.goodness_of_fit.failed == ("accel pose",)
    assert not back.quality.passed and back.quality.extra == {"future_section": {"a": 1}}
    d = json.loads(text)
    assert d["quality"]["determinability"]["undetermined"][0] == {
        "triad": "accel", "parameter": "correlation_time_s", "axis": "y",
        "reason": "T_c 1392 s beyond the recording's 237 s since power-on"}
    # a file written before determinability existed: loads, nothing flagged, rule not stated
    del d["quality"]["determinability"]
    old = ParameterSet.from_dict(d)
    assert old.quality.undetermined == () and old.quality.determinability_rule == ""
    # a malformed known section is a FormatError; an unknown format is refused
    bad = json.loads(text)
    bad["quality"]["determinability"]["undetermined"] = [{"triad": "accel", "parameter": "x", "axis": "y"}]
    with pytest.raises(FormatError):
        ParameterSet.from_dict(bad)
    bad = json.loads(text)
    bad["quality"]["goodness_of_fit"] = {"passed": "yes"}
    with pytest.raises(FormatError):
        ParameterSet.from_dict(bad)
    with pytest.raises(UnsupportedVersionError):
        ParameterSet.from_dict({**json.loads(text), "format": "station-params/4"})
    with pytest.raises(FormatError):
        Undetermined("accel", "noise_std", 0, "")


# --- known truth: a short recording where T_c cannot be determined, a long one where it can ----------------------


def _unit(seed: int, tc_s: float, accel_drift_mps2: float, gyro_drift_radps: float):  # type: ignore[no-untyped-def]
    u = draw_unit(TABLE1, np.random.default_rng(seed))
    return replace(
        u,
        accel=replace(u.accel, correlation_time_s=np.full(3, tc_s), bias_drift=np.full(3, accel_drift_mps2),
                      drift_noise=np.full(3, 0.01 * accel_drift_mps2)),
        gyro=replace(u.gyro, correlation_time_s=np.full(3, tc_s), bias_drift=np.full(3, gyro_drift_radps),
                     drift_noise=np.full(3, 0.01 * gyro_drift_radps)),
    )


def test_a_correlation_time_far_beyond_the_recording_is_not_a_result() -> None:
    # truth: T_c 20000 s on every axis; the default plan lasts about 820 s: no recording of it determines T_c
    sim = simulate_session(70, unit=_unit(70, 20000.0, 0.018, 0.006))
    params = fit_session(sim.session)
    end = params.quality.record_end_s
    assert end == pytest.approx(float(sim.session.t_s[-1])) and end < 1000.0
    for name, tri in (("accel", params.accel), ("gyro", params.gyro)):
        for k in range(3):
            if math.isfinite(tri.correlation_time_s[k]):  # a number: flagged, never a result
                assert not params.quality.is_determined(name, "correlation_time_s", k), (name, k)
                assert not params.quality.is_determined(name, "bias_drift", k), (name, k)
    assert params.quality.undetermined, "the fit printed every T_c of a 20000 s decay from 820 s as a result"


def test_a_correlation_time_well_inside_the_recording_is_determined() -> None:
    # truth: T_c 60 s (about 14 time constants in the record), drifts well above the noise: nothing flagged, and
    # each T_c within 3 of its standard uncertainties of the truth
    sim = simulate_session(71, unit=_unit(71, 60.0, 0.05, 0.02))
    params = fit_session(sim.session)
    assert params.quality.undetermined == (), [u.reason for u in params.quality.undetermined]
    for tri in (params.accel, params.gyro):
        assert np.all(np.abs(tri.correlation_time_s - 60.0) < 3.0 * tri.correlation_time_s_std), (
            tri.correlation_time_s, tri.correlation_time_s_std)


def test_station_fit_prints_not_determined_and_the_json_says_so(tmp_path: Path) -> None:
    sim = simulate_session(70, unit=_unit(70, 20000.0, 0.018, 0.006))
    path = tmp_path / "s.csv"
    write_session(sim.session, path)
    runner = CliRunner()
    r = runner.invoke(app, ["fit", str(path)], env={"COLUMNS": "200"})
    assert r.exit_code == 0, r.output
    assert "not determined (see below)" in r.output
    assert "T_c: not determined (T_c " in r.output
    assert "the image holds the fitted warm-up curve" in r.output
    r = runner.invoke(app, ["fit", str(path), "--json"])
    d = json.loads(r.stdout)
    assert d["quality"]["determinability"]["rule"] == RULE
    assert {u["parameter"] for u in d["quality"]["determinability"]["undetermined"]} >= {
        "correlation_time_s", "bias_drift"}
