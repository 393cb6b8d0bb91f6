"""Units: the engineer's unit page (``/units/{serial}``) with its plots, ``GET /api/units``, ``GET
/api/units/{serial}`` and the EEPROM image download ``GET /api/units/{serial}/eeprom.bin``.

The unit page shows the parameter set against its limits (marginal values highlighted), the run history, the
plots (``/units/{serial}/plots/{name}.svg``, see :mod:`station.web.plots`) and the diagnosis section (see
:mod:`station.web.routes.diagnosis`).
"""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, HTTPException, Query, Request
from fastapi.responses import HTMLResponse, Response

from station.eeprom.image import ImageError
from station.kernel.errors import StationError
from station.kernel.found_terms import found_terms
from station.session.csv_v1 import read_session
from station.store.quality_index import TESTED
from station.store.queries import show_unit, unit_image
from station.web import plots
from station.web.context import Web
from station.web.listing import (
    PAGED,
    CursorError,
    latest_checks,
    latest_checks_of_run,
    list_unit_results,
    next_page,
    shown_marginal,
)
from station.web.lookup import plot_source, recordings, unit_or_404
from station.web.models import UnitFilter, UnitOverview, UnitRecord, problem
from station.web.templating import templates

PLOT_NAMES = ("raw_corrected", "drift", "acf", "allan", "residuals")
_UNIT_PLOTS = {"raw_corrected": plots.raw_corrected_svg, "drift": plots.drift_svg, "acf": plots.acf_svg,
               "allan": plots.allan_svg}
_SVG_CACHED = {"Cache-Control": "max-age=60"}

router = APIRouter()


@router.get("/units/{serial:path}/plots/{name}.svg", include_in_schema=False)
def unit_plot(web: Web, serial: str, name: str) -> Response:
    if name not in PLOT_NAMES:
        raise HTTPException(404, f"no plot {name}")
    detail = unit_or_404(web.db, serial)
    source = plot_source(detail)
    if source is None:
        svg = plots.message_svg("no recording or parameter set for this unit")
    else:
        run_id, path = source

        def render() -> str:
            params = detail.latest_params()
            assert params is not None
            try:
                session = read_session(path)
                if name == "residuals":
                    return plots.residuals_svg(params)
                return _UNIT_PLOTS[name](session, params)
            except (StationError, ValueError) as exc:
                return plots.message_svg(f"cannot plot: {exc}")

        svg = web.svgs.get((serial, run_id, name), render)
    return Response(svg, media_type="image/svg+xml", headers=_SVG_CACHED)


@router.get("/units/{serial:path}", response_class=HTMLResponse, include_in_schema=False)
def unit_page(request: Request, web: Web, serial: str) -> HTMLResponse:
    detail = show_unit(web.db, serial)
    if detail is None:
        return templates.TemplateResponse(request, "missing.html", {"what": f"unit {serial}"}, status_code=404)
    checks_run, latest = latest_checks_of_run(web.db, serial)
    checks = [(c, shown_marginal(c, web.marginal_fraction)) for c in latest]
    recorded = {rec.run_id for rec in recordings(detail)}
    verdict = next((r for r in detail.runs if r.outcome in TESTED and r.run_outcome != "UNFINISHED"), None)
    newest = detail.runs[0] if detail.runs else None
    params = detail.latest_params()
    return templates.TemplateResponse(request, "unit.html", {
        "d": detail, "checks": checks, "plots": PLOT_NAMES if plot_source(detail) is not None else (),
        "params": params, "found": found_terms(params) if params is not None else None,
        "marginal_fraction": web.marginal_fraction,
        "diag_runs": [r for r in detail.runs if r.run_id in recorded],
        "verdict": verdict, "newest": newest, "checks_run": checks_run,
        "disposition": detail.dispositions[-1] if detail.dispositions else None,
    })


@router.get("/api/units", tags=["units"], response_model=list[UnitOverview], responses=PAGED)
def api_units(web: Web, query: Annotated[UnitFilter, Query()], request: Request,
              response: Response) -> list[UnitOverview]:
    """Units by serial with their latest result among the runs matching the filters; ``limit`` per page, the
    next page's cursor in the ``X-Next-Cursor`` header (and a ``Link: <...>; rel="next"`` header)."""
    try:
        units, nxt = list_unit_results(web.db, day_from=query.date_from, day_to=query.date_to,
                                       outcome=query.outcome, station=query.station, search=query.q,
                                       limit=query.limit, cursor=query.cursor)
    except CursorError as exc:
        raise HTTPException(422, f"cursor: {exc}") from None
    next_page(request, response, nxt)
    return units


@router.get("/units", response_class=HTMLResponse, include_in_schema=False)
def units_page(request: Request, web: Web, query: Annotated[UnitFilter, Query()]) -> HTMLResponse:
    try:
        units, nxt = list_unit_results(web.db, day_from=query.date_from, day_to=query.date_to,
                                       outcome=query.outcome, station=query.station, search=query.q,
                                       limit=min(query.limit, 100), cursor=query.cursor)
    except CursorError as exc:
        raise HTTPException(422, f"cursor: {exc}") from None
    more = str(request.url.include_query_params(cursor=nxt)) if nxt else None
    return templates.TemplateResponse(request, "units.html", {"units": units, "query": query, "next": more})


@router.get("/api/units/{serial:path}/eeprom.bin", tags=["units"], response_class=Response,
            responses={200: {"content": {"application/octet-stream": {}}, "description": "the EEPROM image"},
                       404: problem("unknown serial, or the unit never passed"),
                       409: problem("the parameter set does not fit the image format")})
def api_eeprom(web: Web, serial: str) -> Response:
    """The calibration image (see ``station/eeprom/layout.md``) of the unit's latest PASS parameter set.

    The bytes its run wrote into the unit (as read back); without a recorded write, the image that run
    would write (its station and start time; :func:`station.store.queries.unit_image`). The same bytes
    as ``station eeprom image SERIAL``.
    """
    try:
        found = unit_image(web.db, serial)
    except ImageError as exc:
        raise HTTPException(409, f"cannot encode the image: {exc}") from exc
    if found is None:
        raise HTTPException(404, f"no passed parameter set for unit {serial}")
    data = found.data
    return Response(data, media_type="application/octet-stream",
                    headers={"Content-Disposition": f'attachment; filename="{_safe(serial)}.eeprom.bin"'})


@router.get("/api/units/{serial:path}", tags=["units"], response_model=UnitRecord,
            responses={404: problem("unknown serial")})
def api_unit(web: Web, serial: str) -> UnitRecord:
    """One unit: its runs (newest first), latest parameter set (SI units), limit checks, EEPROM writes."""
    return UnitRecord.of(unit_or_404(web.db, serial), latest_checks(web.db, serial))


def _safe(serial: str) -> str:
    return "".join(c if c.isalnum() or c in "-_." else "_" for c in serial) or "unit"


__all__ = ["PLOT_NAMES", "api_eeprom", "api_unit", "api_units", "router", "unit_page", "unit_plot"]
