"""Product limits on a fitted parameter set (minimal: the paper's Table 1 ranges).

A :class:`ProductLimits` holds one range per parameter family of eq. (1) and (3)
(SI: m/s^2 for the accelerometer, rad/s for the gyroscope, s, 1). A fitted value
fails its limit when it lies outside the range by more than ``k_sigma`` of its
own standard uncertainty: Table 1 describes the population of true values, so an
estimate of a unit at the edge of the range may scatter across it without the unit
being bad. Unresolved estimates (NaN: a drift too small to resolve) are not checked.

The correlation time T_c is not checked by default: a 300 s power-on rest cannot
resolve the gyro's 1000-3800 s T_c, and the fit then may return T_c at its search
bound with a local (Wald) uncertainty far too small, which failed 5 of 40 simulated
Table 1 units (``table1_limits(check_correlation_time=True)`` checks it anyway).
Versioned limits files (``fixtures/limits/*.toml``) are loaded by
:mod:`station.kernel.limits_file`; a :class:`ProductLimits` from a file also carries
:class:`FitQualityLimits` (largest residual RMS and standard uncertainties), which
:func:`check_limits` then checks too (``table1_limits()`` has none: unchanged verdicts).
"""

from __future__ import annotations

import math

import numpy as np

from station.fit.params import ParameterSet, TriadParams
from station.kernel.limits import FitQualityLimits, ProductLimits, TriadLimits
from station.kernel.measurement import Measurement
from station.kernel.sensor_class import Range

AXES = "xyz"


def _check(name: str, value: float, std: float, rng: Range, unit: str, k: float) -> Measurement | None:
    if not math.isfinite(value):
        return None
    s = std if math.isfinite(std) else 0.0
    ok = rng[0] - k * s <= value <= rng[1] + k * s
    return Measurement(name, float(value), unit, float(rng[0]), float(rng[1]), bool(ok), float(std))


def _triad_checks(prefix: str, tri: TriadParams, lim: TriadLimits, unit: str, k: float) -> list[Measurement]:
    out: list[Measurement | None] = []
    m, ms = np.asarray(tri.misalignment), np.asarray(tri.misalignment_std)
    for i in range(3):
        for j in range(3):
            rng = lim.scale if i == j else lim.cross_axis
            out.append(_check(f"{prefix}.M.{AXES[i]}{AXES[j]}", m[i, j], ms[i, j], rng, "1", k))
    families: list[tuple[str, Range, str]] = [
        ("bias_static", lim.bias_static, unit),
        ("bias_drift", lim.bias_drift, unit),
        ("noise_std", lim.noise_std, unit),
    ]
    if lim.correlation_time_s is not None:
        families.append(("correlation_time_s", lim.correlation_time_s, "s"))
    for field, rng, u in families:
        v, s = np.asarray(getattr(tri, field)), np.asarray(getattr(tri, f"{field}_std"))
        for i in range(3):
            if field in ("bias_drift", "correlation_time_s") and not math.isfinite(float(tri.correlation_time_s[i])):
                continue  # drift not resolved: nothing to check
            out.append(_check(f"{prefix}.{field}.{AXES[i]}", float(v[i]), float(s[i]), rng, u, k))
    return [c for c in out if c is not None]


def check_fit_quality(params: ParameterSet, limits: FitQualityLimits) -> list[Measurement]:
    """Fit-quality figures of ``params`` against ``limits`` (each passes when ``0 <= value <= max``).

    Names start with ``fit.``; unresolved figures (NaN) are not checked.
    """
    out: list[Measurement] = []

    def add(name: str, values: np.ndarray, limit: float | None, unit: str) -> None:
        if limit is None:
            return
        for idx, v in np.ndenumerate(np.asarray(values, dtype=np.float64)):
            if not math.isfinite(float(v)):
                continue
            suffix = "".join(AXES[i] for i in idx)
            out.append(Measurement.in_range(f"fit.{name}.{suffix}", float(v), 0.0, limit, unit))

    a, g = params.accel, params.gyro
    add("accel.residual_rms", a.residual_rms, limits.accel_residual_rms_mps2, "m/s^2")
    add("gyro.residual_rms", g.residual_rms, limits.gyro_residual_rms_radps, "rad/s")
    add("accel.M_std", a.misalignment_std, limits.accel_misalignment_std, "1")
    add("gyro.M_std", g.misalignment_std, limits.gyro_misalignment_std, "1")
    add("accel.bias_static_std", a.bias_static_std, limits.accel_bias_static_std_mps2, "m/s^2")
    add("gyro.bias_static_std", g.bias_static_std, limits.gyro_bias_static_std_radps, "rad/s")
    return out


def check_limits(params: ParameterSet, limits: ProductLimits) -> list[Measurement]:
    """Every checked parameter of ``params`` against ``limits``, accelerometer first, then fit quality."""
    out = _triad_checks("accel", params.accel, limits.accel, "m/s^2", limits.k_sigma) + _triad_checks(
        "gyro", params.gyro, limits.gyro, "rad/s", limits.k_sigma
    )
    if limits.fit_quality is not None:
        out += check_fit_quality(params, limits.fit_quality)
    return out


def is_marginal(check: Measurement, fraction: float) -> bool:
    """A passed check whose value lies within ``fraction`` of the range width of an edge."""
    if not check.passed or fraction <= 0:
        return False
    band = fraction * (check.high - check.low)
    return check.value < check.low + band or check.value > check.high - band
