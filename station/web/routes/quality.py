"""Quality analytics: the quality page (``/quality``), its CSV exports, its histograms, and the same
statistics as JSON under ``/api/quality/...``.

Every statistic is aggregated by the database over the quality tables (:mod:`station.store.quality`);
filters (UTC date range, station, lot, limits version, shift calendar) are validated: a bad one answers 422.
"""

from __future__ import annotations

import csv
import io
from dataclasses import replace
from typing import Annotated

from fastapi import APIRouter, HTTPException, Query, Request
from fastapi.responses import HTMLResponse, Response
from sqlalchemy import select

from station.kernel.display import display_of_check, limits_identity
from station.kernel.golden import GoldenTrend, GoldenUnit, golden_trends
from station.store import quality as q
from station.store.golden_records import GoldenCheckRow, golden_checks, golden_units
from station.store.models import QualityDaily, QualityYield, Run
from station.store.models import Station as StationRow
from station.store.spc import MIN_CAPABILITY_N, RULES, cpk_interval, run_rules
from station.web import charts
from station.web.context import Web
from station.web.labels import parameter_label, unit_label
from station.web.models.common import problem
from station.web.models.golden import GoldenChart, GoldenCharts, GoldenCheckEntry, GoldenParameterChart
from station.web.models.quality import (
    DEFINITIONS,
    CapabilityEntry,
    ChartPointEntry,
    ControlChartEntry,
    ControlCharts,
    GroupBy,
    HistogramEntry,
    QualityQuery,
    RuleEntry,
    YieldEntry,
    YieldTable,
)
from station.web.templating import templates

router = APIRouter()
Filters = Annotated[QualityQuery, Query()]
ByQuery = Annotated[GroupBy, Query(description="group by station, shift (the shift calendar), UTC day of the run "
                                               "start, lot, or one total row")]
CPK_TARGET = 1.33
"""Capability below this is flagged on the page (the usual customer requirement)."""


def _yield_tables(web: Web, query: QualityQuery) -> dict[str, YieldTable]:
    cal = query.calendar(web.shifts)
    return {by: YieldTable(by=by, shifts=cal.text(), definitions=DEFINITIONS, rows=[
        YieldEntry(group=r.group, results=r.results, not_tested=r.not_tested, tested=r.tested,
                   units_tested=r.units_tested, first_tested=r.first_tested, first_pass=r.first_pass,
                   final_pass=r.final_pass, retests=r.retests, first_pass_yield=r.first_pass_yield,
                   final_yield=r.final_yield) for r in rows])
        for by, rows in q.yield_tables(web.db, query.filter(), cal).items()}


def _yield_table(web: Web, by: str, query: QualityQuery) -> YieldTable:
    return _yield_tables(web, query)[by]


def _capability(web: Web, query: QualityQuery,
                rules: dict[str, tuple[int, ...]] | None = None) -> list[CapabilityEntry]:
    out = []
    for c in q.capabilities(web.db, query.filter()):
        k = c.cap
        ci = cpk_interval(k.cpk, k.n)
        out.append(CapabilityEntry(name=c.name, label=parameter_label(c.name), unit=c.unit,
                                   limits_versions=c.limits_versions, n=k.n, mean=k.mean,
                                   sigma_within=k.sigma_within, sigma_overall=k.sigma_overall, low=k.low, high=k.high,
                                   cp=k.cp, cpk=k.cpk, pp=k.pp, ppk=k.ppk, n_below=c.n_below, n_above=c.n_above,
                                   min=c.vmin, max=c.vmax, rules=list((rules or {}).get(c.name, ())),
                                   enough=k.n >= MIN_CAPABILITY_N, cpk_low=ci[0] if ci else None,
                                   cpk_high=ci[1] if ci else None))
    return out


def _charts(web: Web, query: QualityQuery, names: list[str] | None = None) -> list[q.ParameterChart]:
    return q.control_charts(web.db, query.filter(), names)


def _chart_entry(pc: q.ParameterChart) -> ControlChartEntry:
    ch = pc.chart
    return ControlChartEntry(name=pc.name, unit=pc.unit, center=ch.center, sigma_within=ch.sigma_within, low=pc.low,
                             high=pc.high, violations=list(ch.violations), points=[
                                 ChartPointEntry(day=p.label, n=p.n, mean=p.mean, s=p.s, lcl=p.lcl, ucl=p.ucl,
                                                 s_lcl=p.s_lcl, s_ucl=p.s_ucl, z=p.z, rules=list(p.rules))
                                 for p in ch.points])


