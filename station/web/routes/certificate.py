"""The calibration certificate of a unit: ``GET /units/{serial}/certificate.pdf`` and ``.html``.

Both render :func:`station.store.certificate.unit_certificate` (the newest run with a verdict, or
``?run=ID``); the unit page links them. 404: unknown unit or run, or no parameter set with a verdict;
409: the stored parameter set does not match its recorded SHA-256 (no certificate is issued).
"""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, HTTPException, Query
from fastapi.responses import HTMLResponse, Response

from station.store.certificate import Certificate, CertificateError, CertificateRecordError, unit_certificate
from station.store.certificate_html import certificate_html
from station.store.certificate_pdf import certificate_pdf
from station.web.context import Web
from station.web.models import problem

router = APIRouter()

RunQuery = Annotated[str | None, Query(max_length=100, description="the run (default: the unit's newest run "
                                                                   "with a verdict and a parameter set)")]
_RESPONSES: dict[int | str, dict[str, object]] = {
    404: problem("unknown serial or run, or no parameter set with a verdict"),
    409: problem("the stored parameter set does not match its recorded SHA-256"),
}


def _certificate(web: Web, serial: str, run: str | None) -> Certificate:
    try:
        return unit_certificate(web.db, serial, run)
    except CertificateRecordError as exc:
        raise HTTPException(409, str(exc)) from None
    except CertificateError as exc:
        raise HTTPException(404, str(exc)) from None


def _filename(serial: str, run_id: str, ext: str) -> str:
    safe = "".join(c if c.isalnum() or c in "-_." else "_" for c in f"{serial}_{run_id}") or "unit"
    return f"certificate_{safe}.{ext}"


@router.get("/units/{serial:path}/certificate.pdf", tags=["units"], response_class=Response,
            responses={200: {"content": {"application/pdf": {}}, "description": "the calibration certificate"},
                       **_RESPONSES})
def certificate_pdf_route(web: Web, serial: str, run: RunQuery = None) -> Response:
    """The unit's calibration certificate as PDF (parameters ± U with k = 2, verdicts, verification, limits file
    name, version and SHA-256, the decision rule, station, rig, operator, date, the parameter set's SHA-256)."""
    cert = _certificate(web, serial, run)
    return Response(certificate_pdf(cert), media_type="application/pdf",
                    headers={"Content-Disposition": f'inline; filename="{_filename(serial, cert.run_id, "pdf")}"'})


@router.get("/units/{serial:path}/certificate.html", response_class=HTMLResponse, include_in_schema=False)
def certificate_html_route(web: Web, serial: str, run: RunQuery = None) -> HTMLResponse:
    return HTMLResponse(certificate_html(_certificate(web, serial, run)))


__all__ = ["certificate_html_route", "certificate_pdf_route", "router"]
