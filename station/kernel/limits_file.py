"""Versioned limits files (TOML, format ``station-limits/2``; ``/1`` still read): load and validate.

A limits file (``fixtures/limits/default.toml`` is the default) holds:

* ``[product]``: ranges per parameter family of eq. (1) and (3) for both triads (the
  paper's Table 1 by default) and the conformance rule: ``rule`` (``"guard-band"`` or
  ``"widen"``), ``coverage_factor_k`` and what an ``inconclusive`` verdict becomes
  (``"fail"`` or ``"retest"``); a ``/1`` file has ``k_sigma`` and the ``widen`` rule
  (see :mod:`station.sequence.limits`);
* ``[marginal]``: ``fraction`` of the range width at each edge that makes a PASS MARGINAL;
* ``[fit_quality]``: largest residual RMS per axis and largest standard uncertainties;
* ``[verification]``: residual limits and the short plan of the post-calibration check;
* ``[retest]``: ``max_attempts`` runs per unit before a disposition is required;
* ``[thermal]`` (optional, ``/2`` files): ranges and largest uncertainties of the first-order temperature
  coefficients of bias and scale (:class:`~station.kernel.limits.ThermalLimits`), checked where the fit
  fitted temperature terms. A file without it checks none.

Units are in the key names (``_mps2`` m/s^2, ``_dps`` deg/s, ``_s`` s); everything is
converted to SI on load. Validation is strict: a missing key, an unknown key (a typo),
a wrong type, a range with low > high, or a non-positive limit raises
:class:`LimitsFileError` naming the file and the key, so the station refuses to start
with a limits file it does not fully understand.
"""

from __future__ import annotations

import hashlib
import math
import tomllib
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from station.kernel.datafiles import data_path
from station.kernel.errors import FormatError, UnsupportedVersionError
from station.kernel.limits import (
    FAMILIES,
    INCONCLUSIVE_POLICIES,
    RULES,
    WIDEN,
    FitQualityLimits,
    ProductLimits,
    ThermalLimits,
    TriadLimits,
)

LIMITS_FORMAT = "station-limits/2"
#: Formats this station reads. ``/1`` files keep their own conformance rule (``widen``: a value passes
#: within its range widened by ``k_sigma`` standard uncertainties); ``/2`` files name the rule.
LIMITS_FORMATS = ("station-limits/1", LIMITS_FORMAT)
DEFAULT_LIMITS_PATH = data_path("fixtures", "limits", "default.toml")
_DEG = math.pi / 180.0


class LimitsFileError(FormatError):
    """A limits file is malformed; the message names the file and the key."""


@dataclass(frozen=True)
class VerificationLimits:
    """Limits and plan of the post-calibration verification (see :mod:`station.sequence.verify`).

    Attributes:
        accel_mps2: largest allowed |mean corrected specific force - g up| per axis (m/s^2).
        gyro_static_radps: largest allowed |mean corrected rate| per axis at rest (rad/s).
        rate_radps: largest allowed |mean corrected rate - commanded| about the rate axis (rad/s).
        pose: static pose ('+z', ...); rate_pose: pose of the rate check (its up axis is turned about).
        rate_dps: table rate of the rate check (deg/s).
        settle_s: corrected samples discarded after the rig confirmed (s; at least: the verifier also waits for the
            moving average to fill, n / f, `station.sequence.verify.settle_before_window`).
        hold_s: captured window per check (s).
    """

    accel_mps2: float = 0.05
    gyro_static_radps: float = 0.05 * _DEG
    rate_radps: float = 0.2 * _DEG
    pose: str = "+z"
    rate_pose: str = "+z"
    rate_dps: float = 50.0
    settle_s: float = 1.0
    hold_s: float = 5.0

    def __post_init__(self) -> None:
        for name in ("accel_mps2", "gyro_static_radps", "rate_radps", "settle_s", "hold_s"):
            v = getattr(self, name)
            if not (isinstance(v, int | float) and math.isfinite(v) and v > 0):
                raise ValueError(f"verification limit {name} must be a positive number, got {v!r}")
        for p in (self.pose, self.rate_pose):
            if not (isinstance(p, str) and len(p) == 2 and p[0] in "+-" and p[1] in "xyz"):
                raise ValueError(f"verification pose must be like '+z', got {p!r}")


@dataclass(frozen=True)
class RetestPolicy:
    """At most ``max_attempts`` runs per unit; then the station refuses it until a disposition is recorded."""

    max_attempts: int = 3


