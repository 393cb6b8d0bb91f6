"""Read the station database: units, a unit's runs and latest parameter set, attempts for the retest policy.

Every function opens its own read transaction on a :class:`~station.store.db.Database`
and returns plain frozen dataclasses (no ORM objects escape), with ``to_dict()`` for JSON.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import asdict, dataclass, replace
from datetime import UTC, datetime
from typing import Any

from sqlalchemy import func, select

from station.eeprom.image import encode_image, run_image
from station.kernel.parameters import ParameterSet
from station.store.db import Database
from station.store.models import (
    UNFINISHED,
    Disposition,
    EepromWrite,
    LimitCheck,
    ParameterSetRecord,
    Run,
    RunUnit,
    SessionRecording,
    Unit,
)
from station.store.models import Station as StationRow


def _iso(t: datetime | None) -> str | None:
    """ISO 8601 with the UTC offset (SQLite hands back the stored UTC time without it)."""
    if t is None:
        return None
    return (t.replace(tzinfo=UTC) if t.tzinfo is None else t.astimezone(UTC)).isoformat()


@dataclass(frozen=True)
class UnitSummary:
    """One line of ``station units list``: runs of the unit and its latest result."""

    serial: str
    runs: int
    last_outcome: str
    last_started_at: str | None
    attempts: int
    disposition: str = ""  # the latest disposition's decision ('' none): 'scrap' locks the serial


@dataclass(frozen=True)
class UnitRun:
    """A unit's result in one run (limit checks counted; failed ones named)."""

    run_id: str
    station: str
    slot: int
    outcome: str
    message: str
    run_outcome: str
    started_at: str | None
    finished_at: str | None
    operator: str
    lot: str
    software_version: str
    limits_version: str
    limits_hash: str
    sequence_version: str
    sequence_hash: str
    checks: int
    failed_checks: tuple[str, ...]
    session_path: str | None
    session_sha256: str | None


@dataclass(frozen=True)
class UnitDetail:
    """Everything ``station units show`` prints about one unit."""

    serial: str
    runs: tuple[UnitRun, ...]
    attempts: int
    latest_params_json: str | None
    latest_params_run_id: str | None
    eeprom_writes: tuple[dict[str, Any], ...]
    dispositions: tuple[dict[str, Any], ...]

    def latest_params(self) -> ParameterSet | None:
        """The latest fitted parameter set, parsed (None if the unit was never fitted)."""
        return ParameterSet.from_json(self.latest_params_json) if self.latest_params_json else None

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d["latest_params"] = json.loads(self.latest_params_json) if self.latest_params_json else None
        del d["latest_params_json"]
        return d


def attempt_count(
    db: Database, serial: str, *, since_disposition: bool = True, exclude_run: str | None = None
) -> int:
    """Failed attempts of ``serial`` since its latest disposition (or ever): runs whose outcome for the
    unit was FAIL. Station faults (ERROR, UNFINISHED), aborted runs, refusals and retests are the
    station's or nobody's doing and do not count against the unit.

    ``exclude_run``: a run id not to count (the run asking whether the unit may be tested).
    """
    with db.transaction() as s:
        unit = s.scalar(select(Unit).where(Unit.serial == serial))
        if unit is None:
            return 0
        return _attempts(s, unit.id, since_disposition, exclude_run)


def retest_gate(db: Database, max_attempts: int) -> Callable[[str, str], str | None]:
    """The retest policy for :class:`~station.sequence.runner.SequenceRunner` ``admit``.

    A scrapped unit is refused for good. A unit with ``max_attempts`` failed attempts since its latest
    disposition is refused (the reason is returned) until a disposition is recorded
    (:func:`~station.store.recorder.record_disposition`).
    """

    def admit(serial: str, run_id: str) -> str | None:
        scrapped = scrapped_at(db, serial)
        if scrapped is not None:
            return f"{serial} was scrapped ({scrapped.isoformat()}): a scrapped unit is not tested again"
        n = attempt_count(db, serial, exclude_run=run_id)
        if n >= max_attempts:
            return (f"{serial} has failed {n} attempt(s), the limit is {max_attempts}: "
                    "record a disposition before testing it again")
        return None

    return admit


