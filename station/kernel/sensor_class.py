"""Sensor classes: the parameter distributions of a kind of unit (the paper's Table 1).

:data:`TABLE1` is the class of the paper's Table 1: every parameter uniform over the
range the paper determined. Units on the class are the paper's (m/s^2 and deg/s);
a unit drawn from it (:func:`station.physics.unit.draw_unit`) is SI (m/s^2, rad/s, s, K).

The model of each triad is the paper's eq. (1) with the bias of eq. (2)/(3):

    x~(t) = M x(t) + b_stat + b_drift * g(t) + n(t),   g(0) = 1,   dg/dt = -g / T_c + w_g

The class also holds what Table 1 leaves out (documented defaults on
:class:`SensorClass`): the stochastic part of the drift, outliers, the ADC, and the
temperature channel.
"""

from __future__ import annotations

from dataclasses import dataclass

from station.kernel.constants import STANDARD_GRAVITY

Range = tuple[float, float]



@dataclass(frozen=True)
class SensorClass:
    """Distribution of the parameters of a sensor class; ranges ``(low, high)`` are uniform.

    Table 1 of the paper (per axis, resp. per matrix element):
        accel_bias_static_mps2, accel_bias_drift_mps2 (m/s^2), accel_correlation_time_s (s),
        accel_scale (diagonal of M_a, 1), accel_cross_axis (off-diagonal of M_a, 1),
        accel_noise_std_mps2 (white noise std per sample, m/s^2); the same for the gyro in deg/s.

    Not in Table 1:
        drift_noise_rel: stationary std of the stochastic part of the Gauss-Markov drift
            (eq. 3's ``w_g``), relative to ``|b_drift|`` (1); default 0.01 = 1 %. The paper
            neglects it; the simulated drift is ``b_drift * (exp(-t/T_c) + x(t))`` with ``x``
            a stationary-std ``drift_noise_rel`` GM process started at ``x(0) = 0``.
        accel_outlier_probability, gyro_outlier_probability: probability per sample and axis
            of an outlier (1); the paper sees outliers on the accelerometer only.
        outlier_sigma: typical outlier size in multiples of that axis's noise std; each
            outlier is uniform in [0.5, 1.5] times this, random sign.
        accel_full_scale_mps2, accel_bits: ADC range +-full scale and resolution; default
            +-8 g, 16 bit (LSB 2.39e-3 m/s^2, quantization std 0.7e-3 m/s^2 << noise).
        gyro_full_scale_dps, gyro_bits: default +-2000 deg/s, 20 bit (high-resolution
            FIFO mode; LSB 3.8e-3 deg/s, quantization std 1.1e-3 deg/s << noise).
        ambient_degc (degC): room temperature at power-on; ambient_rate_k_per_h (K/h):
            slow linear ambient drift; self_heating_k (K) and self_heating_tau_s (s):
            the sensor warms by ``dT (1 - exp(-t/tau))`` after power-on;
            temp_noise_std_k (K) and temp_lsb_k (K): temperature-sensor noise and resolution.
        ambient_cycle_k (K) and ambient_cycle_period_s (s): a climate-chamber program on top of
            the room, ``A sin(2 pi t / P)`` from power-on; 0 (default) for an ordinary room.
    """

    name: str = "table1"
    accel_bias_static_mps2: Range = (-0.17, 0.026)
    accel_bias_drift_mps2: Range = (-0.002, 0.018)
    accel_correlation_time_s: Range = (50.0, 167.0)
    accel_scale: Range = (0.998, 1.02)
    accel_cross_axis: Range = (-0.03, 0.02)
    accel_noise_std_mps2: Range = (0.017, 0.028)
    gyro_bias_static_dps: Range = (-0.726, 2.739)
    gyro_bias_drift_dps: Range = (-0.115, 0.347)
    gyro_correlation_time_s: Range = (1030.0, 3760.0)
    gyro_scale: Range = (0.97, 1.003)
    gyro_cross_axis: Range = (-0.001, 0.001)
    gyro_noise_std_dps: Range = (0.01, 0.013)
    drift_noise_rel: float = 0.01
    accel_outlier_probability: float = 1e-4
    gyro_outlier_probability: float = 0.0
    outlier_sigma: float = 8.0
    accel_full_scale_mps2: float = 8.0 * STANDARD_GRAVITY
    accel_bits: int = 16
    gyro_full_scale_dps: float = 2000.0
    gyro_bits: int = 20
    ambient_degc: Range = (21.0, 25.0)
    ambient_rate_k_per_h: Range = (-1.0, 1.0)
    self_heating_k: Range = (3.0, 8.0)
    self_heating_tau_s: Range = (200.0, 600.0)
    temp_noise_std_k: float = 0.05
    temp_lsb_k: float = 1.0 / 256.0
    ambient_cycle_k: float = 0.0
    ambient_cycle_period_s: float = 600.0


TABLE1 = SensorClass()
