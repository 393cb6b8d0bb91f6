"""Exports of a parameter set for other tools: imu_tk, OpenAXES, Kalibr (beside ``station-params/2``).

Our model (eq. 1) is ``y = M x + b`` (y the measurement); the corrections these tools apply:

* **imu_tk convention** (as OpenAXES's imu_tk_matlab uses it): accelerometer
  ``calibrated = T K raw - b_a``, the bias *after* the matrix; ``T K = M_a^-1``, T the unit
  upper-triangular misalignment, K the diagonal scale; so ``b_a = M_a^-1 b_stat``. Gyroscope
  ``calibrated = T_w K_w (raw - b_w)``, the bias *before* the matrix, ``T_w K_w = M_w^-1`` (full: the
  gyro is referred to the accelerometer's frame), ``b_w = b_stat``. Written by :func:`imu_tk_document`
  as JSON in our own format ``station-imutk/1`` (:data:`IMU_TK_FORMAT`): matrices row-major, vectors
  x, y, z, SI units. The drift of eq. (3) has no place in it (``b_drift``, ``T_c`` are left out: the
  bias is the settled one, b_stat).
* **imu_tk's own parameter files** (:func:`imu_tk_calib_files`): what imu_tk's ``CalibratedTriad::save``
  writes and ``CalibratedTriad::load`` reads, one file per triad (imu_tk's programs name them
  ``*_acc.calib`` and ``*_gyro.calib``): the misalignment matrix T (3 x 3, unit diagonal), the scale matrix
  K (3 x 3, diagonal), the bias vector B (3), as whitespace-separated numbers, matrices row by row. imu_tk
  (C++) corrects both triads as ``X' = T K (X - B)``, the bias *before* the matrix: ``T K = M^-1``, ``B =
  b_stat`` for the accelerometer as for the gyro. Units are those of the station's measurement (m/s^2,
  rad/s): X is the unit's output in SI, as the station records it.
* **OpenAXES coefficient list** (:func:`openaxes_coefficients`): per accelerometer its 3x3 matrix
  ``T K`` column-major (9) and its bias after the matrix (3), then the gyro matrix column-major (9) and
  its bias (3, rad/s): 24 numbers for one parameter set, 36 for OpenAXES's two accelerometers (the gyro
  from the last set given), the order OpenAXES's script prints.

Each number carries a standard uncertainty where the parameter set has one (linear propagation
through the inverse; from the full covariance of a rig-free fit when it is in ``quality``).

An axis whose b_stat the recording cannot determine (``quality.determinability``) is exported with the
rule of :meth:`~station.kernel.parameters.ParameterSet.constant_bias_values`: the bias at the end of the recording,
its uncertainty not stated (NaN, ``null``); :func:`export_notes` says which axes, and the imu_tk document
carries the same notes under ``convention.undetermined``.
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from station.kernel.errors import FormatError
from station.kernel.parameters import ParameterSet, TriadParams

__all__ = ["IMU_TK_FORMAT", "export_notes", "imu_tk_calib_files", "imu_tk_document", "imu_tk_terms",
           "kalibr_imu_yaml", "left_out_notes", "openaxes_coefficients", "openaxes_text"]

IMU_TK_FORMAT = "station-imutk/1"


def _inv_with_std(m: np.ndarray, m_std: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """inv(M) and its element std, propagating independent element stds of M (d inv = -inv dM inv)."""
    inv = np.linalg.inv(m)
    var = np.zeros((3, 3))
    for i in range(3):
        for j in range(3):
            if m_std[i, j] > 0:
                var += (np.outer(inv[:, i], inv[j, :]) * m_std[i, j]) ** 2
    return inv, np.sqrt(var)


def imu_tk_terms(params: ParameterSet) -> dict[str, dict[str, np.ndarray]]:
    """Accelerometer and gyro in the imu_tk convention (see the module docstring), each with ``*_std``."""
    if not (np.isfinite(params.accel.misalignment).all() and np.isfinite(params.gyro.misalignment).all()):
        raise FormatError("the parameter set has unresolved misalignment elements; nothing to export")
    out: dict[str, dict[str, np.ndarray]] = {}
    rig_free = params.quality.rig_free or {}
    params = params.constant_bias_values()[0]
    a_tk, a_tk_std = _inv_with_std(params.accel.misalignment, np.nan_to_num(params.accel.misalignment_std))
    b = params.accel.bias_static
    bias_after = a_tk @ b
    cov = rig_free.get("accel_param_cov")
    if cov is not None and np.all(np.isfinite(params.accel.bias_static_std)) and np.array(cov).shape == (9, 9):
        # exact propagation from the rig-free fit's parameters (A00, A01, A02, A11, A12, A22, b0, b1, b2)
        cov = np.array(cov)
        upper = ((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2))
        a_tk_std = np.zeros((3, 3))
        for k, (i, j) in enumerate(upper):
            a_tk_std[i, j] = np.sqrt(max(cov[k, k], 0.0))
        jac = np.zeros((3, 9))
        for k, (i, j) in enumerate(upper):
            jac[i, k] = b[j]
        jac[:, 6:9] = a_tk
        bias_after_std = np.sqrt(np.clip(np.diag(jac @ cov @ jac.T), 0.0, None))
    else:
        bias_after_std = np.sqrt((a_tk_std * b) ** 2 @ np.ones(3) + (a_tk**2) @ (params.accel.bias_static_std**2))
    k_a = np.diag(np.diag(a_tk))
    out["accel"] = {
        "TK": a_tk, "TK_std": a_tk_std, "T": a_tk @ np.linalg.inv(k_a), "K": np.diag(k_a),
        "bias_after_matrix": bias_after, "bias_after_matrix_std": bias_after_std,
    }
    g_tk, g_tk_std = _inv_with_std(params.gyro.misalignment, np.nan_to_num(params.gyro.misalignment_std))
    gyro_cov = rig_free.get("gyro_param_cov")
    if gyro_cov is not None and np.array(gyro_cov).shape == (9, 9):
        g_tk_std = np.sqrt(np.clip(np.diag(np.array(gyro_cov)), 0.0, None)).reshape(3, 3)
    k_w = np.diag(np.diag(g_tk))
    out["gyro"] = {
        "TK": g_tk, "TK_std": g_tk_std, "T": g_tk @ np.linalg.inv(k_w), "K": np.diag(k_w),
        "bias_before_matrix": params.gyro.bias_static, "bias_before_matrix_std": params.gyro.bias_static_std,
    }
    return out


def _list(a: np.ndarray) -> Any:
    """Rounded nested lists; a number not stated (NaN) is ``null``."""
    def clean(v: Any) -> Any:
        return [clean(x) for x in v] if isinstance(v, list) else (None if v != v else v)

    return clean(np.round(np.asarray(a, dtype=float), 12).tolist())


def imu_tk_document(params: ParameterSet) -> str:
    """The parameter set in the imu_tk convention as JSON (format ``station-imutk/1``)."""
    terms = imu_tk_terms(params)
    notes = export_notes(params)
    doc = {
        "format": IMU_TK_FORMAT,
        "serial": params.serial,
        "convention": {
            "accel": "calibrated_mps2 = TK @ raw_mps2 - bias_after_matrix; TK = T @ diag(K), T unit upper-triangular",
            "gyro": "calibrated_radps = TK @ (raw_radps - bias_before_matrix); TK = T @ diag(K)",
            "order": "matrices row-major [[row x], [row y], [row z]]; vectors [x, y, z]; SI units",
            "drift": "not representable: the bias is the settled b_stat; b_drift exp(-t/T_c) of eq. (3) is left out",
            "frame": (params.quality.rig_free or {}).get("convention", "the rig's frame"),
            **({"undetermined": list(notes)} if notes else {}),
        },
        "accel": {k: _list(v) for k, v in terms["accel"].items()},
        "gyro": {k: _list(v) for k, v in terms["gyro"].items()},
        "source": {"station_params_serial": params.serial, **{k: v for k, v in params.source.items()
                                                               if k in ("software", "method", "gravity_mps2")}},
    }
    return json.dumps(doc, indent=2) + "\n"


def export_notes(params: ParameterSet) -> tuple[str, ...]:
    """What an export writes differently from the set's own numbers: one line per axis whose b_stat the recording
    cannot determine (the bias at the end of the recording is exported instead); empty when none."""
    return params.constant_bias_values()[1]


def left_out_notes(params: ParameterSet) -> tuple[str, ...]:
    """What the set holds that imu_tk's and OpenAXES's models cannot (their files carry ``T K`` and one constant
    bias): one line per kind that is left out of those exports; empty when none. The drift of eq. 3 is named when
    it is large against the bias's own uncertainty, since then the exported constant bias (b_stat, the settled one)
    does not describe the recording's warm-up (docs/exports.md)."""
    out: list[str] = []
    for name, tri in (("accel", params.accel), ("gyro", params.gyro)):
        drift = np.abs(np.nan_to_num(np.asarray(tri.bias_drift, dtype=float)))
        std = np.nan_to_num(np.asarray(tri.bias_drift_std, dtype=float), nan=np.inf)
        big = ["xyz"[k] for k in range(3) if drift[k] > 3 * std[k] and drift[k] > 0]
        if big:
            unit = "m/s^2" if name == "accel" else "rad/s"
            size = max(drift["xyz".index(a)] for a in big)
            hint = ("; for a bias of the recording itself fit without the drift (station fit --no-accel-drift, "
                    "rig-free)" if name == "accel" else "")
            out.append(f"{name} {', '.join(big)}: the eq. 3 warm-up drift (b_drift up to {size:.3g} {unit}) is left "
                       f"out: the files hold the settled bias, not the bias during the warm-up{hint}")
    if params.compensates_temperature:
        out.append("the temperature terms are left out (no temperature model in these files)")
    if params.has_nonlinearity:
        out.append("the scale nonlinearity (u|u|, IEEE 952 k2, k3) is left out (no polynomial in these files)")
    if params.time_offset_s:
        out.append(f"the time offset ({1e3 * params.time_offset_s:.3g} ms) is left out: apply it to the time stamps")
    return tuple(out)


