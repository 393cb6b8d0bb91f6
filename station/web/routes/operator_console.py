"""The operator console: ``/operator`` (the page), sign-in, scans and the answers to the station's prompts.

* ``GET /operator``: the console (sign in, lot and serials by barcode scanner, prompts, start and abort, live
  progress and the verdict per nest); it follows ``/events`` as the status page does.
* ``GET|POST|DELETE /api/operator/session``: who is signed in; sign in (name, role; from another computer than
  the station's own also the station's token, typed, never shown); sign out.
* ``POST /api/operator/scan``: check one scanned serial for a nest (:func:`station.web.console.check_scan`).
* ``POST /api/prompts/{prompt_id}``: answer the prompt the station waits on (confirm or cancel).

Starting and aborting use ``POST /api/runs`` and ``POST /api/runs/{run_id}/abort``, which accept a signed-in
operator as well as the bearer token (:func:`station.web.context.require_writer`).
"""

from __future__ import annotations

import hmac
import ipaddress
from typing import Annotated, Literal

from fastapi import APIRouter, Body, Depends, HTTPException, Request
from fastapi.responses import HTMLResponse
from pydantic import BaseModel, ConfigDict, Field

from station.web.console import LOT_PATTERN, ROLES, ConsoleOperator, ConsoleSettings, Role, check_scan
from station.web.context import Web, Writer, require_writer, signed_in
from station.web.models import problem
from station.web.templating import templates

router = APIRouter(tags=["operator"])


class SignIn(BaseModel):
    """Who signs in at the console."""

    model_config = ConfigDict(extra="forbid")

    name: str = Field(min_length=1, max_length=60, pattern=r"^[^\x00-\x1f<>]+$",
                      description="the operator's name (or badge number), recorded on every run they start")
    role: Role = Field(default="operator", description="operator, technician or engineer")
    token: str | None = Field(default=None, max_length=200,
                              description="the station's token: needed when signing in from another computer than "
                                          "the station's own (never shown by any page)")


class SignedInOperator(BaseModel):
    """The operator signed in on this browser."""

    signed_in: bool = Field(description="someone is signed in")
    name: str = Field(default="", description="their name ('' when nobody is)")
    role: str = Field(default="", description="their role ('' when nobody is)")


class ScanRequest(BaseModel):
    """One scan from the barcode reader (it types the serial and presses Enter)."""

    model_config = ConfigDict(extra="forbid")

    serial: str = Field(max_length=200, description="what the reader typed")
    nest: int = Field(ge=1, le=64, description="the nest it is for (numbered from 1)")
    scanned: dict[int, str] = Field(default_factory=dict, description="nest -> serial scanned into the other nests")


class ScanResult(BaseModel):
    """What a scan is worth."""

    accepted: bool = Field(description="the serial may go into the nest")
    serial: str = Field(description="the serial as scanned (trimmed)")
    nest: int = Field(description="the nest it was scanned for")
    message: str = Field(description="why it is refused, or what the station knows of the unit, in plain words")


class PromptAnswer(BaseModel):
    """The operator's answer to a prompt."""

    model_config = ConfigDict(extra="forbid")

    answer: Literal["confirmed", "cancelled"] = Field(description="confirmed: done, go on; cancelled: stop the run")


class PromptAnswerAccepted(BaseModel):
    """The answer reached the station."""

    prompt_id: str = Field(description="the prompt answered")
    answer: str = Field(description="the answer given: confirmed or cancelled")


def _loopback(request: Request) -> bool:
    host = request.client.host if request.client is not None else ""
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return host in ("localhost", "testclient")  # Starlette's test client


@router.get("/operator", response_class=HTMLResponse, include_in_schema=False)
def operator_page(request: Request, web: Web) -> HTMLResponse:
    snap = web.live.snapshot()
    who = signed_in(request)
    ctx = {"s": snap, "who": who, "roles": ROLES, "lot_pattern": LOT_PATTERN,
           "nests": web.live.nests or len(snap["slots"]), "can_run": web.live.on_start is not None,
           "local": _loopback(request)}
    return templates.TemplateResponse(request, "operator.html", ctx)


