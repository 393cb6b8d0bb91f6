"""The station database on a real PostgreSQL server: migrations, and two stations writing at once.

The server is a throwaway cluster started here: ``initdb`` (from PATH or Debian's
``/usr/lib/postgresql/*/bin``; run as the ``postgres`` user when the tests run as root)
in a temporary directory, listening on 127.0.0.1 on a free port, stopped and deleted
afterwards. ``STATION_TEST_PG_URL`` (a ``postgresql+psycopg://`` URL of a server whose
user may create databases) uses an existing server instead. Without either the tests
are skipped with the reason. Debian packages: ``postgresql`` (server and initdb).
"""

from __future__ import annotations

import contextlib
import os
import threading
from collections.abc import Iterator
from pathlib import Path

import pytest
from alembic.autogenerate import compare_metadata
from alembic.runtime.migration import MigrationContext
from pgcluster import ClusterStartError, PostgresUnavailable, fresh_database, throwaway_cluster
from sqlalchemy import func, inspect, select

from station.kernel.measurement import Measurement
from station.sequence.records import (
    Measured,
    Outcome,
    Record,
    RunFinished,
    RunStarted,
    StepFinished,
    StepStarted,
    UnitFinished,
)
from station.store import Recorder, RunContext, attempt_count, list_units, open_database, recover_unfinished
from station.store.db import current_revision, downgrade, make_engine, upgrade
from station.store.models import UNFINISHED, Base, LimitCheck, Run, RunUnit, Station, StepTiming, Unit

pytestmark = pytest.mark.integration

TABLES = {
    "stations", "fixture_slots", "units", "runs", "run_units", "step_timings", "limit_checks",
    "parameter_sets", "session_recordings", "eeprom_writes", "dispositions", "rig_locks",
    "quality_parameters", "quality_results", "quality_values", "quality_daily", "quality_yield",
}
RUNS_PER_STATION = 100


@pytest.fixture(scope="module")
def pg_server() -> Iterator[str]:
    """A server URL (database 'postgres'); a throwaway cluster unless STATION_TEST_PG_URL is set."""
    url = os.environ.get("STATION_TEST_PG_URL")
    if url:
        yield url
        return
    with contextlib.ExitStack() as stack:
        try:
            url = stack.enter_context(throwaway_cluster(server_options="-c fsync=off -c max_connections=50"))
        except PostgresUnavailable as exc:
            pytest.skip(f"{exc} (or set STATION_TEST_PG_URL)")
        except ClusterStartError as exc:
            pytest.fail(str(exc))
        yield url


@pytest.fixture
def pg_url(pg_server: str) -> Iterator[str]:
    """A fresh, empty database on the server; dropped afterwards."""
    with fresh_database(pg_server) as url:
        yield url


def test_upgrade_from_empty_and_round_trip(pg_url: str) -> None:
    engine = make_engine(pg_url)
    assert engine.dialect.name == "postgresql"
    assert current_revision(engine) is None and inspect(engine).get_table_names() == []
    upgrade(engine)
    assert current_revision(engine) == "0007"
    assert set(inspect(engine).get_table_names()) == TABLES | {"alembic_version"}
    with engine.connect() as conn:
        assert compare_metadata(MigrationContext.configure(conn), Base.metadata) == []
    downgrade(engine, "base")
    assert current_revision(engine) is None
    assert set(inspect(engine).get_table_names()) <= {"alembic_version"}
    upgrade(engine)
    assert current_revision(engine) == "0007"
    assert set(inspect(engine).get_table_names()) == TABLES | {"alembic_version"}
    engine.dispose()


def _run_records(run_id: str, station: str, serial: str, outcome: Outcome) -> list[Record]:
    """A two-step, one-unit run with two gates and one limit check."""
    return [
        RunStarted(run_id, "2026-11-21T10:00:00+00:00", 0.0, station, "rig", ("pty0",), ("rest", "pose +z")),
        StepStarted(run_id, 0, "rest", "rest", 0.0, 60.0),
        Measured(run_id, 0, serial, "rest", Measurement("stillness", 0.001, "rad/s", 0.0, 0.01, True)),
        StepFinished(run_id, 0, "rest", 60.0, 60.0, True, 1),
        StepStarted(run_id, 1, "pose +z", "pose", 60.0, 30.0),
        Measured(run_id, 0, serial, "pose +z", Measurement("gravity_ratio", 1.001, "1", 0.95, 1.05, True)),
        StepFinished(run_id, 1, "pose +z", 95.0, 35.0, True, 1),
        Measured(run_id, 0, serial, "limits",
                 Measurement("gyro.bias_static.z", 1e-4, "rad/s", -1e-3, 1e-3, outcome == Outcome.PASS, float("nan"))),
        UnitFinished(run_id, 0, serial, outcome, "" if outcome == Outcome.PASS else "out of limits"),
        RunFinished(run_id, outcome, 95.0, 95.0, 0.01,
                    (UnitFinished(run_id, 0, serial, outcome, "" if outcome == Outcome.PASS else "out of limits"),)),
    ]


