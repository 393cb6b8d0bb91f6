"""What the routers of one web application share (:class:`WebContext`, on ``app.state.web``) and the
dependencies that hand it to them: the context itself and the bearer-token check of the write actions."""

from __future__ import annotations

import hmac
from dataclasses import dataclass, field
from typing import Annotated

from fastapi import Depends, HTTPException, Request
from fastapi.security import HTTPAuthorizationCredentials, HTTPBearer

from station.store.db import Database
from station.store.quality import ShiftCalendar
from station.web.cache import SvgCache
from station.web.diagnosis_worker import DiagnosisService
from station.web.state import LiveStatus


@dataclass(frozen=True)
class WebContext:
    """The state of one web application.

    Attributes:
        db: the station database.
        live: the station's live status (its ``on_start``/``on_abort`` hooks start and abort runs).
        diagnoses: the background diagnosis of recordings.
        marginal_fraction: a passed value within this fraction of its limit range's width of an edge is
            marginal (1).
        token: the bearer token of the write actions (None: they always answer 401).
        owns_db: the application opened ``db`` and closes it when it stops.
        svgs: rendered plots of the last few units.
        shifts: the shift calendar of the status page and the quality statistics (UTC starts).
    """

    db: Database
    live: LiveStatus
    diagnoses: DiagnosisService
    marginal_fraction: float
    token: str | None = None
    owns_db: bool = False
    svgs: SvgCache = field(default_factory=SvgCache)
    shifts: ShiftCalendar = field(default_factory=ShiftCalendar)


async def web_context(request: Request) -> WebContext:
    """The context of the application serving ``request`` (async: resolved on the event loop, no thread hop)."""
    return request.app.state.web


Web = Annotated[WebContext, Depends(web_context)]
_bearer = HTTPBearer(auto_error=False)


async def require_token(web: Web, creds: Annotated[HTTPAuthorizationCredentials | None, Depends(_bearer)]) -> None:
    """Let a write action through only with ``Authorization: Bearer <the station's token>``; 401 otherwise."""
    ok = (web.token is not None and creds is not None and creds.scheme.lower() == "bearer"
          and hmac.compare_digest(creds.credentials.encode(), web.token.encode()))
    if not ok:
        raise HTTPException(401, "a valid bearer token is required", headers={"WWW-Authenticate": "Bearer"})


__all__ = ["Web", "WebContext", "require_token", "web_context"]
