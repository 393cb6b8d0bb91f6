"""The station database on SQLite: migrations, the recorder, recovery, queries and the ``units`` commands.

Records are synthetic (built here) except in the last test, where a short simulated
sequence (one unit, real Modbus/TCP rig server and pty sensor on a fast clock) feeds
the recorder and the database must tell the same story as the runner's result.
"""

from __future__ import annotations

import json
import math
import re
from collections.abc import Iterator
from pathlib import Path

import pytest
import typer
from alembic.autogenerate import compare_metadata
from alembic.runtime.migration import MigrationContext
from sqlalchemy import func, inspect, select
from typer.testing import CliRunner

from station.commands.units import units_app
from station.compose import attach_recorder
from station.kernel.measurement import Measurement
from station.kernel.parameters import ParameterSet
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
from station.store import (
    Database,
    Recorder,
    RunContext,
    StoreError,
    attempt_count,
    latest_parameter_set,
    list_units,
    open_database,
    record_disposition,
    record_eeprom_write,
    recover_unfinished,
    show_unit,
)
from station.store.db import current_revision, downgrade, head_revision, make_engine, upgrade
from station.store.models import (
    UNFINISHED,
    Base,
    Disposition,
    LimitCheck,
    ParameterSetRecord,
    Run,
    RunUnit,
    SessionRecording,
    StepTiming,
    Unit,
)
from station.store.queries import retest_gate
from station.store.recorder import DispositionError, sha256_file

TABLES = {
    "stations", "fixture_slots", "units", "runs", "run_units", "step_timings", "limit_checks",
    "parameter_sets", "session_recordings", "eeprom_writes", "dispositions", "rig_locks",
    "quality_parameters", "quality_results", "quality_values", "quality_daily", "quality_yield",
    "nest_calibrations", "golden_units", "golden_checks", "rack_recordings",
}


def synthetic_run(
    run_id: str, serials: list[str], outcomes: list[Outcome], *, station: str = "st1", out_dir: Path | None = None,
    steps: int = 2,
) -> list[Record]:
    """The records of a run of ``len(serials)`` units: ``steps`` steps with a gate each, one limit check per unit."""
    sensors = tuple(f"pty{k}" for k in range(len(serials)))
    recs: list[Record] = [RunStarted(run_id, "2026-11-21T10:00:00+00:00", 0.0, station, "sim-rig", sensors,
                                     tuple(f"s{i}" for i in range(steps)))]
    t = 0.0
    for i in range(steps):
        recs.append(StepStarted(run_id, i, f"s{i}", "pose", t, 10.0))
        for k, serial in enumerate(serials):
            ratio = 1.0 + 0.001 * i
            gate = Measurement("gravity_ratio", ratio, "1", 0.95, 1.05, True)
            recs.append(Measured(run_id, k, serial, f"s{i}", gate))
        recs.append(StepFinished(run_id, i, f"s{i}", t + 12.5, 12.5, True, len(serials)))
        t += 12.5
    finished = []
    for k, (serial, outcome) in enumerate(zip(serials, outcomes, strict=True)):
        check = Measurement("accel.bias_static.x", 0.01, "m/s^2", -0.1, 0.1, outcome != Outcome.FAIL, math.nan)
        recs.append(Measured(run_id, k, serial, "limits", check))
        session_path = params_path = None
        if out_dir is not None:
            session_path = out_dir / f"{serial}_{run_id}.csv"
            session_path.write_text(f"# session of {serial}\n1,2,3\n")
            params_path = out_dir / f"{serial}_{run_id}.params.json"
            params_path.write_text(json.dumps({"format": "station-params/1", "serial": serial,
                                               "accel": {"bias_static": [0.0] * 3, "bias_static_std": [1e-3] * 3}}))
        u = UnitFinished(run_id, k, serial, outcome, "" if outcome == Outcome.PASS else "bad",
                         str(session_path) if session_path else None, str(params_path) if params_path else None)
        recs.append(u)
        finished.append(u)
    from station.sequence.records import worst

    recs.append(RunFinished(run_id, worst(outcomes), t, t, 0.5, tuple(finished)))
    return recs


