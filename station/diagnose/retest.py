"""Findings re-tested under the final model: the outlier count, and each finding's size.

* **Outliers recounted.** The base fit's outlier count (:mod:`station.diagnose.residuals`) is taken on the
  residual against the base model: an effect the base model lacks (a time offset leaves large errors at every
  tumble and ramp edge) shows up there as "outliers". The count is taken again on the residual minus the
  accepted effects' fitted signal, with the same rule (a sample further than ``OUTLIER_SIGMA`` noise sigmas
  from its local mean).
* **Sizes re-fitted.** A finding's reported value is the one of the forward-selection step that accepted it,
  before the later effects came in, and with eq. 3's drift noise fitted freely. Its size is fitted again in
  the final model (all accepted effects together) with the drift noise free and with it bounded by the
  sensor class (:func:`station.diagnose.locator.class_drift_noise`). The range of the three values (the spread)
  is added in quadrature to the finding's stated standard deviation (its ``parameters``' ``std``): how much the
  value depends on the model around it is part of its uncertainty. When the three values differ by more than the
  finding's uncertainty, the finding is also not stated at ``high`` confidence (``evidence.retest`` holds them).
* **Warm-up-like sizes with T_c integrated out.** For an effect that competes with eq. 3's warm-up (``PROFILE_TC``:
  the temperature bias and scale), the final model's value and its uncertainty are taken over the warm-up's T_c
  (:meth:`station.diagnose.likelihood.SensorProblem.tc_marginal`), not at the one T_c the drift's re-fit settled on
  (often a bound of the class's range: a self-heating course and the warm-up have nearly the same shape, and the
  value at a wrong T_c is biased by about its whole stated uncertainty). That value replaces the selection step's,
  and the spread is taken between the two integrated values (drift noise free and bounded by the class).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from scipy import linalg
from scipy.ndimage import uniform_filter1d

from station.diagnose.effect_registry import engineering
from station.diagnose.likelihood import PROFILE_TC
from station.diagnose.locator import class_drift_noise
from station.diagnose.residuals import OUTLIER_SIGMA, SensorData
from station.diagnose.results import SizeRetest
from station.session.model import Kind

#: A finding whose value changes by more than this many of its standard deviations between the fits has
#: its confidence capped.
SPREAD_STD = 1.0
NUISANCE = "~"


def recount_outliers(session: Any, sd: SensorData, fitted: np.ndarray) -> SensorData:
    """``sd`` with its outlier count taken on ``residual - fitted`` (``fitted``: the accepted effects' signal per
    sample, (n, 3)); the same rule as the base count, settled segments only."""
    outliers = np.zeros(3, dtype=int)
    for s in session.segments():
        if len(s) < 10 or s.kind == Kind.MOVE or not np.all(np.isfinite(session.ref_accel_mps2[s.start:s.stop])):
            continue
        x = sd.residual[s.start:s.stop] - fitted[s.start:s.stop]  # a segment at a time: no (n, 3) copy
        local = uniform_filter1d(x, size=max(3, min(len(s), 101)), axis=0, mode="nearest")
        outliers += (np.abs(x - local) > OUTLIER_SIGMA * sd.sigma).sum(axis=0)
    return replace(sd, outlier_count=outliers)


@dataclass(frozen=True)
class SizeCheck:
    """One finding's size in three fits (SI parameters) and the uncertainty it is compared with (SI)."""

    effect: str
    sensor: str
    reported: np.ndarray
    final: np.ndarray
    final_class_q: np.ndarray
    std: np.ndarray
    #: the final values are integrated over the warm-up's T_c (:meth:`SensorProblem.tc_marginal`): they replace the
    #: selection step's value, which is conditional on one T_c and left out of the spread
    integrated: bool = False

    @property
    def spread(self) -> np.ndarray:
        """Per parameter, the range of the three values (SI; of the two integrated ones where :attr:`integrated`):
        how much the value depends on the model around it."""
        values = [self.final, self.final_class_q] if self.integrated else [self.reported, self.final,
                                                                             self.final_class_q]
        return np.ptp(np.stack(values), axis=0)

    @property
    def change_over_std(self) -> float:
        return float(np.max(self.spread / np.maximum(self.std, 1e-300)))

    def stated_std(self, stated: np.ndarray) -> np.ndarray:
        """The finding's stated standard deviations ``stated`` (SI) with the spread added in quadrature: the
        statistical uncertainty of one model's value and the value's dependence on the model (which effects are in
        beside it, how free eq. 3's drift noise is), a type B component in the sense of the GUM (JCGM 100, 4.3)."""
        return np.sqrt(np.asarray(stated, dtype=float) ** 2 + self.spread**2)

    def result(self) -> SizeRetest:
        """The re-test as the finding's evidence carries it (engineering units)."""
        cov = np.diag(self.std**2)
        return SizeRetest(
            engineering(self.effect, self.sensor, self.final, cov),
            engineering(self.effect, self.sensor, self.final_class_q, cov),
            round(self.change_over_std, 2),
            ("the value differs between the selection step, the final model and the final model with eq. 3's drift "
             "noise bounded by the sensor class by more than its uncertainty: the spread is the uncertainty")
            if self.change_over_std > SPREAD_STD else "stable")


def _joint(prob: Any) -> tuple[np.ndarray, np.ndarray, int]:
    fit = prob.whitened_fit()
    return fit.beta, linalg.pinv(fit.x.T @ fit.x), fit.nbase


def sizes(prob: Any, names: list[str], reported: dict[str, tuple[np.ndarray, np.ndarray | None]]
          ) -> dict[str, SizeCheck]:
    """Per accepted mean effect of ``names`` (with its ``reported`` SI parameters and their stated standard
    deviations, None: unknown) its :class:`SizeCheck`; the uncertainty it is compared with is the larger of the
    stated one and the final model's."""
    if not names:
        return {}
    beta, cov, nbase = _joint(prob)
    q_class = class_drift_noise(prob.sd.sensor, prob.sd.params.bias_drift)
    with prob.drift_noise_at_most(q_class):
        beta_c, _, _ = _joint(prob)
    out: dict[str, SizeCheck] = {}
    col = nbase
    for index, (name, zb) in enumerate(zip(names, prob.accepted, strict=True)):
        p = zb.shape[2]
        sl = slice(col, col + p)
        col += p
        if name.startswith(NUISANCE) or name not in reported or len(reported[name][0]) != p:
            continue
        theta, stated = reported[name]
        final, final_c = beta[sl].copy(), beta_c[sl].copy()
        std = np.sqrt(np.clip(np.diag(cov)[sl], 0.0, None))
        integrated = name in PROFILE_TC and (marginal := prob.tc_marginal(index, q_class)) is not None
        if integrated:
            final, std, final_c = marginal
        if stated is not None and len(stated) == p:
            std = np.maximum(std, np.asarray(stated, dtype=float))
        out[name] = SizeCheck(name, prob.sd.sensor, np.asarray(theta, dtype=float), final, final_c, std,
                              integrated)
    return out


__all__ = ["SPREAD_STD", "SizeCheck", "recount_outliers", "sizes"]
