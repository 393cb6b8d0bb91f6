"""A finding re-tested against the empirical alternative: is it a stand-in for physics the library does not have?

The forward selection (:mod:`station.diagnose.selection`) only compares library candidates with each other. Physics
outside the library leaves a signal that a library effect can partly take up: on a gyro whose scale depends on the
specific force along its axis, a ``temperature_scale`` takes the difference between the scale seen in the rate holds
and in the tumbles (they happen at other temperatures), and is named although the temperature has nothing to do
with it. So each accepted finding is re-tested against the strongest covariates of the locator's dictionary
(:func:`station.diagnose.locator.covariates_by_axis`, the empirical models' terms: rate, force and temperature and their
products), each a per-axis term ``E`` that is no library effect:

- ``E`` is taken from the residual of the model without the finding: the :data:`RIVALS` covariates (over the three
  axes) with the largest chi^2 on it, each beyond the chi^2(1) tail ``ALPHA`` shared by the dictionary's tests
  (Bonferroni: the rival is the best of many; a bigger dictionary pays for itself here);
- the finding ``F`` is a **stand-in** for ``E`` when ``F`` is not significant given ``E`` (its own test and
  threshold, :meth:`station.diagnose.likelihood.SensorProblem.test_mean`), while ``E`` is significant given ``F``
  by its own test (the same level ``ALPHA`` as ``F``'s), explains at least as much as ``F`` (its gain given ``F``
  not below ``F``'s given it: the model with ``E`` alone fits as well as the one with ``F`` alone) and does not make
  the held-out segments' prediction worse (``Test.validates``).

The conditions together are the selection's own rule for two candidates that explain the same signal
(``selection._unique``), with the empirical term as the other candidate. A library effect whose form is a
dictionary term (a ``temperature_scale`` on one axis is ``rate * temperature``) is kept: given ``F`` such a
rival takes nothing (a chi^2(1) draw, not beyond ``ALPHA``'s level). A true library effect of another form is not
explained by a dictionary term: it stays significant given it. A stand-in is rejected; what it took up is then
left to the locator (``unexplained``).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy import stats

from station.diagnose import locator
from station.diagnose.likelihood import ALPHA, SensorProblem

#: Covariates of the dictionary (over the three axes) a finding is re-tested against.
RIVALS = 3


@dataclass(frozen=True)
class StandIn:
    """A finding that an empirical term explains: the term, ``F``'s gain given it and its threshold, the term's
    gain given ``F`` and its (Bonferroni) threshold."""

    effect: str
    rival: str
    axis: str
    gain_given_rival: float
    threshold: float
    rival_gain: float
    rival_threshold: float

    def details(self) -> dict[str, Any]:
        return {"rival": f"{self.rival} on {self.axis}", "gain_given_rival": round(self.gain_given_rival, 2),
                "threshold": round(self.threshold, 2), "rival_gain_given_it": round(self.rival_gain, 2),
                "rival_threshold": round(self.rival_threshold, 2)}


def _strongest(prob: SensorProblem, values: Sequence[Mapping[str, np.ndarray]]
               ) -> tuple[list[tuple[float, int, str, np.ndarray]], int]:
    """The :data:`RIVALS` covariates (``values``: per axis, name -> block values) with the largest chi^2 on the
    current model's whitened residual: (gain, axis, name, block values), and the number of covariates tried."""
    m = prob.m
    fit = prob.whitened_fit()
    chols, x, res = fit.chols, fit.x, fit.res
    found: list[tuple[float, int, str, np.ndarray]] = []
    n = 0
    for k in range(3):
        gains = locator.covariate_gains(values[k], chols[k], x[k * m:(k + 1) * m], res[k * m:(k + 1) * m])
        n += len(gains)
        found.extend((g, k, name, values[k][name]) for name, _cw, _coef, g in gains)
    found.sort(key=lambda t: -t[0])
    return found[:RIVALS], n


def stand_ins(prob: SensorProblem, baseline: Any, names: Sequence[str]) -> list[StandIn]:
    """The accepted effects ``names`` (in ``prob``'s order; names starting with ``~`` are not tested) that stand in
    for an empirical term (module docstring)."""
    out: list[StandIn] = []
    values: Sequence[Mapping[str, np.ndarray]] = ()
    for i, name in enumerate(names):
        if name.startswith("~"):
            continue
        if not values:
            values = locator.covariates_by_axis(baseline, prob.sd)
        zf = prob.accepted[i]
        with prob.without(i):
            rivals, n_tried = _strongest(prob, values)
        crit = float(stats.chi2.isf(ALPHA / max(n_tried, 1), 1))
        for g, k, rname, v in rivals:
            if g <= crit:  # a term that takes less than that without F is no rival given F
                break
            ze = np.zeros((prob.m, 3, 1))
            ze[:, k, 0] = v
            with prob.without(i), prob.given(ze):
                f_given = prob.test_mean(name, zf)
            if f_given.passes:
                continue
            e_given = prob.test_mean(f"empirical {rname}", ze)
            # the term given F at its own test's level (F's is F's): the dictionary's multiplicity was paid above,
            # in choosing the term (its gain without F beyond ``crit``); and it explains at least as much as F
            if (e_given.params > 0 and e_given.gain > e_given.threshold and e_given.gain >= f_given.gain
                    and e_given.validates):
                out.append(StandIn(name, rname, locator.AX[k], f_given.gain, f_given.threshold, e_given.gain,
                                   e_given.threshold))
                break
    return out


__all__ = ["RIVALS", "StandIn", "stand_ins"]
