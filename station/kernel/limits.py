"""Product limits of a sensor class: ranges per parameter family of eq. (1) and (3), in SI.

A :class:`ProductLimits` holds one range per parameter family (m/s^2 for the accelerometer,
rad/s for the gyroscope, s, 1) and optional :class:`FitQualityLimits`. :func:`table1_limits`
gives the paper's Table 1 as limits. Versioned limits files are read by
:mod:`station.kernel.limits_file`; checking a parameter set against limits is the sequence's
job (:mod:`station.sequence.limits`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from station.kernel.sensor_class import TABLE1, Range, SensorClass


@dataclass(frozen=True)
class TriadLimits:
    """Ranges for one triad (unit U = m/s^2 or rad/s).

    Attributes:
        scale: diagonal of M (1); cross_axis: off-diagonal of M (1).
        bias_static, bias_drift: (U); noise_std: (U).
        correlation_time_s: T_c (s), None: not checked.
    """

    scale: Range
    cross_axis: Range
    bias_static: Range
    bias_drift: Range
    noise_std: Range
    correlation_time_s: Range | None = None


@dataclass(frozen=True)
class FitQualityLimits:
    """Largest allowed fit-quality figures (SI); None: not checked.

    Attributes:
        accel_residual_rms_mps2, gyro_residual_rms_radps: residual RMS per axis (m/s^2, rad/s).
        accel_misalignment_std, gyro_misalignment_std: standard uncertainty of each M element (1).
        accel_bias_static_std_mps2 (m/s^2), gyro_bias_static_std_radps (rad/s): b_stat uncertainty.
    """

    accel_residual_rms_mps2: float | None = None
    gyro_residual_rms_radps: float | None = None
    accel_misalignment_std: float | None = None
    gyro_misalignment_std: float | None = None
    accel_bias_static_std_mps2: float | None = None
    gyro_bias_static_std_radps: float | None = None


@dataclass(frozen=True)
class ThermalLimits:
    """Limits of the temperature terms (the thermal model), checked only where the fit fitted them (SI).

    Attributes:
        accel_temp_bias_mps2_per_k, gyro_temp_bias_radps_per_k: range of the first-order temperature
            coefficient of the bias, per axis (m/s^2/K, rad/s/K).
        accel_temp_scale_per_k, gyro_temp_scale_per_k: range of the first-order temperature coefficient of
            the scale factor (1/K).
        *_std_*: largest standard uncertainty of each (same units); None: not checked.
    """

    accel_temp_bias_mps2_per_k: Range
    gyro_temp_bias_radps_per_k: Range
    accel_temp_scale_per_k: Range
    gyro_temp_scale_per_k: Range
    accel_temp_bias_std_mps2_per_k: float | None = None
    gyro_temp_bias_std_radps_per_k: float | None = None
    accel_temp_scale_std_per_k: float | None = None
    gyro_temp_scale_std_per_k: float | None = None


#: Conformance rules for a value with a stated standard uncertainty u (see :class:`ProductLimits`).
WIDEN = "widen"
GUARD_BAND = "guard-band"
RULES = (WIDEN, GUARD_BAND)
#: The parameter families of a triad that product limits hold a range for.
FAMILIES = ("scale", "cross_axis", "bias_static", "bias_drift", "noise_std", "correlation_time_s")
#: What an inconclusive verdict of the guard-band rule becomes for the unit.
INCONCLUSIVE_POLICIES = ("fail", "retest")


@dataclass(frozen=True)
class ProductLimits:
    """Limits for a product: both triads, the conformance rule, optional fit quality.

    Attributes:
        rule: ``'guard-band'`` (ISO 14253-1 / JCGM 106): a value conforms when ``value +- k u`` lies
            inside the range, fails when the value itself lies outside, and is inconclusive in
            between; ``'widen'`` (the rule of ``station-limits/1`` files): a value passes within
            ``[low - k u, high + k u]``, so a noisier fit passes more easily.
        k_sigma: the coverage factor k of either rule.
        inconclusive: what an inconclusive verdict makes the unit: ``'fail'`` or ``'retest'``.
        marginal_fraction: a pass closer to a limit than this fraction of the range width is
            flagged MARGINAL; a one-sided limit at zero (``[0, max]``) is flagged near ``max`` only.
        thermal: limits of the temperature terms (checked where the fit fitted them); None: none.
        plausibility: parameter families (``'bias_drift'``, ``'noise_std'``, ``'correlation_time_s'``)
            whose range describes the sensor class rather than the calibrated product: they are
            judged with the ``widen`` rule at ``plausibility_k`` (is the estimate consistent with the
            class?), the others with ``rule``.
    """

    name: str
    accel: TriadLimits
    gyro: TriadLimits
    k_sigma: float = 3.0
    fit_quality: FitQualityLimits | None = None
    rule: str = WIDEN
    inconclusive: str = "fail"
    marginal_fraction: float = 0.0
    plausibility: frozenset[str] = frozenset()
    plausibility_k: float = 3.0
    thermal: ThermalLimits | None = None

    def __post_init__(self) -> None:
        if self.rule not in RULES:
            raise ValueError(f"conformance rule must be one of {', '.join(RULES)}, got {self.rule!r}")
        unknown = set(self.plausibility) - set(FAMILIES)
        if unknown:
            raise ValueError(f"plausibility families must be among {', '.join(FAMILIES)}, got {sorted(unknown)}")
        if self.inconclusive not in INCONCLUSIVE_POLICIES:
            raise ValueError(
                f"inconclusive must be one of {', '.join(INCONCLUSIVE_POLICIES)}, got {self.inconclusive!r}"
            )


def table1_limits(
    sensor_class: SensorClass = TABLE1, k_sigma: float = 3.0, *, check_correlation_time: bool = False
) -> ProductLimits:
    """Table 1 of the paper as product limits (converted to SI); T_c only if ``check_correlation_time``."""
    c = sensor_class
    d = math.pi / 180.0

    def dps(r: Range) -> Range:
        return (r[0] * d, r[1] * d)

    # white noise seen by the fit includes ADC quantization (LSB^2 / 12), far below the range
    accel = TriadLimits(
        scale=c.accel_scale,
        cross_axis=c.accel_cross_axis,
        bias_static=c.accel_bias_static_mps2,
        bias_drift=c.accel_bias_drift_mps2,
        correlation_time_s=c.accel_correlation_time_s if check_correlation_time else None,
        noise_std=c.accel_noise_std_mps2,
    )
    gyro = TriadLimits(
        scale=c.gyro_scale,
        cross_axis=c.gyro_cross_axis,
        bias_static=dps(c.gyro_bias_static_dps),
        bias_drift=dps(c.gyro_bias_drift_dps),
        correlation_time_s=c.gyro_correlation_time_s if check_correlation_time else None,
        noise_std=dps(c.gyro_noise_std_dps),
    )
    return ProductLimits(name=f"{c.name}-ranges", accel=accel, gyro=gyro, k_sigma=k_sigma)