def openaxes_coefficients(param_sets: Sequence[ParameterSet]) -> tuple[np.ndarray, np.ndarray]:
    """(values, stds): each set's accelerometer (9 column-major, 3 bias after), then the last set's gyro
    (9 column-major, 3 bias)."""
    if not param_sets:
        raise FormatError("no parameter set to export")
    values: list[np.ndarray] = []
    stds: list[np.ndarray] = []
    for p in param_sets:
        t = imu_tk_terms(p)["accel"]
        values += [t["TK"].ravel(order="F"), t["bias_after_matrix"]]
        stds += [t["TK_std"].ravel(order="F"), t["bias_after_matrix_std"]]
    g = imu_tk_terms(param_sets[-1])["gyro"]
    values += [g["TK"].ravel(order="F"), g["bias_before_matrix"]]
    stds += [g["TK_std"].ravel(order="F"), g["bias_before_matrix_std"]]
    return np.concatenate(values), np.concatenate(stds)


def openaxes_text(param_sets: Sequence[ParameterSet]) -> str:
    """The coefficient list as OpenAXES's script prints it: numbers separated by spaces, one line."""
    values, _ = openaxes_coefficients(param_sets)
    return " ".join(f"{v:.8g}" for v in values) + "\n"


def _calib_text(t: np.ndarray, k: np.ndarray, b: np.ndarray) -> str:
    """One triad as ``CalibratedTriad::save`` writes it: T rows, a blank line, K rows, a blank line, B one value
    per line (Eigen prints a column vector that way), a blank line."""
    def rows(m: np.ndarray) -> str:
        return "\n".join(" ".join(f"{float(v):.17g}" for v in row) for row in np.atleast_2d(m)) + "\n"

    return rows(t) + "\n" + rows(k) + "\n" + "\n".join(f"{float(v):.17g}" for v in b) + "\n\n"