def _choices(web: Web) -> dict[str, list[str]]:
    with web.db.transaction() as s:
        return {
            "stations": list(s.scalars(select(StationRow.name).order_by(StationRow.name))),
            "lots": [x for x in s.scalars(select(QualityYield.lot).distinct().order_by(QualityYield.lot)) if x],
            "limits": [x for x in s.scalars(select(QualityDaily.limits_version).distinct()
                                            .order_by(QualityDaily.limits_version)) if x],
        }


def _limits_labels(web: Web, versions: list[str]) -> dict[str, str]:
    """Each limits version as people see it: name, version and the content hash of the file(s) recorded under it.

    Two different files recorded under one name and version (an edited file) are named as such."""
    hashes: dict[str, list[str]] = {}
    with web.db.transaction() as s:
        for version, digest in s.execute(select(Run.limits_version, Run.limits_hash).distinct()
                                         .where(Run.limits_version.in_(versions))):
            hashes.setdefault(version, []).append(digest or "")
    out = {}
    for v in versions:
        found = sorted(set(hashes.get(v, [])))
        if len(found) > 1:
            out[v] = f"{v}: {len(found)} different files (sha256 " + ", ".join(h[:12] for h in found) + ")"
        else:
            out[v] = limits_identity(v, found[0] if found else "")
    return out


def _displayed_chart(pc: q.ParameterChart) -> q.ParameterChart:
    """The chart in the display convention (values with the quantity's offset, sigmas without)."""
    d = display_of_check(pc.name, pc.unit)

    def v(x: float | None) -> float | None:
        return d.value(x)

    ch = pc.chart
    points = tuple(replace(p, mean=d.convert(p.mean), s=d.spread(p.s), lcl=v(p.lcl), ucl=v(p.ucl),
                           s_lcl=d.spread(p.s_lcl), s_ucl=d.spread(p.s_ucl)) for p in ch.points)
    chart = replace(ch, center=d.convert(ch.center), sigma_within=d.spread(ch.sigma_within), points=points)
    return replace(pc, unit=d.unit, low=v(pc.low), high=v(pc.high), chart=chart)


def _displayed_histogram(h: q.Histogram) -> q.Histogram:
    d = display_of_check(h.name, h.unit)
    return replace(h, unit=d.unit, lo=d.convert(h.lo), hi=d.convert(h.hi), mean=d.convert(h.mean),
                   sigma=d.spread(h.sigma), low=d.value(h.low),
                   high=d.value(h.high))


def _displayed(c: CapabilityEntry) -> CapabilityEntry:
    """The entry in the display convention (station/kernel/display.py): values and spreads in the quantity's
    engineering unit (a scale factor as its error in ppm); the capability indices are unit-free."""
    d = display_of_check(c.name, c.unit)

    def v(x: float | None) -> float | None:
        return d.value(x)

    return c.model_copy(update={"unit": d.unit, "mean": v(c.mean), "low": v(c.low), "high": v(c.high),
                                "min": v(c.min), "max": v(c.max), "sigma_within": d.spread(c.sigma_within),
                                "sigma_overall": d.spread(c.sigma_overall)})


class _Golden:
    """One registered golden unit's checks (of the selected station) and its parameters' individuals charts."""

    def __init__(self, serial: str, version: int, unit: GoldenUnit, checks: list[GoldenCheckRow]) -> None:
        self.serial, self.version, self.unit, self.checks = serial, version, unit, checks
        self.trends: tuple[GoldenTrend, ...] = golden_trends(unit, [c.deviations for c in checks], run_rules)
        self.labels = [f"{c.checked_at:%Y-%m-%d %H:%M}" for c in checks]

    def svg(self, trend: GoldenTrend) -> str:
        ref = self.unit.reference(trend.parameter)
        assert ref is not None
        return charts.golden_chart_svg(trend, ref, self.labels)

    def rows(self) -> list[dict[str, object]]:
        """Per parameter what the page shows, in the display convention; ``flagged``: a rule fired or the last
        check failed on it."""
        out: list[dict[str, object]] = []
        last = self.checks[-1] if self.checks else None
        for t in self.trends:
            ref = self.unit.reference(t.parameter)
            assert ref is not None
            d = display_of_check(t.parameter, t.unit)
            latest = t.deviations[-1] if t.deviations else None
            failed = (last is not None and (latest is None or abs(latest) > ref.allowed))
            fired = sorted({r for rs in t.rules for r in rs})
            out.append({"name": t.parameter, "label": parameter_label(t.parameter), "unit": d.unit,
                        "reference": d.value(ref.value), "allowed": d.spread(ref.allowed),
                        "sigma": d.spread(ref.repeatability), "latest": d.spread(latest), "rules": fired,
                        "first_signal": t.first_signal,
                        "first_signal_at": self.labels[t.first_signal] if t.first_signal is not None else None,
                        "failed": failed, "flagged": bool(fired) or failed})
        return out


