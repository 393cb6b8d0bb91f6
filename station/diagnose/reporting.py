"""The report entries of a diagnosis: findings in engineering units, detectable sizes, the outlier count.

Numbers come from :mod:`station.diagnose.likelihood` tests; :mod:`station.diagnose.selection` decides which.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from scipy import optimize, stats

from station.diagnose.likelihood import ALPHA, Test
from station.diagnose.registry import REGISTRY, engineering, unit_factor
from station.diagnose.residuals import SensorData

#: Outlier rate per sample and axis that the base fit already tolerates (it rejects them):
#: the paper reports outliers on the accelerometer; none are expected on the gyroscope.
OUTLIER_ALLOWANCE = {"accel": 2e-4, "gyro": 1e-5}
#: Power at which a rejected candidate's ``detectable_from`` is quoted (:func:`detectable_from`).
DETECT_POWER = 0.9
AX = "xyz"


def detectable_from(t: Test) -> dict[str, Any] | None:
    """How large each of a mean candidate's parameters would have had to be for this recording to show it.

    Per parameter, in engineering units: the size at which the test (chi^2 with ``t.params`` degrees of
    freedom against the larger of the critical value and the BIC penalty) passes with probability
    ``DETECT_POWER``, that parameter alone non-zero. It takes the parameter's marginal standard error,
    so the true noncentrality of such an effect is at least the one quoted (conservative); the held-out
    gate and the re-fitted T_c are not part of it. None where the recording does not determine every
    parameter (the base model absorbs some of them).
    """
    p = int(t.params)
    if p <= 0 or p < t.theta.size:
        return None
    lam = optimize.brentq(lambda x: stats.ncx2.sf(t.threshold, p, x) - DETECT_POWER, 1e-9, 1e6)
    factor, unit = unit_factor(t.effect, t.sensor)
    size = math.sqrt(lam) * np.sqrt(np.clip(np.diag(t.cov), 0.0, None)) * factor
    shape = REGISTRY[t.effect].shape
    if shape is not None:
        size = size.reshape(shape)
    return {"value": round_sig(size).tolist(), "unit": unit, "power": DETECT_POWER,
            "noncentrality": round(lam, 2)}


def round_sig(x: np.ndarray, digits: int = 3) -> np.ndarray:
    """``x`` rounded to ``digits`` significant figures (0 stays 0)."""
    x = np.asarray(x, dtype=float)
    scale = np.where(x != 0.0, 10.0 ** (digits - 1 - np.floor(np.log10(np.abs(np.where(x != 0.0, x, 1.0))))), 1.0)
    return np.round(x * scale) / scale


def outlier_test(sd: SensorData) -> dict[str, Any]:
    n = max(sd.settled_samples, 1)
    count = int(sd.outlier_count.sum())
    lam = OUTLIER_ALLOWANCE[sd.sensor] * 3 * n
    p_value = float(stats.poisson.sf(count - 1, lam)) if count > 0 else 1.0
    rate = count / (3 * n)
    return {
        "effect": "outliers", "sensor": sd.sensor, "count": count, "samples": 3 * n,
        "rate": rate, "rate_std": math.sqrt(max(count, 1)) / (3 * n), "allowance": OUTLIER_ALLOWANCE[sd.sensor],
        "p_value": p_value, "accepted": p_value < ALPHA,
        "axes": [k for k in range(3) if sd.outlier_count[k] > OUTLIER_ALLOWANCE[sd.sensor] * n + 3 * math.sqrt(
            OUTLIER_ALLOWANCE[sd.sensor] * n + 1)],
    }


def affected_axes(name: str, theta: np.ndarray, cov: np.ndarray) -> list[int]:
    std = np.sqrt(np.clip(np.diag(cov), 1e-300, None))
    z = np.abs(theta) / std
    if len(theta) == 3 and REGISTRY[name].per_axis:
        return [k for k in range(3) if z[k] > 3.0] or [int(np.argmax(z))]
    if len(theta) == 9:
        zz = z.reshape(3, 3)
        return [k for k in range(3) if zz[k].max() > 3.0] or [int(np.argmax(zz.max(axis=1)))]
    return [0, 1, 2]



def finding(sd: SensorData, t: Test, before: dict[str, Any], after: dict[str, Any]) -> dict[str, Any]:
    if REGISTRY[t.effect].kind == "noise":  # bias_random_walk: a density
        k, k_std = float(t.theta[0]), float(math.sqrt(t.cov[0, 0]))
        factor, unit = unit_factor(t.effect, sd.sensor)
        params: dict[str, Any] = {"density": {"value": k * factor, "std": k_std * factor, "unit": unit}}
        axes = [0, 1, 2]
    else:
        params = engineering(t.effect, sd.sensor, t.theta, t.cov)
        axes = affected_axes(t.effect, t.theta, t.cov)
    out_factor = 180.0 / math.pi if sd.sensor == "gyro" else 1.0
    unit = "deg/s" if sd.sensor == "gyro" else "m/s^2"
    return {
        "effect": t.effect,
        "sensor": sd.sensor,
        "axes": [AX[k] for k in axes],
        "parameters": params,
        "evidence": {
            "likelihood_gain_chi2": round(t.gain, 3), "params": t.params, "bic_gain": round(t.bic_gain, 3),
            "critical_chi2": round(t.critical, 3), "heldout_before": round(t.heldout_before, 4),
            "heldout_after": round(t.heldout_after, 4), "heldout_change_se": round(t.heldout_change_se, 4),
        },
        "fit": {
            "before": {"bic": round(before["bic"], 3), "block_chi2": np.round(before["block_chi2"], 4).tolist(),
                       "block_rms": np.round(before["block_rms"] * out_factor, 9).tolist(), "unit": unit},
            "after": {"bic": round(after["bic"], 3), "block_chi2": np.round(after["block_chi2"], 4).tolist(),
                      "block_rms": np.round(after["block_rms"] * out_factor, 9).tolist(), "unit": unit},
        },
        "_block_residual": (before["block_residual"], after["block_residual"]),
        "_theta": np.array(t.theta, dtype=float),  # fitted SI parameters, for the simulator re-run (rerun.py)
        "_theta_std": np.sqrt(np.clip(np.diag(t.cov), 0.0, None)),  # their stated uncertainty (retest.py)
    }


__all__ = ["AX", "DETECT_POWER", "OUTLIER_ALLOWANCE", "detectable_from"]
