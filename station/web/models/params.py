"""A fitted parameter set (``station-params/3``; /1 and /2 read alike, see :mod:`station.kernel.parameters`) in
the JSON API.

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
    temp_bias_coeff: Matrix3 = Field(description="temperature coefficients of the bias, row = axis, column = order "
                                                 "1..3 (unit/K^order)" + _U + "; zeros where not fitted")
    temp_bias_coeff_std: Matrix3 = _std("temp_bias_coeff")
    temp_scale_coeff: Matrix3 = Field(description="temperature coefficients of the scale factor, row = axis, column = "
                                                  "order 1..3 (1/K^order); zeros where not fitted")
    temp_scale_coeff_std: Matrix3 = _std("temp_scale_coeff")
    scale_nonlinearity: Vector3 = Field(description="k of u + k u|u| per axis (1/unit); zeros where not fitted")
    scale_nonlinearity_std: Vector3 = _std("scale_nonlinearity")
    scale_quadratic: Vector3 = Field(default=[0.0, 0.0, 0.0],
                                     description="k2 of the IEEE 952 scale polynomial u + k2 u^2 + k3 u^3 per axis "
                                                 "(1/unit); zeros where not kept (see found_terms for why)")
    scale_quadratic_std: Vector3 = Field(default=[0.0, 0.0, 0.0], description="standard uncertainty of "
                                                                              "scale_quadratic, same unit")
    scale_cubic: Vector3 = Field(default=[0.0, 0.0, 0.0],
                                 description="k3 of the IEEE 952 scale polynomial per axis (1/unit^2); zeros where "
                                             "not kept (see found_terms for why)")
    scale_cubic_std: Vector3 = Field(default=[0.0, 0.0, 0.0], description="standard uncertainty of scale_cubic, "
                                                                          "same unit")


class ThermalNote(BaseModel):
    """Whether and how the temperature terms were fitted."""

    status: str = Field(description="fitted, not_separable, no_temperature, disabled or absent")
    reason: str = Field(description="why not, for people")
    span_k: float | None = Field(description="temperature span of the settled data (K)")
    independent_k: float | None = Field(description="RMS of the temperature course not explained by a warm-up "
                                                    "shape (K)")
    orders: dict[str, dict[str, list[int]]] = Field(description="per triad and term (bias, scale), the order per axis")
    rule: str = Field(description="how the orders were chosen")


class FoundTermEntry(BaseModel):
    """One found term (:mod:`station.kernel.found_terms`) and whether the recording determined it."""

    name: str = Field(description="'time_offset', or 'gyro.k2.x' ... 'gyro.k3.z' (the IEEE 952 polynomial's terms)")
    status: str = Field(description="fitted (kept, applied by Algorithm 1), not_significant (estimated, below the "
                                    "Wald threshold: the set holds 0), not_determined (the recording cannot determine "
                                    "it: no number), beyond_range (time offset beyond what Algorithm 1 applies), "
                                    "not_fitted (the fit did not try)")
    value: float | None = Field(description="the value the set holds and Algorithm 1 applies (SI, see unit); null "
                                            "unless fitted")
    std: float | None = Field(description="standard uncertainty of the value or of the estimate, same unit; null: "
                                          "none")
    unit: str = Field(description="SI unit of value and std: s, 1/(rad/s), 1/(rad/s)^2")
    estimate: float | None = Field(description="the fit's estimate (also when not kept); null: none")
    z: float | None = Field(description="estimate / its standard uncertainty (the Wald statistic's root); null: none")
    reason: str = Field(description="for people: why not kept or not determined, and the rig step that would "
                                    "determine it")


class FoundTermsSummary(BaseModel):
    """The time offset and the gyro's IEEE 952 polynomial terms with their determinability."""

    time_offset: FoundTermEntry = Field(description="the unit's time offset behind the rig (s)")
    polynomial: list[FoundTermEntry] = Field(description="gyro k2 x, y, z then k3 x, y, z")


class CalibrationParameters(BaseModel):
    """Everything Algorithm 1 and the station need about one calibrated unit (format ``station-params/3``)."""

    format: str = Field(description="the parameter set's format, 'station-params/1', '/2' or '/3'")
    serial: str = Field(description="the unit's serial number")
    sample_period_s: float = Field(description="T_sampl of Algorithm 1 (s)")
    moving_average_length: int = Field(description="n of the one-sided moving average, eq. (6) (samples)")
    reference_temperature_degc: float | None = Field(description="T_ref of the temperature terms (degC); null: none")
    time_offset_s: float = Field(description="the unit's sample time minus the rig's (s), applied by Algorithm 1; 0 "
                                             "when not kept (see found_terms for why)")
    time_offset_std_s: float = Field(default=0.0, description="standard uncertainty of time_offset_s (s)")
    thermal: ThermalNote = Field(description="whether the temperature terms were fitted, and why not")
    accel: TriadCalibration = Field(description="accelerometer triad (m/s^2)")
    gyro: TriadCalibration = Field(description="gyroscope triad (rad/s)")
    quality: dict[str, Any] = Field(description="fit-quality figures (residual RMS per axis and per segment, ...); "
                                                "which ones depends on how the set was made")
    source: dict[str, Any] = Field(description="where the parameters came from (software version, samples, ...)")
    found_terms: FoundTermsSummary | None = Field(
        default=None, description="the time offset and the gyro polynomial with what the fit could say about each "
                                  "(derived from the set and its notes)")


__all__ = ["AllanNoise", "CalibrationParameters", "FoundTermEntry", "FoundTermsSummary", "Matrix3", "ThermalNote",
           "TriadCalibration", "Vector3"]
