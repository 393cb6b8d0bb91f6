"""A power interruption between rack and rig, on the simulated line's real transports: the rig role detects it
(a power-on counter that changed, a transfer longer than the plan allows), the unit goes back to the rack or gets
the full rig plan, and the run's record says why."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import pytest
from sqlalchemy import select

from station.compose import Station
from station.kernel.line_plan import load_line_plan_file
from station.kernel.virtual_clock import VirtualClock, acting
from station.line.recordings import DatabaseArchive
from station.sim.line_station import SimLine
from station.store.db import open_database
from station.store.models import Run, RunUnit


def _records(db_url: str) -> list[tuple[str, str]]:
    with open_database(db_url) as db, db.transaction() as s:
        run = s.scalars(select(Run).order_by(Run.id.desc())).first()
        assert run is not None
        return [(u.outcome, u.message) for u in
                s.scalars(select(RunUnit).where(RunUnit.run_id == run.id).order_by(RunUnit.slot)).all()]


def test_a_counter_reset_sends_the_unit_back_to_the_rack(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("STATION_LOCK_DIR", str(tmp_path / "locks"))
    db_url = f"sqlite:///{tmp_path / 'line.sqlite'}"
    line = load_line_plan_file(None)
    clock = VirtualClock()  # the test's thread acts on it throughout: the run repeats whatever the host's load
    with acting(clock, name="test"), SimLine(2, 30.0, 5, line.rig_plan(), clock=clock) as sim:
        with open_database(db_url) as db:
            sim.soak([0, 1], 200.0, DatabaseArchive(db.sessions))
        sim.to_rig([0, 1], 20.0, interrupt=[0])
        config = sim.rig_config([0, 1], line, db_url=db_url, back_to_rack=True)
        result = Station(config, clock=sim.clock).run()
    interrupted, kept = result.units
    assert interrupted.outcome.value == "REFUSED" and "back to rack: power-on counter changed" in interrupted.message
    # the line's decision refused it, not the retest policy (which was not asked)
    assert interrupted.message.startswith("refused by the line's rack-to-rig decision")
    assert "retest policy" not in interrupted.message
    # the other unit kept its power: not refused, fitted over both recordings (its EEPROM verification is
    # tests/test_line_demo.py's; on a scaled clock, under load, it failed once in five runs with the raw output)
    assert kept.outcome.value != "REFUSED" and kept.params is not None, kept.message
    assert kept.params.source["fit"] == "joint (rack + rig)"
    recorded = _records(db_url)
    assert recorded[0][0] == "REFUSED" and "back to rack: power-on counter changed" in recorded[0][1]
    assert recorded[1][0] == kept.outcome.value


def test_a_transfer_longer_than_the_plan_allows_gets_the_full_plan(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("STATION_LOCK_DIR", str(tmp_path / "locks"))
    db_url = f"sqlite:///{tmp_path / 'line.sqlite'}"
    line = load_line_plan_file(None)
    line = replace(line, plan=replace(line.plan, max_transfer_s=60.0))
    clock = VirtualClock()
    with acting(clock, name="test"), SimLine(1, 30.0, 6, line.rig_plan(), clock=clock) as sim:
        with open_database(db_url) as db:
            sim.soak([0], 120.0, DatabaseArchive(db.sessions))
        sim.to_rig([0], 150.0)  # powered all along, but longer than the 60 s the plan allows
        result = Station(sim.rig_config([0], line, db_url=db_url), clock=sim.clock).run()
    (unit,) = result.units
    assert unit.outcome.value == "REFUSED" and "full: transfer from rack to rig took" in unit.message
    assert "retest policy" not in unit.message
    assert "full: transfer from rack to rig took" in _records(db_url)[0][1]