def _goldens(web: Web, station: str | None) -> list[_Golden]:
    return [_Golden(serial, version, unit, golden_checks(web.db, serial=serial, station=station))
            for serial, (version, unit) in sorted(golden_units(web.db).items())]


def _golden_entry(g: _Golden) -> GoldenChart:
    params = []
    for t in g.trends:
        ref = g.unit.reference(t.parameter)
        assert ref is not None
        params.append(GoldenParameterChart(parameter=t.parameter, unit=t.unit, reference=ref.value,
                                           allowed=ref.allowed, repeatability=ref.repeatability,
                                           deviation=list(t.deviations), z=list(t.z),
                                           rules=[list(r) for r in t.rules], first_signal=t.first_signal))
    return GoldenChart(serial=g.serial, version=g.version, registered_at=g.unit.registered_at, parameters=params,
                       checks=[GoldenCheckEntry(checked_at=c.checked_at, station=c.station, version=c.version,
                                                passed=c.passed) for c in g.checks])


@router.get("/quality", response_class=HTMLResponse, include_in_schema=False)
def quality_page(request: Request, web: Web, query: Filters) -> HTMLResponse:
    cal = query.calendar(web.shifts)
    tables = _yield_tables(web, query)
    chart_list = _charts(web, query)
    rules = {c.name: c.chart.violations for c in chart_list}
    caps = _capability(web, query, rules)
    flagged = [c for c in caps if c.rules or (c.enough and c.cpk is not None and c.cpk < CPK_TARGET)]
    shown = {c.name for c in flagged}
    svgs = {c.name: charts.control_chart_svg(_displayed_chart(c)) for c in chart_list if c.name in shown}
    days = tables["day"].rows
    trend = charts.yield_trend_svg([r.group for r in days], [r.first_pass_yield for r in days],
                                   [r.final_yield for r in days])
    choices = _choices(web)
    goldens = [{"serial": g.serial, "version": g.version, "checks": g.checks, "rows": (rows := g.rows()),
                "svgs": {t.parameter: g.svg(t) for t, r in zip(g.trends, rows, strict=True) if r["flagged"]}}
               for g in _goldens(web, query.station)]
    params = request.query_params
    qs = "&".join(f"{k}={v}" for k, v in params.multi_items() if v)
    return templates.TemplateResponse(request, "quality.html", {
        "query": query, "qs": qs, "tables": tables, "caps": [_displayed(c) for c in caps], "svgs": svgs,
        "trend": trend, "rules": RULES, "cpk_target": CPK_TARGET, "min_n": MIN_CAPABILITY_N, "shifts": cal.text(),
        "definitions": DEFINITIONS,
        "choices": choices, "limits_labels": _limits_labels(web, choices["limits"]), "unit_label": unit_label,
        "flagged": flagged, "goldens": goldens,
    })


@router.get("/quality/histogram/{name}.svg", include_in_schema=False)
def quality_histogram_svg(web: Web, name: str, query: Filters) -> Response:
    h = q.histogram(web.db, name, query.filter())
    if h is None:
        raise HTTPException(404, f"no values of {name} in the selection")
    return Response(charts.histogram_svg(_displayed_histogram(h)), media_type="image/svg+xml",
                    headers={"Cache-Control": "max-age=30"})


@router.get("/quality/control/{name}.svg", include_in_schema=False)
def quality_control_svg(web: Web, name: str, query: Filters) -> Response:
    found = q.control_charts(web.db, query.filter(), [name])
    if not found:
        raise HTTPException(404, f"no values of {name} in the selection")
    return Response(charts.control_chart_svg(_displayed_chart(found[0])), media_type="image/svg+xml",
                    headers={"Cache-Control": "max-age=30"})


