"""The versioned limits file: the default equals Table 1, validation names the key, fit-quality and marginal checks."""

from __future__ import annotations

import math
import re
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from station.kernel.errors import UnsupportedVersionError
from station.kernel.limits import table1_limits
from station.kernel.limits_file import DEFAULT_LIMITS_PATH, FitQualityLimits, LimitsFileError, load_limits, parse_limits
from station.kernel.measurement import Measurement, Verdict
from station.kernel.parameters import ParameterSet
from station.kernel.sensor_class import TABLE1
from station.physics.unit import draw_unit
from station.sequence.limits import check_fit_quality, check_limits, conformance, is_marginal
from station.sequence.records import Outcome
from station.sequence.runner import unit_verdict

DEFAULT_TEXT = DEFAULT_LIMITS_PATH.read_text()


def _edit(old: str, new: str) -> str:
    assert old in DEFAULT_TEXT, old
    return DEFAULT_TEXT.replace(old, new, 1)


def test_default_file_is_table1() -> None:
    lim = load_limits()
    assert (lim.name, lim.version, lim.path) == ("table1-default", "2.0.0", DEFAULT_LIMITS_PATH)
    assert re.fullmatch(r"[0-9a-f]{64}", lim.sha256)
    ref = table1_limits()
    # ISO 14253-1 guard bands with k = 2 (table1_limits() keeps the widening rule of station-limits/1)
    assert (lim.product.rule, lim.product.k_sigma, lim.product.inconclusive) == ("guard-band", 2.0, "fail")
    assert (ref.rule, ref.k_sigma) == ("widen", 3.0)
    for tri in ("accel", "gyro"):
        a, b = getattr(lim.product, tri), getattr(ref, tri)
        for f in ("scale", "cross_axis", "bias_static", "bias_drift", "noise_std"):
            np.testing.assert_allclose(getattr(a, f), getattr(b, f), rtol=1e-12, err_msg=f"{tri}.{f}")
        assert a.correlation_time_s is None  # check_correlation_time = false
    # ... but the sensor class's T_c range is kept for the diagnosis
    assert lim.correlation_time_s == {"accel": (50.0, 167.0), "gyro": (1030.0, 3760.0)}
    assert lim.product.gyro.bias_static[1] == pytest.approx(2.739 * math.pi / 180)
    assert lim.retest.max_attempts == 3
    assert lim.marginal_fraction == 0.05
    assert lim.verification.gyro_static_radps == pytest.approx(0.05 * math.pi / 180)
    assert lim.fit_quality.gyro_residual_rms_radps == pytest.approx(0.02 * math.pi / 180)
    assert lim.fit_quality.gyro_bias_static_std_radps == pytest.approx(0.2 * math.pi / 180)


def test_same_verdicts_as_table1_limits() -> None:
    lim = load_limits()
    for seed in range(5):
        params = draw_unit(TABLE1, np.random.default_rng(seed)).as_parameter_set(0.01)
        a = check_limits(params, lim.product)
        b = check_limits(params, table1_limits())
        product = [c for c in a if not c.name.startswith("fit.")]
        assert [(c.name, c.passed) for c in product] == [(c.name, c.passed) for c in b]
        assert len(b) == 2 * (9 + 9) and all(c.passed for c in a)
        # truth has zero uncertainties and no residual: fit quality checks M_std and b_stat std (all 0)
        assert {c.name.rsplit(".", 1)[0] for c in a if c.name.startswith("fit.")} == {
            "fit.accel.M_std", "fit.gyro.M_std", "fit.accel.bias_static_std", "fit.gyro.bias_static_std"}


def test_correlation_time_checked_when_enabled() -> None:
    lim = parse_limits(_edit("check_correlation_time = false", "check_correlation_time = true"))
    assert lim.product.gyro.correlation_time_s == (1030.0, 3760.0)
    assert lim.sha256 != load_limits().sha256