def imu_tk_calib_files(params: ParameterSet) -> dict[str, str]:
    """imu_tk's parameter files of the set: ``{"acc": text, "gyro": text}`` (see the module docstring).

    ``T K = M^-1`` is split into K = its diagonal and T = ``M^-1 K^-1`` (unit diagonal, imu_tk's general
    misalignment); B = b_stat (the bias at the end of the recording where b_stat is not determined,
    :func:`export_notes`). Refused (:class:`FormatError`) when M is not resolved or singular."""
    out: dict[str, str] = {}
    params = params.constant_bias_values()[0]
    for name, tri in (("acc", params.accel), ("gyro", params.gyro)):
        m = np.asarray(tri.misalignment, dtype=np.float64)
        b = np.asarray(tri.bias_static, dtype=np.float64)
        if not (np.isfinite(m).all() and np.isfinite(b).all()):
            raise FormatError(f"the parameter set's {name} misalignment or bias is unresolved; nothing to export")
        try:
            tk = np.linalg.inv(m)
        except np.linalg.LinAlgError:
            raise FormatError(f"the {name} matrix M is singular; nothing to export") from None
        k = np.diag(np.diag(tk))
        out[name] = _calib_text(tk @ np.linalg.inv(k), k, b)
    return out


# --- Kalibr ---------------------------------------------------------------------------------------


