"""Golden units in the database: registrations (versioned per serial) and every check of a station.

The shift gate (:func:`golden_gate`) is the retest-policy hook of the runner (``admit(serial, run_id)``):
a golden unit is always admitted; a production unit only when the station's newest golden check passed
and lies in the current shift of the calendar.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Callable
from dataclasses import dataclass
from datetime import UTC, datetime, timedelta

from sqlalchemy import func, select

from station.kernel.golden import GoldenCheck, GoldenUnit, golden_from_json
from station.store.db import Database
from station.store.models import GoldenCheckRecord, GoldenUnitRecord, LimitCheck, Run, RunUnit, Unit
from station.store.quality import ShiftCalendar


def save_golden(db: Database, golden: GoldenUnit) -> int:
    """Register ``golden`` as the serial's next version; returns the version."""
    body = json.dumps(golden.to_json(), sort_keys=True)
    with db.transaction() as s:
        last = s.scalar(select(func.max(GoldenUnitRecord.version)).where(GoldenUnitRecord.serial == golden.serial))
        version = int(last or 0) + 1
        when = datetime.fromisoformat(golden.registered_at) if golden.registered_at else datetime.now(UTC)
        s.add(GoldenUnitRecord(serial=golden.serial, version=version, registered_at=when, body=body,
                               sha256=hashlib.sha256(body.encode()).hexdigest()))
    return version


def golden_units(db: Database) -> dict[str, tuple[int, GoldenUnit]]:
    """Every registered golden unit's newest registration: serial -> (version, unit)."""
    out: dict[str, tuple[int, GoldenUnit]] = {}
    with db.transaction() as s:
        for row in s.scalars(select(GoldenUnitRecord).order_by(GoldenUnitRecord.serial, GoldenUnitRecord.version)):
            out[row.serial] = (row.version, golden_from_json(json.loads(row.body)))
    return out


def unit_runs(db: Database, serial: str, run_uids: tuple[str, ...] = (), lot: str | None = None
              ) -> list[dict[str, tuple[float, str, float | None, float | None]]]:
    """Per tested run of unit ``serial`` (oldest first): product parameter -> (value, unit, low, high)."""
    q = (select(RunUnit.id, LimitCheck.name, LimitCheck.value, LimitCheck.unit, LimitCheck.low, LimitCheck.high)
         .join(LimitCheck, LimitCheck.run_unit_id == RunUnit.id).join(Run, RunUnit.run_id == Run.id)
         .join(Unit, RunUnit.unit_id == Unit.id)
         .where(Unit.serial == serial, LimitCheck.step == "limits", RunUnit.outcome.in_(("PASS", "FAIL", "RETEST")))
         .order_by(Run.started_at, Run.id, LimitCheck.id))
    if run_uids:
        q = q.where(Run.run_uid.in_(run_uids))
    if lot is not None:
        q = q.where(Run.lot == lot)
    runs: dict[int, dict[str, tuple[float, str, float | None, float | None]]] = {}
    with db.transaction() as s:
        for ru_id, name, value, unit, low, high in s.execute(q):
            if value is None or name.startswith("fit."):
                continue
            runs.setdefault(int(ru_id), {})[str(name)] = (float(value), str(unit or ""), low, high)
    return list(runs.values())


def record_golden_check(db: Database, check: GoldenCheck, *, station: str, version: int, run_uid: str | None,
                        slot: int | None, checked_at: datetime | None = None) -> None:
    """Store one golden check (linked to the run's unit row when the run was recorded)."""
    body = json.dumps([{"parameter": d.parameter, "unit": d.unit, "measured": d.measured, "deviation": d.deviation,
                        "allowed": d.allowed, "passed": d.passed} for d in check.deviations])
    with db.transaction() as s:
        ru_id = None
        if run_uid is not None and slot is not None:
            ru_id = s.scalar(select(RunUnit.id).join(Run).where(Run.run_uid == run_uid, RunUnit.slot == slot))
        s.add(GoldenCheckRecord(run_unit_id=ru_id, serial=check.serial, station=station, golden_version=version,
                                checked_at=checked_at or datetime.now(UTC), passed=check.passed, body=body))


@dataclass(frozen=True)
class GoldenCheckRow:
    """A stored golden check: when, which unit and registration, passed, and the deviation per parameter."""

    serial: str
    station: str
    version: int
    checked_at: datetime
    passed: bool
    deviations: dict[str, float | None]
    allowed: dict[str, float]


def golden_checks(db: Database, *, serial: str | None = None, station: str | None = None) -> list[GoldenCheckRow]:
    """Stored golden checks, oldest first (of one unit and/or one station when given)."""
    q = select(GoldenCheckRecord).order_by(GoldenCheckRecord.checked_at, GoldenCheckRecord.id)
    if serial is not None:
        q = q.where(GoldenCheckRecord.serial == serial)
    if station is not None:
        q = q.where(GoldenCheckRecord.station == station)
    out = []
    with db.transaction() as s:
        for r in s.scalars(q):
            body = json.loads(r.body)
            when = r.checked_at if r.checked_at.tzinfo else r.checked_at.replace(tzinfo=UTC)
            out.append(GoldenCheckRow(r.serial, r.station, r.golden_version, when, r.passed,
                                      {d["parameter"]: d["deviation"] for d in body},
                                      {d["parameter"]: d["allowed"] for d in body}))
    return out


def shift_start(now: datetime, calendar: ShiftCalendar) -> datetime:
    """The start (UTC) of the shift that ``now`` falls in."""
    now = now.astimezone(UTC)
    minute = now.hour * 60 + now.minute
    starts = [m for _, m in calendar.shifts]
    today = now.replace(hour=0, minute=0, second=0, microsecond=0)
    past = [m for m in starts if m <= minute]
    if past:
        return today + timedelta(minutes=max(past))
    return today - timedelta(days=1) + timedelta(minutes=starts[-1])  # the night shift from yesterday


def golden_gate(db: Database, station: str, calendar: ShiftCalendar,
                inner: Callable[[str, str], str | None] | None = None,
                now: Callable[[], datetime] = lambda: datetime.now(UTC)) -> Callable[[str, str], str | None]:
    """The admit hook of a station that must run a golden unit at every shift start (see the module)."""

    def admit(serial: str, run_id: str) -> str | None:
        goldens = golden_units(db)
        if serial in goldens:
            return None
        if not goldens:
            return "no golden unit is registered: register one (station golden register) before production"
        checks = golden_checks(db, station=station)
        start = shift_start(now(), calendar)
        names = ", ".join(sorted(goldens))
        if not checks or checks[-1].checked_at < start:
            return (f"no golden-unit run on station {station} in this shift (since {start:%H:%M} UTC): "
                    f"run a golden unit ({names}) first")
        last = checks[-1]
        if not last.passed:
            return (f"golden unit {last.serial} failed its check at {last.checked_at:%H:%M} UTC: production is "
                    "stopped until a golden run passes")
        return inner(serial, run_id) if inner is not None else None

    return admit


__all__ = ["GoldenCheckRow", "golden_checks", "golden_gate", "golden_units", "record_golden_check", "save_golden",
           "shift_start", "unit_runs"]
