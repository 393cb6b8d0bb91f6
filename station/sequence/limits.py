"""Conformance of a fitted parameter set with its product limits.

A :class:`~station.kernel.limits.ProductLimits` holds one range per parameter family of eq. (1)
and (3) (SI: m/s^2 for the accelerometer, rad/s for the gyroscope, s, 1) and the rule that judges
an estimate with standard uncertainty u against it (every result is a
:class:`~station.kernel.measurement.Measurement`):

* ``guard-band`` (ISO 14253-1, JCGM 106, the default limits file): the value conforms (PASS) when
  ``value +- k u`` lies inside the range; it FAILs when the value itself lies outside; in between it
  is INCONCLUSIVE: neither proven. A larger uncertainty can only make a verdict less favourable.
* ``widen`` (``station-limits/1`` files, :func:`~station.kernel.limits.table1_limits`): the value
  passes within ``[low - k u, high + k u]``: Table 1 describes the population of true values, so
  an estimate of a unit at the edge may scatter across it. A noisier fit passes more easily.
  The limits file may name *plausibility* families (drift amplitude, noise, T_c) judged this way
  while the product's own parameters (M, b_stat) are guard-banded: their range describes the
  sensor class, and the question is whether the estimate is consistent with it.

Fit-quality figures (residual RMS, standard uncertainties) are one-sided limits ``[0, max]``.
MARGINAL flags a pass within the limits file's fraction of the range width of a limit; a one-sided
limit at zero is flagged near ``max`` only. Unresolved estimates (NaN: a drift too small to resolve)
are not checked.

The correlation time T_c is not checked by default: a 300 s power-on rest cannot
resolve the gyro's 1000-3800 s T_c (``table1_limits(check_correlation_time=True)`` checks it).
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from station.kernel.limits import GUARD_BAND, WIDEN, FitQualityLimits, ProductLimits, ThermalLimits, TriadLimits
from station.kernel.measurement import Measurement
from station.kernel.parameters import ParameterSet, TriadParams
from station.kernel.sensor_class import Range

AXES = "xyz"


def conformance(
    name: str, value: float, std: float, rng: Range, unit: str, limits: ProductLimits, family: str = ""
) -> Measurement | None:
    """``value`` (standard uncertainty ``std``) against ``rng`` by the rule of ``limits``; None if NaN.

    A ``family`` listed in ``limits.plausibility`` is judged with the widening rule at ``plausibility_k``.
    """
    if not math.isfinite(value):
        return None
    lo, hi = float(rng[0]), float(rng[1])
    plausibility = family in limits.plausibility
    rule = WIDEN if plausibility else limits.rule
    k = float(limits.plausibility_k if plausibility else limits.k_sigma)
    ku = k * std if math.isfinite(std) else 0.0
    inconclusive = False
    if rule == GUARD_BAND:
        ok = lo + ku <= value <= hi - ku
        inconclusive = not ok and lo <= value <= hi
    else:
        ok = lo - ku <= value <= hi + ku
    marginal = ok and _near_edge(value, lo, hi, limits.marginal_fraction)
    return Measurement(name, float(value), unit, lo, hi, bool(ok), float(std), marginal=marginal,
                       inconclusive=inconclusive, k=k)


def _near_edge(value: float, lo: float, hi: float, fraction: float) -> bool:
    """Within ``fraction`` of the width of a limit; a one-sided ``[0, max]`` limit only near ``max``."""
    if fraction <= 0 or not (math.isfinite(lo) and math.isfinite(hi)):
        return False
    band = fraction * (hi - lo)
    return value > hi - band or (lo != 0.0 and value < lo + band)


def _triad_checks(
    prefix: str, tri: TriadParams, lim: TriadLimits, unit: str, limits: ProductLimits
) -> list[Measurement]:
    out: list[Measurement | None] = []
    m, ms = np.asarray(tri.misalignment), np.asarray(tri.misalignment_std)
    for i in range(3):
        for j in range(3):
            rng, family = (lim.scale, "scale") if i == j else (lim.cross_axis, "cross_axis")
            out.append(conformance(f"{prefix}.M.{AXES[i]}{AXES[j]}", m[i, j], ms[i, j], rng, "1", limits, family))
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
            out.append(conformance(f"{prefix}.{field}.{AXES[i]}", float(v[i]), float(s[i]), rng, u, limits, field))
    return [c for c in out if c is not None]


def check_fit_quality(
    params: ParameterSet, limits: FitQualityLimits, marginal_fraction: float = 0.0
) -> list[Measurement]:
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
            m = Measurement.in_range(f"fit.{name}.{suffix}", float(v), 0.0, limit, unit)
            if m.passed and _near_edge(m.value, 0.0, limit, marginal_fraction):
                m = replace(m, marginal=True)
            out.append(m)

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
    out = _triad_checks("accel", params.accel, limits.accel, "m/s^2", limits) + _triad_checks(
        "gyro", params.gyro, limits.gyro, "rad/s", limits
    )
    if limits.fit_quality is not None:
        out += check_fit_quality(params, limits.fit_quality, limits.marginal_fraction)
    if limits.thermal is not None and params.thermal.fitted:
        out += check_thermal(params, limits.thermal, limits)
    return out


def check_thermal(params: ParameterSet, thermal: ThermalLimits, limits: ProductLimits) -> list[Measurement]:
    """The first-order temperature coefficients of ``params`` (the thermal model) against ``thermal``: each value by
    the product's rule (:func:`conformance`), each standard uncertainty as a one-sided limit ``[0, max]``.
    Names ``accel.temp_bias_coeff.x``, ``fit.gyro.temp_scale_coeff_std.z``, ...; call only for a fitted set."""
    t = thermal
    families = (
        ("accel", "temp_bias_coeff", t.accel_temp_bias_mps2_per_k, t.accel_temp_bias_std_mps2_per_k, "m/s^2/K"),
        ("accel", "temp_scale_coeff", t.accel_temp_scale_per_k, t.accel_temp_scale_std_per_k, "1/K"),
        ("gyro", "temp_bias_coeff", t.gyro_temp_bias_radps_per_k, t.gyro_temp_bias_std_radps_per_k, "rad/s/K"),
        ("gyro", "temp_scale_coeff", t.gyro_temp_scale_per_k, t.gyro_temp_scale_std_per_k, "1/K"),
    )
    out: list[Measurement] = []
    for tri_name, field, rng, max_std, unit in families:
        tri = getattr(params, tri_name)
        v, s = getattr(tri, field)[:, 0], getattr(tri, f"{field}_std")[:, 0]
        for i in range(3):
            m = conformance(f"{tri_name}.{field}.{AXES[i]}", float(v[i]), float(s[i]), rng, unit, limits, field)
            if m is not None:
                out.append(m)
            if max_std is not None and math.isfinite(float(s[i])):
                q = Measurement.in_range(f"fit.{tri_name}.{field}_std.{AXES[i]}", float(s[i]), 0.0, max_std, unit)
                if q.passed and _near_edge(q.value, 0.0, max_std, limits.marginal_fraction):
                    q = replace(q, marginal=True)
                out.append(q)
    return out


def is_marginal(check: Measurement, fraction: float) -> bool:
    """A passed check whose value lies within ``fraction`` of the range width of either edge.

    For the verdicts the station records, :func:`conformance` and :func:`check_fit_quality` set
    ``Measurement.marginal`` themselves (one-sided limits at zero flagged near ``max`` only).
    """
    if not check.passed or fraction <= 0:
        return False
    band = fraction * (check.high - check.low)
    return check.value < check.low + band or check.value > check.high - band
