"""The population page (``/population``): a histogram per limit-checked parameter over all units, with limits."""

from __future__ import annotations

from fastapi import APIRouter, HTTPException, Request
from fastapi.responses import HTMLResponse, Response

from station.web import plots
from station.web.context import Web
from station.web.listing import population
from station.web.templating import templates

router = APIRouter()


@router.get("/population", response_class=HTMLResponse, include_in_schema=False)
def population_page(request: Request, web: Web) -> HTMLResponse:
    return templates.TemplateResponse(request, "population.html", {"params": population(web.db)})


@router.get("/population/plots/{name}.svg", include_in_schema=False)
def population_plot(web: Web, name: str) -> Response:
    for p in population(web.db, name=name):
        return Response(plots.histogram_svg(p.name, p.unit, p.values, p.low, p.high), media_type="image/svg+xml")
    raise HTTPException(404, f"no parameter {name}")


__all__ = ["population_page", "population_plot", "router"]