def scrapped_at(db: Database, serial: str) -> datetime | None:
    """When ``serial`` was scrapped (its first 'scrap' disposition), None if it never was."""
    with db.transaction() as s:
        when = s.scalar(select(func.min(Disposition.decided_at)).join(Unit, Disposition.unit_id == Unit.id)
                        .where(Unit.serial == serial, Disposition.decision == "scrap"))
    return None if when is None else (when if when.tzinfo is not None else when.replace(tzinfo=UTC))


def _attempts(s: Any, unit_id: int, since_disposition: bool, exclude_run: str | None = None) -> int:
    q = select(func.count(RunUnit.id)).join(Run).where(RunUnit.unit_id == unit_id, RunUnit.outcome == "FAIL")
    if exclude_run is not None:
        q = q.where(Run.run_uid != exclude_run)
    if since_disposition:
        last = s.scalar(select(func.max(Disposition.decided_at)).where(Disposition.unit_id == unit_id))
        if last is not None:
            q = q.where(Run.started_at > last)
    return int(s.scalar(q) or 0)


def latest_parameter_set(db: Database, serial: str, *, passed_only: bool = True) -> ParameterSet | None:
    """The newest parameter set of ``serial`` from a finished run (only from a PASS result by default)."""
    with db.transaction() as s:
        q = (select(ParameterSetRecord.params_json).join(RunUnit, ParameterSetRecord.run_unit_id == RunUnit.id)
             .join(Run, RunUnit.run_id == Run.id).join(Unit, ParameterSetRecord.unit_id == Unit.id)
             .where(Unit.serial == serial, Run.outcome != UNFINISHED))
        if passed_only:
            q = q.where(RunUnit.outcome == "PASS")
        text = s.scalar(q.order_by(Run.started_at.desc(), ParameterSetRecord.id.desc()).limit(1))
    return ParameterSet.from_json(text) if text is not None else None


@dataclass(frozen=True)
class UnitImage:
    """A unit's calibration image: the bytes, where they come from, and the parameter set's run.

    ``written`` is True when the bytes are those the run wrote into the unit (as read back), False when
    no write was recorded and they were built with :func:`~station.eeprom.image.run_image` from the
    run's parameter set, station and start time (update count 1: what a first write would write).
    """

    serial: str
    data: bytes
    run_id: str
    written: bool


def unit_image(db: Database, serial: str) -> UnitImage | None:
    """The image of ``serial``'s newest PASS run (None if it has neither a written image nor a parameter set).

    One source for the API download and ``station eeprom image``: the image its run wrote, else the one
    :func:`~station.eeprom.image.run_image` builds from the run's parameter set, station and start.
    Raises :class:`~station.eeprom.image.ImageError` if the parameter set does not fit the image format.
    """
    with db.transaction() as s:
        row = s.execute(
            select(RunUnit.id, Run.run_uid, Run.started_at, StationRow.name)
            .join(Run, RunUnit.run_id == Run.id).join(StationRow, Run.station_id == StationRow.id)
            .join(Unit, RunUnit.unit_id == Unit.id)
            .where(Unit.serial == serial, Run.outcome != UNFINISHED, RunUnit.outcome == "PASS")
            .order_by(Run.started_at.desc(), Run.id.desc()).limit(1)
        ).first()
        if row is None:
            return None
        ru_id, run_uid, started_at, station_name = row
        written = s.scalar(select(EepromWrite.image).where(EepromWrite.run_unit_id == ru_id,
                                                           EepromWrite.image.is_not(None),
                                                           EepromWrite.state == "complete")
                           .order_by(EepromWrite.id.desc()).limit(1))
        params_json = s.scalar(select(ParameterSetRecord.params_json).where(ParameterSetRecord.run_unit_id == ru_id)
                               .order_by(ParameterSetRecord.id.desc()).limit(1))
    if written is not None:
        return UnitImage(serial, bytes(written), run_uid, True)
    if params_json is None:
        return None
    when = started_at if started_at.tzinfo is not None else started_at.replace(tzinfo=UTC)
    image = run_image(ParameterSet.from_json(params_json), station_name, when)
    return UnitImage(serial, encode_image(image), run_uid, False)