@dataclass(frozen=True)
class LimitsFile:
    """A loaded, validated limits file.

    Attributes:
        name, version: from the file (recorded with every run); sha256: hex hash of the file bytes.
        path: where it was read from (None for text).
        product: product limits (SI) for :func:`station.sequence.limits.check_limits`, with ``fit_quality``.
        marginal_fraction: edge band of each range, as a fraction of its width (1).
        fit_quality, verification, retest: see their classes.
        correlation_time_s: the sensor class's range of eq. 3's T_c (s) per triad (``accel``, ``gyro``) as
            the file gives it, checked or not (``check_correlation_time``); the diagnosis keeps the warm-up
            drift inside it (:func:`station.diagnose.diagnose`). Empty when the file gives none.
        drift_noise: the sensor class's stationary std of eq. 3's stochastic drift per triad (SI), where the file
            gives it (optional ``drift_noise_mps2`` / ``drift_noise_dps``): the diagnosis's locator bounds the
            drift noise by it (:mod:`station.diagnose.locator`). Where not given, the locator takes Table 1's
            relative rule on the file's ``bias_drift`` range.
    """

    name: str
    version: str
    sha256: str
    path: Path | None
    product: ProductLimits
    marginal_fraction: float
    fit_quality: FitQualityLimits
    verification: VerificationLimits
    retest: RetestPolicy
    correlation_time_s: dict[str, tuple[float, float]] = field(default_factory=dict)
    drift_noise: dict[str, float] = field(default_factory=dict)


def _finite_number(v: Any) -> bool:
    """A TOML integer or float that is a finite float (TOML integers can be too large for one)."""
    if isinstance(v, bool) or not isinstance(v, int | float):
        return False
    try:
        return math.isfinite(float(v))
    except OverflowError:
        return False


class _Table:
    """A TOML table being validated: every key must be read, values are checked as read."""

    def __init__(self, data: Any, where: str, source: str) -> None:
        if not isinstance(data, dict):
            raise LimitsFileError(f"{source}: [{where}] must be a table")
        self.data, self.where, self.source = data, where, source
        self.used: set[str] = set()

    def _key(self, key: str) -> str:
        return f"{self.where}.{key}" if self.where else key

    def fail(self, key: str, why: str) -> LimitsFileError:
        return LimitsFileError(f"{self.source}: {self._key(key)}: {why}")

    def has(self, key: str) -> bool:
        return key in self.data

    def raw(self, key: str, required: bool = True) -> Any:
        if key not in self.data:
            if required:
                raise LimitsFileError(f"{self.source}: missing key {self._key(key)}")
            return None
        self.used.add(key)
        return self.data[key]

    def table(self, key: str) -> _Table:
        return _Table(self.raw(key), self._key(key), self.source)

    def number(self, key: str, *, positive: bool = False, required: bool = True) -> float | None:
        v = self.raw(key, required)
        if v is None:
            return None
        if not _finite_number(v):
            raise self.fail(key, f"expected a finite number, got {v!r}")
        if positive and v <= 0:
            raise self.fail(key, f"must be > 0, got {v!r}")
        return float(v)

    def value(self, key: str, *, positive: bool = False) -> float:
        """A required number (a missing key is an error, so never None)."""
        v = self.number(key, positive=positive)
        if v is None:  # pragma: no cover - number() raises for a missing required key
            raise self.fail(key, "missing")
        return v

    def text(self, key: str) -> str:
        v = self.raw(key)
        if not isinstance(v, str) or not v.strip():
            raise self.fail(key, f"expected a non-empty string, got {v!r}")
        return v

    def boolean(self, key: str) -> bool:
        v = self.raw(key)
        if not isinstance(v, bool):
            raise self.fail(key, f"expected true or false, got {v!r}")
        return v

    def range(self, key: str, scale: float = 1.0) -> tuple[float, float]:
        v = self.raw(key)
        ok = isinstance(v, list) and len(v) == 2
        ok = ok and all(_finite_number(x) for x in v)
        if not ok:
            raise self.fail(key, f"expected [low, high] with two finite numbers, got {v!r}")
        if v[0] > v[1]:
            raise self.fail(key, f"low {v[0]} is above high {v[1]}")
        return (float(v[0]) * scale, float(v[1]) * scale)

    def done(self) -> None:
        extra = sorted(set(self.data) - self.used)
        if extra:
            raise LimitsFileError(f"{self.source}: unknown key(s) {', '.join(self._key(k) for k in extra)}")


