"""Keep the quality tables (:class:`~station.store.models.QualityResult`, ``QualityValue``, ``QualityDaily``)
in step with the records: :func:`index_run` in the transaction that records a run's end, :func:`rebuild`
from all records (migration 0003, and after a bulk load).

What is counted (the definitions the quality page and the README state):

- a *result* is one unit (a fixture slot with a serial) in one run that ended (run outcome not UNFINISHED);
- a result is *tested* when the run reached a verdict on the unit: PASS, FAIL or RETEST. ERROR (station
  fault), ABORTED (stopped by the operator or a signal), REFUSED (retest policy) and UNFINISHED results are
  kept as *not tested*: they neither count as a unit tested nor use up its first pass;
- ``attempt`` numbers a unit's tested results in time order (1 = its first pass); 0 when not tested;
- ``final_outcome`` is the outcome of the unit's newest tested result;
- the values of tested results only enter the parameter statistics (the product-limit checks, step 'limits').
"""

from __future__ import annotations

from datetime import UTC, datetime
from typing import Any

from sqlalchemy import Connection, func, select, text, update
from sqlalchemy.dialects import postgresql, sqlite
from sqlalchemy.exc import IntegrityError
from sqlalchemy.orm import Session

from station.store.models import (
    LimitCheck,
    QualityDaily,
    QualityParameter,
    QualityResult,
    QualityValue,
    QualityYield,
    Run,
    RunUnit,
)

TESTED = ("PASS", "FAIL", "RETEST")
"""Unit outcomes that mean the station reached a verdict on the unit."""


def _utc(t: datetime) -> datetime:
    return t.replace(tzinfo=UTC) if t.tzinfo is None else t.astimezone(UTC)


def _param(s: Session, cache: dict[str, QualityParameter], name: str, unit: str, low: float | None,
           high: float | None, value: float) -> QualityParameter:
    p = cache.get(name)
    if p is None:
        p = s.scalar(select(QualityParameter).where(QualityParameter.name == name))
        if p is None:
            ref = (low + high) / 2.0 if low is not None and high is not None else value
            try:
                with s.begin_nested():  # another station may add it at the same moment
                    p = QualityParameter(name=name, unit=unit, ref=ref)
                    s.add(p)
            except IntegrityError:
                p = s.scalars(select(QualityParameter).where(QualityParameter.name == name)).one()
        cache[name] = p
    return p


