"""The station's live status (``GET /api/status``, the status page and its server-sent events).

Times are station clock seconds (rig seconds, s) unless a field says otherwise; the rig's
readings keep the rig's own units (deg, deg/s), named in their field names.
"""

from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, ConfigDict, Field

from station.web.models.runs import RunSummary

#: idle (ready for a run), running, or fault (a run or the rig failed; see ``message``).
StationState = Literal["idle", "running", "fault"]


class SlotStatus(BaseModel):
    """One fixture slot's tile (updated in place while the run goes on)."""

    slot: int = Field(description="fixture slot (0-based)")
    sensor: str = Field("", description="the slot's sensor URL")
    serial: str = Field("", description="the unit's serial number ('' until the sensor reported it)")
    state: str = Field("waiting", description="what the slot is doing: waiting, measuring, fitting, done, or the "
                                              "step and value that went out of limits")
    verdict: str | None = Field(None, description="the unit's outcome (PASS, FAIL, ERROR, ABORTED); null until known")
    message: str = Field("", description="why the verdict is what it is ('' when there is nothing to say)")
    reason: str = Field(default="", description="the verdict in plain words for the operator: what it means and "
                                                "where the unit goes ('' until the verdict)")


class RigState(BaseModel):
    """What the rig last reported in the current run."""

    model_config = ConfigDict(frozen=True)

    roll_deg: float = Field(description="measured roll angle (deg)")
    pitch_deg: float = Field(description="measured pitch angle (deg)")
    yaw_deg: float = Field(description="measured yaw angle (deg)")
    rate_dps: float = Field(description="measured table rate (deg/s)")
    status: str = Field(description="the rig's status flags, e.g. 'MOVING|REMOTE'")
    fault_code: int = Field(description="latched fault code (0: none)")
    t_s: float = Field(description="station clock time of the reading (s)")


class PromptStatus(BaseModel):
    """A prompt of the station waiting for the operator's answer (``POST /api/prompts/{prompt_id}``)."""

    model_config = ConfigDict(frozen=True)

    prompt_id: str = Field(description="the prompt's id within the run")
    kind: str = Field(description="load, close-lid, unload or confirm")
    text: str = Field(description="what the operator is asked to do, in plain words")
    nests: list[int] = Field(description="the nests concerned (numbered from 1; empty: the whole fixture)")
    timeout_s: float = Field(description="how long the station waits for the answer (wall-clock s)")
    shown_at: str = Field(description="when the prompt was shown (UTC, ISO 8601)")


class StepProgress(BaseModel):
    """The step under way (index -1 and empty names before the first step)."""

    index: int = Field(description="0-based index of the step in the run's plan (-1: none yet)")
    name: str = Field(description="the step's name, e.g. 'rest', 'pose -z', 'rate x +50', 'fit and limits'")
    kind: str = Field(description="rest, pose, rate or fit ('' when idle)")
    hold_s: float = Field(description="planned capture time of the step (s)")


class ShiftStats(BaseModel):
    """Production figures of the current shift (the station's shift calendar, UTC), over every station recording
    into the database. Tested: the run reached a verdict on the unit (PASS, FAIL or RETEST); ERROR, ABORTED,
    REFUSED and UNFINISHED results are not tested and never use up a unit's first pass."""

    model_config = ConfigDict(frozen=True)

    shift: str = Field(description="the shift's name in the calendar")
    since: str = Field(description="start of the shift (UTC, ISO 8601)")
    results: int = Field(description="unit results of ended runs in the shift (tested or not)")
    not_tested: int = Field(description="of those, results without a verdict (ERROR, ABORTED, REFUSED)")
    units_tested: int = Field(description="distinct units with a tested result in the shift")
    first_pass_units: int = Field(description="units whose first tested result was in this shift")
    first_pass_yield: float | None = Field(description="fraction of those that passed that first test (1); null if "
                                                       "there were none")
    units_per_hour: float = Field(description="distinct units tested in the last ``rate_window_s`` seconds, per hour "
                                              "(1/h); not since the shift's start, so it does not fall while idle "
                                              "at the start of a shift")
    rate_window_s: float = Field(default=3600.0, description="the window of ``units_per_hour``: the last this many "
                                                             "seconds (wall clock, s)")
    units_in_window: int = Field(default=0, description="distinct units tested in that window")


class StationStatus(BaseModel):
    """The station's live status."""

    version: int = Field(description="increases with every change (the server-sent events' id)")
    state: StationState = Field(description="idle, running or fault")
    run_id: str = Field(description="the current or last run's id ('' before the first)")
    station: str = Field(description="the station's name in that run")
    rig: str = Field(description="the rig in that run (URL or firmware id)")
    message: str = Field(description="why the station is in fault, or why the last run did not complete")
    outcome: str | None = Field(description="the run's outcome (PASS, FAIL, ERROR, ABORTED); null while it runs and "
                                            "before the first run")
    step: StepProgress = Field(description="the step under way")
    steps_done: int = Field(description="steps of the plan finished")
    steps_total: int = Field(description="steps in the plan")
    progress: float = Field(description="fraction of the plan's steps finished (1)")
    remaining_s: float | None = Field(description="estimated time until the run ends (station clock s); null when not "
                                                  "running")
    remaining_basis: str = Field(default="", description="how ``remaining_s`` was estimated, in words (the "
                                                         "plan's capture times, the rig motion measured so far)")
    slots: list[SlotStatus] = Field(description="one tile per fixture slot")
    rig_state: RigState | None = Field(description="the rig's last reading in this run; null before the first")
    shift: ShiftStats | None = Field(description="the current shift's figures; null without a database (or "
                                                     "when the store was not read)")
    recent_runs: list[RunSummary] = Field(description="the newest runs (at most 10), newest first")
    prompt: PromptStatus | None = Field(default=None, description="the prompt waiting for the operator; null when none")
    nests: int = Field(default=0, description="nests of the station's fixture (0: unknown, a read-only server)")


__all__ = ["PromptStatus", "RigState", "ShiftStats", "SlotStatus", "StationState", "StationStatus", "StepProgress"]
