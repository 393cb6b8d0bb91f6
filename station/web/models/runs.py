"""Runs in the JSON API: the run list (``GET /api/runs``) and starting and aborting a run."""

from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, ConfigDict, Field

from station.web.models.common import Message, Outcome, OutcomeText, RunId, StationName, Timestamp


class RunUnitOutcome(BaseModel):
    """One fixture slot's unit in a run and its outcome."""

    slot: int = Field(description="fixture slot (0-based)")
    serial: str = Field(description="the unit's serial number ('' if the run never read it)")
    outcome: OutcomeText
    message: Message


class RunSummary(BaseModel):
    """One run of the sequence on one station, with every slot's unit and outcome."""

    run_id: RunId
    station: StationName
    outcome: OutcomeText
    started_at: Timestamp
    finished_at: Timestamp
    duration_s: float | None = Field(description="length of the run on the station clock (s); null until it ended")
    wall_s: float | None = Field(description="length of the run in wall-clock time (s); null until it ended")
    message: Message
    operator: str = Field(description="who ran the station ('' when not configured)")
    units: list[RunUnitOutcome] = Field(description="one entry per fixture slot, by slot")


class RunFilter(BaseModel):
    """Which runs ``GET /api/runs`` lists."""

    limit: int = Field(50, ge=1, le=1000, description="newest runs to return")
    station: str | None = Field(None, description="station name")
    outcome: Outcome | None = Field(None, description="run outcome")
    cursor: str | None = Field(None, max_length=400, description="the next page: the ``X-Next-Cursor`` header of "
                                                                 "the previous page (absent on the last page)")


class StartRunRequest(BaseModel):
    """Options of a run started from the API; the station runs the plan and limits it was configured with."""

    model_config = ConfigDict(extra="forbid")

    operator: str | None = Field(default=None, max_length=100,
                                 description="who starts the run, recorded on it (default: the station's operator; "
                                             "a signed-in operator's own name wins)")
    lot: str | None = Field(default=None, max_length=40, pattern=r"^[A-Za-z0-9][A-Za-z0-9._/-]{0,39}$",
                            description="the units' lot, recorded on the run (default: the station's)")
    serials: dict[int, str] = Field(default_factory=dict,
                                    description="nest (numbered from 1) -> the serial scanned for it; each is "
                                                "checked as a scan is (422 when one is refused) and the unit in the "
                                                "nest must report it, or it is REFUSED before anything moves")


class RunAccepted(BaseModel):
    """A run was started (``POST /api/runs``)."""

    run_id: str = Field(description="the started run's id")


class RunAbortAccepted(BaseModel):
    """The running run was asked to stop as soon as possible (``POST /api/runs/{run_id}/abort``); its outcome
    becomes ABORTED."""

    run_id: str = Field(description="the aborting run's id")
    state: Literal["aborting"] = Field(description="always 'aborting': the run is stopping")


__all__ = ["RunAbortAccepted", "RunAccepted", "RunFilter", "RunSummary", "RunUnitOutcome", "StartRunRequest"]
