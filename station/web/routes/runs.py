"""Runs: ``GET /api/runs``, and the write actions ``POST /api/runs`` (start) and ``POST /api/runs/{run_id}/abort``.

The write actions need ``Authorization: Bearer <token>`` with the token configured on the station, or an operator
signed in at ``/operator`` (the console's session cookie); otherwise they answer 401 (read-only by default).
They go through the live status's ``on_start``/``on_abort`` hooks (:class:`station.web.control.StationControl`);
unset hooks answer 503.
"""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import APIRouter, Body, Depends, HTTPException, Query, Request, Response

from station.kernel.errors import StationBusy, StationError
from station.web.console import ConsoleSettings, check_scan
from station.web.context import Web, WebContext, Writer, require_writer
from station.web.listing import PAGED, CursorError, list_runs, next_page
from station.web.models import RunAbortAccepted, RunAccepted, RunFilter, RunSummary, StartRunRequest, problem

router = APIRouter(tags=["runs"])
UNAUTHORIZED: dict[int | str, dict[str, Any]] = {
    401: problem("no operator signed in and a missing or wrong bearer token (or no token configured)")}


@router.get("/api/runs", response_model=list[RunSummary], responses=PAGED)
def api_runs(web: Web, query: Annotated[RunFilter, Query()], request: Request, response: Response) -> list[RunSummary]:
    """Runs, newest first, with every slot's unit and outcome; ``limit`` per page, the next page's cursor in the
    ``X-Next-Cursor`` header (and a ``Link: <...>; rel="next"`` header)."""
    try:
        runs, nxt = list_runs(web.db, limit=query.limit, station=query.station, outcome=query.outcome,
                              cursor=query.cursor)
    except CursorError as exc:
        raise HTTPException(422, f"cursor: {exc}") from None
    next_page(request, response, nxt)
    return runs


@router.post("/api/runs", status_code=202, response_model=RunAccepted,
             responses={**UNAUTHORIZED, 409: problem("a run is in progress"),
                        422: problem("a scanned serial is refused, or a nest the fixture does not have"),
                        503: problem("this station cannot start runs")})
def api_start_run(web: Web, request: Request, writer: Annotated[Writer, Depends(require_writer)],
                  options: Annotated[StartRunRequest | None, Body()] = None) -> RunAccepted:
    """Start a run on the station (write action: bearer token or a signed-in operator)."""
    live = web.live
    if live.on_start is None:
        raise HTTPException(503, "this station cannot start runs from the API")
    if live.status(with_store=False).state == "running":
        raise HTTPException(409, "a run is in progress")
    req = options.model_dump() if options is not None else {}
    if writer.via == "session":
        req["operator"] = writer.name
    check_serials(web, request, req.get("serials") or {})
    try:
        return RunAccepted(run_id=live.on_start(req))
    except StationBusy as exc:
        raise HTTPException(409, str(exc)) from None
    except StationError as exc:
        raise HTTPException(503, str(exc)) from None


@router.post("/api/runs/{run_id}/abort", status_code=202, response_model=RunAbortAccepted,
             dependencies=[Depends(require_writer)],
             responses={**UNAUTHORIZED, 404: problem("no running run with this id"),
                        503: problem("this station cannot abort runs")})
def api_abort_run(web: Web, run_id: str) -> RunAbortAccepted:
    """Abort the running run ``run_id`` (write action: bearer token or a signed-in operator)."""
    if web.live.on_abort is None:
        raise HTTPException(503, "this station cannot abort runs from the API")
    if not web.live.on_abort(run_id):
        raise HTTPException(404, f"no running run {run_id}")
    return RunAbortAccepted(run_id=run_id, state="aborting")


def check_serials(web: WebContext, request: Request, serials: dict[int, str]) -> None:
    """Check the scanned serials of a start as the console checks a scan (422 with the first refusal)."""
    settings: ConsoleSettings = getattr(request.app.state, "console", None) or ConsoleSettings()
    nests = web.live.nests
    for nest, serial in serials.items():
        if nest < 1 or (nests and nest > nests):
            raise HTTPException(422, f"nest {nest}: the fixture has nests 1 to {nests or '?'}")
        check = check_scan(web.db, serial, settings, serials, nest)
        if not check.accepted:
            raise HTTPException(422, f"nest {nest}: {check.message}")


__all__ = ["api_abort_run", "api_runs", "api_start_run", "check_serials", "router"]
