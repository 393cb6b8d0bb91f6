"""What the routers of one web application share (:class:`WebContext`, on ``app.state.web``) and the
dependencies that hand it to them: the context itself, the bearer-token check of the write actions, and the
check that lets a signed-in operator of the console write as well (:func:`require_writer`)."""

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
    if not token_ok(web, creds):
        raise HTTPException(401, "a valid bearer token is required", headers={"WWW-Authenticate": "Bearer"})


@dataclass(frozen=True)
class Writer:
    """Who a write action is from: a signed-in operator (``via='session'``, name and role) or the bearer token
    (``via='token'``, no name: the run records the station's operator)."""

    via: str
    name: str = ""
    role: str = ""


def signed_in(request: Request) -> Writer | None:
    """The operator signed in on this browser (the console's signed session cookie), None if nobody is."""
    session = request.scope.get("session") or {}
    name, role = session.get("operator"), session.get("role")
    return Writer("session", name, role) if isinstance(name, str) and name and isinstance(role, str) else None


def token_ok(web: WebContext, creds: HTTPAuthorizationCredentials | None) -> bool:
    """``creds`` carry the station's bearer token (never true without a configured token)."""
    return (web.token is not None and creds is not None and creds.scheme.lower() == "bearer"
            and hmac.compare_digest(creds.credentials.encode(), web.token.encode()))


async def require_writer(request: Request, web: Web,
                         creds: Annotated[HTTPAuthorizationCredentials | None, Depends(_bearer)]) -> Writer:
    """Let a write action through with the bearer token or a signed-in operator; 401 otherwise.

    The operator's cookie is ``SameSite=Strict``; a cookie-authorised request whose ``Origin`` is another site
    is refused as well (403), so no other page can act in the operator's name.
    """
    if token_ok(web, creds):
        return Writer("token")
    who = signed_in(request)
    if who is None:
        raise HTTPException(401, "sign in at /operator or give a valid bearer token",
                            headers={"WWW-Authenticate": "Bearer"})
    origin = request.headers.get("origin")
    if origin is not None and origin.split("://", 1)[-1] != request.headers.get("host", ""):
        raise HTTPException(403, "a write from another site's page is refused")
    return who


__all__ = ["Web", "WebContext", "Writer", "require_token", "require_writer", "signed_in", "token_ok",
           "web_context"]
