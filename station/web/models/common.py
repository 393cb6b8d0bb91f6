"""What every area of the JSON API shares: the error body and the descriptions of recurring fields."""

from __future__ import annotations

from typing import Annotated, Any, Literal

from pydantic import BaseModel, Field

#: The outcomes of a unit or a run as stored (UNFINISHED: not ended yet, or the process died).
Outcome = Literal["PASS", "RETEST", "FAIL", "REFUSED", "ERROR", "ABORTED", "UNFINISHED"]

Serial = Annotated[str, Field(description="the unit's serial number")]
RunId = Annotated[str, Field(description="the run's id")]
StationName = Annotated[str, Field(description="the station's name")]
Message = Annotated[str, Field(description="why the outcome is what it is, one line ('' when there is nothing to say)")]
OutcomeText = Annotated[
    str, Field(description="PASS, RETEST, FAIL, REFUSED, ERROR, ABORTED or UNFINISHED (not ended yet)")
]
Timestamp = Annotated[str | None, Field(description="UTC time, ISO 8601 (null: not known)")]


class ErrorDetail(BaseModel):
    """Why the request failed (every error but a request validation error, see ``HTTPValidationError``)."""

    detail: str = Field(description="what is wrong, one line")


def problem(description: str) -> dict[str, Any]:
    """An OpenAPI ``responses`` entry: an :class:`ErrorDetail` body, with ``description``."""
    return {"model": ErrorDetail, "description": description}


__all__ = ["ErrorDetail", "Message", "Outcome", "OutcomeText", "RunId", "Serial", "StationName", "Timestamp",
           "problem"]