def _triad(t: _Table, gyro: bool, check_tc: bool) -> tuple[TriadLimits, tuple[float, float] | None, float | None]:
    """The triad's product limits (T_c only if checked), its T_c range (s) as given or None, and its class's
    drift noise (SI) as given or None."""
    unit, scale = ("dps", _DEG) if gyro else ("mps2", 1.0)
    drift_noise = t.number(f"drift_noise_{unit}", positive=True, required=False)
    out = TriadLimits(
        scale=t.range("scale"),
        cross_axis=t.range("cross_axis"),
        bias_static=t.range(f"bias_static_{unit}", scale),
        bias_drift=t.range(f"bias_drift_{unit}", scale),
        noise_std=t.range(f"noise_std_{unit}", scale),
        correlation_time_s=t.range("correlation_time_s") if t.has("correlation_time_s") else None,
    )
    tc = out.correlation_time_s
    if tc is not None and tc[0] <= 0:
        raise t.fail("correlation_time_s", "must be a positive range")
    if not check_tc:
        out = replace(out, correlation_time_s=None)
    t.done()
    return out, tc, None if drift_noise is None else drift_noise * scale


def _thermal(t: _Table) -> ThermalLimits:
    """The ``[thermal]`` table: ranges (``_per_k``) and largest standard uncertainties (``_std_``), SI on return."""

    def std(key: str, scale: float = 1.0) -> float | None:
        v = t.number(key, positive=True, required=False)
        return None if v is None else v * scale

    out = ThermalLimits(
        accel_temp_bias_mps2_per_k=t.range("accel_temp_bias_mps2_per_k"),
        gyro_temp_bias_radps_per_k=t.range("gyro_temp_bias_dps_per_k", _DEG),
        accel_temp_scale_per_k=t.range("accel_temp_scale_ppm_per_k", 1e-6),
        gyro_temp_scale_per_k=t.range("gyro_temp_scale_ppm_per_k", 1e-6),
        accel_temp_bias_std_mps2_per_k=std("accel_temp_bias_std_mps2_per_k"),
        gyro_temp_bias_std_radps_per_k=std("gyro_temp_bias_std_dps_per_k", _DEG),
        accel_temp_scale_std_per_k=std("accel_temp_scale_std_ppm_per_k", 1e-6),
        gyro_temp_scale_std_per_k=std("gyro_temp_scale_std_ppm_per_k", 1e-6),
    )
    t.done()
    return out


