"""Units in the JSON API: the unit list (``GET /api/units``) and one unit (``GET /api/units/{serial}``)."""

from __future__ import annotations

from datetime import date

from pydantic import BaseModel, Field

from station.kernel.found_terms import found_terms
from station.store.queries import UnitDetail
from station.web.models.common import Message, Outcome, OutcomeText, RunId, Serial, StationName, Timestamp
from station.web.models.params import CalibrationParameters


class UnitFilter(BaseModel):
    """Which units ``GET /api/units`` lists (every filter is on the runs; each unit shows its latest matching one)."""

    date_from: date | None = Field(None, description="first UTC day of the run start (inclusive)")
    date_to: date | None = Field(None, description="last UTC day of the run start (inclusive)")
    outcome: Outcome | None = Field(None, description="the unit's latest outcome (PASS, FAIL, ERROR, ABORTED, "
                                                      "UNFINISHED)")
    station: str | None = Field(None, description="station name")
    q: str | None = Field(None, max_length=100, description="part of the serial number (case-insensitive)")
    limit: int = Field(100, ge=1, le=1000, description="units per page (ordered by serial)")
    cursor: str | None = Field(None, max_length=400, description="the next page: the ``X-Next-Cursor`` header of "
                                                                 "the previous page (absent on the last page)")


class UnitOverview(BaseModel):
    """A unit with its latest result among the runs that match the filters."""

    serial: Serial
    runs: int = Field(description="runs of the unit that match the filters")
    last_outcome: OutcomeText
    last_run_id: RunId
    last_started_at: Timestamp
    station: StationName
    disposition: str | None = Field(None, description="the unit's latest disposition (retest, scrap, rework, "
                                                      "accept-deviation; scrap is final); null: none")


class LimitCheckResult(BaseModel):
    """A fitted parameter against its product limits (SI, in ``unit``)."""

    name: str = Field(description="the parameter, e.g. 'accel.bias_static.x'")
    value: float | None = Field(description="the fitted value (in unit); null if not finite")
    std: float | None = Field(description="its standard uncertainty (in unit); null if unknown")
    low: float | None = Field(description="lower limit (in unit); null: none")
    high: float | None = Field(description="upper limit (in unit); null: none")
    unit: str = Field(description="the SI unit of value, std, low and high, e.g. 'm/s^2', 'rad/s', 's', '1'")
    passed: bool = Field(description="the value conforms: by the guard-band rule, value +- k std inside [low, high]; "
                                     "by the widening rule of station-limits/1 files, outside by at most k std")
    verdict: str | None = Field(default=None, description="PASS, MARGINAL (a pass near a limit), INCONCLUSIVE (inside, "
                                                         "but value +- k std straddles a limit) or FAIL; null for "
                                                         "checks recorded by an older station")
    k: float | None = Field(default=None, description="the coverage factor k of the uncertainty interval the verdict "
                                                      "used (1); null: none")


class UnitRunResult(BaseModel):
    """The unit's result in one run."""

    run_id: RunId
    station: StationName
    slot: int = Field(description="fixture slot (0-based)")
    outcome: OutcomeText
    message: Message
    run_outcome: str = Field(description="the whole run's outcome (PASS, FAIL, ERROR, ABORTED, UNFINISHED)")
    started_at: Timestamp
    finished_at: Timestamp
    operator: str = Field(description="who ran the station ('' when not configured)")
    lot: str = Field("", description="the production lot of the run ('' when not given)")
    software_version: str = Field(description="the station software's version")
    limits_version: str = Field(description="the product limits' name and version")
    limits_hash: str = Field(description="hex SHA-256 of the limits file's bytes (an edited file with the same name "
                                         "and version has another hash)")
    sequence_version: str = Field(description="the sequence's (plan's) version")
    sequence_hash: str = Field(description="hex SHA-256 of the sequence (plan)")
    checks: int = Field(description="limit checks of the unit in the run (capture gates and product limits)")
    failed_checks: list[str] = Field(description="the failed ones, as 'step:name'")
    session_path: str | None = Field(description="where the session recording was saved; null: none")
    session_sha256: str | None = Field(description="hex SHA-256 of the recording when saved; null: none")


class EepromWriteEntry(BaseModel):
    """A calibration image written into the unit's EEPROM."""

    image_sha256: str = Field(description="hex SHA-256 of the image")
    layout_version: int = Field(description="the image layout's version (station/eeprom/layout.md)")
    attempts: int = Field(description="write attempts")
    verified: bool = Field(description="the read-back matched the image")
    message: str = Field(description="what the write reported ('' when there is nothing to say)")
    written_at: Timestamp
    state: str = Field("complete", description="'complete': written and read back; 'intended': recorded ahead, "
                                              "not completed yet (or the station died; reconciled at its next "
                                              "start); 'not-applied': reconciled, the image never reached the unit")


class DispositionEntry(BaseModel):
    """A person's decision about the unit (it resets the attempt count)."""

    decision: str = Field(description="e.g. 'retest', 'scrap', 'rework'")
    operator: str = Field(description="who decided")
    note: str = Field(description="free text")
    decided_at: Timestamp


class UnitRecord(BaseModel):
    """One unit: its runs, latest parameter set, limit checks and EEPROM writes."""

    serial: Serial
    runs: list[UnitRunResult] = Field(description="the unit's runs, newest first")
    attempts: int = Field(description="runs since the latest disposition (the retest policy counts these)")
    latest_params_run_id: str | None = Field(description="the run of the latest parameter set; null: never fitted")
    eeprom_writes: list[EepromWriteEntry] = Field(description="EEPROM writes, oldest first")
    dispositions: list[DispositionEntry] = Field(description="dispositions, oldest first")
    latest_params: CalibrationParameters | None = Field(description="the latest fitted parameter set (SI); null: "
                                                                    "never fitted")
    checks: list[LimitCheckResult] = Field(description="the product limit checks of the newest finished run with any")

    @classmethod
    def of(cls, detail: UnitDetail, checks: list[LimitCheckResult]) -> UnitRecord:
        """The store's account of the unit (:func:`station.store.queries.show_unit`) with its limit checks."""
        d = detail.to_dict()
        params = detail.latest_params()
        if params is not None:  # the found terms with their determinability, read from the set and its notes
            d["latest_params"]["found_terms"] = found_terms(params).to_dict()
        return cls.model_validate({**d, "checks": checks})


__all__ = ["DispositionEntry", "EepromWriteEntry", "LimitCheckResult", "UnitFilter", "UnitOverview", "UnitRecord",
           "UnitRunResult"]
