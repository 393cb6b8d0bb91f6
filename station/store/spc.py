"""Statistical process control on summed subgroups: capability indices and X-bar/S control charts with the
Western Electric / Nelson run rules. Pure numerics: sums in, frozen results out (no database here).

Definitions (AIAG SPC manual; Montgomery, *Introduction to Statistical Quality Control*):

- a subgroup is the values of one parameter from one day, station, lot and limits version (the rows of
  :class:`station.store.models.QualityDaily`); ``n_i``, ``S1_i = sum(x - ref)``, ``S2_i = sum((x - ref)^2)``;
- sigma within = sqrt(sum_i (S2_i - S1_i^2/n_i) / sum_i (n_i - 1)) (pooled within-subgroup standard deviation);
  sigma overall = the sample standard deviation of all values;
- Cp = (USL - LSL) / (6 sigma_within), Cpk = min(USL - mean, mean - LSL) / (3 sigma_within);
  Pp and Ppk the same with sigma overall. With one limit only, Cp/Pp are None and Cpk/Ppk use that side.
- capability indices are shown from :data:`MIN_CAPABILITY_N` values on ("too few units" below): from a handful
  of values a Cpk is mostly noise; with them goes the approximate confidence interval of Cpk
  (:func:`cpk_interval`, Bissell 1990, as in the NIST/SEMATECH e-Handbook of Statistical Methods, 6.1.6).
- X-bar chart per day: centre line the grand mean, limits grand mean +- 3 sigma_within / sqrt(n_day)
  (variable subgroup size); S chart: centre c4(n) sigma_within, limits (c4 +- 3 sqrt(1 - c4^2)) sigma_within.
- run rules on z_i = (xbar_i - centre) / (sigma_within / sqrt(n_i)) (Nelson's numbering; 1-4 are Western
  Electric's zone rules 1, 4 and 2 and 3 in his order): 1 one point beyond 3 sigma; 2 nine in a row on one
  side; 3 six in a row steadily rising or falling; 4 fourteen in a row alternating; 5 two of three beyond
  2 sigma on one side; 6 four of five beyond 1 sigma on one side; 7 fifteen in a row within 1 sigma;
  8 eight in a row beyond 1 sigma on either side.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass
from statistics import NormalDist

RULES: dict[int, str] = {
    1: "one point beyond 3 sigma",
    2: "9 points in a row on one side of the centre line",
    3: "6 points in a row steadily rising or falling",
    4: "14 points in a row alternating up and down",
    5: "2 of 3 points beyond 2 sigma on one side",
    6: "4 of 5 points beyond 1 sigma on one side",
    7: "15 points in a row within 1 sigma",
    8: "8 points in a row beyond 1 sigma on either side",
}


@dataclass(frozen=True)
class Capability:
    """n values of one parameter against its limits (``low``/``high``, None: no limit on that side).

    ``mean``, ``sigma_within`` and ``sigma_overall`` are in the parameter's unit; indices are 1.
    """

    n: int
    mean: float
    sigma_within: float | None
    sigma_overall: float | None
    low: float | None
    high: float | None
    cp: float | None
    cpk: float | None
    pp: float | None
    ppk: float | None


def _index(mean: float, sigma: float | None, low: float | None,
           high: float | None) -> tuple[float | None, float | None]:
    if sigma is None or not sigma > 0.0:
        return None, None
    cp = (high - low) / (6.0 * sigma) if low is not None and high is not None else None
    sides = [x for x in ((high - mean) if high is not None else None, (mean - low) if low is not None else None)
             if x is not None]
    cpk = min(sides) / (3.0 * sigma) if sides else None
    return cp, cpk


def capability(n: int, s1: float, s2: float, within_ss: float, within_df: int, ref: float,
               low: float | None, high: float | None) -> Capability:
    """Capability from summed subgroups: ``n`` values, ``s1 = sum(x - ref)``, ``s2 = sum((x - ref)^2)``,
    ``within_ss = sum_i (S2_i - S1_i^2 / n_i)`` over the subgroups and ``within_df = sum_i (n_i - 1)``."""
    mean_d = s1 / n if n else 0.0
    overall = math.sqrt(max(s2 - s1 * mean_d, 0.0) / (n - 1)) if n > 1 else None
    within = math.sqrt(max(within_ss, 0.0) / within_df) if within_df > 0 else None
    mean = ref + mean_d
    cp, cpk = _index(mean, within, low, high)
    pp, ppk = _index(mean, overall, low, high)
    return Capability(n, mean, within, overall, low, high, cp, cpk, pp, ppk)


#: Capability indices (Cp, Cpk, Pp, Ppk) are shown from this many values on; below, "too few units".
MIN_CAPABILITY_N = 25


def cpk_interval(cpk: float | None, n: int, confidence: float = 0.95) -> tuple[float, float] | None:
    """The two-sided ``confidence`` interval of ``cpk`` estimated from ``n`` values (None: no Cpk, or n < 2).

    Bissell's normal approximation: Cpk +- z sqrt(1 / (9 n) + Cpk^2 / (2 (n - 1))) (NIST/SEMATECH e-Handbook
    6.1.6). Written here because neither scipy nor statsmodels has it; it assumes normal values and treats the
    pooled within-subgroup sigma as the sample sigma of n values (close for many subgroups).
    """
    if cpk is None or n < 2 or not 0.0 < confidence < 1.0:
        return None
    z = NormalDist().inv_cdf(0.5 + confidence / 2.0)
    half = z * math.sqrt(1.0 / (9.0 * n) + cpk * cpk / (2.0 * (n - 1)))
    return cpk - half, cpk + half


def c4(n: int) -> float:
    """The bias factor of the sample standard deviation of n normal values (E[s] = c4 sigma)."""
    if n < 2:
        return float("nan")
    return math.exp(math.lgamma(n / 2.0) - math.lgamma((n - 1) / 2.0)) * math.sqrt(2.0 / (n - 1))


@dataclass(frozen=True)
class ChartPoint:
    """One subgroup (day) on the X-bar and S charts; ``rules``: the run rules this point completes."""

    label: str
    n: int
    mean: float
    s: float | None
    lcl: float | None
    ucl: float | None
    s_lcl: float | None
    s_ucl: float | None
    z: float | None
    rules: tuple[int, ...]


@dataclass(frozen=True)
class ControlChart:
    """X-bar/S chart of one parameter: centre line, sigma within (unit), points, and the rules violated."""

    center: float
    sigma_within: float | None
    points: tuple[ChartPoint, ...]
    violations: tuple[int, ...]  # the rules violated anywhere, ascending


def control_chart(labels: Sequence[str], n: Sequence[int], s1: Sequence[float], s2: Sequence[float],
                  ref: float) -> ControlChart:
    """The X-bar/S chart of subgroups ``labels`` (in time order) from their sums about ``ref``."""
    total = sum(n)
    center_d = sum(s1) / total if total else 0.0
    ss = sum(max(b - a * a / k, 0.0) for k, a, b in zip(n, s1, s2, strict=True) if k > 0)
    df = sum(k - 1 for k in n if k > 0)
    sigma = math.sqrt(ss / df) if df > 0 and ss > 0 else None
    z: list[float | None] = []
    for k, a in zip(n, s1, strict=True):
        z.append((a / k - center_d) / (sigma / math.sqrt(k)) if sigma and k > 0 else None)
    flags = run_rules(z)
    points = []
    for i, (lab, k, a, b) in enumerate(zip(labels, n, s1, s2, strict=True)):
        mean = ref + a / k
        s = math.sqrt(max(b - a * a / k, 0.0) / (k - 1)) if k > 1 else None
        half = 3.0 * sigma / math.sqrt(k) if sigma else None
        cc = c4(k)
        s_lcl = s_ucl = None
        if sigma and k > 1:
            w = 3.0 * math.sqrt(max(1.0 - cc * cc, 0.0))
            s_lcl, s_ucl = max(cc - w, 0.0) * sigma, (cc + w) * sigma
        points.append(ChartPoint(lab, k, mean, s, None if half is None else ref + center_d - half,
                                 None if half is None else ref + center_d + half, s_lcl, s_ucl, z[i],
                                 tuple(sorted(flags[i]))))
    violated = sorted({r for f in flags for r in f})
    return ControlChart(ref + center_d, sigma, tuple(points), tuple(violated))


def run_rules(z: Sequence[float | None]) -> list[set[int]]:
    """For each standardized point the run rules (1-8, see :data:`RULES`) whose window ends there.

    A point without a value (None) breaks every run.
    """
    out: list[set[int]] = [set() for _ in z]

    def window(i: int, k: int) -> list[float] | None:
        if i + 1 < k:
            return None
        w = z[i + 1 - k: i + 1]
        given = [float(v) for v in w if v is not None]
        return given if len(given) == len(w) else None

    for i, v in enumerate(z):
        if v is None:
            continue
        if abs(v) > 3.0:
            out[i].add(1)
        w = window(i, 9)
        if w and (all(x > 0 for x in w) or all(x < 0 for x in w)):
            out[i].add(2)
        w = window(i, 6)
        if w and (all(b > a for a, b in itertools.pairwise(w))
                  or all(b < a for a, b in itertools.pairwise(w))):
            out[i].add(3)
        w = window(i, 14)
        if w:
            d = [b - a for a, b in itertools.pairwise(w)]
            if all(d[j] * d[j + 1] < 0 for j in range(len(d) - 1)):
                out[i].add(4)
        w = window(i, 3)
        if w and (sum(x > 2 for x in w) >= 2 or sum(x < -2 for x in w) >= 2):
            out[i].add(5)
        w = window(i, 5)
        if w and (sum(x > 1 for x in w) >= 4 or sum(x < -1 for x in w) >= 4):
            out[i].add(6)
        w = window(i, 15)
        if w and all(abs(x) < 1 for x in w):
            out[i].add(7)
        w = window(i, 8)
        if w and all(abs(x) > 1 for x in w):
            out[i].add(8)
    return out


__all__ = ["RULES", "Capability", "ChartPoint", "ControlChart", "c4", "capability", "control_chart", "run_rules"]
