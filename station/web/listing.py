"""Store queries the web pages and the JSON API need beyond :mod:`station.store.queries`.

Runs (newest first, filtered), units with their latest result (filtered by date,
outcome and station), a unit's limit checks of its latest finished run, and the
population of limit-checked values over all units. Every function opens its own read
transaction and returns typed results (the JSON API's models, :mod:`station.web.models`).
Values are SI as stored (see the ``unit`` field).
"""

from __future__ import annotations

import base64
import math
from dataclasses import dataclass
from datetime import UTC, date, datetime, time
from typing import Any

from fastapi import Request, Response
from sqlalchemy import and_, func, or_, select

from station.store.db import Database
from station.store.models import UNFINISHED, LimitCheck, Run, RunUnit, Unit
from station.store.models import Station as StationRow
from station.store.queries import latest_dispositions
from station.web.models import LimitCheckResult, RunSummary, RunUnitOutcome, UnitOverview


def _iso(t: datetime | None) -> str | None:
    if t is None:
        return None
    return (t.replace(tzinfo=UTC) if t.tzinfo is None else t.astimezone(UTC)).isoformat()


class CursorError(ValueError):
    """A pagination cursor this listing did not hand out."""


def _encode(text: str) -> str:
    return base64.urlsafe_b64encode(text.encode("utf-8")).decode("ascii").rstrip("=")


def _decode(cursor: str, kind: str) -> str:
    """The text of a cursor this listing (``kind``: 'units' or 'runs') handed out."""
    try:
        text = base64.b64decode(cursor + "=" * (-len(cursor) % 4), altchars=b"-_", validate=True).decode("utf-8")
    except (ValueError, UnicodeDecodeError):
        text = ""
    head, sep, rest = text.partition("|")
    if head != kind or not sep:
        raise CursorError("not a cursor of this listing")
    return rest


def list_runs(db: Database, *, limit: int = 50, station: str | None = None, outcome: str | None = None,
              cursor: str | None = None) -> tuple[list[RunSummary], str | None]:
    """The newest ``limit`` runs (after ``cursor``) with every slot's unit and outcome, and the next page's cursor
    (None: no more). The cursor is opaque: the start time and id of the page's last run."""
    with db.transaction() as s:
        q = select(Run, StationRow.name).join(StationRow, Run.station_id == StationRow.id)
        if station:
            q = q.where(StationRow.name == station)
        if outcome:
            q = q.where(Run.outcome == outcome)
        if cursor:
            at, _, pk = _decode(cursor, "runs").rpartition("|")
            try:
                t, run_pk = datetime.fromisoformat(at), int(pk)
            except ValueError:
                raise CursorError("not a cursor of this listing") from None
            t = t.astimezone(UTC) if s.get_bind().dialect.name == "postgresql" else t.replace(tzinfo=None)
            q = q.where(or_(Run.started_at < t, and_(Run.started_at == t, Run.id < run_pk)))
        rows = s.execute(q.order_by(Run.started_at.desc(), Run.id.desc()).limit(limit + 1)).all()
        more = len(rows) > limit
        rows = rows[:limit]
        out = []
        for run, station_name in rows:
            units = [RunUnitOutcome(slot=ru.slot, serial=ru.unit.serial if ru.unit else "", outcome=ru.outcome,
                                    message=ru.message) for ru in run.units]
            out.append(RunSummary(run_id=run.run_uid, station=station_name, outcome=run.outcome,
                                  started_at=_iso(run.started_at), finished_at=_iso(run.finished_at),
                                  duration_s=run.duration_s, wall_s=run.wall_s, message=run.message,
                                  operator=run.operator, units=units))
        nxt = None
        if more and rows:
            last = rows[-1][0]
            nxt = _encode(f"runs|{_iso(last.started_at)}|{last.id}")
    return out, nxt


PAGED: dict[int | str, dict[str, Any]] = {
    200: {"headers": {"X-Next-Cursor": {"description": "cursor of the next page (absent on the last page)",
                                        "schema": {"type": "string"}},
                      "Link": {"description": "<URL of the next page>; rel=\"next\" (absent on the last page)",
                               "schema": {"type": "string"}}}},
}
"""OpenAPI ``responses`` of a paged listing."""


def next_page(request: Request, response: Response, cursor: str | None) -> None:
    """Set the ``X-Next-Cursor`` and ``Link: <...>; rel="next"`` headers of a page (none on the last page)."""
    if cursor is None:
        return
    response.headers["X-Next-Cursor"] = cursor
    response.headers["Link"] = f'<{request.url.include_query_params(cursor=cursor)}>; rel="next"'


def _like(text: str) -> str:
    return "%" + text.replace("\\", "\\\\").replace("%", "\\%").replace("_", "\\_") + "%"