@router.get("/quality/golden/{serial}/{name}.svg", include_in_schema=False)
def quality_golden_svg(web: Web, serial: str, name: str, query: Filters) -> Response:
    found = [g for g in _goldens(web, query.station) if g.serial == serial]
    trend = next((t for g in found for t in g.trends if t.parameter == name), None)
    if trend is None:
        raise HTTPException(404, f"{serial} is not a registered golden unit with a reference for {name}")
    return Response(found[0].svg(trend), media_type="image/svg+xml", headers={"Cache-Control": "max-age=30"})


def _csv(name: str, header: list[str], rows: list[list[object]]) -> Response:
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(header)
    w.writerows(rows)
    return Response(buf.getvalue(), media_type="text/csv; charset=utf-8",
                    headers={"Content-Disposition": f'attachment; filename="{name}.csv"'})


@router.get("/quality/yield.csv", include_in_schema=False)
def quality_yield_csv(web: Web, query: Filters, by: ByQuery = "station") -> Response:
    t = _yield_table(web, by, query)
    fields = list(YieldEntry.model_fields)
    return _csv(f"yield-by-{by}", fields, [[getattr(r, f) for f in fields] for r in t.rows])


@router.get("/quality/capability.csv", include_in_schema=False)
def quality_capability_csv(web: Web, query: Filters) -> Response:
    caps = [_displayed(c) for c in _capability(web, query)]  # the display convention (the API stays SI)
    fields = [f for f in CapabilityEntry.model_fields if f != "rules"]
    return _csv("capability", fields, [[getattr(c, f) for f in fields] for c in caps])


@router.get("/api/quality/yield", tags=["quality"], response_model=YieldTable)
def api_quality_yield(web: Web, query: Filters, by: ByQuery = "station") -> YieldTable:
    """First-pass and final yield grouped by station, shift, day, lot or in total (see ``definitions``)."""
    return _yield_table(web, by, query)


@router.get("/api/quality/capability", tags=["quality"], response_model=list[CapabilityEntry])
def api_quality_capability(web: Web, query: Filters) -> list[CapabilityEntry]:
    """Population statistics: per parameter n, mean, sigma within/overall, Cp/Cpk, Pp/Ppk against its limits,
    worst Cpk first, with the run rules violated on its daily X-bar chart."""
    rules = {c.name: c.chart.violations for c in _charts(web, query)}
    return _capability(web, query, rules)


@router.get("/api/quality/control-charts", tags=["quality"], response_model=ControlCharts)
def api_quality_control_charts(web: Web, query: Filters,
                               name: Annotated[list[str] | None, Query(description="parameters (default: all)")]
                               = None) -> ControlCharts:
    """Daily X-bar/S charts with control limits and the run rules each day completes."""
    return ControlCharts(rules=[RuleEntry(number=k, text=v) for k, v in RULES.items()],
                         charts=[_chart_entry(c) for c in _charts(web, query, name)])


@router.get("/api/quality/golden", tags=["quality"], response_model=GoldenCharts)
def api_quality_golden(web: Web, query: Filters) -> GoldenCharts:
    """Every registered golden unit: its checks (of the selected station; the date, lot and limits filters do
    not apply: a chart's rules need its whole sequence) and per referenced parameter its individuals chart
    (deviation from the reference, z over the registered repeatability, the Nelson rules per check)."""
    return GoldenCharts(rules=[RuleEntry(number=k, text=v) for k, v in RULES.items()],
                        units=[_golden_entry(g) for g in _goldens(web, query.station)])


@router.get("/api/quality/histogram/{name}", tags=["quality"], response_model=HistogramEntry,
            responses={404: problem("no values of this parameter in the selection")})
def api_quality_histogram(web: Web, name: str, query: Filters,
                          bins: Annotated[int, Query(ge=5, le=200, description="number of bins")] = 40
                          ) -> HistogramEntry:
    """One parameter's values in equal bins (counted by the database) with the fitted normal."""
    h = q.histogram(web.db, name, query.filter(), bins)
    if h is None:
        raise HTTPException(404, f"no values of {name} in the selection")
    return HistogramEntry(name=h.name, unit=h.unit, lo=h.lo, hi=h.hi, counts=list(h.counts), n=h.n, mean=h.mean,
                          sigma=h.sigma, low=h.low, high=h.high)


__all__ = ["CPK_TARGET", "router"]