def latest_dispositions(db: Database, serials: list[str]) -> dict[str, str]:
    """The latest disposition's decision of each of ``serials`` that has one (e.g. ``{"SIM-1": "scrap"}``).

    A scrap is final (the station refuses the serial from then on), so a scrapped unit shows "scrap" even if a
    later decision was recorded."""
    out: dict[str, str] = {}
    if not serials:
        return out
    with db.transaction() as s:
        for i in range(0, len(serials), 500):
            rows = s.execute(select(Unit.serial, Disposition.decision).join(Disposition, Disposition.unit_id == Unit.id)
                             .where(Unit.serial.in_(serials[i:i + 500]))
                             .order_by(Disposition.decided_at, Disposition.id)).all()
            for serial, decision in rows:
                if out.get(serial) != "scrap":
                    out[serial] = decision
    return out


def list_units(db: Database) -> list[UnitSummary]:
    """Every unit, by serial, with its run count, latest outcome, attempts since its last disposition and
    that disposition (scrap shown for good)."""
    out: list[UnitSummary] = []
    with db.transaction() as s:
        for unit in s.scalars(select(Unit).order_by(Unit.serial)):
            rows = s.execute(
                select(RunUnit.outcome, Run.started_at).join(Run).where(RunUnit.unit_id == unit.id)
                .order_by(Run.started_at.desc(), Run.id.desc())
            ).all()
            last = rows[0] if rows else None
            out.append(UnitSummary(unit.serial, len(rows), last[0] if last else "", _iso(last[1]) if last else None,
                                   _attempts(s, unit.id, True)))
    shown = latest_dispositions(db, [u.serial for u in out])
    return [replace(u, disposition=shown.get(u.serial, "")) for u in out]


def show_unit(db: Database, serial: str) -> UnitDetail | None:
    """The unit ``serial`` with its runs (newest first), latest parameter set, EEPROM writes, dispositions."""
    with db.transaction() as s:
        unit = s.scalar(select(Unit).where(Unit.serial == serial))
        if unit is None:
            return None
        runs: list[UnitRun] = []
        q = (select(RunUnit, Run, StationRow.name).join(Run, RunUnit.run_id == Run.id)
             .join(StationRow, Run.station_id == StationRow.id).where(RunUnit.unit_id == unit.id)
             .order_by(Run.started_at.desc(), Run.id.desc()))
        for ru, run, station_name in s.execute(q).all():
            checks = s.scalars(select(LimitCheck).where(LimitCheck.run_unit_id == ru.id).order_by(LimitCheck.id)).all()
            rec = s.scalar(select(SessionRecording).where(SessionRecording.run_unit_id == ru.id))
            runs.append(UnitRun(
                run.run_uid, station_name, ru.slot, ru.outcome, ru.message, run.outcome, _iso(run.started_at),
                _iso(run.finished_at), run.operator, run.lot or "", run.software_version, run.limits_version,
                run.limits_hash, run.sequence_version, run.sequence_hash, len(checks),
                tuple(f"{c.step}:{c.name}" for c in checks if not c.passed),
                rec.path if rec else None, rec.sha256 if rec else None,
            ))
        latest = s.execute(
            select(ParameterSetRecord, Run.run_uid).join(RunUnit, ParameterSetRecord.run_unit_id == RunUnit.id)
            .join(Run, RunUnit.run_id == Run.id)
            .where(ParameterSetRecord.unit_id == unit.id, Run.outcome != UNFINISHED)
            .order_by(Run.started_at.desc(), ParameterSetRecord.id.desc()).limit(1)
        ).first()
        writes = tuple(
            {"image_sha256": w.image_sha256, "layout_version": w.layout_version, "attempts": w.attempts,
             "verified": w.verified, "message": w.message, "written_at": _iso(w.written_at), "state": w.state}
            for w in s.scalars(select(EepromWrite).where(EepromWrite.unit_id == unit.id).order_by(EepromWrite.id))
        )
        dispositions = tuple(
            {"decision": d.decision, "operator": d.operator, "note": d.note, "decided_at": _iso(d.decided_at)}
            for d in unit.dispositions
        )
        return UnitDetail(
            unit.serial, tuple(runs), _attempts(s, unit.id, True),
            latest[0].params_json if latest else None, latest[1] if latest else None, writes, dispositions,
        )
