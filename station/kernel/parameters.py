"""The calibration result: a frozen, versioned parameter set with a JSON round trip, and its typed fit quality.

It lives in the kernel (not beside the estimator in :mod:`station.fit`) because everything below the fit that
uses a calibration (Algorithm 1, the IMU model, the EEPROM image, the store) needs the set, not the estimator.

Units (SI): accelerometer quantities in m/s^2, gyroscope quantities in rad/s, times
in s. The model per triad is the paper's eq. (1):

    x~(t) = M x(t) + b_stat + b_drift * g(t) + n(t),   g(0) = 1,
    dg/dt = -g / T_c + w_g                              (eq. 3)

so the bias starts at ``b_stat + b_drift`` at power-on and settles to ``b_stat``.

Format ``station-params/2`` adds the compensable effects beyond eq. (1) (the paper's own next
step, "thermal effects depending on the ambient temperature"), per triad and output axis k,
with ``dT = T - T_ref`` the unit's temperature minus :attr:`ParameterSet.reference_temperature_degc`:

    x~_k = (M x)_k (1 + sum_j s_kj dT^j) + b_stat,k + sum_j c_kj dT^j + b_drift,k g(t) + n,  j = 1..3

(``temp_scale_coeff`` s, ``temp_bias_coeff`` c; zeros beyond the fitted order), the symmetric scale
nonlinearity ``u + k u|u|`` applied to ``(M x)_k (1 + s dT)``, the gyro's g-sensitivity, and the unit's
time offset. A ``station-params/1`` file still loads, with all of them zero and no reference temperature.

Format ``station-params/3`` adds the IEEE Std 952 scale-factor polynomial of the gyro and accelerometer
(the even and the cubic term, per output axis k, on ``u = (M x)_k (1 + s dT)``):

    y_k = u + k_nl u|u| + k2 u^2 + k3 u^3        (``scale_nonlinearity``, ``scale_quadratic``, ``scale_cubic``)

and makes the time offset a compensated term: ``time_offset_s`` (tau, with ``time_offset_std_s``) is the
sensor's lag behind the rig (the sample stamped t holds the input at rig time t - tau), estimated by the fit
and applied by Algorithm 1 (:mod:`station.correct.streaming`). A set writes ``/3`` only when it has a
polynomial term or a non-zero time offset; otherwise it writes ``/2``, byte for byte as before. A ``/2``
file loads with k2 = k3 = 0 (its ``time_offset_s`` was never fitted: 0). The ``u|u|`` term stays in all
three formats (old files and images keep meaning what they meant); the fit now fits k2 and k3 instead.
Every estimate carries a standard uncertainty (``*_std``, same unit). An estimate
that the recording cannot resolve is NaN in memory and ``null`` in JSON; an estimate that the fit computed
but the recording cannot determine (e.g. a correlation time far beyond the record's length) keeps its number
and is flagged in :attr:`FitQuality.undetermined` (``quality.determinability`` in JSON), so that no reader
prints it as a result (:meth:`ParameterSet.constant_bias_values` states the rule an export uses instead).
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Mapping
from dataclasses import dataclass, field, fields, replace
from pathlib import Path
from typing import Any

import numpy as np

from station.kernel.errors import FormatError, UnsupportedVersionError

FORMAT_2 = "station-params/2"
#: The format of a set with a scale polynomial term (k2, k3) or a time offset.
FORMAT = "station-params/3"
#: Formats :meth:`ParameterSet.from_dict` reads (``/1``: no compensable effects beyond eq. 1 and g-sensitivity;
#: ``/2``: no scale polynomial, no applied time offset).
FORMATS = ("station-params/1", FORMAT_2, FORMAT)
#: Highest polynomial order of the temperature terms.
MAX_TEMP_ORDER = 3
#: What :attr:`ThermalFit.status` can say.
THERMAL_STATUSES = ("fitted", "not_separable", "no_temperature", "disabled", "absent")


def _arr(value: Any, shape: tuple[int, ...]) -> np.ndarray:
    a = np.array(value, dtype=np.float64)
    if a.shape != shape:
        raise FormatError(f"expected shape {shape}, got {a.shape}")
    a.flags.writeable = False
    return a


def _to_json_value(a: np.ndarray) -> Any:
    return json.loads(json.dumps(np.where(np.isfinite(a), a, np.nan).tolist()).replace("NaN", "null"))


def _from_json_value(v: Any) -> Any:
    if v is None:
        return math.nan
    if isinstance(v, list):
        return [_from_json_value(x) for x in v]
    return v


@dataclass(frozen=True, eq=False)
class AllanCoefficients:
    """IEEE Std 952 noise coefficients from the Allan deviation, per axis.

    For a gyro (rad/s): ``random_walk`` is the angle random walk N (rad/s/sqrt(Hz)
    = rad/sqrt(s)), ``bias_instability`` B (rad/s), ``rate_random_walk`` K
    (rad/s^2/sqrt(Hz)). For an accelerometer the same in m/s^2: velocity random walk
    (m/s^2/sqrt(Hz)), bias instability (m/s^2), acceleration random walk
    (m/s^3/sqrt(Hz)). Each shape (3,), with ``*_std`` standard uncertainties.
    """

    random_walk: np.ndarray
    random_walk_std: np.ndarray
    bias_instability: np.ndarray
    bias_instability_std: np.ndarray
    rate_random_walk: np.ndarray
    rate_random_walk_std: np.ndarray

    def __post_init__(self) -> None:
        for f in fields(self):
            object.__setattr__(self, f.name, _arr(getattr(self, f.name), (3,)))


@dataclass(frozen=True, eq=False)
class TriadParams:
    """Fitted parameters of one sensor triad (accelerometer or gyroscope).

    Attributes (unit U = m/s^2 for the accelerometer, rad/s for the gyroscope):
        misalignment: M, scale on the diagonal and cross-axis terms off it, (3, 3), 1.
        bias_static: b_stat, asymptotic bias (U), (3,).
        bias_drift: b_drift, drifting bias at power-on (U), (3,).
        correlation_time_s: T_c of the Gauss-Markov drift (s), (3,); NaN if unresolved.
        drift_noise: stationary std of the drift's stochastic part (U), (3,).
        noise_std: white-noise std per sample (U), (3,) (the paper's sigma).
        g_sensitivity: gyro output per unit specific force (rad/s per m/s^2), (3, 3);
            zeros for the accelerometer or when not fitted.
        allan: Allan-deviation noise coefficients.
        residual_rms: RMS of the fit residual per axis (U), (3,).
        temp_bias_coeff: c_kj, bias change per K^j of ``T - T_ref`` (U/K^j), (3, 3): row k = output
            axis, column j - 1 = order j (1..3); zeros beyond the fitted order or when not fitted.
        temp_scale_coeff: s_kj, relative scale change per K^j (1/K^j), (3, 3), same layout.
        scale_nonlinearity: k of ``u + k u|u|`` per axis (1/U), (3,); zeros when not fitted (the fit of
            ``station-params/3`` fits the polynomial below instead; the term stays for older sets).
        scale_quadratic: k2 of the IEEE 952 polynomial ``u + k2 u^2 + k3 u^3`` per axis (1/U), (3,).
        scale_cubic: k3 of that polynomial per axis (1/U^2), (3,).
        (``*_std``: standard uncertainties; 0 for terms not in the model.)
    """

    misalignment: np.ndarray
    misalignment_std: np.ndarray
    bias_static: np.ndarray
    bias_static_std: np.ndarray
    bias_drift: np.ndarray
    bias_drift_std: np.ndarray
    correlation_time_s: np.ndarray
    correlation_time_s_std: np.ndarray
    drift_noise: np.ndarray
    drift_noise_std: np.ndarray
    noise_std: np.ndarray
    noise_std_std: np.ndarray
    allan: AllanCoefficients
    residual_rms: np.ndarray
    g_sensitivity: np.ndarray = field(default_factory=lambda: np.zeros((3, 3)))
    g_sensitivity_std: np.ndarray = field(default_factory=lambda: np.zeros((3, 3)))
    temp_bias_coeff: np.ndarray = field(default_factory=lambda: np.zeros((3, MAX_TEMP_ORDER)))
    temp_bias_coeff_std: np.ndarray = field(default_factory=lambda: np.zeros((3, MAX_TEMP_ORDER)))
    temp_scale_coeff: np.ndarray = field(default_factory=lambda: np.zeros((3, MAX_TEMP_ORDER)))
    temp_scale_coeff_std: np.ndarray = field(default_factory=lambda: np.zeros((3, MAX_TEMP_ORDER)))
    scale_nonlinearity: np.ndarray = field(default_factory=lambda: np.zeros(3))
    scale_nonlinearity_std: np.ndarray = field(default_factory=lambda: np.zeros(3))
    scale_quadratic: np.ndarray = field(default_factory=lambda: np.zeros(3))
    scale_quadratic_std: np.ndarray = field(default_factory=lambda: np.zeros(3))
    scale_cubic: np.ndarray = field(default_factory=lambda: np.zeros(3))
    scale_cubic_std: np.ndarray = field(default_factory=lambda: np.zeros(3))

    _MATRIX_FIELDS = (
        "misalignment", "misalignment_std", "g_sensitivity", "g_sensitivity_std",
        "temp_bias_coeff", "temp_bias_coeff_std", "temp_scale_coeff", "temp_scale_coeff_std",
    )
    #: Fields a ``station-params/1`` file does not have (they default to zero).
    _V2_FIELDS = (
        "temp_bias_coeff", "temp_bias_coeff_std", "temp_scale_coeff", "temp_scale_coeff_std",
        "scale_nonlinearity", "scale_nonlinearity_std",
    )
    #: Fields a ``station-params/2`` file does not have (they default to zero).
    _V3_FIELDS = ("scale_quadratic", "scale_quadratic_std", "scale_cubic", "scale_cubic_std")

    def __post_init__(self) -> None:
        for f in fields(self):
            if f.name == "allan":
                continue
            shape = (3, 3) if f.name in self._MATRIX_FIELDS else (3,)
            object.__setattr__(self, f.name, _arr(getattr(self, f.name), shape))

    @property
    def has_polynomial(self) -> bool:
        """A non-zero IEEE 952 polynomial term (k2 or k3)."""
        return bool(np.any(self.scale_quadratic != 0) or np.any(self.scale_cubic != 0))

    def to_dict(self, version: int = 3) -> dict[str, Any]:
        out: dict[str, Any] = {}
        for f in fields(self):
            value = getattr(self, f.name)
            if version < 3 and f.name in self._V3_FIELDS:
                continue
            if f.name == "allan":
                out["allan"] = {g.name: _to_json_value(getattr(value, g.name)) for g in fields(value)}
            else:
                out[f.name] = _to_json_value(value)
        return out

    def warmup_drift(self, t_s: np.ndarray) -> np.ndarray:
        """Eq. 3's warm-up ``b_drift exp(-t/T_c)`` at the times ``t_s`` (s since power-on), (n, 3), in the triad's
        unit; zero on axes the fit left unresolved (T_c or b_drift not finite, or b_drift 0)."""
        t = np.asarray(t_s, dtype=float)
        out = np.zeros((len(t), 3))
        for k in range(3):
            tc, bd = float(self.correlation_time_s[k]), float(self.bias_drift[k])
            if math.isfinite(tc) and tc > 0 and math.isfinite(bd) and bd != 0.0:
                out[:, k] = bd * np.exp(-t / tc)
        return out

    @property
    def has_temperature_terms(self) -> bool:
        """Any non-zero temperature coefficient."""
        return bool(np.any(self.temp_bias_coeff != 0) or np.any(self.temp_scale_coeff != 0))

    @classmethod
    def from_dict(cls, d: dict[str, Any], version: int = 3) -> TriadParams:
        try:
            kwargs = {f.name: _from_json_value(d[f.name]) for f in fields(cls)
                      if f.name != "allan" and (version >= 2 or f.name not in cls._V2_FIELDS)
                      and (version >= 3 or f.name not in cls._V3_FIELDS)}
            if not isinstance(d["allan"], dict):
                raise TypeError("'allan' must be an object")
            allan = AllanCoefficients(**{k: _from_json_value(v) for k, v in d["allan"].items()})
            return cls(allan=allan, **kwargs)
        except (KeyError, TypeError, ValueError, AttributeError) as exc:
            raise FormatError(f"parameter set: triad is missing or has a bad field: {_brief(exc)}") from exc


@dataclass(frozen=True)
class ThermalFit:
    """Whether and how the temperature terms were fitted (the typed note of the result).

    Attributes:
        status: ``'fitted'``; ``'not_separable'``: the recording's temperature does not move enough, or
            moves only along a warm-up shape, to tell a temperature course from eq. 3's warm-up drift
            (``reason`` says which and by how much); ``'no_temperature'``: the recording has no
            temperature column; ``'disabled'``: the fit was told not to; ``'absent'``: a
            ``station-params/1`` file or an EEPROM image without thermal terms.
        reason: one line for people.
        span_k: range of the block-mean temperature over the settled data (K); NaN when unknown.
        independent_k: RMS of the temperature course left after the best warm-up shape
            ``a + b exp(-t/tau)`` (any tau) is taken out (K): what the fit separates the terms on.
        orders: per triad (``'accel'``, ``'gyro'``) and term (``'bias'``, ``'scale'``), the polynomial
            order fitted per output axis (x, y, z), e.g. ``{'gyro': {'bias': [1, 2, 1], 'scale': [1, 1, 1]}}``.
        rule: how the orders were chosen (stated in the result).
    """

    status: str = "absent"
    reason: str = ""
    span_k: float = math.nan
    independent_k: float = math.nan
    orders: dict[str, dict[str, list[int]]] = field(default_factory=dict)
    rule: str = ""

    def __post_init__(self) -> None:
        if self.status not in THERMAL_STATUSES:
            raise FormatError(f"thermal status must be one of {', '.join(THERMAL_STATUSES)}, got {self.status!r}")

    @property
    def fitted(self) -> bool:
        return self.status == "fitted"

    def to_dict(self) -> dict[str, Any]:
        def num(x: float) -> float | None:
            return float(x) if math.isfinite(x) else None

        return {"status": self.status, "reason": self.reason, "span_k": num(self.span_k),
                "independent_k": num(self.independent_k), "orders": self.orders, "rule": self.rule}

    @classmethod
    def from_dict(cls, d: Any) -> ThermalFit:
        if not isinstance(d, dict):
            raise TypeError("'thermal' must be an object")
        orders = d.get("orders", {})
        if not isinstance(orders, dict):
            raise TypeError("'thermal.orders' must be an object")
        clean: dict[str, dict[str, list[int]]] = {}
        for tri, terms in orders.items():
            if not isinstance(terms, dict):
                raise TypeError("'thermal.orders' entries must be objects")
            clean[str(tri)] = {}
            for term, v in terms.items():
                if not (isinstance(v, list) and len(v) == 3
                        and all(isinstance(x, int) and not isinstance(x, bool) and 0 <= x <= MAX_TEMP_ORDER
                                for x in v)):
                    raise TypeError(f"'thermal.orders.{tri}.{term}' must be three orders 0..{MAX_TEMP_ORDER}")
                clean[str(tri)][str(term)] = list(v)
        span, indep = d.get("span_k"), d.get("independent_k")
        for name, v in (("span_k", span), ("independent_k", indep)):
            if v is not None and (isinstance(v, bool) or not isinstance(v, int | float)):
                raise TypeError(f"'thermal.{name}' must be a number or null")
        return cls(status=str(d.get("status", "absent")), reason=str(d.get("reason", "")),
                   span_k=math.nan if span is None else float(span),
                   independent_k=math.nan if indep is None else float(indep), orders=clean,
                   rule=str(d.get("rule", "")))


#: The parameters whose determinability :class:`FitQuality` states, per triad and axis.
DETERMINABLE = ("bias_static", "bias_drift", "correlation_time_s")
AXES = "xyz"


def _numbers(v: Any, what: str) -> tuple[float, ...]:
    if not isinstance(v, list) or not all(
            x is None or (isinstance(x, int | float) and not isinstance(x, bool)) for x in v):
        raise TypeError(f"{what!r} must be a list of numbers")
    return tuple(math.nan if x is None else float(x) for x in v)


def _num_json(x: float) -> float | None:
    return x if math.isfinite(x) else None


@dataclass(frozen=True)
class ResidualFigures:
    """RMS of the fit residual of one triad (its unit) over the samples the fit kept: per axis, and per segment
    (segment index as text -> per axis) when the fit went segment by segment; ``samples`` the count (None when
    not stated, e.g. a rig-free fit)."""

    rms: tuple[float, ...]
    segments: Mapping[str, tuple[float, ...]] | None = None
    samples: int | None = None

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {"rms": [_num_json(x) for x in self.rms]}
        if self.segments is not None:
            out["segments"] = {k: [_num_json(x) for x in v] for k, v in self.segments.items()}
        if self.samples is not None:
            out["samples"] = self.samples
        return out

    @classmethod
    def from_dict(cls, d: Any, what: str) -> ResidualFigures:
        if not isinstance(d, dict):
            raise TypeError(f"'quality.{what}' must be an object")
        segs = d.get("segments")
        if segs is not None and not isinstance(segs, dict):
            raise TypeError(f"'quality.{what}.segments' must be an object")
        samples = d.get("samples")
        if samples is not None and (isinstance(samples, bool) or not isinstance(samples, int)):
            raise TypeError(f"'quality.{what}.samples' must be an integer")
        return cls(rms=_numbers(d.get("rms"), f"quality.{what}.rms"),
                   segments=None if segs is None else {str(k): _numbers(v, f"quality.{what}.segments")
                                                       for k, v in segs.items()},
                   samples=samples)


@dataclass(frozen=True)
class GoodnessOfFit:
    """The fit's test against its own recording (``station-goodness/1``): ``passed``, the names of the failed
    tests (``'<triad> <segment kind>'``), and the whole report as the fit wrote it (per-test statistics, or a
    rig-free fit's ``note``), read-only."""

    passed: bool
    failed: tuple[str, ...] = ()
    report: Mapping[str, Any] = field(default_factory=dict)

    @property
    def note(self) -> str:
        return str(self.report.get("note", ""))

    def to_dict(self) -> dict[str, Any]:
        return {**self.report, "passed": self.passed, "failed": list(self.failed)}

    @classmethod
    def from_dict(cls, d: Any) -> GoodnessOfFit:
        if not isinstance(d, dict) or not isinstance(d.get("passed"), bool):
            raise TypeError("'quality.goodness_of_fit' must be an object with a boolean 'passed'")
        failed = d.get("failed", [])
        if not isinstance(failed, list) or not all(isinstance(x, str) for x in failed):
            raise TypeError("'quality.goodness_of_fit.failed' must be a list of names")
        return cls(passed=d["passed"], failed=tuple(failed), report=json.loads(json.dumps(d)))


@dataclass(frozen=True)
class NonlinearityNote:
    """Whether a triad's scale polynomial ``u + k2 u^2 + k3 u^3`` was fitted: ``status`` (``'fitted'``,
    ``'not_significant'``, ``'not_identifiable'``), the axes kept, the rule, a reason when not fitted, and the
    rest of the fit's note (rate levels per axis, Wald statistics) read-only in ``detail``."""

    status: str
    axes: tuple[str, ...] = ()
    rule: str = ""
    reason: str = ""
    detail: Mapping[str, Any] = field(default_factory=dict)

    @property
    def fitted(self) -> bool:
        return self.status == "fitted"

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {"status": self.status, "rule": self.rule, "axes": list(self.axes)}
        out.update(self.detail)
        if self.reason:
            out["reason"] = self.reason
        return out

    @classmethod
    def from_dict(cls, d: Any, name: str = "scale_nonlinearity") -> NonlinearityNote:
        if not isinstance(d, dict) or not isinstance(d.get("status"), str):
            raise TypeError(f"'quality.{name}' must be an object with a 'status'")
        axes = d.get("axes", [])
        if not isinstance(axes, list) or not all(isinstance(a, str) for a in axes):
            raise TypeError(f"'quality.{name}.axes' must be a list of axis names")
        detail = {k: v for k, v in d.items() if k not in ("status", "rule", "axes", "reason")}
        return cls(status=d["status"], axes=tuple(axes), rule=str(d.get("rule", "")), reason=str(d.get("reason", "")),
                   detail=json.loads(json.dumps(detail)))


#: What :attr:`TimeOffsetNote.status` can say (``'beyond_range'``: estimated, more than Algorithm 1 applies).
TIME_OFFSET_STATUSES = ("fitted", "not_significant", "not_determined", "beyond_range")
#: Largest lag (samples) Algorithm 1's line 0 extrapolates over, and largest lead its delay line holds.
MAX_LAG_SAMPLES = 4.0
MAX_LEAD_SAMPLES = 1024.0


@dataclass(frozen=True)
class TimeOffsetNote:
    """The fit's estimate of the time offset tau (the sensor's lag behind the rig's reference, s) and what it did
    with it: ``'fitted'`` (kept: in :attr:`ParameterSet.time_offset_s`, applied by Algorithm 1),
    ``'not_significant'`` (estimated, below the Wald threshold: the set keeps 0), ``'not_determined'`` (the
    recording's transitions do not determine it: ``estimate_s`` NaN, with the reason and the rig step that would).
    ``transitions``: the move/ramp segments that carried information; ``rule``: the estimator and the selection."""

    status: str
    estimate_s: float = math.nan
    std_s: float = math.nan
    transitions: int = 0
    rule: str = ""
    reason: str = ""

    def __post_init__(self) -> None:
        if self.status not in TIME_OFFSET_STATUSES:
            raise FormatError(f"time offset status must be one of {', '.join(TIME_OFFSET_STATUSES)}, "
                              f"got {self.status!r}")

    @property
    def fitted(self) -> bool:
        return self.status == "fitted"

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {"status": self.status, "estimate_s": _num_json(self.estimate_s),
                               "std_s": _num_json(self.std_s), "transitions": self.transitions, "rule": self.rule}
        if self.reason:
            out["reason"] = self.reason
        return out

    @classmethod
    def from_dict(cls, d: Any) -> TimeOffsetNote:
        if not isinstance(d, dict) or not isinstance(d.get("status"), str):
            raise TypeError("'quality.time_offset' must be an object with a 'status'")
        vals = []
        for name in ("estimate_s", "std_s"):
            v = d.get(name)
            if v is not None and (isinstance(v, bool) or not isinstance(v, int | float)):
                raise TypeError(f"'quality.time_offset.{name}' must be a number or null")
            vals.append(math.nan if v is None else float(v))
        n = d.get("transitions", 0)
        if isinstance(n, bool) or not isinstance(n, int):
            raise TypeError("'quality.time_offset.transitions' must be an integer")
        return cls(status=d["status"], estimate_s=vals[0], std_s=vals[1], transitions=n, rule=str(d.get("rule", "")),
                   reason=str(d.get("reason", "")))


@dataclass(frozen=True)
class Undetermined:
    """One parameter of one triad axis that the recording cannot determine (its number is kept in the set but
    is not a result): ``triad`` ``'accel'`` or ``'gyro'``, ``parameter`` a :data:`DETERMINABLE` field name,
    ``axis`` 0..2, ``reason`` one line for people (with the numbers that decided it)."""

    triad: str
    parameter: str
    axis: int
    reason: str

    def __post_init__(self) -> None:
        if self.triad not in ("accel", "gyro") or self.parameter not in DETERMINABLE or self.axis not in (0, 1, 2):
            raise FormatError(f"undetermined parameter {self.triad!r} {self.parameter!r} axis {self.axis!r}: "
                              f"expected accel/gyro, one of {', '.join(DETERMINABLE)}, axis 0..2")

    def to_dict(self) -> dict[str, Any]:
        return {"triad": self.triad, "parameter": self.parameter, "axis": AXES[self.axis], "reason": self.reason}

    @classmethod
    def from_dict(cls, d: Any) -> Undetermined:
        if not isinstance(d, dict) or d.get("axis") not in tuple(AXES):
            raise TypeError("'quality.determinability.undetermined' entries must be objects with an axis x, y or z")
        return cls(triad=str(d.get("triad")), parameter=str(d.get("parameter")), axis=AXES.index(d["axis"]),
                   reason=str(d.get("reason", "")))


@dataclass(frozen=True)
class FitQuality:
    """How good a parameter set is, as the fit judged it (one typed object; a dict only in JSON, ``quality``).

    Attributes:
        accel, gyro: residual figures per triad (None: not stated, e.g. an EEPROM image).
        gyro_scale_method: how M_w was found (``'rate'``, ``'angle'``, ``'rig-free'``; ``''`` not stated).
        outliers: samples the noise estimate left out, per triad and axis.
        drift_likelihood_ratio: eq. 3's drift against none, per triad and axis.
        known_angle: the known-angle gyro fit's report (a Ferraris recording), read-only JSON.
        scale_nonlinearity: the gyro's scale polynomial note (None when the fit did not consider it).
        accel_scale_polynomial: the accelerometer's scale polynomial note (None when the fit did not consider it,
            e.g. a set from before the accelerometer's polynomial was fitted).
        time_offset: the time-offset note (None when the fit did not consider it).
        goodness_of_fit: the test against the recording (None: not tested, e.g. an image or an old file).
        rig_free: a rig-free fit's report (``station-rigfree/1``: convention, gravity-norm and move figures,
            covariances, cross-validation, read timing), read-only JSON; None for a rig fit.
        determinability_rule: the rule that decided :attr:`undetermined` (``''``: not assessed, e.g. an old file).
        undetermined: the parameters the recording cannot determine.
        record_end_s: time since power-on of the recording's last sample (s; NaN: not stated), where
            :meth:`ParameterSet.constant_bias_values` evaluates the bias of an axis whose b_stat is not determined.
        extra: sections this software does not know (kept for the round trip), read-only JSON.
    """

    accel: ResidualFigures | None = None
    gyro: ResidualFigures | None = None
    gyro_scale_method: str = ""
    outliers: Mapping[str, tuple[int, ...]] | None = None
    drift_likelihood_ratio: Mapping[str, tuple[float, ...]] | None = None
    known_angle: Mapping[str, Any] | None = None
    scale_nonlinearity: NonlinearityNote | None = None
    accel_scale_polynomial: NonlinearityNote | None = None
    goodness_of_fit: GoodnessOfFit | None = None
    rig_free: Mapping[str, Any] | None = None
    determinability_rule: str = ""
    undetermined: tuple[Undetermined, ...] = ()
    record_end_s: float = math.nan
    extra: Mapping[str, Any] = field(default_factory=dict)
    time_offset: TimeOffsetNote | None = None

    _KNOWN = ("rig_free", "accel", "gyro", "gyro_scale_method", "outliers", "drift_likelihood_ratio", "known_angle",
              "scale_nonlinearity", "accel_scale_polynomial", "goodness_of_fit", "determinability", "time_offset")

    @property
    def passed(self) -> bool:
        """False only when the goodness-of-fit test ran and failed."""
        return self.goodness_of_fit is None or self.goodness_of_fit.passed

    def is_determined(self, triad: str, parameter: str, axis: int) -> bool:
        return self.why_undetermined(triad, parameter, axis) is None

    def why_undetermined(self, triad: str, parameter: str, axis: int) -> str | None:
        """The reason ``parameter`` of ``triad`` on ``axis`` is not determined, or None when it is."""
        for u in self.undetermined:
            if (u.triad, u.parameter, u.axis) == (triad, parameter, axis):
                return u.reason
        return None

    def residual(self, triad: str) -> ResidualFigures | None:
        return self.accel if triad == "accel" else self.gyro if triad == "gyro" else None

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {}
        if self.rig_free is not None:
            out["rig_free"] = dict(self.rig_free)
        if self.accel is not None:
            out["accel"] = self.accel.to_dict()
        if self.gyro is not None:
            out["gyro"] = self.gyro.to_dict()
        if self.gyro_scale_method:
            out["gyro_scale_method"] = self.gyro_scale_method
        if self.outliers is not None:
            out["outliers"] = {k: list(v) for k, v in self.outliers.items()}
        if self.drift_likelihood_ratio is not None:
            out["drift_likelihood_ratio"] = {k: [_num_json(x) for x in v]
                                             for k, v in self.drift_likelihood_ratio.items()}
        if self.known_angle is not None:
            out["known_angle"] = dict(self.known_angle)
        if self.scale_nonlinearity is not None:
            out["scale_nonlinearity"] = self.scale_nonlinearity.to_dict()
        if self.accel_scale_polynomial is not None:
            out["accel_scale_polynomial"] = self.accel_scale_polynomial.to_dict()
        if self.time_offset is not None:
            out["time_offset"] = self.time_offset.to_dict()
        if self.goodness_of_fit is not None:
            out["goodness_of_fit"] = self.goodness_of_fit.to_dict()
        if self.determinability_rule:
            out["determinability"] = {"rule": self.determinability_rule, "record_end_s": _num_json(self.record_end_s),
                                      "undetermined": [u.to_dict() for u in self.undetermined]}
        out.update(self.extra)
        return out

    @classmethod
    def from_dict(cls, d: Any) -> FitQuality:
        """The quality section of a parameter file; a known section of the wrong shape is a TypeError."""
        if not isinstance(d, dict):
            raise TypeError("'quality' must be an object")

        def section(name: str) -> Mapping[str, Any] | None:
            v = d.get(name)
            if v is not None and not isinstance(v, dict):
                raise TypeError(f"'quality.{name}' must be an object")
            # a section kept as JSON must be writable again: NaN and infinity are refused here, not at the next save
            return None if v is None else json.loads(json.dumps(v, allow_nan=False))

        def per_triad(name: str) -> dict[str, list[Any]] | None:
            v = section(name)
            if v is not None and not all(isinstance(x, list) for x in v.values()):
                raise TypeError(f"'quality.{name}' must map triads to lists")
            return None if v is None else dict(v)

        outliers = per_triad("outliers")
        if outliers is not None and not all(isinstance(i, int) and not isinstance(i, bool)
                                            for v in outliers.values() for i in v):
            raise TypeError("'quality.outliers' must map triads to lists of counts")
        lr = per_triad("drift_likelihood_ratio")
        det = section("determinability")
        if det is not None and not isinstance(det.get("undetermined", []), list):
            raise TypeError("'quality.determinability.undetermined' must be a list")
        end = None if det is None else det.get("record_end_s")
        if end is not None and (isinstance(end, bool) or not isinstance(end, int | float)):
            raise TypeError("'quality.determinability.record_end_s' must be a number or null")
        method = d.get("gyro_scale_method", "")
        if not isinstance(method, str):
            raise TypeError("'quality.gyro_scale_method' must be text")
        return cls(
            accel=None if d.get("accel") is None else ResidualFigures.from_dict(d["accel"], "accel"),
            gyro=None if d.get("gyro") is None else ResidualFigures.from_dict(d["gyro"], "gyro"),
            gyro_scale_method=method,
            outliers=None if outliers is None else {k: tuple(v) for k, v in outliers.items()},
            drift_likelihood_ratio=None if lr is None else {k: _numbers(v, f"quality.drift_likelihood_ratio.{k}")
                                                           for k, v in lr.items()},
            known_angle=section("known_angle"),
            scale_nonlinearity=(None if d.get("scale_nonlinearity") is None
                                else NonlinearityNote.from_dict(d["scale_nonlinearity"])),
            accel_scale_polynomial=(None if d.get("accel_scale_polynomial") is None
                                    else NonlinearityNote.from_dict(d["accel_scale_polynomial"],
                                                                    "accel_scale_polynomial")),
            goodness_of_fit=None if d.get("goodness_of_fit") is None else GoodnessOfFit.from_dict(d["goodness_of_fit"]),
            time_offset=None if d.get("time_offset") is None else TimeOffsetNote.from_dict(d["time_offset"]),
            rig_free=section("rig_free"),
            determinability_rule="" if det is None else str(det.get("rule", "")),
            undetermined=() if det is None else tuple(Undetermined.from_dict(u) for u in det.get("undetermined", [])),
            record_end_s=math.nan if end is None else float(end),
            extra=json.loads(json.dumps({k: v for k, v in d.items() if k not in cls._KNOWN}, allow_nan=False)),
        )


@dataclass(frozen=True, eq=False)
class ParameterSet:
    """Everything Algorithm 1 and the station need about one calibrated unit.

    Attributes:
        serial: the unit's serial number.
        sample_period_s: T_sampl of Algorithm 1 (s).
        moving_average_length: n of the one-sided moving average, eq. (6).
        accel: accelerometer triad (m/s^2).
        gyro: gyroscope triad (rad/s).
        quality: how good the set is, as the fit judged it, and which parameters the recording cannot
            determine (:class:`FitQuality`).
        source: where the parameters came from (session hash, software version, ...).
        reference_temperature_degc: T_ref of the temperature terms (degC); NaN when the set has none.
        time_offset_s: tau, the sensor's lag behind the rig (s): the sample stamped t holds the input at rig
            time t - tau (the unit's sample time minus the rig's); 0 when not fitted or not kept. Algorithm 1
            shifts its input by it (:mod:`station.correct.streaming`).
        time_offset_std_s: its standard uncertainty (s); 0 when not fitted, NaN when not stated (an image).
        thermal: whether the temperature terms were fitted, and why not (:class:`ThermalFit`).
    """

    serial: str
    sample_period_s: float
    accel: TriadParams
    gyro: TriadParams
    moving_average_length: int = 40
    quality: FitQuality = field(default_factory=FitQuality)
    source: dict[str, Any] = field(default_factory=dict)
    reference_temperature_degc: float = math.nan
    time_offset_s: float = 0.0
    thermal: ThermalFit = field(default_factory=ThermalFit)
    time_offset_std_s: float = 0.0

    @property
    def compensates_temperature(self) -> bool:
        """Algorithm 1 applies temperature terms: a finite T_ref and a non-zero coefficient."""
        return math.isfinite(self.reference_temperature_degc) and (
            self.accel.has_temperature_terms or self.gyro.has_temperature_terms
        )

    @property
    def has_nonlinearity(self) -> bool:
        """Any scale nonlinearity term (``u|u|``, k2 or k3) is non-zero."""
        return bool(np.any(self.accel.scale_nonlinearity != 0) or np.any(self.gyro.scale_nonlinearity != 0)
                    or self.has_polynomial)

    @property
    def has_polynomial(self) -> bool:
        """An IEEE 952 polynomial term (k2, k3) is non-zero in either triad."""
        return self.accel.has_polynomial or self.gyro.has_polynomial

    @property
    def format(self) -> str:
        """The format the set writes: ``/3`` with a polynomial term or a time offset, else ``/2``."""
        return FORMAT if (self.has_polynomial or self.time_offset_s != 0.0) else FORMAT_2

    def constant_bias_values(self) -> tuple[ParameterSet, tuple[str, ...]]:
        """The set with one constant bias per axis where b_stat is not determined (for a consumer that holds a
        constant bias only: the exports), and one note per such axis.

        Rule: where the recording cannot determine b_stat (:attr:`FitQuality.undetermined`; T_c beyond the
        recording), the fitted bias at the end of the recording, ``b_stat + b_drift exp(-t_end/T_c)`` (what the
        recording last saw), with b_drift 0 and T_c unresolved (NaN), instead of an extrapolated asymptote; its
        uncertainty is not stated (NaN: the fit gives no covariance to combine). Other axes unchanged. Raises
        :class:`FormatError` when an axis needs the rule but the set does not state the recording's end time
        (refused rather than guessed).

        A device that applies Algorithm 1 keeps the fitted warm-up curve instead (the recording determines the
        curve over its length, after every power-on; see :mod:`station.eeprom.image`).
        """
        triads: dict[str, TriadParams] = {}
        notes: list[str] = []
        for name, tri in (("accel", self.accel), ("gyro", self.gyro)):
            axes = sorted({u.axis for u in self.quality.undetermined
                           if u.triad == name and u.parameter == "bias_static"})
            if not axes:
                triads[name] = tri
                continue
            b_stat, b_drift = tri.bias_static.copy(), tri.bias_drift.copy()
            tc, b_stat_std = tri.correlation_time_s.copy(), tri.bias_static_std.copy()
            b_drift_std, tc_std = tri.bias_drift_std.copy(), tri.correlation_time_s_std.copy()
            t_end = self.quality.record_end_s
            for k in axes:
                if not math.isfinite(t_end):
                    raise FormatError(f"{name} {AXES[k]}: b_stat not determined and no recording end time to "
                                      "evaluate the bias at: no constant bias")
                b_stat[k] = float(tri.bias_static[k]) + float(tri.warmup_drift(np.array([t_end]))[0, k])
                b_stat_std[k] = b_drift_std[k] = tc_std[k] = math.nan
                b_drift[k], tc[k] = 0.0, math.nan
                notes.append(f"{name} {AXES[k]}: the bias at the end of the recording (t = {t_end:.1f} s), "
                             f"{b_stat[k]:.6g}, instead of b_stat {float(tri.bias_static[k]):.6g} (not determined)")
            triads[name] = replace(tri, bias_static=b_stat, bias_static_std=b_stat_std, bias_drift=b_drift,
                                   bias_drift_std=b_drift_std, correlation_time_s=tc, correlation_time_s_std=tc_std)
        if not notes:
            return self, ()
        return replace(self, accel=triads["accel"], gyro=triads["gyro"]), tuple(notes)

    def to_dict(self) -> dict[str, Any]:
        fmt = self.format
        version = FORMATS.index(fmt) + 1
        extra: dict[str, Any] = {"time_offset_std_s": _num_json(self.time_offset_std_s)} if version >= 3 else {}
        return {
            "format": fmt,
            "serial": self.serial,
            "sample_period_s": self.sample_period_s,
            "moving_average_length": self.moving_average_length,
            "reference_temperature_degc": (
                self.reference_temperature_degc if math.isfinite(self.reference_temperature_degc) else None
            ),
            "time_offset_s": self.time_offset_s,
            **extra,
            "thermal": self.thermal.to_dict(),
            "accel": self.accel.to_dict(version),
            "gyro": self.gyro.to_dict(version),
            "quality": self.quality.to_dict(),
            "source": self.source,
        }

    def to_json(self, indent: int | None = 2) -> str:
        return json.dumps(self.to_dict(), indent=indent, allow_nan=False)

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> ParameterSet:
        fmt = d.get("format") if isinstance(d, dict) else None
        if fmt not in FORMATS:
            raise UnsupportedVersionError(
                f"parameter set has format {fmt!r}; this station reads {', '.join(map(repr, FORMATS))} only"
            )
        version = FORMATS.index(fmt) + 1
        try:
            serial, period, n = d["serial"], d["sample_period_s"], d["moving_average_length"]
            if not isinstance(serial, str) or not serial.strip():
                raise TypeError(f"'serial' must be a non-empty string, got {serial!r}")
            if isinstance(period, bool) or not isinstance(period, int | float) or not math.isfinite(period):
                raise TypeError(f"'sample_period_s' must be a finite number, got {period!r}")
            if isinstance(n, bool) or not isinstance(n, int):
                raise TypeError(f"'moving_average_length' must be an integer, got {n!r}")
            for key in ("quality", "source"):
                if not isinstance(d.get(key, {}), dict):
                    raise TypeError(f"{key!r} must be an object")
            extra: dict[str, Any] = {}
            if version >= 2:
                t_ref, offset = d["reference_temperature_degc"], d["time_offset_s"]
                if t_ref is not None and (isinstance(t_ref, bool) or not isinstance(t_ref, int | float)
                                          or not math.isfinite(t_ref)):
                    raise TypeError(f"'reference_temperature_degc' must be a finite number or null, got {t_ref!r}")
                if isinstance(offset, bool) or not isinstance(offset, int | float) or not math.isfinite(offset):
                    raise TypeError(f"'time_offset_s' must be a finite number, got {offset!r}")
                extra = {
                    "reference_temperature_degc": math.nan if t_ref is None else float(t_ref),
                    "time_offset_s": float(offset),
                    "thermal": ThermalFit.from_dict(d["thermal"]),
                }
            if version >= 3:
                std = d["time_offset_std_s"]  # null: not stated (an EEPROM image)
                if std is not None and (isinstance(std, bool) or not isinstance(std, int | float)
                                        or not (math.isfinite(std) and std >= 0)):
                    raise TypeError(f"'time_offset_std_s' must be a finite number >= 0 or null, got {std!r}")
                extra["time_offset_std_s"] = math.nan if std is None else float(std)
            return cls(
                serial=serial,
                sample_period_s=float(period),
                moving_average_length=n,
                accel=TriadParams.from_dict(d["accel"], version),
                gyro=TriadParams.from_dict(d["gyro"], version),
                quality=FitQuality.from_dict(d.get("quality", {})),
                source=dict(d.get("source", {})),
                **extra,
            )
        except (KeyError, TypeError, ValueError, AttributeError, FormatError) as exc:
            if isinstance(exc, FormatError) and str(exc).startswith("parameter set"):
                raise
            raise FormatError(f"parameter set: missing or bad field: {_brief(exc)}") from exc

    @classmethod
    def from_json(cls, text: str | bytes) -> ParameterSet:
        """Parse a parameter set (text, or UTF-8 bytes); any malformation is a :class:`FormatError`."""
        try:
            if isinstance(text, bytes):
                text = text.decode("utf-8")
            d = json.loads(text)
        except UnicodeDecodeError as exc:
            raise FormatError(f"parameter set is not UTF-8 text (byte {exc.start})") from exc
        except json.JSONDecodeError as exc:
            raise FormatError(f"parameter set is not JSON: {exc}") from exc
        except RecursionError as exc:
            raise FormatError("parameter set is nested too deeply to be a parameter set") from exc
        return cls.from_dict(d)

    @classmethod
    def read(cls, path: str | os.PathLike[str]) -> ParameterSet:
        """Read a parameter JSON file; an unreadable or malformed file is a :class:`FormatError`."""
        try:
            data = Path(path).read_bytes()
        except OSError as exc:
            raise FormatError(f"cannot read parameter set {os.fspath(path)}: {exc.strerror or exc}") from exc
        try:
            return cls.from_json(data)
        except FormatError as exc:
            raise FormatError(f"{os.fspath(path)}: {exc}") from None


def _brief(exc: BaseException) -> str:
    """An exception's message on one line (KeyError quotes its key)."""
    text = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
    return f"missing {text}" if isinstance(exc, KeyError) else text