def index_run(s: Session, run_pk: int) -> int:
    """Add the results of the ended run ``run_pk`` (and their values) to the quality tables; returns how many.

    Called in the transaction that records the run's end (or its recovery), so the quality tables never show
    a run the records do not. A result already indexed is left alone.
    """
    run = s.get(Run, run_pk)
    if run is None or run.outcome == "UNFINISHED":
        return 0
    started = _utc(run.started_at)
    day, minute = started.strftime("%Y-%m-%d"), started.hour * 60 + started.minute
    done = set(s.scalars(select(QualityResult.run_unit_id).join(RunUnit, QualityResult.run_unit_id == RunUnit.id)
                         .where(RunUnit.run_id == run_pk)))
    sums: dict[int, list[Any]] = {}
    cache: dict[str, QualityParameter] = {}
    added = 0
    lot, lv = run.lot or "", run.limits_version
    # yield counts per bucket (day, quarter, station, lot, limits version): results, not tested, tested,
    # first tested, first pass, final pass, retests
    counts: dict[tuple[str, int, int, str, str], list[int]] = {}
    here = (day, minute // 15, run.station_id, lot, lv)
    for ru in s.scalars(select(RunUnit).where(RunUnit.run_id == run_pk).order_by(RunUnit.slot)):
        if ru.unit_id is None or ru.id in done:
            continue
        tested = ru.outcome in TESTED
        s.execute(update(QualityResult).where(QualityResult.unit_id == ru.unit_id, QualityResult.latest)
                  .values(latest=False))
        c = counts.setdefault(here, [0] * 7)
        c[0] += 1
        if tested:
            prior = s.scalar(select(func.count()).select_from(QualityResult)
                             .where(QualityResult.unit_id == ru.unit_id, QualityResult.tested)) or 0
            attempt, final = prior + 1, ru.outcome
            c[2] += 1
            if attempt == 1:
                c[3] += 1
                c[4] += int(final == "PASS")
                c[5] += int(final == "PASS")
            else:
                c[6] += 1
                first = s.execute(select(QualityResult.day, QualityResult.minute, QualityResult.station_id,
                                         QualityResult.lot, QualityResult.limits_version, QualityResult.final_outcome)
                                  .where(QualityResult.unit_id == ru.unit_id, QualityResult.attempt == 1)).first()
                if first is not None:  # the unit's final pass is counted where it was first tested
                    key = (first[0], first[1] // 15, first[2], first[3], first[4])
                    counts.setdefault(key, [0] * 7)[5] += int(final == "PASS") - int(first[5] == "PASS")
            s.execute(update(QualityResult).where(QualityResult.unit_id == ru.unit_id).values(final_outcome=final))
        else:
            c[1] += 1
            attempt = 0
            final = s.scalar(select(QualityResult.final_outcome).where(QualityResult.unit_id == ru.unit_id)
                             .limit(1)) or ""
        row = QualityResult(run_unit_id=ru.id, unit_id=ru.unit_id, station_id=run.station_id, lot=run.lot or "",
                            limits_version=run.limits_version, started_at=started, day=day, minute=minute,
                            outcome=ru.outcome, tested=tested, attempt=attempt, final_outcome=final, latest=True)
        s.add(row)
        s.flush()
        added += 1
        if not tested:
            continue
        seen: set[str] = set()
        for check in s.scalars(select(LimitCheck).where(LimitCheck.run_unit_id == ru.id, LimitCheck.step == "limits",
                                                    LimitCheck.value.is_not(None)).order_by(LimitCheck.id)):
            if check.name in seen or check.value is None:
                continue
            seen.add(check.name)
            p = _param(s, cache, check.name, check.unit, check.low, check.high, check.value)
            s.add(QualityValue(result_id=row.id, param_id=p.id, day=day, value=check.value))
            d = check.value - p.ref
            acc = sums.setdefault(p.id, [0, 0.0, 0.0, check.value, check.value, check.low, check.high, 0, 0])
            acc[0] += 1
            acc[1] += d
            acc[2] += d * d
            acc[3], acc[4] = min(acc[3], check.value), max(acc[4], check.value)
            acc[7] += int(check.low is not None and check.value < check.low)
            acc[8] += int(check.high is not None and check.value > check.high)
    if counts:
        _upsert_yield(s, [dict(day=k[0], quarter=k[1], station_id=k[2], lot=k[3], limits_version=k[4], results=v[0],
                               not_tested=v[1], tested=v[2], first_tested=v[3], first_pass=v[4], final_pass=v[5],
                               retests=v[6]) for k, v in counts.items()])
    if sums:
        _upsert_daily(s, [dict(param_id=pid, day=day, station_id=run.station_id, lot=run.lot or "",
                               limits_version=run.limits_version, n=a[0], s1=a[1], s2=a[2], vmin=a[3], vmax=a[4],
                               low=a[5], high=a[6], n_below=a[7], n_above=a[8]) for pid, a in sums.items()])
    return added


def _upsert_daily(s: Session, rows: list[dict[str, Any]]) -> None:
    dialect = s.get_bind().dialect.name
    ins: Any = (postgresql.insert if dialect == "postgresql" else sqlite.insert)(QualityDaily)
    least, greatest = (func.least, func.greatest) if dialect == "postgresql" else (func.min, func.max)
    t = QualityDaily.__table__
    stmt = ins.values(rows).on_conflict_do_update(
        index_elements=["param_id", "day", "station_id", "lot", "limits_version"],
        set_={"n": t.c.n + ins.excluded.n, "s1": t.c.s1 + ins.excluded.s1, "s2": t.c.s2 + ins.excluded.s2,
              "vmin": least(t.c.vmin, ins.excluded.vmin), "vmax": greatest(t.c.vmax, ins.excluded.vmax),
              "low": ins.excluded.low, "high": ins.excluded.high,
              "n_below": t.c.n_below + ins.excluded.n_below, "n_above": t.c.n_above + ins.excluded.n_above})
    s.execute(stmt)


YIELD_COUNTS = ("results", "not_tested", "tested", "first_tested", "first_pass", "final_pass", "retests")


def _upsert_yield(s: Session, rows: list[dict[str, Any]]) -> None:
    dialect = s.get_bind().dialect.name
    ins: Any = (postgresql.insert if dialect == "postgresql" else sqlite.insert)(QualityYield)
    t = QualityYield.__table__
    rows = sorted(rows, key=lambda r: (r["day"], r["quarter"], r["station_id"], r["lot"], r["limits_version"]))
    s.execute(ins.values(rows).on_conflict_do_update(  # sorted: stations lock shared rows in one order
        index_elements=["day", "quarter", "station_id", "lot", "limits_version"],
        set_={k: t.c[k] + ins.excluded[k] for k in YIELD_COUNTS}))


def _day_minute(dialect: str) -> tuple[str, str]:
    if dialect == "postgresql":
        utc = "(r.started_at AT TIME ZONE 'UTC')"
        return (f"to_char({utc}, 'YYYY-MM-DD')",
                f"CAST(EXTRACT(HOUR FROM {utc}) * 60 + EXTRACT(MINUTE FROM {utc}) AS INTEGER)")
    # SQLAlchemy stores a SQLite DateTime as 'YYYY-MM-DD HH:MM:SS[.ffffff]' (the station writes UTC)
    return ("substr(r.started_at, 1, 10)",
            "CAST(substr(r.started_at, 12, 2) AS INTEGER) * 60 + CAST(substr(r.started_at, 15, 2) AS INTEGER)")


def rebuild(conn: Connection) -> None:
    """Recompute every quality table from the records with SQL (INSERT ... SELECT; window functions)."""
    dialect = conn.dialect.name
    day, minute = _day_minute(dialect)
    tested = "ru.outcome IN ('PASS', 'FAIL', 'RETEST')"
    for table in ("quality_yield", "quality_daily", "quality_values", "quality_results", "quality_parameters"):
        conn.execute(text(f"DELETE FROM {table}"))
    conn.execute(text(
        "INSERT INTO quality_parameters (name, unit, ref) "
        "SELECT name, MAX(unit), AVG(value) FROM limit_checks WHERE step = 'limits' AND value IS NOT NULL "
        "GROUP BY name"))
    conn.execute(text(
        "INSERT INTO quality_results (run_unit_id, unit_id, station_id, lot, limits_version, started_at, day, "
        "minute, outcome, tested, attempt, final_outcome, latest) "
        f"SELECT ru.id, ru.unit_id, r.station_id, r.lot, r.limits_version, r.started_at, {day}, {minute}, "
        f"ru.outcome, CASE WHEN {tested} THEN TRUE ELSE FALSE END, "
        f"CASE WHEN {tested} THEN ROW_NUMBER() OVER (PARTITION BY ru.unit_id, CASE WHEN {tested} THEN 1 ELSE 0 END "
        "ORDER BY r.started_at, r.id) ELSE 0 END, '', "
        "CASE WHEN ROW_NUMBER() OVER (PARTITION BY ru.unit_id ORDER BY r.started_at DESC, r.id DESC) = 1 "
        "THEN TRUE ELSE FALSE END "
        "FROM run_units ru JOIN runs r ON ru.run_id = r.id "
        "WHERE ru.unit_id IS NOT NULL AND r.outcome <> 'UNFINISHED'"))
    conn.execute(text(
        "UPDATE quality_results SET final_outcome = COALESCE((SELECT q2.outcome FROM quality_results q2 "
        "WHERE q2.unit_id = quality_results.unit_id AND q2.tested ORDER BY q2.attempt DESC LIMIT 1), '')"))
    conn.execute(text(
        "INSERT INTO quality_yield (day, quarter, station_id, lot, limits_version, results, not_tested, tested, "
        "first_tested, first_pass, final_pass, retests) "
        "SELECT day, minute / 15, station_id, lot, limits_version, COUNT(*), "
        "SUM(CASE WHEN tested THEN 0 ELSE 1 END), SUM(CASE WHEN tested THEN 1 ELSE 0 END), "
        "SUM(CASE WHEN attempt = 1 THEN 1 ELSE 0 END), "
        "SUM(CASE WHEN attempt = 1 AND outcome = 'PASS' THEN 1 ELSE 0 END), "
        "SUM(CASE WHEN attempt = 1 AND final_outcome = 'PASS' THEN 1 ELSE 0 END), "
        "SUM(CASE WHEN attempt > 1 THEN 1 ELSE 0 END) "
        "FROM quality_results GROUP BY day, minute / 15, station_id, lot, limits_version"))
    conn.execute(text(
        "INSERT INTO quality_values (result_id, param_id, day, value) "
        "SELECT q.id, p.id, q.day, c.value FROM limit_checks c "
        "JOIN quality_results q ON q.run_unit_id = c.run_unit_id "
        "JOIN quality_parameters p ON p.name = c.name "
        "WHERE c.step = 'limits' AND c.value IS NOT NULL AND q.tested "
        "ON CONFLICT DO NOTHING"))  # a name checked twice in one result (never written so): the first value
    conn.execute(text(
        "INSERT INTO quality_daily (param_id, day, station_id, lot, limits_version, n, s1, s2, vmin, vmax, low, "
        "high, n_below, n_above) "
        "SELECT p.id, q.day, q.station_id, q.lot, q.limits_version, COUNT(*), SUM(c.value - p.ref), "
        "SUM((c.value - p.ref) * (c.value - p.ref)), MIN(c.value), MAX(c.value), MIN(c.low), MAX(c.high), "
        "SUM(CASE WHEN c.low IS NOT NULL AND c.value < c.low THEN 1 ELSE 0 END), "
        "SUM(CASE WHEN c.high IS NOT NULL AND c.value > c.high THEN 1 ELSE 0 END) "
        "FROM limit_checks c JOIN quality_results q ON q.run_unit_id = c.run_unit_id "
        "JOIN quality_parameters p ON p.name = c.name "
        "WHERE c.step = 'limits' AND c.value IS NOT NULL AND q.tested "
        "GROUP BY p.id, q.day, q.station_id, q.lot, q.limits_version"))
    if dialect == "postgresql":
        for table in ("quality_results", "quality_values", "quality_daily", "quality_yield"):
            conn.execute(text(f"ANALYZE {table}"))
    else:
        conn.execute(text("ANALYZE"))


__all__ = ["TESTED", "index_run", "rebuild"]
