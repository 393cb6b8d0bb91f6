"""Store queries the web pages and the JSON API need beyond :mod:`station.store.queries`.

Runs (newest first, filtered), units with their latest result (filtered by date,
outcome and station), a unit's limit checks of its latest finished run, and the
population of limit-checked values over all units. Every function opens its own read
transaction and returns typed results (the JSON API's models, :mod:`station.web.models`).
Values are SI as stored (see the ``unit`` field).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from datetime import UTC, date, datetime, time
from typing import Any

from sqlalchemy import select

from station.store.db import Database
from station.store.models import UNFINISHED, LimitCheck, Run, RunUnit, Unit
from station.store.models import Station as StationRow
from station.web.models import LimitCheckResult, RunSummary, RunUnitOutcome, UnitOverview


def _iso(t: datetime | None) -> str | None:
    if t is None:
        return None
    return (t if t.tzinfo is not None else t.replace(tzinfo=UTC)).isoformat()


def list_runs(db: Database, *, limit: int = 50, station: str | None = None, outcome: str | None = None,
              ) -> list[RunSummary]:
    """The newest ``limit`` runs with every slot's unit and outcome."""
    with db.transaction() as s:
        q = select(Run, StationRow.name).join(StationRow, Run.station_id == StationRow.id)
        if station:
            q = q.where(StationRow.name == station)
        if outcome:
            q = q.where(Run.outcome == outcome)
        out = []
        for run, station_name in s.execute(q.order_by(Run.started_at.desc(), Run.id.desc()).limit(limit)).all():
            units = [RunUnitOutcome(slot=ru.slot, serial=ru.unit.serial if ru.unit else "", outcome=ru.outcome,
                                    message=ru.message) for ru in run.units]
            out.append(RunSummary(run_id=run.run_uid, station=station_name, outcome=run.outcome,
                                  started_at=_iso(run.started_at), finished_at=_iso(run.finished_at),
                                  duration_s=run.duration_s, wall_s=run.wall_s, message=run.message,
                                  operator=run.operator, units=units))
    return out


def list_unit_results(
    db: Database, *, day_from: date | None = None, day_to: date | None = None, outcome: str | None = None,
    station: str | None = None,
) -> list[UnitOverview]:
    """Units with their latest result among the runs matching the filters.

    ``day_from``/``day_to``: inclusive UTC dates of the run start; ``outcome``: the unit's outcome in that run;
    ``station``: the station name.
    """
    with db.transaction() as s:
        q = (select(Unit.serial, RunUnit.outcome, Run.run_uid, Run.started_at, StationRow.name)
             .join(RunUnit, RunUnit.unit_id == Unit.id).join(Run, RunUnit.run_id == Run.id)
             .join(StationRow, Run.station_id == StationRow.id))
        if day_from is not None:
            q = q.where(Run.started_at >= datetime.combine(day_from, time(0), UTC))
        if day_to is not None:  # the end of that day (the last representable day has no next day)
            end = datetime.combine(day_to, time.max, UTC)
            q = q.where(Run.started_at <= end)
        if station:
            q = q.where(StationRow.name == station)
        rows = s.execute(q.order_by(Unit.serial, Run.started_at.desc(), Run.id.desc())).all()
    latest: dict[str, tuple[Any, ...]] = {}
    runs: dict[str, int] = {}
    for row in rows:  # newest run of each unit first
        latest.setdefault(row[0], row)
        runs[row[0]] = runs.get(row[0], 0) + 1
    result = [UnitOverview(serial=serial, runs=runs[serial], last_outcome=unit_outcome, last_run_id=run_uid,
                           last_started_at=_iso(started), station=station_name)
              for serial, unit_outcome, run_uid, started, station_name in latest.values()]
    return [r for r in result if r.last_outcome == outcome] if outcome else result


def _num(x: float | None) -> float | None:
    return None if x is None or not math.isfinite(x) else float(x)


def latest_checks(db: Database, serial: str) -> list[LimitCheckResult]:
    """The limit checks (step ``'limits'``) of the unit's newest finished run with any."""
    with db.transaction() as s:
        ru_id = s.scalar(
            select(RunUnit.id).join(Run, RunUnit.run_id == Run.id).join(Unit, RunUnit.unit_id == Unit.id)
            .join(LimitCheck, LimitCheck.run_unit_id == RunUnit.id)
            .where(Unit.serial == serial, Run.outcome != UNFINISHED, LimitCheck.step == "limits")
            .order_by(Run.started_at.desc(), Run.id.desc()).limit(1)
        )
        if ru_id is None:
            return []
        checks = s.scalars(select(LimitCheck).where(LimitCheck.run_unit_id == ru_id, LimitCheck.step == "limits")
                           .order_by(LimitCheck.id)).all()
        return [LimitCheckResult(name=c.name, value=_num(c.value), std=_num(c.std), low=_num(c.low),
                                 high=_num(c.high), unit=c.unit, passed=c.passed, verdict=c.verdict, k=c.k)
                for c in checks]


def shown_marginal(c: LimitCheckResult, fraction: float) -> bool:
    """Whether the page flags a check MARGINAL: its recorded verdict; for older rows, :func:`is_marginal`."""
    if c.verdict is not None:
        return c.verdict == "MARGINAL"
    return c.passed and is_marginal(c.value, c.low, c.high, fraction)


def is_marginal(value: float | None, low: float | None, high: float | None, fraction: float) -> bool:
    """True if ``value`` is inside [low, high] but within ``fraction`` of the range width of an edge."""
    if value is None or low is None or high is None or not high > low:
        return False
    band = fraction * (high - low)
    return low <= value <= high and (value < low + band or value > high - band)


@dataclass(frozen=True)
class PopulationParameter:
    """One limit-checked parameter over all units: values (unit), their limits (unit)."""

    name: str
    unit: str
    values: tuple[float, ...]
    low: float | None
    high: float | None


def population(db: Database, *, station: str | None = None, name: str | None = None) -> list[PopulationParameter]:
    """Every limit-checked parameter (or only ``name``) of every unit's newest finished run, by name."""
    with db.transaction() as s:
        q = (select(RunUnit.id, RunUnit.unit_id).join(Run, RunUnit.run_id == Run.id)
             .join(StationRow, Run.station_id == StationRow.id)
             .where(Run.outcome != UNFINISHED, RunUnit.unit_id.is_not(None)))
        if station:
            q = q.where(StationRow.name == station)
        latest: dict[int, int] = {}
        for ru_id, unit_id in s.execute(q.order_by(Run.started_at.desc(), Run.id.desc())).all():
            latest.setdefault(unit_id, ru_id)
        if not latest:
            return []
        q2 = select(LimitCheck).where(LimitCheck.run_unit_id.in_(list(latest.values())), LimitCheck.step == "limits")
        if name is not None:
            q2 = q2.where(LimitCheck.name == name)
        checks = s.scalars(q2.order_by(LimitCheck.id)).all()
        by_name: dict[str, list[Any]] = {}
        for c in checks:
            by_name.setdefault(c.name, []).append(c)
    out = []
    for name, cs in by_name.items():
        vals = tuple(float(c.value) for c in cs if c.value is not None and math.isfinite(c.value))
        out.append(PopulationParameter(name, cs[0].unit, vals, _num(cs[0].low), _num(cs[0].high)))
    return out
