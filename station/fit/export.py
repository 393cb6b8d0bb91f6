"""Exports of a parameter set in the conventions of imu_tk and OpenAXES (beside ``station-params``).

Our model (eq. 1) is ``y = M x + b`` (y the measurement); the corrections these tools apply:

* **imu_tk convention** (as OpenAXES's imu_tk_matlab uses it): accelerometer
  ``calibrated = T K raw - b_a``, the bias *after* the matrix; ``T K = M_a^-1``, T the unit
  upper-triangular misalignment, K the diagonal scale; so ``b_a = M_a^-1 b_stat``. Gyroscope
  ``calibrated = T_w K_w (raw - b_w)``, the bias *before* the matrix, ``T_w K_w = M_w^-1`` (full: the
  gyro is referred to the accelerometer's frame), ``b_w = b_stat``. Written by :func:`imu_tk_document`
  as JSON in our own format ``station-imutk/1`` (:data:`IMU_TK_FORMAT`): matrices row-major, vectors
  x, y, z, SI units. The drift of eq. (3) has no place in it (``b_drift``, ``T_c`` are left out: the
  bias is the settled one, b_stat).
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
from collections.abc import Sequence
from typing import Any

import numpy as np

from station.kernel.errors import FormatError
from station.kernel.parameters import ParameterSet

__all__ = ["IMU_TK_FORMAT", "export_notes", "imu_tk_document", "imu_tk_terms", "openaxes_coefficients", "openaxes_text"]

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