@pytest.fixture
def db(tmp_path: Path) -> Iterator[Database]:
    with open_database(f"sqlite:///{tmp_path / 'station.sqlite'}") as database:
        yield database


def test_upgrade_from_empty_and_round_trip(tmp_path: Path) -> None:
    engine = make_engine(f"sqlite:///{tmp_path / 'm.sqlite'}")
    assert current_revision(engine) is None
    upgrade(engine)
    assert current_revision(engine) == head_revision() == "0007"
    assert set(inspect(engine).get_table_names()) == TABLES | {"alembic_version"}
    with engine.connect() as conn:  # the migration builds exactly the ORM's schema
        assert compare_metadata(MigrationContext.configure(conn), Base.metadata) == []
    downgrade(engine, "base")
    assert current_revision(engine) is None
    assert set(inspect(engine).get_table_names()) <= {"alembic_version"}
    upgrade(engine)
    assert current_revision(engine) == "0007"
    assert set(inspect(engine).get_table_names()) == TABLES | {"alembic_version"}
    engine.dispose()


def test_default_url_is_sqlite_file_in_working_directory(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(tmp_path)
    monkeypatch.delenv("STATION_DB", raising=False)
    with open_database() as database:
        assert database.url == "sqlite:///station.sqlite"
        assert current_revision(database.engine) == "0007"
    assert (tmp_path / "station.sqlite").is_file()


def test_unreachable_database_is_a_store_error(tmp_path: Path) -> None:
    with pytest.raises(StoreError, match="cannot open"):
        open_database(f"sqlite:///{tmp_path / 'no' / 'such' / 'dir.sqlite'}")


def test_recorder_writes_every_record(db: Database, tmp_path: Path) -> None:
    ctx = RunContext(operator="ann", software_version="9.9", sequence_version="plan/2", sequence_hash="a" * 64,
                     limits_version="table1", limits_hash="b" * 64)
    rec = Recorder(db, ctx)
    recs = synthetic_run("r1", ["SN1", "SN2"], [Outcome.PASS, Outcome.FAIL], out_dir=tmp_path)
    for r in recs:
        rec(r)
    with db.transaction() as s:
        run = s.scalars(select(Run)).one()
        assert (run.run_uid, run.outcome, run.operator, run.software_version) == ("r1", "FAIL", "ann", "9.9")
        assert (run.limits_version, run.limits_hash, run.sequence_hash) == ("table1", "b" * 64, "a" * 64)
        assert run.finished_at is not None and run.duration_s == 25.0 and run.rig == "sim-rig"
        steps = s.scalars(select(StepTiming).order_by(StepTiming.step_index)).all()
        assert [(st.name, st.started_t_s, st.duration_s, st.ok, st.hold_s) for st in steps] == [
            ("s0", 0.0, 12.5, True, 10.0), ("s1", 12.5, 12.5, True, 10.0)]
        units = s.scalars(select(RunUnit).order_by(RunUnit.slot)).all()
        assert [(u.unit.serial, u.outcome, u.message) for u in units] == [("SN1", "PASS", ""), ("SN2", "FAIL", "bad")]
        assert s.scalar(select(func.count(LimitCheck.id))) == 2 * 3
        lim = s.scalars(select(LimitCheck).where(LimitCheck.step == "limits").order_by(LimitCheck.id)).all()
        assert [(c.value, c.low, c.high, c.std, c.passed, c.unit) for c in lim] == [
            (0.01, -0.1, 0.1, None, True, "m/s^2"), (0.01, -0.1, 0.1, None, False, "m/s^2")]
        rec_rows = s.scalars(select(SessionRecording).order_by(SessionRecording.id)).all()
        for row in rec_rows:
            assert (row.sha256, row.size_bytes) == sha256_file(Path(row.path))
        assert len(rec_rows) == 2
        ps = s.scalars(select(ParameterSetRecord).order_by(ParameterSetRecord.id)).all()
        assert [p.format for p in ps] == ["station-params/1"] * 2
        assert json.loads(ps[0].uncertainties_json) == {"accel.bias_static_std": [1e-3] * 3}


def test_run_is_unfinished_until_its_end_is_recorded(db: Database) -> None:
    rec = Recorder(db)
    recs = synthetic_run("r2", ["SN1"], [Outcome.PASS])
    for r in recs[:-1]:  # everything but RunFinished, UnitFinished(PASS) included
        rec(r)
    with db.transaction() as s:
        assert s.scalars(select(Run.outcome)).one() == UNFINISHED
    # the process is still alive (it is us, and the run is ours): not recovered
    assert rec.recover("st1") == []
    # a fresh process would see a dead run: recovery makes it ERROR, the PASS unit too
    assert recover_unfinished(db, "st1") == ["r2"]
    with db.transaction() as s:
        run = s.scalars(select(Run)).one()
        assert run.outcome == "ERROR" and "ended before the run was finished" in run.message
        assert [u.outcome for u in run.units] == ["ERROR"]
    assert recover_unfinished(db) == []


def test_recovery_spares_other_stations_and_live_processes(db: Database) -> None:
    rec_a = Recorder(db)
    for r in synthetic_run("a", ["A1"], [Outcome.PASS], station="st-a")[:3]:
        rec_a(r)
    rec_b = Recorder(db)
    rec_b(synthetic_run("b", ["B1"], [Outcome.PASS], station="st-b")[0])
    with db.transaction() as s:  # pretend run b belongs to a live process on this host (pid 1)
        s.scalars(select(Run).where(Run.run_uid == "b")).one().pid = 1
    assert recover_unfinished(db, "st-a", outcome=Outcome.ABORTED) == ["a"]
    assert recover_unfinished(db) == []  # b: a live process on this host
    with db.transaction() as s:
        assert dict(s.execute(select(Run.run_uid, Run.outcome)).all()) == {"a": "ABORTED", "b": UNFINISHED}


def test_queries_and_retest_attempts(db: Database, tmp_path: Path) -> None:
    rec = Recorder(db)
    for k, outcome in enumerate([Outcome.FAIL, Outcome.FAIL, Outcome.PASS]):
        for r in synthetic_run(f"run{k}", ["SN7", f"OTHER{k}"], [outcome, Outcome.PASS], out_dir=tmp_path):
            rec(r)
    # only the unit's own failures count as attempts: station faults, aborts, refusals and retests do not
    for k, outcome in enumerate([Outcome.ERROR, Outcome.ABORTED, Outcome.REFUSED, Outcome.RETEST]):
        for r in synthetic_run(f"other{k}", ["SN8"], [outcome], out_dir=tmp_path):
            rec(r)
    for r in synthetic_run("unfinished", ["SN8"], [Outcome.FAIL], out_dir=tmp_path)[:4]:  # never finished
        rec(r)
    assert attempt_count(db, "SN8") == 0
    assert attempt_count(db, "SN7") == 2
    assert attempt_count(db, "nobody") == 0
    record_disposition(db, "SN7", "retest", operator="bob", note="reseated")
    assert attempt_count(db, "SN7") == 0 and attempt_count(db, "SN7", since_disposition=False) == 2
    record_eeprom_write(db, "SN7", "c" * 64, attempts=2, verified=True, run_id="run2", slot=0, layout_version=1)
    summary = {u.serial: u for u in list_units(db)}
    assert set(summary) >= {"SN7", "OTHER0", "OTHER1", "OTHER2", "SN8"}
    assert (summary["SN7"].runs, summary["SN7"].last_outcome, summary["SN7"].attempts) == (3, "PASS", 0)
    detail = show_unit(db, "SN7")
    assert detail is not None
    assert [r.run_id for r in detail.runs] == ["run2", "run1", "run0"]
    assert [r.outcome for r in detail.runs] == ["PASS", "FAIL", "FAIL"]
    assert detail.runs[1].failed_checks == ("limits:accel.bias_static.x",)
    assert detail.latest_params_run_id == "run2"
    assert detail.eeprom_writes[0]["attempts"] == 2 and detail.eeprom_writes[0]["verified"] is True
    assert detail.dispositions[0]["decision"] == "retest"
    assert show_unit(db, "nobody") is None
    for r in synthetic_run("runF", ["FAILER"], [Outcome.FAIL], out_dir=tmp_path):
        rec(r)
    assert latest_parameter_set(db, "FAILER") is None  # only a PASS result's parameters by default
    assert latest_parameter_set(db, "nobody") is None
    json.dumps(detail.to_dict())


@pytest.mark.parametrize(
    ("serial", "decision", "operator", "note", "message"),
    [
        ("NOPE", "retest", "bob", "why", "no unit with serial 'NOPE'"),
        ("SN9", "maybe", "bob", "why", "unknown decision 'maybe'"),
        ("SN9", "retest", "", "why", "needs the operator"),
        ("SN9", "retest", "bob", " ", "needs its reason"),
    ],
)
def test_dispositions_are_refused_without_a_known_unit_operator_reason(
    db: Database, tmp_path: Path, serial: str, decision: str, operator: str, note: str, message: str
) -> None:
    rec = Recorder(db)
    for r in synthetic_run("r1", ["SN9"], [Outcome.FAIL], out_dir=tmp_path):
        rec(r)
    with pytest.raises(DispositionError, match=re.escape(message)):
        record_disposition(db, serial, decision, operator=operator, note=note)
    with db.transaction() as s:
        assert s.scalar(select(func.count(Disposition.id))) == 0
        assert s.scalar(select(func.count(Unit.id)).where(Unit.serial == "NOPE")) == 0  # no phantom unit


def test_scrap_locks_the_serial(db: Database, tmp_path: Path) -> None:
    rec = Recorder(db)
    for r in synthetic_run("r1", ["SN10"], [Outcome.FAIL], out_dir=tmp_path):
        rec(r)
    gate = retest_gate(db, max_attempts=3)
    assert gate("SN10", "next") is None
    record_disposition(db, "SN10", "scrap", operator="qa", note="cracked housing")
    reason = gate("SN10", "next")
    assert reason is not None and "scrapped" in reason
    assert attempt_count(db, "SN10") == 0  # the count is reset, but a scrapped unit stays refused
    with pytest.raises(DispositionError, match="is scrapped"):
        record_disposition(db, "SN10", "retest", operator="qa", note="try again")
    assert gate("SN10", "next") is not None


def test_units_commands(db: Database, tmp_path: Path) -> None:
    rec = Recorder(db)
    for r in synthetic_run("r9", ["SN9"], [Outcome.PASS], out_dir=tmp_path):
        rec(r)
    cli = CliRunner()
    out = cli.invoke(units_app, ["list", "--db", db.url])
    assert out.exit_code == 0, out.output
    assert "SN9" in out.output and "PASS" in out.output
    out = cli.invoke(units_app, ["show", "SN9", "--json", "--db", db.url])
    assert out.exit_code == 0, out.output
    d = json.loads(out.output)
    assert d["serial"] == "SN9" and d["runs"][0]["run_id"] == "r9" and d["runs"][0]["outcome"] == "PASS"
    assert d["latest_params"]["serial"] == "SN9"
    out = cli.invoke(units_app, ["show", "SN9", "--db", db.url])
    assert out.exit_code == 0 and "run r9" in out.output
    out = cli.invoke(units_app, ["show", "NOPE", "--db", db.url])
    assert out.exit_code == 1
    app = typer.Typer()  # wired as station/cli.py does it: `station units list`
    app.add_typer(units_app, name="units")
    out = cli.invoke(app, ["units", "list", "--db", db.url])
    assert out.exit_code == 0 and "SN9" in out.output


def test_attach_recorder_to_a_subscriber_list(tmp_path: Path) -> None:
    url = f"sqlite:///{tmp_path / 'a.sqlite'}"
    with open_database(url) as database:  # a stale run from a "previous process"
        Recorder(database)(synthetic_run("old", ["SN1"], [Outcome.PASS])[0])
    subscribers: list[object] = []
    recorder = attach_recorder(subscribers.append, url, station_name="st1", operator="eve")
    assert subscribers == [recorder]
    for r in synthetic_run("new", ["SN1"], [Outcome.PASS]):
        recorder(r)
    with recorder.db.transaction() as s:
        assert dict(s.execute(select(Run.run_uid, Run.outcome)).all()) == {"old": "ERROR", "new": "PASS"}
        assert s.scalars(select(Run.operator).where(Run.run_uid == "new")).one() == "eve"
    recorder.db.close()


# --- a real (short) simulated sequence ------------------------------------------------------------


@pytest.mark.integration
def test_recorder_fed_by_a_simulated_sequence(tmp_path: Path) -> None:
    from station.kernel.plan import RigPlan
    from station.rig import open_rig
    from station.sensor import open_sensor
    from station.sequence import SequenceOptions, SequenceRunner
    from station.sim.station_sim import SimStation

    # 60x: the rig's watchdog (capped at 60 rig s by its 16-bit ms register) is then 1 wall second; at 200x
    # it was 0.3 s, and a loaded 2-core CI machine once stalled the heartbeat that long (WATCHDOG, run ERROR)
    scale = 60.0
    plan = RigPlan(sample_rate_hz=50.0, rest_s=120.0, pose_hold_s=5.0,
                   rate_steps=(("x", 100.0), ("y", 100.0), ("z", 100.0)), rate_hold_s=4.0)
    url = f"sqlite:///{tmp_path / 'sim.sqlite'}"
    with SimStation(1, scale, 3, plan=plan) as sim:
        truth_serial = sim.units[0].truth.serial
        rig = open_rig(sim.rig_url, sim.clock, **sim.rig_client_options())
        sensors = [open_sensor(u, sim.clock) for u in sim.sensor_urls]
        try:
            runner = SequenceRunner(rig, sensors, sim.clock, plan=plan, options=SequenceOptions().for_scale(scale),
                                    out_dir=tmp_path / "out", station="pytest-sim", rig_name="sim",
                                    sensor_urls=sim.sensor_urls)
            recorder = attach_recorder(runner, url, station_name="pytest-sim", operator="ci")
            result = runner.run()
        finally:
            for s in sensors:
                s.close()
            rig.close()
    assert recorder.errors == []
    unit = result.units[0]
    print(f"simulated run {result.run_id}: {result.outcome.value} {unit.message}, {len(result.records)} records")
    measurements = [r.measurement for r in result.records if isinstance(r, Measured)]
    with recorder.db.transaction() as s:
        run = s.scalars(select(Run)).one()
        assert (run.run_uid, run.outcome, run.message) == (result.run_id, result.outcome.value, result.message)
        assert run.limits_version == runner.limits.name and len(run.limits_hash) == 64
        assert run.sequence_version == f"plan/{len(runner.steps)} steps" and run.operator == "ci"
        assert [st.name for st in run.steps] == [st.name for st in runner.steps]
        assert all(st.duration_s is not None and st.duration_s > 0 for st in run.steps)
        ru = s.scalars(select(RunUnit)).one()
        assert ru.unit is not None and ru.unit.serial == unit.serial == truth_serial
        assert ru.outcome == unit.outcome.value
        assert s.scalar(select(func.count(LimitCheck.id))) == len(measurements)
        assert s.scalar(select(func.count(LimitCheck.id)).where(~LimitCheck.passed)) == sum(
            not m.passed for m in measurements)
        assert unit.session_path is not None and unit.params is not None
        recording = s.scalars(select(SessionRecording)).one()
        assert (recording.sha256, recording.size_bytes) == sha256_file(unit.session_path)
        stored = ParameterSet.from_json(s.scalars(select(ParameterSetRecord.params_json)).one())
        assert stored.to_json() == unit.params.to_json()
        assert s.scalar(select(func.count(Unit.id))) == 1
    latest = latest_parameter_set(recorder.db, truth_serial)
    assert latest is not None and latest.to_json() == unit.params.to_json()
    recorder.db.close()