@pytest.mark.parametrize(
    ("old", "new", "message"),
    [
        ('version = "2.0.0"\n', "", "missing key version"),
        ("scale = [0.97, 1.003]", "scale = [1.003, 0.97]", "product.gyro.scale: low 1.003 is above high 0.97"),
        ("bias_static_mps2 = [-0.17, 0.026]", "bias_static_mps2 = [-0.17]",
         "product.accel.bias_static_mps2: expected [low, high]"),
        ("noise_std_dps = [0.01, 0.013]", "noise_std_dsp = [0.01, 0.013]", "missing key product.gyro.noise_std_dps"),
        ("coverage_factor_k = 2.0", "coverage_factor_k = 2.0\nk_sgima = 2.0", "unknown key(s) product.k_sgima"),
        ("coverage_factor_k = 2.0", 'coverage_factor_k = "2"', "product.coverage_factor_k: expected a finite number"),
        ("coverage_factor_k = 2.0", "coverage_factor_k = -1.0", "product.coverage_factor_k: must be >= 0"),
        ('rule = "guard-band"', 'rule = "lenient"', "product.rule: must be one of 'widen', 'guard-band'"),
        ('inconclusive = "fail"', 'inconclusive = "pass"', "product.inconclusive: must be one of 'fail', 'retest'"),
        ("check_correlation_time = false", "check_correlation_time = 0", "product.check_correlation_time"),
        ("fraction = 0.05", "fraction = 0.7", "marginal.fraction: must be in [0, 0.5)"),
        ("accel_residual_rms_mps2 = 0.04", "accel_residual_rms_mps2 = -1", "fit_quality.accel_residual_rms_mps2"),
        ("accel_residual_rms_mps2 = 0.04", "accel_residual_rms = 0.04", "unknown key(s) fit_quality.accel_residual"),
        ('pose = "+z"', 'pose = "up"', "verification: verification pose must be like '+z'"),
        ("hold_s = 5.0", "hold_s = 0", "verification.hold_s: must be > 0"),
        ("max_attempts = 3", "max_attempts = 0", "retest.max_attempts: expected an integer >= 1"),
        ("[retest]\nmax_attempts = 3\n", "", "missing key retest"),
        ("[marginal]", "[marginal", "not valid TOML"),
    ],
)
def test_bad_files_name_the_key(old: str, new: str, message: str) -> None:
    with pytest.raises(LimitsFileError) as info:
        parse_limits(_edit(old, new), "bad.toml")
    text = str(info.value)
    assert text.startswith("bad.toml: ") and message in text, text


def test_unknown_format_version(tmp_path: Path) -> None:
    p = tmp_path / "future.toml"
    p.write_text(_edit('format = "station-limits/2"', 'format = "station-limits/3"'))
    with pytest.raises(UnsupportedVersionError, match="station-limits/3"):
        load_limits(p)
    with pytest.raises(LimitsFileError, match="cannot read limits file"):
        load_limits(tmp_path / "missing.toml")


def test_fit_quality_checks() -> None:
    params = draw_unit(TABLE1, np.random.default_rng(2)).as_parameter_set(0.01)
    d = params.to_dict()
    d["accel"]["residual_rms"] = [0.02, 0.05, None]  # z unresolved: not checked
    d["gyro"]["residual_rms"] = [2e-4, 2e-4, 2e-4]
    d["accel"]["misalignment_std"] = [[3e-5] * 3] * 3
    p = ParameterSet.from_dict(d)
    fq = load_limits().fit_quality
    checks = {c.name: c for c in check_fit_quality(p, fq)}
    assert checks["fit.accel.residual_rms.x"].passed and not checks["fit.accel.residual_rms.y"].passed
    assert "fit.accel.residual_rms.z" not in checks
    assert all(checks[f"fit.gyro.residual_rms.{a}"].passed for a in "xyz")
    assert checks["fit.accel.M_std.xy"].passed and checks["fit.accel.M_std.xy"].high == 2e-4
    gyro_bstat = checks["fit.gyro.bias_static_std.z"]
    assert gyro_bstat.passed and gyro_bstat.high == fq.gyro_bias_static_std_radps
    assert check_fit_quality(p, FitQualityLimits()) == []
    # the runner's check_limits includes them when the limits come from a file
    failed = [c.name for c in check_limits(p, load_limits().product) if not c.passed]
    assert failed == ["fit.accel.residual_rms.y"]
    assert all(c.passed for c in check_limits(p, table1_limits()))


def test_marginal_band() -> None:
    def c(v: float, ok: bool = True) -> Measurement:
        return Measurement("x", v, "1", 0.0, 1.0, ok, 0.0)

    assert is_marginal(c(0.04), 0.05) and is_marginal(c(0.97), 0.05)
    assert not is_marginal(c(0.5), 0.05) and not is_marginal(c(0.04), 0.0)
    assert not is_marginal(c(1.5, ok=False), 0.05)  # a failure is not marginal


def _limits(rule: str, inconclusive: str = "fail", marginal: float = 0.0):
    return replace(table1_limits(), rule=rule, k_sigma=2.0, inconclusive=inconclusive, marginal_fraction=marginal)