def test_two_stations_write_concurrently(pg_url: str) -> None:
    open_database(pg_url).close()  # migrate once, as the first station to start would
    serials = [f"SN{k:03d}" for k in range(20)]  # both stations see the same units: concurrent unit creation
    errors: list[BaseException] = []
    barrier = threading.Barrier(2)

    def station(name: str) -> None:
        try:
            with open_database(pg_url) as db:
                rec = Recorder(db, RunContext(operator=name))
                barrier.wait(timeout=60)
                for k in range(RUNS_PER_STATION):
                    outcome = Outcome.FAIL if k % 7 == 0 else Outcome.PASS
                    for r in _run_records(f"{name}-{k:03d}", name, serials[k % len(serials)], outcome):
                        rec(r)
        except BaseException as exc:
            errors.append(exc)
            barrier.abort()

    threads = [threading.Thread(target=station, args=(n,)) for n in ("station-a", "station-b")]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert errors == []
    with open_database(pg_url) as db, db.transaction() as s:
        uids = s.scalars(select(Run.run_uid)).all()
        assert len(uids) == len(set(uids)) == 2 * RUNS_PER_STATION
        expected = {f"station-{x}-{k:03d}" for x in "ab" for k in range(RUNS_PER_STATION)}
        assert set(uids) == expected
        per_station = dict(s.execute(select(Station.name, func.count(Run.id)).join(Run).group_by(Station.name)).all())
        assert per_station == {"station-a": RUNS_PER_STATION, "station-b": RUNS_PER_STATION}
        assert s.scalar(select(func.count(Run.id)).where(Run.outcome == UNFINISHED)) == 0
        n_fail = sum(1 for k in range(RUNS_PER_STATION) if k % 7 == 0)
        assert s.scalar(select(func.count(Run.id)).where(Run.outcome == "FAIL")) == 2 * n_fail
        assert s.scalar(select(func.count(RunUnit.id))) == 2 * RUNS_PER_STATION
        assert s.scalar(select(func.count(StepTiming.id))) == 2 * 2 * RUNS_PER_STATION
        assert s.scalar(select(func.count(LimitCheck.id))) == 3 * 2 * RUNS_PER_STATION
        assert s.scalar(select(func.count(LimitCheck.id)).where(LimitCheck.std.is_(None))) == 2 * 3 * RUNS_PER_STATION
        assert sorted(s.scalars(select(Unit.serial)).all()) == serials
        assert s.scalar(select(func.count(RunUnit.id)).where(RunUnit.unit_id.is_(None))) == 0
    with open_database(pg_url) as db:
        assert sum(u.runs for u in list_units(db)) == 2 * RUNS_PER_STATION
        # failed attempts of SN000: its runs (every len(serials)-th) that FAILed (every 7th), on both stations
        fails = sum(1 for k in range(0, RUNS_PER_STATION, len(serials)) if k % 7 == 0)
        assert fails > 0 and attempt_count(db, "SN000") == 2 * fails


def test_recovery_on_postgres(pg_url: str) -> None:
    with open_database(pg_url) as db:
        rec = Recorder(db)
        for r in _run_records("dead", "st", "SN1", Outcome.PASS)[:-1]:
            rec(r)
        with db.transaction() as s:
            assert s.scalars(select(Run.outcome)).one() == UNFINISHED
        assert recover_unfinished(db, "st") == ["dead"]
        with db.transaction() as s:
            assert s.scalars(select(Run.outcome)).one() == "ERROR"
            assert s.scalars(select(RunUnit.outcome)).one() == "ERROR"


def test_quality_statistics_agree_with_sqlite(pg_url: str, tmp_path: Path) -> None:
    """The same synthetic history on PostgreSQL and on SQLite: every yield table, capability, control chart and
    histogram computed by the two databases' SQL agrees (the day and minute of a run come from different SQL)."""
    from synthetic_history import DRIFTING, SHIFTED_LOT, fill

    from station.store.quality import QualityFilter, capabilities, control_charts, histogram, yield_tables

    pg = open_database(pg_url)
    lite = open_database(f"sqlite:///{tmp_path / 'q.sqlite'}")
    try:
        for db in (pg, lite):
            fill(db, 1500, seed=5, days=6)
        for f in (QualityFilter(), QualityFilter(lot=SHIFTED_LOT, station="EOL-2")):
            assert yield_tables(pg, f) == yield_tables(lite, f)
            a, b = capabilities(pg, f), capabilities(lite, f)
            assert [c.name for c in a] == [c.name for c in b] and a
            for x, y in zip(a, b, strict=True):
                assert (x.cap.n, x.n_below, x.n_above) == (y.cap.n, y.n_below, y.n_above)
                assert x.cap.cpk == pytest.approx(y.cap.cpk, rel=1e-9)
                assert x.cap.ppk == pytest.approx(y.cap.ppk, rel=1e-9)
            ca, cb = control_charts(pg, f), control_charts(lite, f)
            for x, y in zip(ca, cb, strict=True):
                assert [p.label for p in x.chart.points] == [p.label for p in y.chart.points]
                assert x.chart.violations == y.chart.violations
                assert x.chart.center == pytest.approx(y.chart.center, rel=1e-9)
            ha, hb = histogram(pg, DRIFTING, f), histogram(lite, DRIFTING, f)
            assert ha is not None and hb is not None and ha.counts == hb.counts
    finally:
        pg.close()
        lite.close()
