"""A Gage R&R study of every limited parameter: measurements grouped per parameter, balanced, analysed.

Input: :class:`StudyPoint` values (one per parameter, part, appraiser and repeat), from the records or
from a simulated study. Per parameter the cells (part x appraiser) are balanced to the smallest number
of repeats any cell has, keeping the oldest ``r`` (the points' order); a parameter whose cells are not
all present, or that has fewer than 2 repeats, is reported with the reason instead of a number. The
tolerance is the width of the parameter's limits (the last point's, the limits in force at the end).
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Any

from station.msa.gage_rr import GageStudy, StudyDesignError, gage_rr

FORMAT = "station-msa/1"
"""Format of the JSON and CSV a study writes."""


@dataclass(frozen=True)
class StudyPoint:
    """One measured value: ``part`` (serial), ``appraiser`` (nest, rig or operator), in the parameter's unit."""

    parameter: str
    unit: str
    part: str
    appraiser: str
    value: float
    low: float | None = None
    high: float | None = None


@dataclass(frozen=True)
class ParameterStudy:
    """The study of one parameter: the ANOVA result, or why there is none (``reason``).

    ``dropped``: measurements left out to balance the design (the newest repeats of fuller cells).
    """

    parameter: str
    unit: str
    study: GageStudy | None
    reason: str | None
    dropped: int

    @property
    def pct_grr(self) -> float | None:
        return None if self.study is None else self.study.pct_grr


@dataclass(frozen=True)
class StudyReport:
    """Every parameter's study, with the design it was run on."""

    by: str
    parts: tuple[str, ...]
    appraisers: tuple[str, ...]
    parameters: tuple[ParameterStudy, ...]
    level: float

    def to_json(self) -> dict[str, Any]:
        """The JSON edge (format ``station-msa/1``): SI values in each parameter's unit, percentages in %."""

        def num(x: float | None) -> float | None:
            return None if x is None or not math.isfinite(x) else x

        out: list[dict[str, Any]] = []
        for p in self.parameters:
            entry: dict[str, Any] = {"parameter": p.parameter, "unit": p.unit, "dropped": p.dropped,
                                     "reason": p.reason}
            g = p.study
            if g is not None:
                entry.update({
                    "parts": g.parts, "appraisers": g.appraisers, "repeats": g.repeats,
                    "tolerance": g.tolerance, "pooled_interaction": g.pooled, "ndc": g.ndc,
                    "ndc_adequate": g.ndc_adequate, "verdict": g.verdict, "determined": g.determined,
                    "pct_grr": num(g.pct_grr),
                    "anova": [{"source": r.source, "df": r.df, "ss": r.ss, "ms": r.ms, "f": num(r.f),
                               "p": num(r.p)} for r in g.anova],
                    "components": [{"name": c.name, "variance": c.variance, "std": c.std,
                                    "pct_total_variation": num(c.pct_total),
                                    "pct_contribution": num(c.pct_contribution),
                                    "pct_tolerance": num(c.pct_tolerance), "std_ci_low": c.ci_low,
                                    "std_ci_high": num(c.ci_high)} for c in g.components],
                })
            out.append(entry)
        return {"format": FORMAT, "by": self.by, "parts": list(self.parts), "appraisers": list(self.appraisers),
                "confidence_level": self.level, "parameters": out}

    def to_csv_rows(self) -> list[list[str]]:
        """One row per parameter and component (header first)."""
        rows = [["format", "parameter", "unit", "component", "std", "std_ci_low", "std_ci_high",
                 "pct_total_variation", "pct_tolerance", "ndc", "verdict", "reason"]]
        for p in self.parameters:
            g = p.study
            if g is None:
                rows.append([FORMAT, p.parameter, p.unit, "", "", "", "", "", "", "", "", p.reason or ""])
                continue
            for c in g.components:
                rows.append([FORMAT, p.parameter, p.unit, c.name, f"{c.std:.6g}", f"{c.ci_low:.6g}",
                             f"{c.ci_high:.6g}", f"{c.pct_total:.4g}",
                             "" if c.pct_tolerance is None else f"{c.pct_tolerance:.4g}", str(g.ndc), g.verdict, ""])
        return rows


def load_report_json(text: str) -> dict[str, Any]:
    """Read a study's JSON back; refuses other formats."""
    from station.kernel.errors import UnsupportedVersionError

    data = json.loads(text)
    found = data.get("format") if isinstance(data, dict) else None
    if found != FORMAT:
        raise UnsupportedVersionError(f"not a {FORMAT} study (format {found!r})")
    assert isinstance(data, dict)
    return data


def analyse(points: Iterable[StudyPoint], *, by: str = "nest", level: float = 0.90) -> StudyReport:
    """Group ``points`` per parameter, balance each, and run :func:`~station.msa.gage_rr.gage_rr` on it."""
    per: dict[str, list[StudyPoint]] = {}
    for pt in points:
        per.setdefault(pt.parameter, []).append(pt)
    parts = sorted({pt.part for pts in per.values() for pt in pts})
    apps = sorted({pt.appraiser for pts in per.values() for pt in pts})
    results = tuple(_one(name, pts, level) for name, pts in per.items())
    return StudyReport(by=by, parts=tuple(parts), appraisers=tuple(apps), parameters=results, level=level)


def _one(name: str, pts: Sequence[StudyPoint], level: float) -> ParameterStudy:
    unit = pts[-1].unit
    cells: dict[tuple[str, str], list[float]] = {}
    for pt in pts:
        cells.setdefault((pt.part, pt.appraiser), []).append(pt.value)
    parts = sorted({p for p, _ in cells})
    apps = sorted({a for _, a in cells})
    missing = [(p, a) for p in parts for a in apps if (p, a) not in cells]
    if missing:
        return ParameterStudy(name, unit, None,
                              f"not crossed: part {missing[0][0]} has no value in {missing[0][1]} "
                              f"({len(missing)} of {len(parts) * len(apps)} cells empty)", 0)
    r = min(len(v) for v in cells.values())
    dropped = sum(len(v) - r for v in cells.values())
    low, high = pts[-1].low, pts[-1].high
    tolerance = high - low if low is not None and high is not None and high > low else None
    p_list: list[str] = []
    a_list: list[str] = []
    y: list[float] = []
    for (p, a), values in cells.items():
        for v in values[:r]:
            p_list.append(p)
            a_list.append(a)
            y.append(v)
    try:
        study = gage_rr(p_list, a_list, y, tolerance=tolerance, level=level)
    except StudyDesignError as exc:
        return ParameterStudy(name, unit, None, str(exc), dropped)
    return ParameterStudy(name, unit, study, None, dropped)