def parse_limits(text: str | bytes, source: str = "<limits>", path: Path | None = None) -> LimitsFile:
    """Parse and validate limits-file text; raises :class:`LimitsFileError` naming ``source`` and the key."""
    raw = text.encode("utf-8") if isinstance(text, str) else bytes(text)
    try:
        data = tomllib.loads(raw.decode("utf-8"))
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise LimitsFileError(f"{source}: not valid TOML: {exc}") from exc
    top = _Table(data, "", source)
    fmt = top.raw("format")
    if fmt not in LIMITS_FORMATS:
        raise UnsupportedVersionError(
            f"{source}: limits format {fmt!r}; this station reads {', '.join(map(repr, LIMITS_FORMATS))} only"
        )
    name, version = top.text("name"), top.text("version")
    top.raw("description", required=False)

    prod = top.table("product")
    if fmt == LIMITS_FORMAT:
        rule, k_key = prod.text("rule"), "coverage_factor_k"
        if rule not in RULES:
            raise prod.fail("rule", f"must be one of {', '.join(map(repr, RULES))}, got {rule!r}")
        inconclusive = prod.text("inconclusive")
        if inconclusive not in INCONCLUSIVE_POLICIES:
            raise prod.fail("inconclusive", f"must be one of {', '.join(map(repr, INCONCLUSIVE_POLICIES))}, "
                                            f"got {inconclusive!r}")
        plaus = prod.raw("plausibility", required=False) or []
        if not (isinstance(plaus, list) and all(isinstance(f, str) and f in FAMILIES for f in plaus)):
            raise prod.fail("plausibility", f"expected a list of families among {', '.join(FAMILIES)}, got {plaus!r}")
        plaus_k = prod.number("plausibility_k", required=bool(plaus))
        if plaus_k is not None and plaus_k < 0:
            raise prod.fail("plausibility_k", f"must be >= 0, got {plaus_k}")
    else:
        rule, k_key, inconclusive, plaus, plaus_k = WIDEN, "k_sigma", "fail", [], None
    k_sigma = prod.number(k_key)
    assert k_sigma is not None
    if k_sigma < 0:
        raise prod.fail(k_key, f"must be >= 0, got {k_sigma}")
    check_tc = prod.boolean("check_correlation_time")
    accel, accel_tc, accel_q = _triad(prod.table("accel"), False, check_tc)
    gyro, gyro_tc, gyro_q = _triad(prod.table("gyro"), True, check_tc)
    tc_ranges = {name: r for name, r in (("accel", accel_tc), ("gyro", gyro_tc)) if r is not None}
    drift_noise = {name: q for name, q in (("accel", accel_q), ("gyro", gyro_q)) if q is not None}
    prod.done()

    marg = top.table("marginal")
    fraction = marg.number("fraction")
    assert fraction is not None
    if not 0 <= fraction < 0.5:
        raise marg.fail("fraction", f"must be in [0, 0.5), got {fraction}")
    marg.done()

    fq = top.table("fit_quality")

    def opt(key: str, scale: float = 1.0) -> float | None:
        v = fq.number(key, positive=True, required=False)
        return None if v is None else v * scale

    fit_quality = FitQualityLimits(
        accel_residual_rms_mps2=opt("accel_residual_rms_mps2"),
        gyro_residual_rms_radps=opt("gyro_residual_rms_dps", _DEG),
        accel_misalignment_std=opt("accel_misalignment_std"),
        gyro_misalignment_std=opt("gyro_misalignment_std"),
        accel_bias_static_std_mps2=opt("accel_bias_static_std_mps2"),
        gyro_bias_static_std_radps=opt("gyro_bias_static_std_dps", _DEG),
    )
    fq.done()
    thermal = _thermal(top.table("thermal")) if fmt == LIMITS_FORMAT and top.has("thermal") else None
    product = ProductLimits(name=f"{name}@{version}", accel=accel, gyro=gyro, k_sigma=k_sigma, fit_quality=fit_quality,
                            rule=rule, inconclusive=inconclusive, marginal_fraction=fraction,
                            plausibility=frozenset(plaus), plausibility_k=3.0 if plaus_k is None else plaus_k,
                            thermal=thermal)

    ver = top.table("verification")
    try:
        verification = VerificationLimits(
            accel_mps2=ver.value("accel_error_mps2", positive=True),
            gyro_static_radps=ver.value("gyro_static_error_dps", positive=True) * _DEG,
            rate_radps=ver.value("rate_error_dps", positive=True) * _DEG,
            pose=ver.text("pose"),
            rate_pose=ver.text("rate_pose"),
            rate_dps=ver.value("rate_dps"),
            settle_s=ver.value("settle_s", positive=True),
            hold_s=ver.value("hold_s", positive=True),
        )
    except ValueError as exc:
        raise LimitsFileError(f"{source}: verification: {exc}") from exc
    ver.done()

    rt = top.table("retest")
    n = rt.raw("max_attempts")
    if isinstance(n, bool) or not isinstance(n, int) or n < 1:
        raise rt.fail("max_attempts", f"expected an integer >= 1, got {n!r}")
    rt.done()
    top.done()
    return LimitsFile(
        name=name,
        version=version,
        sha256=hashlib.sha256(raw).hexdigest(),
        path=path,
        product=product,
        marginal_fraction=fraction,
        fit_quality=fit_quality,
        verification=verification,
        retest=RetestPolicy(n),
        correlation_time_s=tc_ranges,
        drift_noise=drift_noise,
    )


def load_limits(path: str | Path | None = None) -> LimitsFile:
    """Load and validate a limits file (default: ``fixtures/limits/default.toml``)."""
    p = Path(path) if path is not None else DEFAULT_LIMITS_PATH
    try:
        raw = p.read_bytes()
    except OSError as exc:
        raise LimitsFileError(f"cannot read limits file {p}: {exc.strerror or exc}") from exc
    return parse_limits(raw, str(p), p)


__all__ = [
    "DEFAULT_LIMITS_PATH",
    "LIMITS_FORMAT",
    "LIMITS_FORMATS",
    "FitQualityLimits",
    "LimitsFile",
    "LimitsFileError",
    "RetestPolicy",
    "VerificationLimits",
    "load_limits",
    "parse_limits",
]
