"""A fitted parameter set (``station-params/1``, see :mod:`station.fit.params`) in the JSON API.

SI units: accelerometer quantities in m/s^2, gyroscope quantities in rad/s, times in s. An
estimate the recording could not resolve is null. Vectors are per axis (x, y, z); matrices
are 3 x 3, row-major.
"""

from __future__ import annotations

from typing import Annotated, Any

from pydantic import BaseModel, Field

Vector3 = Annotated[list[float | None], Field(min_length=3, max_length=3)]
Matrix3 = Annotated[list[Vector3], Field(min_length=3, max_length=3)]

_U = " (m/s^2 for the accelerometer, rad/s for the gyroscope)"


def _std(what: str) -> Any:
    return Field(description=f"standard uncertainty of {what}, same unit")


class AllanNoise(BaseModel):
    """IEEE Std 952 noise coefficients from the Allan deviation, per axis."""

    random_walk: Vector3 = Field(description="white-noise density: velocity random walk (m/s^2/sqrt(Hz)) for the "
                                             "accelerometer, angle random walk (rad/s/sqrt(Hz) = rad/sqrt(s)) for the "
                                             "gyroscope")
    random_walk_std: Vector3 = _std("random_walk")
    bias_instability: Vector3 = Field(description="bias instability" + _U)
    bias_instability_std: Vector3 = _std("bias_instability")
    rate_random_walk: Vector3 = Field(description="random walk of the bias: m/s^3/sqrt(Hz) for the accelerometer, "
                                                  "rad/s^2/sqrt(Hz) for the gyroscope")
    rate_random_walk_std: Vector3 = _std("rate_random_walk")


class TriadCalibration(BaseModel):
    """Fitted parameters of one sensor triad (eq. 1 and eq. 3 of the method)."""

    misalignment: Matrix3 = Field(description="M: scale factors on the diagonal, cross-axis terms off it (1)")
    misalignment_std: Matrix3 = _std("misalignment")
    bias_static: Vector3 = Field(description="b_stat, the asymptotic bias" + _U)
    bias_static_std: Vector3 = _std("bias_static")
    bias_drift: Vector3 = Field(description="b_drift, the drifting bias at power-on" + _U)
    bias_drift_std: Vector3 = _std("bias_drift")
    correlation_time_s: Vector3 = Field(description="T_c of the Gauss-Markov drift (s)")
    correlation_time_s_std: Vector3 = _std("correlation_time_s")
    drift_noise: Vector3 = Field(description="stationary std of the drift's stochastic part" + _U)
    drift_noise_std: Vector3 = _std("drift_noise")
    noise_std: Vector3 = Field(description="white-noise std per sample" + _U)
    noise_std_std: Vector3 = _std("noise_std")
    allan: AllanNoise = Field(description="Allan-deviation noise coefficients")
    residual_rms: Vector3 = Field(description="RMS of the fit residual" + _U)
    g_sensitivity: Matrix3 = Field(description="gyro output per unit specific force (rad/s per m/s^2); zeros for "
                                               "the accelerometer or when not fitted")
    g_sensitivity_std: Matrix3 = _std("g_sensitivity")


class CalibrationParameters(BaseModel):
    """Everything Algorithm 1 and the station need about one calibrated unit (format ``station-params/1``)."""

    format: str = Field(description="the parameter set's format, 'station-params/1'")
    serial: str = Field(description="the unit's serial number")
    sample_period_s: float = Field(description="T_sampl of Algorithm 1 (s)")
    moving_average_length: int = Field(description="n of the one-sided moving average, eq. (6) (samples)")
    accel: TriadCalibration = Field(description="accelerometer triad (m/s^2)")
    gyro: TriadCalibration = Field(description="gyroscope triad (rad/s)")
    quality: dict[str, Any] = Field(description="fit-quality figures (residual RMS per axis and per segment, ...); "
                                                "which ones depends on how the set was made")
    source: dict[str, Any] = Field(description="where the parameters came from (software version, samples, ...)")


__all__ = ["AllanNoise", "CalibrationParameters", "Matrix3", "TriadCalibration", "Vector3"]
