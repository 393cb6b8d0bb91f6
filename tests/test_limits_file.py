"""The versioned limits file: the default equals Table 1, validation names the key, fit-quality and marginal checks."""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest

from station.fit.params import ParameterSet
from station.kernel.errors import UnsupportedVersionError
from station.kernel.limits import table1_limits
from station.kernel.limits_file import DEFAULT_LIMITS_PATH, FitQualityLimits, LimitsFileError, load_limits, parse_limits
from station.kernel.measurement import Measurement
from station.kernel.sensor_class import TABLE1
from station.physics.unit import draw_unit
from station.sequence.limits import check_fit_quality, check_limits, is_marginal

DEFAULT_TEXT = DEFAULT_LIMITS_PATH.read_text()


def _edit(old: str, new: str) -> str:
    assert old in DEFAULT_TEXT, old
    return DEFAULT_TEXT.replace(old, new, 1)


def test_default_file_is_table1() -> None:
    lim = load_limits()
    assert (lim.name, lim.version, lim.path) == ("table1-default", "1.0.0", DEFAULT_LIMITS_PATH)
    assert re.fullmatch(r"[0-9a-f]{64}", lim.sha256)
    ref = table1_limits()
    assert lim.product.k_sigma == ref.k_sigma == 3.0
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
    assert lim.fit_quality.gyro_bias_static_std_radps is None


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
            "fit.accel.M_std", "fit.gyro.M_std", "fit.accel.bias_static_std"}


def test_correlation_time_checked_when_enabled() -> None:
    lim = parse_limits(_edit("check_correlation_time = false", "check_correlation_time = true"))
    assert lim.product.gyro.correlation_time_s == (1030.0, 3760.0)
    assert lim.sha256 != load_limits().sha256


@pytest.mark.parametrize(
    ("old", "new", "message"),
    [
        ('version = "1.0.0"\n', "", "missing key version"),
        ("scale = [0.97, 1.003]", "scale = [1.003, 0.97]", "product.gyro.scale: low 1.003 is above high 0.97"),
        ("bias_static_mps2 = [-0.17, 0.026]", "bias_static_mps2 = [-0.17]",
         "product.accel.bias_static_mps2: expected [low, high]"),
        ("noise_std_dps = [0.01, 0.013]", "noise_std_dsp = [0.01, 0.013]", "missing key product.gyro.noise_std_dps"),
        ("k_sigma = 3.0", "k_sigma = 3.0\nk_sgima = 2.0", "unknown key(s) product.k_sgima"),
        ("k_sigma = 3.0", 'k_sigma = "3"', "product.k_sigma: expected a finite number"),
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
    p.write_text(_edit('format = "station-limits/1"', 'format = "station-limits/2"'))
    with pytest.raises(UnsupportedVersionError, match="station-limits/2"):
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
    assert not any(n.startswith("fit.gyro.bias_static_std") for n in checks)
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
