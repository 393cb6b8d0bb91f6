"""Empirical models of located structure: physics the library does not have, described, never named.

For each axis the locator (:mod:`station.diagnose.locator`) flags, a sparse linear model of the block residual
(the final model's, with eq. 3's drift noise at the sensor class) over a dictionary of physical covariates
(:func:`station.diagnose.locator.covariates_by_axis`: rate components, their magnitude, squares, cubes and products,
the products of a rate component with a specific-force component and with the temperature, angular
acceleration, specific force, its square, size and sign, temperature, its direction and rate, force times temperature,
force and rate times the temperature's rate, time since the last rate step, force and rate through first-order lags,
the direction of the last rotation, a delay growing with time, time since power-on, the table's spin phase). Terms
are chosen by forward selection on **held-out segments**: the blocks are split into :data:`FOLDS` folds by segment
(interleaved), every candidate term is fitted on the other folds and scored on the held-out one, and a term is kept
only while the held-out weighted squared error falls by at least :data:`MIN_GAIN` of what is left; at most
:data:`MAX_TERMS`.

The result is reported as *empirical, not in the library*: a description of the structure and how much of it a
held-out segment's prediction removes, not a finding and not a calibration term.
"""

from __future__ import annotations

import numpy as np

from station.diagnose.results import EmpiricalModel

FOLDS = 5
MAX_TERMS = 3
#: A term is kept while it lowers the held-out error by at least this share of what is left.
MIN_GAIN = 0.05


def _folds(segment: np.ndarray) -> np.ndarray:
    """Fold per block: its segment's rank, interleaved over :data:`FOLDS`."""
    _, rank = np.unique(segment, return_inverse=True)
    return np.asarray(rank % FOLDS)


def _cv_error(cols: list[np.ndarray], r: np.ndarray, w: np.ndarray, fold: np.ndarray) -> float:
    """Held-out weighted squared error of the least-squares fit of ``r`` on ``cols`` (with a constant)."""
    x = np.column_stack([np.ones_like(r), *cols])
    err = 0.0
    for f in range(FOLDS):
        test = fold == f
        if not test.any() or test.all():
            continue
        sw = np.sqrt(w[~test])
        beta, *_ = np.linalg.lstsq(x[~test] * sw[:, None], r[~test] * sw, rcond=None)
        e = r[test] - x[test] @ beta
        err += float(np.sum(w[test] * e * e))
    return err


def fit(sensor: str, axis: str, residual: np.ndarray, weight: np.ndarray, segment: np.ndarray,
        dictionary: dict[str, np.ndarray]) -> EmpiricalModel:
    """The forward selection of the module docstring on the block ``residual`` (m,) with ``weight`` (m,)
    (1 / block variance), blocks' ``segment`` (m,), covariates ``dictionary`` (name -> (m,))."""
    fold = _folds(segment)
    chosen: list[str] = []
    base = _cv_error([], residual, weight, fold)
    current = base
    names = [n for n, v in dictionary.items() if np.ptp(v) > 0]
    for _ in range(MAX_TERMS):
        scores = {n: _cv_error([dictionary[c] for c in (*chosen, n)], residual, weight, fold)
                  for n in names if n not in chosen}
        if not scores:
            break
        best = min(scores, key=lambda n: scores[n])
        if current - scores[best] < MIN_GAIN * current:
            break
        chosen.append(best)
        current = scores[best]
    coef: tuple[float, ...] = ()
    if chosen:
        x = np.column_stack([np.ones_like(residual), *[dictionary[c] for c in chosen]])
        sw = np.sqrt(weight)
        beta, *_ = np.linalg.lstsq(x * sw[:, None], residual * sw, rcond=None)
        coef = tuple(float(b) for b in beta[1:])
    improvement = 1.0 - current / base if base > 0 else 0.0
    return EmpiricalModel(sensor, axis, tuple(chosen), coef, max(improvement, 0.0), FOLDS)


__all__ = ["FOLDS", "MAX_TERMS", "MIN_GAIN", "EmpiricalModel", "fit"]