def _noise_density(t: TriadParams, sample_period_s: float) -> float:
    """Continuous-time white-noise density (U/sqrt(Hz)): Allan N if fitted, else sigma * sqrt(T_sampl)."""
    n = np.asarray(t.allan.random_walk, dtype=np.float64)
    if np.isfinite(n).all() and (n > 0).all():
        return float(n.max())
    sigma = np.asarray(t.noise_std, dtype=np.float64)
    if not np.isfinite(sigma).all():
        raise FormatError("noise std is not resolved; cannot give a noise density")
    return float(sigma.max() * math.sqrt(sample_period_s))


def _random_walk(t: TriadParams) -> float:
    """Bias random walk (U/s/sqrt(Hz)): Allan K if fitted, else the Gauss-Markov drive of eq. (3).

    The drift's stochastic part with stationary std sigma_gm and correlation time T_c is
    driven by white noise of density sigma_gm * sqrt(2 / T_c); over times << T_c it is a
    random walk of that density.
    """
    k = np.asarray(t.allan.rate_random_walk, dtype=np.float64)
    if np.isfinite(k).all() and (k > 0).all():  # an Allan fit that found no random walk gives 0
        return float(k.max())
    sg = np.asarray(t.drift_noise, dtype=np.float64)
    tc = np.asarray(t.correlation_time_s, dtype=np.float64)
    ok = np.isfinite(sg) & np.isfinite(tc) & (tc > 0) & (sg > 0)
    if not ok.any():
        raise FormatError("neither an Allan rate random walk nor a resolved drift; cannot give a random walk")
    return float(np.max(sg[ok] * np.sqrt(2.0 / tc[ok])))


def kalibr_imu_yaml(params: ParameterSet, rostopic: str = "/imu0", update_rate_hz: float | None = None) -> str:
    """The unit's noise parameters in Kalibr's ``imu.yaml`` form (SI; the largest axis of each triad).

    ``accelerometer_noise_density`` (m/s^2/sqrt(Hz)), ``accelerometer_random_walk``
    (m/s^3/sqrt(Hz)), ``gyroscope_noise_density`` (rad/s/sqrt(Hz)),
    ``gyroscope_random_walk`` (rad/s^2/sqrt(Hz)), ``update_rate`` (Hz, default 1/T_sampl).
    """
    ts = float(params.sample_period_s)
    rate = update_rate_hz if update_rate_hz is not None else 1.0 / ts
    values = {
        "accelerometer_noise_density": _noise_density(params.accel, ts),
        "accelerometer_random_walk": _random_walk(params.accel),
        "gyroscope_noise_density": _noise_density(params.gyro, ts),
        "gyroscope_random_walk": _random_walk(params.gyro),
    }
    lines = [
        f"# Kalibr IMU noise model of unit {params.serial} (station calibration; SI units)",
        "#Accelerometers",
        f"accelerometer_noise_density: {values['accelerometer_noise_density']:.6e}   #Noise density (continuous-time)",
        f"accelerometer_random_walk:   {values['accelerometer_random_walk']:.6e}   #Bias random walk",
        "#Gyroscopes",
        f"gyroscope_noise_density:     {values['gyroscope_noise_density']:.6e}   #Noise density (continuous-time)",
        f"gyroscope_random_walk:       {values['gyroscope_random_walk']:.6e}   #Bias random walk",
        f"rostopic:                    {rostopic}   #the IMU ROS topic",
        f"update_rate:                 {rate:.1f}   #Hz (for discretization of the values above)",
    ]
    return "\n".join(lines) + "\n"
