"""The report entries of a diagnosis: findings in engineering units, detectable sizes, the outlier count.

Numbers come from :mod:`station.diagnose.likelihood` tests; :mod:`station.diagnose.selection` decides which.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy import optimize, stats

from station.diagnose.effect_registry import REGISTRY, engineering, unit_factor
from station.diagnose.finding_consistency import not_checked
from station.diagnose.likelihood import ALPHA, ModelQuality, Test
from station.diagnose.residuals import SensorData
from station.diagnose.results import (
    BlockFit,
    DetectableSize,
    Evidence,
    Finding,
    FitChange,
    FormInseparable,
    OutlierEvidence,
    Rejection,
)

#: Outlier rate per sample and axis that the base fit already tolerates (it rejects them):
#: the paper reports outliers on the accelerometer; none are expected on the gyroscope.
OUTLIER_ALLOWANCE = {"accel": 2e-4, "gyro": 1e-5}
#: Power at which a rejected candidate's ``detectable_from`` is quoted (:func:`detectable_from`).
DETECT_POWER = 0.9
AX = "xyz"


def detectable_from(t: Test) -> DetectableSize | None:
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
    return DetectableSize(round_sig(size).tolist(), unit, DETECT_POWER, round(lam, 2))


def round_sig(x: np.ndarray, digits: int = 3) -> np.ndarray:
    """``x`` rounded to ``digits`` significant figures (0 stays 0)."""
    x = np.asarray(x, dtype=float)
    scale = np.where(x != 0.0, 10.0 ** (digits - 1 - np.floor(np.log10(np.abs(np.where(x != 0.0, x, 1.0))))), 1.0)
    return np.round(x * scale) / scale


@dataclass(frozen=True)
class OutlierTest:
    """The base fit's outlier count of one sensor against the sensor class's allowance (Poisson tail):
    ``significant`` at :data:`~station.diagnose.likelihood.ALPHA`; ``axes``: those with more than allowed."""

    sensor: str
    count: int
    samples: int
    rate: float
    rate_std: float
    allowance: float
    p_value: float
    axes: tuple[int, ...]

    @property
    def significant(self) -> bool:
        return self.p_value < ALPHA

    def finding(self) -> Finding:
        """The ``outliers`` finding."""
        return Finding(
            "outliers", self.sensor, tuple(AX[k] for k in self.axes) or tuple(AX),
            {"rate_per_sample": {"value": self.rate, "std": self.rate_std, "unit": "1"}},
            OutlierEvidence(self.count, self.samples, self.allowance, self.p_value),
            consistency=tuple(c.entry() for c in not_checked("outliers", self.sensor)))

    def rejection(self, reason: str = "no more outliers than allowed") -> Rejection:
        """The ``outliers`` rejection, with ``reason``."""
        return Rejection("outliers", self.sensor, reason, {"count": self.count, "p_value": self.p_value})


def outlier_test(sd: SensorData) -> OutlierTest:
    n = max(sd.settled_samples, 1)
    count = int(sd.outlier_count.sum())
    lam = OUTLIER_ALLOWANCE[sd.sensor] * 3 * n
    p_value = float(stats.poisson.sf(count - 1, lam)) if count > 0 else 1.0
    limit = OUTLIER_ALLOWANCE[sd.sensor] * n + 3 * math.sqrt(OUTLIER_ALLOWANCE[sd.sensor] * n + 1)
    return OutlierTest(sd.sensor, count, 3 * n, count / (3 * n), math.sqrt(max(count, 1)) / (3 * n),
                       OUTLIER_ALLOWANCE[sd.sensor], p_value, tuple(k for k in range(3) if sd.outlier_count[k] > limit))


def affected_axes(name: str, theta: np.ndarray, cov: np.ndarray) -> list[int]:
    std = np.sqrt(np.clip(np.diag(cov), 1e-300, None))
    z = np.abs(theta) / std
    if len(theta) == 3 and REGISTRY[name].per_axis:
        return [k for k in range(3) if z[k] > 3.0] or [int(np.argmax(z))]
    if len(theta) == 9:
        zz = z.reshape(3, 3)
        return [k for k in range(3) if zz[k].max() > 3.0] or [int(np.argmax(zz.max(axis=1)))]
    return [0, 1, 2]



def finding(sd: SensorData, t: Test, before: ModelQuality, after: ModelQuality, *,
            form: FormInseparable | None = None) -> Finding:
    """The finding of test ``t`` (accepted at one selection step), the sensor's model ``before`` and ``after``
    it; ``form``: the forms of its physics it is not told apart from. Confidence, consistency and bootstrap
    are added when the checks after the selection have run (:func:`station.diagnose.selection.select`)."""
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
    def block_fit(q: ModelQuality) -> BlockFit:
        return BlockFit(round(q.bic, 3), tuple(np.round(q.block_chi2, 4).tolist()),
                        tuple(np.round(q.block_rms * out_factor, 9).tolist()), unit)

    return Finding(
        t.effect, sd.sensor, tuple(AX[k] for k in axes), params,
        Evidence(round(t.gain, 3), t.params, round(t.bic_gain, 3), round(t.critical, 3), round(t.heldout_before, 4),
                 round(t.heldout_after, 4), round(t.heldout_change_se, 4), form),
        FitChange(block_fit(before), block_fit(after)),
        theta=np.array(t.theta, dtype=float),  # fitted SI parameters, for the simulator re-run (rerun.py)
        block_residual=(before.block_residual, after.block_residual),
        theta_std=np.sqrt(np.clip(np.diag(t.cov), 0.0, None)))  # their stated uncertainty (retest.py)


__all__ = ["AX", "DETECT_POWER", "OUTLIER_ALLOWANCE", "OutlierTest", "detectable_from", "finding", "outlier_test"]