@pytest.mark.parametrize(
    ("value", "std", "verdict"),
    [
        (0.0, 0.01, Verdict.PASS),  # value +- 2u = [-0.02, 0.02] inside [-0.1, 0.1]
        (0.09, 0.01, Verdict.INCONCLUSIVE),  # inside, but 0.09 + 0.02 reaches past 0.1
        (0.11, 0.001, Verdict.FAIL),  # the value itself outside: FAIL, however small u
        (0.11, 0.5, Verdict.FAIL),  # ... and however large u (never "passes within its uncertainty")
        (0.0, 0.2, Verdict.INCONCLUSIVE),  # a value at the centre with an interval wider than the range
        (0.1, 0.0, Verdict.PASS),  # on the limit, no uncertainty
    ],
)
def test_guard_band_rule(value: float, std: float, verdict: Verdict) -> None:
    m = conformance("x", value, std, (-0.1, 0.1), "m/s^2", _limits("guard-band"))
    assert m is not None and m.verdict == verdict and m.k == 2.0
    assert m.passed == (verdict == Verdict.PASS)


def test_a_larger_uncertainty_never_passes_more_easily() -> None:
    rank = {Verdict.PASS: 0, Verdict.MARGINAL: 0, Verdict.INCONCLUSIVE: 1, Verdict.FAIL: 2}
    rng = np.random.default_rng(0)
    for _ in range(500):
        value, u1 = rng.normal(0.0, 0.1), abs(rng.normal(0.0, 0.05))
        u2 = u1 * (1.0 + rng.uniform(0.0, 3.0))
        a = conformance("x", value, u1, (-0.1, 0.1), "1", _limits("guard-band"))
        b = conformance("x", value, u2, (-0.1, 0.1), "1", _limits("guard-band"))
        assert a is not None and b is not None and rank[b.verdict] >= rank[a.verdict]
    # the old rule did the opposite: the same out-of-range value passes once its uncertainty is large
    assert not conformance("x", 0.12, 0.001, (-0.1, 0.1), "1", _limits("widen")).passed  # type: ignore[union-attr]
    assert conformance("x", 0.12, 0.05, (-0.1, 0.1), "1", _limits("widen")).passed  # type: ignore[union-attr]


def test_marginal_is_relative_to_the_range_and_not_at_a_one_sided_zero() -> None:
    lim = _limits("guard-band", marginal=0.05)
    near_edge = conformance("x", 0.095, 0.0, (-0.1, 0.1), "1", lim)
    assert near_edge is not None and near_edge.verdict == Verdict.MARGINAL
    middle = conformance("x", 0.0, 0.0, (-0.1, 0.1), "1", lim)
    assert middle is not None and middle.verdict == Verdict.PASS
    params = draw_unit(TABLE1, np.random.default_rng(2)).as_parameter_set(0.01)
    fq = load_limits().fit_quality
    checks = {c.name: c for c in check_fit_quality(params, fq, 0.05)}
    # truth: every uncertainty is 0, at the one-sided limit's zero end: never marginal
    assert all(c.verdict == Verdict.PASS for c in checks.values())
    d = params.to_dict()
    d["gyro"]["misalignment_std"] = [[0.99e-4] * 3] * 3  # just under the 1e-4 limit
    near = {c.name: c for c in check_fit_quality(ParameterSet.from_dict(d), fq, 0.05)}
    assert near["fit.gyro.M_std.xy"].verdict == Verdict.MARGINAL


@pytest.mark.parametrize(("policy", "outcome"), [("fail", Outcome.FAIL), ("retest", Outcome.RETEST)])
def test_inconclusive_policy(policy: str, outcome: Outcome) -> None:
    truth = draw_unit(TABLE1, np.random.default_rng(4)).as_parameter_set(0.01)
    lim = _limits("guard-band", inconclusive=policy)
    hi = lim.gyro.bias_static[1]
    edge = replace(truth, gyro=replace(truth.gyro, bias_static=np.array([0.0, 0.0, 0.99 * hi]),
                                       bias_static_std=np.full(3, 0.05 * hi)))
    got, message = unit_verdict(check_limits(edge, lim), lim)
    assert got == outcome and "inconclusive" in message and "gyro.bias_static.z" in message
    assert unit_verdict(check_limits(truth, lim), lim) == (Outcome.PASS, "")
    out = replace(edge, gyro=replace(edge.gyro, bias_static=np.array([0.0, 0.0, 1.01 * hi])))
    assert unit_verdict(check_limits(out, lim), lim)[0] == Outcome.FAIL


def test_version_1_files_keep_their_rule() -> None:
    v1 = Path(__file__).resolve().parents[1] / "benchmarks" / "limits-wide-tc.toml"
    lim = load_limits(v1)
    assert (lim.product.rule, lim.product.k_sigma) == ("widen", 3.0)
