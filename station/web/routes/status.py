"""The live status: the operator's status page (``/``), its server-sent events (``/events``) and ``GET /api/status``.

The page renders the status once and then follows ``/events``: a ``status`` event with the whole status after
every change (a burst of records within :data:`SSE_COALESCE_S` is one event), a comment every
:data:`SSE_KEEPALIVE_S` seconds otherwise; the browser's EventSource reconnects by itself after a dropped
connection (``retry: 1000`` ms).
"""

from __future__ import annotations

import asyncio
import json
from collections.abc import AsyncIterator

from fastapi import APIRouter, FastAPI, Request
from fastapi.responses import HTMLResponse, StreamingResponse

from station.web.context import Web
from station.web.models import StationStatus
from station.web.state import LiveStatus
from station.web.templating import templates

SSE_KEEPALIVE_S = 15.0
SSE_COALESCE_S = 0.05

router = APIRouter()


@router.get("/", response_class=HTMLResponse, include_in_schema=False)
def status_page(request: Request, web: Web) -> HTMLResponse:
    snap = web.live.snapshot()
    return templates.TemplateResponse(request, "status.html", {"s": snap, "s_json": json.dumps(snap)})


@router.get("/api/status", tags=["status"], response_model=StationStatus)
def api_status(web: Web) -> StationStatus:
    """The station's live status: state (idle/running/fault), current step, progress, time remaining
    (station clock s), one entry per fixture slot, first-pass yield and units per hour of the shift."""
    return web.live.status()


class StatusEvents:
    """``GET /events`` of one live status.

    Bound to the :class:`LiveStatus` when the application is built (see :func:`add_events`), so the endpoint
    needs nothing but the request: a stream is driven by the status's changes, not by a request scope.
    """

    def __init__(self, live: LiveStatus) -> None:
        self.live = live

    async def stream(self, request: Request) -> StreamingResponse:
        """The server-sent events until the client disconnects."""
        return StreamingResponse(self._events(request), media_type="text/event-stream",
                                 headers={"Cache-Control": "no-cache", "X-Accel-Buffering": "no"})

    async def _events(self, request: Request) -> AsyncIterator[str]:
        live = self.live
        yield "retry: 1000\n\n"
        version = -1
        while not await request.is_disconnected():
            current = live.version
            if current != version:
                snap = await asyncio.to_thread(live.snapshot)
                version = snap["version"]
                yield f"id: {version}\nevent: status\ndata: {json.dumps(snap)}\n\n"
                continue
            new = await live.wait_change(version, SSE_KEEPALIVE_S)
            if new == version:
                yield ": keepalive\n\n"
            else:
                await asyncio.sleep(SSE_COALESCE_S)  # let a burst of records land in one event


def add_events(app: FastAPI, live: LiveStatus) -> None:
    """Serve ``GET /events`` of ``live`` on ``app``."""
    app.add_api_route("/events", StatusEvents(live).stream, methods=["GET"], include_in_schema=False)


__all__ = ["SSE_COALESCE_S", "SSE_KEEPALIVE_S", "StatusEvents", "add_events", "api_status", "router",
           "status_page"]
