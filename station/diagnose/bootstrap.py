"""A bootstrap over segments of the accepted findings: how confident each one is.

Per sensor, on the final model: the recording's segments (rest, each pose, each rate step, each move)
are drawn with replacement, :data:`RESAMPLES` times, from a generator seeded with :data:`SEED` and the
sensor (deterministic: same recording, same numbers). A segment drawn ``c`` times counts ``c`` times:
its blocks' white noise variance is divided by ``c`` (the information of ``c`` copies), a segment not
drawn is left out. Only the linear part is re-fitted (the base model's terms of eq. 1 and eq. 3's
warm-up column, every accepted mean effect) by GLS, with the drift's T_c and q of the final model and the
white noise inflated by the final model's dispersion per segment kind
(:func:`station.diagnose.robust.dispersion`); the drift's non-linear parameters are not re-fitted (cost).

Per finding: ``accepted_fraction``, the share of resamples in which its drop-one chi^2 gain against the
rest of the model exceeds the threshold of its test (the larger of the chi^2 critical value and the BIC
penalty); the bootstrap spread of its parameters against the standard error the fit states
(``std_ratio``, median over the parameters: about 1 when the stated uncertainty is right, above it when
the value depends on which segments are in); and the level the report states: ``high`` from
:data:`HIGH` accepted, ``medium`` from :data:`MEDIUM`, else ``low``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy import linalg

from station.diagnose.likelihood import RCOND
from station.diagnose.registry import SHAPES, unit_factor

#: Resamples per sensor (the linear refit costs a few ms each).
RESAMPLES = 60
SEED = 16
HIGH = 0.9
MEDIUM = 0.6
NUISANCE = "~"


@dataclass(frozen=True)
class Bootstrap:
    """One finding's bootstrap (see the module docstring); ``median``/``std``/``unit``: its parameters over the
    resamples in engineering units (per-axis and scalar effects only)."""

    resamples: int
    seed: int
    accepted_fraction: float
    level: str
    std_ratio: float
    median: tuple[float, ...] | None = None
    std: tuple[float, ...] | None = None
    unit: str | None = None

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {"resamples": self.resamples, "seed": self.seed,
                               "accepted_fraction": self.accepted_fraction, "level": self.level,
                               "std_ratio": self.std_ratio,
                               "method": "segments drawn with replacement, linear part refitted"}
        if self.median is not None:
            out.update(median=list(self.median), std=list(self.std or ()), unit=self.unit)
        return out


def level(fraction: float) -> str:
    return "high" if fraction >= HIGH else "medium" if fraction >= MEDIUM else "low"


def _design(prob: Any, keep: np.ndarray, white: np.ndarray) -> tuple[np.ndarray, np.ndarray, int]:
    """Whitened stacked design (base per axis, then the accepted effects) and data on the blocks ``keep``,
    with white block variance ``white`` (m, 3) (0 weight blocks already dropped)."""
    idx = np.flatnonzero(keep)
    chols, y = prob.whitened(idx, white)
    x, total = prob.design(chols, prob.accepted, idx)
    return x, y, total


def _chi2(x: np.ndarray, y: np.ndarray) -> tuple[float, np.ndarray]:
    beta, *_ = linalg.lstsq(x, y, cond=RCOND, check_finite=False)
    r = y - x @ beta
    return float(r @ r), beta


def bootstrap(prob: Any, names: list[str], thresholds: dict[str, float], phi: np.ndarray, *,
              resamples: int = RESAMPLES, seed: int = SEED) -> dict[str, Bootstrap]:
    """The bootstrap of the module docstring for the accepted mean effects ``names`` (order of
    ``prob.accepted``) with a test threshold in ``thresholds``; ``phi``: dispersion per block and axis (m, 3)."""
    sd = prob.sd
    targets = [(j, n) for j, n in enumerate(names) if not n.startswith(NUISANCE) and n in thresholds]
    if not targets:
        return {}
    sizes = [a.shape[2] for a in prob.accepted]
    starts = np.concatenate([[0], np.cumsum(sizes)]).astype(int)
    _, seg_idx = np.unique(sd.segment, return_inverse=True)
    n_seg = int(seg_idx.max()) + 1
    rng = np.random.default_rng([seed, 0 if sd.sensor == "accel" else 1, prob.m])
    white = prob.white * phi
    # the stated standard errors: full data, the model's own noise (not inflated)
    x, y, total = _design(prob, np.ones(prob.m, dtype=bool), prob.white)
    cov = linalg.pinv(x.T @ x)
    stated = np.sqrt(np.clip(np.diag(cov)[total:], 0.0, None))
    accepted = {n: 0 for _, n in targets}
    values: dict[str, list[np.ndarray]] = {n: [] for _, n in targets}
    for _ in range(resamples):
        c = rng.multinomial(n_seg, np.full(n_seg, 1.0 / n_seg))[seg_idx]
        keep = c > 0
        w = np.where(keep[:, None], white / np.maximum(c, 1)[:, None], 0.0)
        try:
            x, y, total = _design(prob, keep, w)
        except linalg.LinAlgError:
            continue
        chi_full, beta = _chi2(x, y)
        for j, n in targets:
            cols = np.r_[total + starts[j]:total + starts[j + 1]]
            chi_without, _ = _chi2(np.delete(x, cols, axis=1), y)
            accepted[n] += (chi_without - chi_full) > thresholds[n]
            values[n].append(beta[cols])
    out: dict[str, Bootstrap] = {}
    for j, n in targets:
        if not values[n]:
            continue
        v = np.array(values[n])
        frac = accepted[n] / len(v)
        s_boot = v.std(axis=0, ddof=1) if len(v) > 1 else np.full(v.shape[1], np.nan)
        s_fit = stated[starts[j]:starts[j + 1]]
        ok = s_fit > 0
        ratio = float(np.median(s_boot[ok] / s_fit[ok])) if ok.any() else float("nan")
        median = std = unit = None
        if n not in SHAPES and v.shape[1] <= 3:
            factor, unit = unit_factor(n, sd.sensor)
            median = tuple(float(f"{a:.4g}") for a in np.median(v, axis=0) * factor)
            std = tuple(float(f"{a:.3g}") for a in s_boot * factor)
        out[n] = Bootstrap(len(v), seed, round(frac, 3), level(frac), round(ratio, 2), median, std, unit)
    return out


__all__ = ["HIGH", "MEDIUM", "RESAMPLES", "SEED", "Bootstrap", "bootstrap", "level"]
