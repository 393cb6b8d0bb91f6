"""The measurement system analysis page (``/msa``) and its JSON (``/api/msa``): a crossed Gage R&R study
of the runs of one lot (parts x nests, rigs or operators x repeats), read from the records."""

from __future__ import annotations

from typing import Annotated, Literal

from fastapi import APIRouter, HTTPException, Query, Request
from fastapi.responses import HTMLResponse, Response
from sqlalchemy import select

from station.kernel.display import display_of_check
from station.kernel.errors import StationError
from station.msa.study import ParameterStudy, StudyPoint, StudyReport, analyse
from station.store.models import Run
from station.store.msa_rows import StudySelection, study_values
from station.web import msa_charts
from station.web.context import Web
from station.web.models.common import problem
from station.web.models.msa import MsaComponent, MsaParameter, MsaStudy
from station.web.templating import templates

router = APIRouter()
By = Literal["nest", "rig", "operator"]
LotQuery = Annotated[str, Query(min_length=1, max_length=100, description="the study's lot")]
ByQuery = Annotated[By, Query(description="what the appraisers are")]


def _report(web: Web, lot: str, by: str) -> StudyReport:
    values = study_values(web.db, StudySelection(lot=lot))
    if not values:
        raise HTTPException(404, f"no tested unit results in lot {lot!r}")

    def appraiser(nest: int, rig: str, operator: str) -> str:
        return f"nest {nest + 1}" if by == "nest" else (rig if by == "rig" else (operator or "(none)"))

    return analyse([StudyPoint(v.parameter, v.unit, v.serial, appraiser(v.nest, v.rig, v.operator), v.value, v.low,
                               v.high) for v in values if not v.parameter.startswith("fit.")], by=by)


def _model(r: StudyReport) -> MsaStudy:
    def finite(x: float | None) -> float | None:
        return None if x is None or x != x or x in (float("inf"), float("-inf")) else x

    out = []
    for p in r.parameters:
        g = p.study
        entry = MsaParameter(parameter=p.parameter, unit=p.unit, reason=p.reason, dropped=p.dropped)
        if g is not None:
            entry = entry.model_copy(update={
                "repeats": g.repeats, "pct_grr": finite(g.pct_grr), "ndc": g.ndc if g.determined else None,
                "verdict": g.verdict, "pooled_interaction": g.pooled,
                "components": [MsaComponent(name=c.name, std=c.std, std_ci_low=c.ci_low, std_ci_high=finite(c.ci_high),
                                            pct_total_variation=finite(c.pct_total),
                                            pct_contribution=finite(c.pct_contribution),
                                            pct_tolerance=finite(c.pct_tolerance)) for c in g.components]})
        out.append(entry)
    return MsaStudy(format="station-msa/1", by=r.by, parts=list(r.parts), appraisers=list(r.appraisers),
                    confidence_level=r.level, parameters=out)


@router.get("/api/msa", response_model=MsaStudy, tags=["quality"],
            responses={404: problem("no tested unit results in the lot"), 422: problem("a bad query")})
def msa_json(web: Web, lot: LotQuery, by: ByQuery = "nest") -> MsaStudy:
    """The Gage R&R study of the lot's runs (SI values; percentages in %)."""
    try:
        return _model(_report(web, lot, by))
    except StationError as exc:
        raise HTTPException(422, str(exc)) from None


def _lots(web: Web) -> list[str]:
    with web.db.transaction() as s:
        return [x for x in s.scalars(select(Run.lot).distinct().order_by(Run.lot)) if x]


@router.get("/msa", response_class=HTMLResponse, include_in_schema=False)
def msa_page(request: Request, web: Web, lot: str | None = None, by: By = "nest",
             parameter: str | None = None) -> HTMLResponse:
    report: StudyReport | None = None
    error = None
    if lot:
        try:
            report = _report(web, lot, by)
        except HTTPException as exc:
            error = str(exc.detail)
        except StationError as exc:
            error = str(exc)
    chosen: ParameterStudy | None = None
    rows = []
    if report is not None:
        analysed = [p for p in report.parameters if p.study is not None]
        chosen = next((p for p in report.parameters if p.parameter == parameter), None) or (
            max(analysed, key=lambda p: p.pct_grr or 0.0) if analysed else None)
        for p in report.parameters:
            d = display_of_check(p.parameter, p.unit)
            rows.append({"p": p, "unit": d.unit, "ev": d.spread(p.study.repeatability.std) if p.study else None,
                         "av": d.spread(p.study.reproducibility.std) if p.study else None,
                         "grr": d.spread(p.study.grr.std) if p.study else None,
                         "pv": d.spread(p.study.part.std) if p.study else None})
    return templates.TemplateResponse(request, "msa.html", {
        "lots": _lots(web), "lot": lot or "", "by": by, "report": report, "rows": rows, "chosen": chosen,
        "error": error})


@router.get("/msa/plots/{kind}.svg", include_in_schema=False)
def msa_plot(web: Web, kind: str, lot: LotQuery, parameter: str, by: ByQuery = "nest") -> Response:
    report = _report(web, lot, by)
    p = next((x for x in report.parameters if x.parameter == parameter), None)
    if p is None:
        raise HTTPException(404, f"no parameter {parameter!r} in the study")
    d = display_of_check(p.parameter, p.unit)
    if kind == "components":
        svg = msa_charts.components_svg(p)
    elif kind == "ranges":
        svg = msa_charts.range_chart_svg(p, d)
    elif kind == "parts":
        svg = msa_charts.parts_by_appraiser_svg(p, d)
    else:
        raise HTTPException(404, f"no chart {kind!r}")
    return Response(svg, media_type="image/svg+xml")


__all__ = ["msa_json", "msa_page", "msa_plot", "router"]