def list_unit_results(
    db: Database, *, day_from: date | None = None, day_to: date | None = None, outcome: str | None = None,
    station: str | None = None, search: str | None = None, limit: int | None = None, cursor: str | None = None,
) -> tuple[list[UnitOverview], str | None]:
    """Units by serial with their latest result among the runs matching the filters, and the next page's cursor.

    ``day_from``/``day_to``: inclusive UTC dates of the run start; ``outcome``: the unit's outcome in that run;
    ``station``: the station name; ``search``: part of the serial (case-insensitive); ``limit``: units per page
    (None: all); ``cursor``: from the previous page (opaque: its last serial).
    """
    conds: list[Any] = []
    if day_from is not None:
        conds.append(Run.started_at >= datetime.combine(day_from, time(0), UTC))
    if day_to is not None:  # the end of that day (the last representable day has no next day)
        conds.append(Run.started_at <= datetime.combine(day_to, time.max, UTC))
    unit_conds: list[Any] = []
    if search:
        unit_conds.append(Unit.serial.ilike(_like(search), escape="\\"))
    if cursor:
        unit_conds.append(Unit.serial > _decode(cursor, "units"))
    with db.transaction() as s:
        if station:
            sid = s.scalar(select(StationRow.id).where(StationRow.name == station))
            conds.append(Run.station_id == (sid if sid is not None else -1))
        take = None if limit is None else limit + 1
        if outcome is None:  # page the units first, then their results
            matching = select(RunUnit.id).join(Run, RunUnit.run_id == Run.id).where(RunUnit.unit_id == Unit.id,
                                                                                    *conds)
            uq = select(Unit.id, Unit.serial).where(*unit_conds, matching.exists()).order_by(Unit.serial)
            page = s.execute(uq.limit(take) if take else uq).all()
            ids = [u[0] for u in page]
            rows: list[Any] = []
            for i in range(0, len(ids), 500):
                rows += s.execute(
                    select(RunUnit.unit_id, RunUnit.outcome, Run.run_uid, Run.started_at, Run.station_id)
                    .join(Run, RunUnit.run_id == Run.id).where(RunUnit.unit_id.in_(ids[i:i + 500]), *conds)
                    .order_by(RunUnit.unit_id, Run.started_at.desc(), Run.id.desc())).all()
            serial_of = dict(page)
            latest: dict[int, Any] = {}
            runs: dict[int, int] = {}
            for row in rows:
                latest.setdefault(row[0], row)
                runs[row[0]] = runs.get(row[0], 0) + 1
            found = [(serial_of[u], runs[u], *latest[u][1:]) for u in ids if u in latest]
        else:  # the outcome of the latest matching result: rank each unit's matching results in the database
            rn = func.row_number().over(partition_by=RunUnit.unit_id,
                                        order_by=(Run.started_at.desc(), Run.id.desc())).label("rn")
            n = func.count().over(partition_by=RunUnit.unit_id).label("n")
            inner = (select(Unit.serial, RunUnit.outcome, Run.run_uid, Run.started_at, Run.station_id, rn, n)
                     .join(RunUnit, RunUnit.unit_id == Unit.id).join(Run, RunUnit.run_id == Run.id)
                     .where(*conds, *unit_conds).subquery())
            oq = (select(inner.c.serial, inner.c.n, inner.c.outcome, inner.c.run_uid, inner.c.started_at,
                         inner.c.station_id).where(inner.c.rn == 1, inner.c.outcome == outcome)
                  .order_by(inner.c.serial))
            found = [tuple(r) for r in s.execute(oq.limit(take) if take else oq).all()]
        names = {int(i): str(nm) for i, nm in s.execute(select(StationRow.id, StationRow.name))}
    more = limit is not None and len(found) > limit
    found = found[:limit] if limit is not None else found
    dispositions = latest_dispositions(db, [str(f[0]) for f in found])
    result = [UnitOverview(serial=serial, runs=int(nruns), last_outcome=unit_outcome, last_run_id=run_uid,
                           last_started_at=_iso(started), station=names.get(st, ""),
                           disposition=dispositions.get(serial))
              for serial, nruns, unit_outcome, run_uid, started, st in found]
    return result, (_encode(f"units|{result[-1].serial}") if more and result else None)


def _num(x: float | None) -> float | None:
    return None if x is None or not math.isfinite(x) else float(x)


def latest_checks(db: Database, serial: str) -> list[LimitCheckResult]:
    """The limit checks (step ``'limits'``) of the unit's newest finished run with any."""
    return latest_checks_of_run(db, serial)[1]


def latest_checks_of_run(db: Database, serial: str) -> tuple[str | None, list[LimitCheckResult]]:
    """The run id and the limit checks (step ``'limits'``) of the unit's newest finished run with any."""
    with db.transaction() as s:
        found = s.execute(
            select(RunUnit.id, Run.run_uid).join(Run, RunUnit.run_id == Run.id).join(Unit, RunUnit.unit_id == Unit.id)
            .join(LimitCheck, LimitCheck.run_unit_id == RunUnit.id)
            .where(Unit.serial == serial, Run.outcome != UNFINISHED, LimitCheck.step == "limits")
            .order_by(Run.started_at.desc(), Run.id.desc()).limit(1)
        ).first()
        if found is None:
            return None, []
        ru_id, run_uid = found
        checks = s.scalars(select(LimitCheck).where(LimitCheck.run_unit_id == ru_id, LimitCheck.step == "limits")
                           .order_by(LimitCheck.id)).all()
        return run_uid, [LimitCheckResult(name=c.name, value=_num(c.value), std=_num(c.std), low=_num(c.low),
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
            if unit_id is not None:  # the query keeps units only; the column allows NULL
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