@router.get("/api/operator/session", response_model=SignedInOperator)
def get_session(request: Request) -> SignedInOperator:
    """Who is signed in on this browser."""
    who = signed_in(request)
    return SignedInOperator(signed_in=who is not None, name=who.name if who else "", role=who.role if who else "")


@router.post("/api/operator/session", response_model=SignedInOperator,
             responses={401: problem("signing in from another computer needs the station's token")})
def sign_in(request: Request, web: Web, body: Annotated[SignIn, Body()]) -> SignedInOperator:
    """Sign in (a signed session cookie, ``SameSite=Strict``, for the console's shift-long session)."""
    if not _loopback(request):
        ok = (web.token is not None and body.token is not None
              and hmac.compare_digest(body.token.encode(), web.token.encode()))
        if not ok:
            raise HTTPException(401, "signing in from another computer than the station's own needs the station's "
                                     "token")
    name = body.name.strip()
    if not name:
        raise HTTPException(422, "a name is needed")
    request.session.clear()
    request.session.update({"operator": name, "role": body.role})
    return SignedInOperator(signed_in=True, name=name, role=body.role)


@router.delete("/api/operator/session", response_model=SignedInOperator)
def sign_out(request: Request) -> SignedInOperator:
    """Sign out."""
    request.session.clear()
    return SignedInOperator(signed_in=False)


@router.post("/api/operator/scan", response_model=ScanResult,
             responses={401: problem("nobody signed in and no bearer token")})
def scan(request: Request, web: Web, body: Annotated[ScanRequest, Body()],
         writer: Annotated[Writer, Depends(require_writer)]) -> ScanResult:
    """Check one scanned serial for a nest: refused on the spot when it is not a serial of this line, already in
    another nest, scrapped, or over its failed attempts."""
    settings: ConsoleSettings = getattr(request.app.state, "console", None) or ConsoleSettings()
    nests = web.live.nests
    if nests and body.nest > nests:
        return ScanResult(accepted=False, serial=body.serial.strip(), nest=body.nest,
                          message=f"the fixture has nests 1 to {nests}")
    check = check_scan(web.db, body.serial, settings, body.scanned, body.nest)
    return ScanResult(accepted=check.accepted, serial=check.serial, nest=body.nest, message=check.message)


@router.post("/api/prompts/{prompt_id:path}", status_code=202, response_model=PromptAnswerAccepted,
             responses={401: problem("nobody signed in and no bearer token"),
                        404: problem("the station is not waiting for this prompt"),
                        409: problem("this station's prompts are answered elsewhere, not from the web")})
def answer_prompt(request: Request, web: Web, prompt_id: str, body: Annotated[PromptAnswer, Body()],
                  writer: Annotated[Writer, Depends(require_writer)]) -> PromptAnswerAccepted:
    """Answer the prompt the station waits on (write action: a signed-in operator or the bearer token)."""
    waiting = web.live.status(with_store=False).prompt
    if waiting is None or waiting.prompt_id != prompt_id:
        raise HTTPException(404, f"the station is not waiting for the prompt {prompt_id}")
    prompter: ConsoleOperator | None = getattr(request.app.state, "prompter", None)
    if prompter is None:
        raise HTTPException(409, "this station's prompts are answered elsewhere (its terminal), not from the web")
    by = writer.name or "API (bearer token)"
    if not prompter.answer(prompt_id, body.answer, by):
        raise HTTPException(404, f"the prompt {prompt_id} is closed already")
    return PromptAnswerAccepted(prompt_id=prompt_id, answer=body.answer)


__all__ = ["answer_prompt", "get_session", "operator_page", "router", "scan", "sign_in", "sign_out"]
