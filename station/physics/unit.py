"""The true parameters of one simulated unit, drawn from a sensor class.

:func:`draw_unit` draws a :class:`UnitTruth` (SI: m/s^2, rad/s, s, K) from a
:class:`~station.kernel.sensor_class.SensorClass` (the paper's Table 1 by default). The
model of each triad is the paper's eq. (1) with the bias of eq. (2)/(3):

    x~(t) = M x(t) + b_stat + b_drift * g(t) + n(t),   g(0) = 1,   dg/dt = -g / T_c + w_g
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields, replace
from typing import Any

import numpy as np

from station.kernel.parameters import AllanCoefficients, ParameterSet, TriadParams
from station.kernel.sensor_class import Range, SensorClass
from station.physics.effects import EffectShapes

_DEG = math.pi / 180.0


def _ro(a: Any, shape: tuple[int, ...]) -> np.ndarray:
    arr = np.array(a, dtype=np.float64)
    if arr.shape != shape:
        raise ValueError(f"expected shape {shape}, got {arr.shape}")
    arr.flags.writeable = False
    return arr


@dataclass(frozen=True, eq=False)
class TriadTruth:
    """True parameters of one triad; names as in :class:`station.kernel.parameters.TriadParams`.

    Unit U is m/s^2 for the accelerometer and rad/s for the gyroscope.

    Attributes:
        misalignment: M of eq. (1), (3, 3), 1.
        bias_static: b_stat (U), (3,).
        bias_drift: b_drift, the drifting bias at power-on (U), (3,).
        correlation_time_s: T_c of eq. (3) (s), (3,).
        drift_noise: stationary std of the drift's stochastic part (U), (3,).
        noise_std: white-noise std per sample (U), (3,) (the paper's sigma), before quantization.
        lsb: ADC resolution (U); full_scale: the ADC clips at ``[-full_scale, full_scale - lsb]`` (U).
        outlier_probability: per sample and axis (1); outlier_size: typical outlier size (U), (3,).
    """

    misalignment: np.ndarray
    bias_static: np.ndarray
    bias_drift: np.ndarray
    correlation_time_s: np.ndarray
    drift_noise: np.ndarray
    noise_std: np.ndarray
    lsb: float
    full_scale: float
    outlier_probability: float
    outlier_size: np.ndarray

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if f.name in ("lsb", "full_scale", "outlier_probability"):
                object.__setattr__(self, f.name, float(value))
            else:
                object.__setattr__(self, f.name, _ro(value, (3, 3) if f.name == "misalignment" else (3,)))

    def bias_at(self, t_s: np.ndarray) -> np.ndarray:
        """Deterministic bias ``b_stat + b_drift exp(-t/T_c)`` at times since power-on (U), (n, 3)."""
        t = np.asarray(t_s, dtype=float)[:, None]
        return self.bias_static + self.bias_drift * np.exp(-t / self.correlation_time_s)

    def as_dict(self) -> dict[str, Any]:
        """The fields named as in ``TriadParams`` (misalignment, bias_static, ...), as numpy arrays."""
        return {
            "misalignment": self.misalignment,
            "bias_static": self.bias_static,
            "bias_drift": self.bias_drift,
            "correlation_time_s": self.correlation_time_s,
            "drift_noise": self.drift_noise,
            "noise_std": self.noise_std,
        }

    def as_triad_params(self, g_sensitivity: np.ndarray | None = None) -> TriadParams:
        """The truth as a :class:`TriadParams` (zero standard uncertainties, NaN Allan figures)."""
        nan3 = np.full(3, np.nan)
        z3, z33 = np.zeros(3), np.zeros((3, 3))
        allan = AllanCoefficients(nan3, nan3, nan3, nan3, nan3, nan3)
        return TriadParams(
            misalignment=self.misalignment, misalignment_std=z33,
            bias_static=self.bias_static, bias_static_std=z3,
            bias_drift=self.bias_drift, bias_drift_std=z3,
            correlation_time_s=self.correlation_time_s, correlation_time_s_std=z3,
            drift_noise=self.drift_noise, drift_noise_std=z3,
            noise_std=self.noise_std, noise_std_std=z3,
            allan=allan, residual_rms=nan3,
            g_sensitivity=z33 if g_sensitivity is None else g_sensitivity, g_sensitivity_std=z33,
        )


@dataclass(frozen=True, eq=False)
class UnitTruth:
    """Every true parameter of one simulated unit (SI).

    Attributes:
        serial: the unit's serial number.
        accel: accelerometer triad (m/s^2).
        gyro: gyroscope triad (rad/s).
        self_heating_k: temperature rise from power-on to steady state (K).
        self_heating_tau_s: time constant of the self-heating (s).
        temp_noise_std_k: temperature-sensor noise (K); temp_lsb_k: its resolution (K).
        shapes: the unit's pattern of the optional effects (see :mod:`station.physics.effects`).
    """

    serial: str
    accel: TriadTruth
    gyro: TriadTruth
    self_heating_k: float
    self_heating_tau_s: float
    temp_noise_std_k: float
    temp_lsb_k: float
    shapes: EffectShapes = field(repr=False)

    def as_parameter_set_dict(self) -> dict[str, dict[str, Any]]:
        """``{"accel": {...}, "gyro": {...}}`` with the ``TriadParams`` field names (SI arrays)."""
        return {"accel": self.accel.as_dict(), "gyro": self.gyro.as_dict()}

    def as_parameter_set(self, sample_period_s: float, g_sensitivity: np.ndarray | None = None) -> ParameterSet:
        """The truth as a :class:`ParameterSet` (what a perfect fit would return)."""
        return ParameterSet(
            serial=self.serial,
            sample_period_s=sample_period_s,
            accel=self.accel.as_triad_params(),
            gyro=self.gyro.as_triad_params(g_sensitivity),
            source={"kind": "simulator truth"},
        )

    def noiseless(self) -> UnitTruth:
        """A copy without white noise, drift noise, outliers and temperature noise (ADC kept)."""
        z3 = np.zeros(3)
        return replace(
            self,
            accel=replace(self.accel, noise_std=z3, drift_noise=z3, outlier_probability=0.0),
            gyro=replace(self.gyro, noise_std=z3, drift_noise=z3, outlier_probability=0.0),
            temp_noise_std_k=0.0,
        )


def _u(rng: np.random.Generator, r: Range, size: int | tuple[int, ...] | None = None) -> Any:
    return rng.uniform(r[0], r[1], size=size)


def _misalignment(rng: np.random.Generator, diag: Range, off: Range) -> np.ndarray:
    m = _u(rng, off, (3, 3))
    m[np.diag_indices(3)] = _u(rng, diag, 3)
    return m


def draw_unit(sensor_class: SensorClass, rng: np.random.Generator, serial: str | None = None) -> UnitTruth:
    """Draw one unit of ``sensor_class``; the draw order is fixed, so a seeded ``rng`` gives the same unit.

    ``serial`` defaults to ``SIM-`` and six digits drawn from ``rng``.
    """
    c = sensor_class
    drawn_serial = f"SIM-{int(rng.integers(0, 1_000_000)):06d}"
    a_drift = _u(rng, c.accel_bias_drift_mps2, 3)
    a_noise = _u(rng, c.accel_noise_std_mps2, 3)
    accel = TriadTruth(
        misalignment=_misalignment(rng, c.accel_scale, c.accel_cross_axis),
        bias_static=_u(rng, c.accel_bias_static_mps2, 3),
        bias_drift=a_drift,
        correlation_time_s=_u(rng, c.accel_correlation_time_s, 3),
        drift_noise=c.drift_noise_rel * np.abs(a_drift),
        noise_std=a_noise,
        lsb=2.0 * c.accel_full_scale_mps2 / 2.0**c.accel_bits,
        full_scale=c.accel_full_scale_mps2,
        outlier_probability=c.accel_outlier_probability,
        outlier_size=c.outlier_sigma * a_noise,
    )
    w_drift = _u(rng, c.gyro_bias_drift_dps, 3) * _DEG
    w_noise = _u(rng, c.gyro_noise_std_dps, 3) * _DEG
    gyro = TriadTruth(
        misalignment=_misalignment(rng, c.gyro_scale, c.gyro_cross_axis),
        bias_static=_u(rng, c.gyro_bias_static_dps, 3) * _DEG,
        bias_drift=w_drift,
        correlation_time_s=_u(rng, c.gyro_correlation_time_s, 3),
        drift_noise=c.drift_noise_rel * np.abs(w_drift),
        noise_std=w_noise,
        lsb=2.0 * c.gyro_full_scale_dps * _DEG / 2.0**c.gyro_bits,
        full_scale=c.gyro_full_scale_dps * _DEG,
        outlier_probability=c.gyro_outlier_probability,
        outlier_size=c.outlier_sigma * w_noise,
    )
    heating = float(_u(rng, c.self_heating_k))
    heating_tau = float(_u(rng, c.self_heating_tau_s))
    shapes = EffectShapes.draw(rng)
    return UnitTruth(
        serial=drawn_serial if serial is None else serial,
        accel=accel,
        gyro=gyro,
        self_heating_k=heating,
        self_heating_tau_s=heating_tau,
        temp_noise_std_k=c.temp_noise_std_k,
        temp_lsb_k=c.temp_lsb_k,
        shapes=shapes,
    )
