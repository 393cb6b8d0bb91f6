"""The calibration result: a frozen, versioned parameter set with a JSON round trip.

Units (SI): accelerometer quantities in m/s^2, gyroscope quantities in rad/s, times
in s. The model per triad is the paper's eq. (1):

    x~(t) = M x(t) + b_stat + b_drift * g(t) + n(t),   g(0) = 1,
    dg/dt = -g / T_c + w_g                              (eq. 3)

so the bias starts at ``b_stat + b_drift`` at power-on and settles to ``b_stat``.
Every estimate carries a standard uncertainty (``*_std``, same unit). An estimate
that the recording cannot resolve is NaN in memory and ``null`` in JSON.
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any

import numpy as np

from station.kernel.errors import FormatError, UnsupportedVersionError

FORMAT = "station-params/1"


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

    _MATRIX_FIELDS = ("misalignment", "misalignment_std", "g_sensitivity", "g_sensitivity_std")

    def __post_init__(self) -> None:
        for f in fields(self):
            if f.name == "allan":
                continue
            shape = (3, 3) if f.name in self._MATRIX_FIELDS else (3,)
            object.__setattr__(self, f.name, _arr(getattr(self, f.name), shape))

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {}
        for f in fields(self):
            value = getattr(self, f.name)
            if f.name == "allan":
                out["allan"] = {g.name: _to_json_value(getattr(value, g.name)) for g in fields(value)}
            else:
                out[f.name] = _to_json_value(value)
        return out

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> TriadParams:
        try:
            kwargs = {f.name: _from_json_value(d[f.name]) for f in fields(cls) if f.name != "allan"}
            if not isinstance(d["allan"], dict):
                raise TypeError("'allan' must be an object")
            allan = AllanCoefficients(**{k: _from_json_value(v) for k, v in d["allan"].items()})
            return cls(allan=allan, **kwargs)
        except (KeyError, TypeError, ValueError, AttributeError) as exc:
            raise FormatError(f"parameter set: triad is missing or has a bad field: {_brief(exc)}") from exc


@dataclass(frozen=True, eq=False)
class ParameterSet:
    """Everything Algorithm 1 and the station need about one calibrated unit.

    Attributes:
        serial: the unit's serial number.
        sample_period_s: T_sampl of Algorithm 1 (s).
        moving_average_length: n of the one-sided moving average, eq. (6).
        accel: accelerometer triad (m/s^2).
        gyro: gyroscope triad (rad/s).
        quality: fit-quality figures (residual RMS per axis and per segment, ...).
        source: where the parameters came from (session hash, software version, ...).
    """

    serial: str
    sample_period_s: float
    accel: TriadParams
    gyro: TriadParams
    moving_average_length: int = 40
    quality: dict[str, Any] = field(default_factory=dict)
    source: dict[str, Any] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        return {
            "format": FORMAT,
            "serial": self.serial,
            "sample_period_s": self.sample_period_s,
            "moving_average_length": self.moving_average_length,
            "accel": self.accel.to_dict(),
            "gyro": self.gyro.to_dict(),
            "quality": self.quality,
            "source": self.source,
        }

    def to_json(self, indent: int | None = 2) -> str:
        return json.dumps(self.to_dict(), indent=indent, allow_nan=False)

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> ParameterSet:
        fmt = d.get("format") if isinstance(d, dict) else None
        if fmt != FORMAT:
            raise UnsupportedVersionError(
                f"parameter set has format {fmt!r}; this station reads {FORMAT!r} only"
            )
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
            return cls(
                serial=serial,
                sample_period_s=float(period),
                moving_average_length=n,
                accel=TriadParams.from_dict(d["accel"]),
                gyro=TriadParams.from_dict(d["gyro"]),
                quality=dict(d.get("quality", {})),
                source=dict(d.get("source", {})),
            )
        except (KeyError, TypeError, ValueError, AttributeError) as exc:
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
