"""Crossed Gage R&R by ANOVA (AIAG MSA, 4th ed., chapter III section B "ANOVA method").

Pure numerics: a balanced crossed study (every part measured by every appraiser the same number of
times) in, a frozen :class:`GageStudy` out. In the station an "appraiser" is whatever is varied besides
the part: a nest (fixture slot) of the rig, a rig, an operator. The sums of squares come from
statsmodels' two-way ANOVA with interaction (``ols`` + ``anova_lm``); in a balanced design the sequential
and the partial sums of squares agree; the sequential ones (type 1) are used. The variance components are the
expected-mean-square solution of the random-effects model

    y_ijk = mu + P_i + A_j + (PA)_ij + e_ijk,

    sigma_e^2  = MS_E                                 (repeatability, EV)
    sigma_PA^2 = (MS_PA - MS_E) / r                   (interaction)
    sigma_A^2  = (MS_A - MS_PA) / (n r)               (reproducibility, AV)
    sigma_P^2  = (MS_P - MS_PA) / (k r)               (part variation, PV)

for n parts, k appraisers and r repeats, negative estimates set to 0. As in the AIAG manual the
interaction is pooled into the error when it is not significant (p > 0.25 by default): then
``MS_E`` becomes (SS_PA + SS_E) / (df_PA + df_E) and ``MS_A``, ``MS_P`` are compared with it.

GRR^2 = EV^2 + AV^2 + INT^2, TV^2 = GRR^2 + PV^2; %TV = 100 sigma / sigma_TV;
%tolerance = 100 * 6 sigma / (USL - LSL) (AIAG 4th ed. uses 6 sigma); ndc = floor(1.41 PV / GRR).

Confidence intervals (two-sided, ``level``): repeatability from the chi-square distribution with the
error's degrees of freedom; every other component, a linear combination of mean squares, from
Satterthwaite's approximate degrees of freedom (Burdick & Graybill, "Confidence Intervals on Variance
Components", 1992, ch. 2). A component estimated as 0 gets a lower limit of 0.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy import stats

from station.kernel.errors import StationError

POOL_P = 0.25
"""The interaction is pooled into the error above this p-value (AIAG MSA 4th ed.)."""


class StudyDesignError(StationError):
    """The measurements do not form a balanced crossed study that the ANOVA method can analyse."""


@dataclass(frozen=True)
class AnovaRow:
    """One line of the two-way ANOVA table. ``f`` and ``p`` are None for the error and total lines."""

    source: str
    df: int
    ss: float
    ms: float
    f: float | None
    p: float | None


@dataclass(frozen=True)
class Component:
    """One source of variation: variance, standard deviation and shares, in the measurand's unit.

    ``pct_tolerance`` is None when the study has no tolerance; ``ci_low``/``ci_high`` bound the
    standard deviation (two-sided, :attr:`GageStudy.level`).
    """

    name: str
    variance: float
    std: float
    pct_total: float
    pct_contribution: float
    pct_tolerance: float | None
    ci_low: float
    ci_high: float


@dataclass(frozen=True)
class GageStudy:
    """The result of one crossed Gage R&R study of one measurand.

    ``verdict``: 'acceptable' (%GRR < 10), 'conditional' (%GRR <= 30), 'unacceptable' (AIAG's bands),
    where %GRR is of the tolerance when one is given, else of the total variation; ``ndc`` (number of
    distinct categories, AIAG asks >= 5) is judged on its own: :attr:`ndc_adequate`.
    ``determined`` is False when the parts show no variation the study can separate from the gage
    (PV = 0): then %TV and ndc carry no information and the verdict is 'not determined'.
    """

    parts: int
    appraisers: int
    repeats: int
    anova: tuple[AnovaRow, ...]
    pooled: bool
    repeatability: Component
    reproducibility: Component
    interaction: Component
    grr: Component
    part: Component
    total: Component
    ndc: int
    tolerance: float | None
    level: float
    verdict: str
    determined: bool

    @property
    def pct_grr(self) -> float:
        """%GRR of the tolerance when there is one, else of the total variation."""
        if self.tolerance is not None and self.grr.pct_tolerance is not None:
            return self.grr.pct_tolerance
        return self.grr.pct_total

    @property
    def ndc_adequate(self) -> bool:
        return self.determined and self.ndc >= 5

    @property
    def components(self) -> tuple[Component, ...]:
        return (self.repeatability, self.reproducibility, self.interaction, self.grr, self.part, self.total)


def _balanced(parts: np.ndarray, appraisers: np.ndarray) -> tuple[list[object], list[object], int]:
    part_levels = sorted(set(parts.tolist()), key=str)
    app_levels = sorted(set(appraisers.tolist()), key=str)
    if len(part_levels) < 2:
        raise StudyDesignError(f"a Gage R&R study needs at least 2 parts, got {len(part_levels)}")
    if len(app_levels) < 2:
        raise StudyDesignError(f"a Gage R&R study needs at least 2 appraisers (nests), got {len(app_levels)}")
    counts: dict[tuple[object, object], int] = {}
    for p, a in zip(parts.tolist(), appraisers.tolist(), strict=True):
        counts[(p, a)] = counts.get((p, a), 0) + 1
    missing = [(p, a) for p in part_levels for a in app_levels if (p, a) not in counts]
    if missing:
        p, a = missing[0]
        raise StudyDesignError(
            f"the study is not crossed: part {p!s} was never measured in {a!s} ({len(missing)} cells empty)")
    repeats = set(counts.values())
    if len(repeats) != 1:
        raise StudyDesignError(
            f"the study is not balanced: cells hold {min(repeats)} to {max(repeats)} repeats; "
            "use the same number of repeats in every part and nest")
    r = repeats.pop()
    if r < 2:
        raise StudyDesignError("a Gage R&R study needs at least 2 repeats per part and nest")
    return part_levels, app_levels, r


def _anova_table(parts: np.ndarray, appraisers: np.ndarray, values: np.ndarray) -> dict[str, tuple[float, float]]:
    """(df, SS) per source from statsmodels' two-way ANOVA with interaction."""
    import pandas as pd
    import statsmodels.formula.api as smf
    from statsmodels.stats.anova import anova_lm

    frame = pd.DataFrame({"y": values, "part": [str(p) for p in parts], "app": [str(a) for a in appraisers]})
    model = smf.ols("y ~ C(part) * C(app)", data=frame).fit()
    table = anova_lm(model, typ=1)  # sequential sums of squares: equal to every other type when balanced
    names = {"C(part)": "part", "C(app)": "appraiser", "C(part):C(app)": "interaction", "Residual": "error"}
    return {names[str(k)]: (float(table.loc[k, "df"]), float(table.loc[k, "sum_sq"])) for k in table.index}


def _satterthwaite_ci(terms: Sequence[tuple[float, float, float]], level: float) -> tuple[float, float, float]:
    """Variance estimate sum(c_i MS_i) with Satterthwaite's df and its two-sided CI on the std.

    ``terms``: (c_i, MS_i, df_i). Returns (variance, std low, std high). A combination <= 0 is estimated
    as 0 with a lower limit of 0; its upper limit then comes from the positive terms alone (conservative).
    """
    var = sum(c * ms for c, ms, _ in terms)
    used = terms if var > 0 else tuple(t for t in terms if t[0] > 0)
    est = sum(c * ms for c, ms, _ in used)
    denom = sum((c * ms) ** 2 / df for c, ms, df in used)
    if est <= 0 or denom <= 0:
        return 0.0, 0.0, 0.0
    nu = est**2 / denom
    alpha = 1.0 - level
    q_low = float(stats.chi2.ppf(alpha / 2.0, nu))
    high = math.sqrt(nu * est / q_low) if q_low > 0 else math.inf  # a fraction of a degree of freedom: unbounded
    if var <= 0:
        return 0.0, 0.0, high
    q_high = float(stats.chi2.ppf(1.0 - alpha / 2.0, nu))
    low = math.sqrt(nu * var / q_high) if q_high > 0 else 0.0
    return var, low, high


def gage_rr(
    parts: Sequence[object],
    appraisers: Sequence[object],
    values: Sequence[float],
    *,
    tolerance: float | None = None,
    level: float = 0.90,
    pool_p: float = POOL_P,
    k_sigma: float = 6.0,
) -> GageStudy:
    """Analyse a balanced crossed study: one value per (part, appraiser, repeat).

    Args:
        parts, appraisers, values: equal-length sequences, one entry per measurement.
        tolerance: USL - LSL in the values' unit (None: no %tolerance).
        level: two-sided confidence level of the intervals.
        pool_p: pool the interaction into the error above this p-value (AIAG: 0.25; 1.0 never pools).
        k_sigma: the spread a tolerance is compared with (AIAG 4th ed.: 6 sigma; older: 5.15).
    """
    p_arr = np.asarray(list(parts), dtype=object)
    a_arr = np.asarray(list(appraisers), dtype=object)
    y = np.asarray(values, dtype=float)
    if not (len(p_arr) == len(a_arr) == len(y)):
        raise StudyDesignError("parts, appraisers and values differ in length")
    if not np.all(np.isfinite(y)):
        raise StudyDesignError(f"{int(np.sum(~np.isfinite(y)))} measured values are not finite")
    part_levels, app_levels, r = _balanced(p_arr, a_arr)
    n, k = len(part_levels), len(app_levels)
    if tolerance is not None and not (tolerance > 0 and math.isfinite(tolerance)):
        raise StudyDesignError(f"the tolerance must be a positive width, got {tolerance}")

    ss = _anova_table(p_arr, a_arr, y)
    df_p, ss_p = ss["part"]
    df_a, ss_a = ss["appraiser"]
    df_pa, ss_pa = ss["interaction"]
    df_e, ss_e = ss["error"]
    ms_p, ms_a, ms_pa, ms_e = ss_p / df_p, ss_a / df_a, ss_pa / df_pa, ss_e / df_e
    p_int = float(stats.f.sf(ms_pa / ms_e, df_pa, df_e)) if ms_e > 0 else 0.0
    # F tests of parts and appraisers against the interaction (random-effects model, as the AIAG table)
    f_p = ms_p / ms_pa if ms_pa > 0 else math.inf
    f_a = ms_a / ms_pa if ms_pa > 0 else math.inf
    table = (
        AnovaRow("appraiser", int(df_a), ss_a, ms_a, f_a, float(stats.f.sf(f_a, df_a, df_pa))),
        AnovaRow("part", int(df_p), ss_p, ms_p, f_p, float(stats.f.sf(f_p, df_p, df_pa))),
        AnovaRow("interaction", int(df_pa), ss_pa, ms_pa, ms_pa / ms_e if ms_e > 0 else math.inf, p_int),
        AnovaRow("repeatability", int(df_e), ss_e, ms_e, None, None),
        AnovaRow("total", int(df_p + df_a + df_pa + df_e), ss_p + ss_a + ss_pa + ss_e,
                 (ss_p + ss_a + ss_pa + ss_e) / (df_p + df_a + df_pa + df_e), None, None),
    )

    pooled = p_int > pool_p
    alpha = 1.0 - level
    if pooled:
        df_err = df_pa + df_e
        ms_err = (ss_pa + ss_e) / df_err
        ms_ref, df_ref = ms_err, df_err  # what parts and appraisers are compared with
        var_int, int_lo, int_hi = 0.0, 0.0, 0.0
    else:
        df_err, ms_err = df_e, ms_e
        ms_ref, df_ref = ms_pa, df_pa
        var_int, int_lo, int_hi = _satterthwaite_ci(((1.0 / r, ms_pa, df_pa), (-1.0 / r, ms_e, df_e)), level)
    var_ev = ms_err
    ev_lo = math.sqrt(df_err * ms_err / stats.chi2.ppf(1.0 - alpha / 2.0, df_err))
    ev_hi = math.sqrt(df_err * ms_err / stats.chi2.ppf(alpha / 2.0, df_err))
    var_av, av_lo, av_hi = _satterthwaite_ci(((1.0 / (n * r), ms_a, df_a), (-1.0 / (n * r), ms_ref, df_ref)), level)
    var_pv, pv_lo, pv_hi = _satterthwaite_ci(((1.0 / (k * r), ms_p, df_p), (-1.0 / (k * r), ms_ref, df_ref)), level)
    # GRR^2 = sigma_A^2 + sigma_PA^2 + sigma_e^2 as one combination of mean squares
    grr_terms: tuple[tuple[float, float, float], ...]
    tv_terms: tuple[tuple[float, float, float], ...]
    if pooled:
        grr_terms = ((1.0 / (n * r), ms_a, df_a), (1.0 - 1.0 / (n * r), ms_err, df_err))
        tv_terms = ((1.0 / (n * r), ms_a, df_a), (1.0 / (k * r), ms_p, df_p),
                    (1.0 - 1.0 / (n * r) - 1.0 / (k * r), ms_err, df_err))
    else:
        grr_terms = ((1.0 / (n * r), ms_a, df_a), (1.0 / r - 1.0 / (n * r), ms_pa, df_pa),
                     (1.0 - 1.0 / r, ms_e, df_e))
        tv_terms = ((1.0 / (n * r), ms_a, df_a), (1.0 / (k * r), ms_p, df_p),
                    (1.0 / r - 1.0 / (n * r) - 1.0 / (k * r), ms_pa, df_pa), (1.0 - 1.0 / r, ms_e, df_e))
    var_grr = var_ev + var_av + var_int
    _, grr_lo, grr_hi = _satterthwaite_ci(grr_terms, level)
    var_tv = var_grr + var_pv
    _, tv_lo, tv_hi = _satterthwaite_ci(tv_terms, level)
    sd_tv = math.sqrt(var_tv)

    def component(name: str, var: float, lo: float, hi: float) -> Component:
        sd = math.sqrt(var)
        return Component(
            name=name,
            variance=var,
            std=sd,
            pct_total=100.0 * sd / sd_tv if sd_tv > 0 else math.nan,
            pct_contribution=100.0 * var / var_tv if var_tv > 0 else math.nan,
            pct_tolerance=None if tolerance is None else 100.0 * k_sigma * sd / tolerance,
            ci_low=lo,
            ci_high=hi,
        )

    grr = component("grr", var_grr, grr_lo, grr_hi)
    pv = component("part", var_pv, pv_lo, pv_hi)
    determined = var_pv > 0 and var_grr > 0
    ndc = math.floor(1.41 * pv.std / grr.std) if determined else 0
    pct = grr.pct_tolerance if grr.pct_tolerance is not None else grr.pct_total
    if tolerance is None and not determined:
        verdict = "not determined"
    elif pct < 10.0:
        verdict = "acceptable"
    elif pct <= 30.0:
        verdict = "conditional"
    else:
        verdict = "unacceptable"
    return GageStudy(
        parts=n,
        appraisers=k,
        repeats=r,
        anova=table,
        pooled=pooled,
        repeatability=component("repeatability", var_ev, ev_lo, ev_hi),
        reproducibility=component("reproducibility", var_av, av_lo, av_hi),
        interaction=component("interaction", var_int, int_lo, int_hi),
        grr=grr,
        part=pv,
        total=component("total", var_tv, tv_lo, tv_hi),
        ndc=ndc,
        tolerance=tolerance,
        level=level,
        verdict=verdict,
        determined=determined,
    )
