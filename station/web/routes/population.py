"""The population page (``/population``): a histogram per limit-checked parameter over all tested units, with
limits.

The histograms are the quality page's (:func:`station.store.quality.histogram`): the database counts the values
into bins from the quality tables, the server draws small SVGs; nothing loads every value into the web server
(which took tens of seconds with a few thousand units). The old per-parameter plot address redirects there.
"""

from __future__ import annotations

from urllib.parse import quote

from fastapi import APIRouter, Request
from fastapi.responses import HTMLResponse, RedirectResponse

from station.store import quality as q
from station.web.context import Web
from station.web.labels import parameter_label
from station.web.templating import templates

router = APIRouter()


@router.get("/population", response_class=HTMLResponse, include_in_schema=False)
def population_page(request: Request, web: Web) -> HTMLResponse:
    names = sorted({c.name for c in q.capabilities(web.db)})
    params = [{"name": n, "label": parameter_label(n)} for n in names]
    return templates.TemplateResponse(request, "population.html", {"params": params})


@router.get("/population/plots/{name}.svg", include_in_schema=False)
def population_plot(name: str) -> RedirectResponse:
    return RedirectResponse(f"/quality/histogram/{quote(name)}.svg", status_code=308)


__all__ = ["population_page", "population_plot", "router"]
