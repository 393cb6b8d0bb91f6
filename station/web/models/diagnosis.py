"""The diagnosis of a unit's recording in the JSON API (``GET /api/units/{serial}/diagnosis``).

One answer per state of the background diagnosis (see :mod:`station.web.diagnosis`): ready
(200), pending (202), failed (422: the recording cannot be diagnosed), queue full (503).
"""

from __future__ import annotations

from typing import Annotated, Any, Literal

from pydantic import BaseModel, Field

from station.web.models.common import Serial

DiagnosedRun = Annotated[str, Field(description="the run whose recording is diagnosed")]
SessionSha256 = Annotated[str, Field(description="hex SHA-256 of the recording as the run stored it")]
Reason = Annotated[str, Field(description="why, one line")]


class DiagnosisReady(BaseModel):
    """The diagnosis is ready."""

    status: Literal["ready"] = Field(description="'ready'")
    serial: Serial
    run_id: DiagnosedRun
    session_sha256: SessionSha256
    elapsed_s: float | None = Field(description="wall time the diagnosis took (s); null when not measured")
    report: dict[str, Any] = Field(description="the station-diagnosis/1 report of station.diagnose, as ``station "
                                               "diagnose --json`` prints it: findings with parameters and "
                                               "uncertainties (engineering units named in each), rejected and "
                                               "inseparable effects, where the residual is, the simulator re-run")


class DiagnosisPending(BaseModel):
    """The diagnosis is being computed: ask again after ``Retry-After`` seconds."""

    status: Literal["pending"] = Field(description="'pending'")
    serial: Serial
    run_id: DiagnosedRun
    session_sha256: SessionSha256


class DiagnosisFailed(BaseModel):
    """The recording cannot be diagnosed (the fit refuses it, it is not a session, it changed since its run)."""

    status: Literal["error"] = Field(description="'error'")
    detail: Reason
    serial: Serial
    run_id: DiagnosedRun
    session_sha256: SessionSha256


class DiagnosisQueueFull(BaseModel):
    """Too many recordings are waiting for a diagnosis: ask again after ``Retry-After`` seconds."""

    status: Literal["busy"] = Field(description="'busy'")
    detail: Reason
    serial: Serial
    run_id: DiagnosedRun
    session_sha256: SessionSha256


__all__ = ["DiagnosisFailed", "DiagnosisPending", "DiagnosisQueueFull", "DiagnosisReady"]
