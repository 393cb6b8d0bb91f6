"""The diagnosis of a unit's recordings: ``GET /api/units/{serial}/diagnosis``, its figure
``/units/{serial}/diagnosis.svg`` (loaded by the unit page) and the diagnosis page ``/units/{serial}/diagnosis``
(the typed summary, :class:`station.web.models.DiagnosisSummary`, as tables; it reloads itself while pending).

A diagnosis is computed once per recording in the background (:class:`station.web.diagnosis_worker.DiagnosisService`):
both answer 202 with ``Retry-After`` until it is ready, 422 when the recording cannot be diagnosed and 503 when
too many recordings are waiting.
"""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Query, Request
from fastapi.responses import HTMLResponse, JSONResponse, Response

from station.web import plots
from station.web.context import Web
from station.web.diagnosis_worker import ERROR, PENDING, READY, DiagnosisBusy
from station.web.lookup import recording_or_404
from station.web.models import (
    DiagnosisFailed,
    DiagnosisPending,
    DiagnosisQueueFull,
    DiagnosisReady,
    DiagnosisSummary,
    problem,
)
from station.web.templating import templates

#: Seconds a client should wait before asking again for a diagnosis in progress.
DIAGNOSIS_RETRY_S = 2
_RETRY = {"Retry-After": str(DIAGNOSIS_RETRY_S)}
_NO_STORE = {"Cache-Control": "no-store"}
RunQuery = Annotated[str | None, Query(description="the run whose recording to diagnose (default: the newest run "
                                                   "with a recording)")]

router = APIRouter()


@router.get("/units/{serial:path}/diagnosis.svg", include_in_schema=False)
def unit_diagnosis_svg(web: Web, serial: str, run_id: str | None = None) -> Response:
    rec = recording_or_404(web.db, serial, run_id)
    try:
        result = web.diagnoses.get(rec)
    except DiagnosisBusy as exc:
        return _svg(plots.message_svg(f"diagnosis busy: {exc}"), 503, _RETRY)
    if result.status == PENDING:
        return _svg(plots.message_svg("diagnosis in progress"), 202, {**_NO_STORE, **_RETRY})
    if result.status == ERROR:
        return _svg(plots.message_svg(f"no diagnosis: {result.error}"), 422, _NO_STORE)
    title = f"{serial}, run {rec.run_id}: " + ("block residual before and after each finding"
                                              if any(c.after is not None for c in result.curves)
                                              else "block residual of the base model (no findings)")
    svg = web.svgs.get((serial, f"{rec.run_id}:{rec.sha256}", "diagnosis"),
                       lambda: plots.diagnosis_svg(result.curves, title))
    return _svg(svg, 200, {"Cache-Control": "max-age=60"})


def _svg(svg: str, status: int, headers: dict[str, str]) -> Response:
    return Response(svg, status_code=status, media_type="image/svg+xml", headers=headers)


@router.get("/api/units/{serial:path}/diagnosis", tags=["units"], response_model=DiagnosisReady, responses={
    202: {"model": DiagnosisPending, "description": "the diagnosis is being computed; ask again (Retry-After)"},
    404: problem("unknown serial, or no session recording of the unit (in that run)"),
    422: {"model": DiagnosisFailed, "description": "the recording cannot be diagnosed"},
    503: {"model": DiagnosisQueueFull, "description": "too many recordings are waiting for a diagnosis; ask again "
                                                      "(Retry-After)"},
})
def api_unit_diagnosis(web: Web, serial: str, run_id: RunQuery = None) -> DiagnosisReady | JSONResponse:
    """Where the unit's session recording and the base model (eq. 1 + eq. 3) disagree and which physics is
    missing (``station diagnose``): findings with parameters and uncertainties, rejected and inseparable
    effects. Computed once per recording in the background: answers 202 until it is ready."""
    rec = recording_or_404(web.db, serial, run_id)
    head = {"serial": serial, "run_id": rec.run_id, "session_sha256": rec.sha256}
    try:
        result = web.diagnoses.get(rec)
    except DiagnosisBusy as exc:
        return _json(DiagnosisQueueFull(status="busy", detail=str(exc), **head), 503, _RETRY)
    if result.status == PENDING:
        return _json(DiagnosisPending(status=PENDING, **head), 202, {**_RETRY, **_NO_STORE})
    if result.status == ERROR:
        return _json(DiagnosisFailed(status=ERROR, detail=result.error or "", **head), 422, {})
    return DiagnosisReady(status=READY, **head, elapsed_s=result.elapsed_s,
                          report=result.json_report() or {}, summary=DiagnosisSummary.of(result.report))


@router.get("/units/{serial:path}/diagnosis", response_class=HTMLResponse, include_in_schema=False)
def unit_diagnosis_page(request: Request, web: Web, serial: str, run_id: RunQuery = None) -> HTMLResponse:
    """The diagnosis page: findings, unexplained structure, inseparable and rejected effects as tables."""
    rec = recording_or_404(web.db, serial, run_id)
    context = {"serial": serial, "run_id": rec.run_id, "sha": rec.sha256, "retry_s": DIAGNOSIS_RETRY_S,
               "summary": None, "error": None, "state": PENDING, "elapsed_s": None}
    try:
        result = web.diagnoses.get(rec)
    except DiagnosisBusy as exc:
        context.update(state="busy", error=str(exc))
        return templates.TemplateResponse(request, "diagnosis.html", context, status_code=503, headers=_RETRY)
    if result.status == PENDING:
        return templates.TemplateResponse(request, "diagnosis.html", context, status_code=202,
                                          headers={**_RETRY, **_NO_STORE})
    if result.status == ERROR:
        context.update(state=ERROR, error=result.error or "")
        return templates.TemplateResponse(request, "diagnosis.html", context, status_code=422)
    context.update(state=result.status, summary=DiagnosisSummary.of(result.report), elapsed_s=result.elapsed_s)
    return templates.TemplateResponse(request, "diagnosis.html", context)


def _json(answer: DiagnosisPending | DiagnosisFailed | DiagnosisQueueFull, status: int,
          headers: dict[str, str]) -> JSONResponse:
    return JSONResponse(answer.model_dump(mode="json"), status_code=status, headers=headers)


__all__ = ["DIAGNOSIS_RETRY_S", "api_unit_diagnosis", "router", "unit_diagnosis_page", "unit_diagnosis_svg"]
