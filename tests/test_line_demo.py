"""``station demo`` (the line) end to end: rack (relay board, ptys) -> recordings in the database -> powered
transfer -> the rig role through the composition root (rig lock, run tables, EEPROM written and verified) ->
joint fit; a unit that lost power on the way is refused with the reason, and the record says why and which plan
file the units were calibrated with."""

from __future__ import annotations

import hashlib
import io
from pathlib import Path

import pytest
from rich.console import Console
from sqlalchemy import select

from station.kernel.line_plan import default_line_plan, line_plan_to_json
from station.rig_lock import RigBusy, RigLock
from station.sequence.records import Outcome
from station.sim.demo import run_line_demo
from station.store.db import open_database
from station.store.models import EepromWrite, RackRecording, Run, RunUnit, StepTiming


def test_line_demo_records_the_rig_role_and_refuses_an_interrupted_unit(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("STATION_LOCK_DIR", str(tmp_path / "locks"))
    plan_file = tmp_path / "line-plan.json"
    plan_file.write_text(line_plan_to_json(default_line_plan()))
    sha = hashlib.sha256(plan_file.read_bytes()).hexdigest()
    db_url = f"sqlite:///{tmp_path / 'line.sqlite'}"
    out = io.StringIO()
    result = run_line_demo(2, 300.0, seed=3, console=Console(file=out, width=140), interrupt=(1,),
                           out_dir=tmp_path / "out", db_url=db_url, plan_path=plan_file)
    text = out.getvalue()
    first, second = result.units
    assert first.outcome == Outcome.PASS, first.message
    assert first.params is not None and first.params.source["fit"] == "joint (rack + rig)"
    assert first.params.quality.extra["line"]["rack_span_s"] > 290.0
    assert second.outcome == Outcome.REFUSED
    assert "full: power-on counter changed" in second.message
    assert "rig time per unit: " in text
    with open_database(db_url) as db, db.transaction() as s:
        assert len(s.scalars(select(RackRecording)).all()) == 2
        run = s.scalars(select(Run)).one()
        assert run.sequence_version == "station-line-plan/1 line-plan.json" and run.sequence_hash == sha
        units = s.scalars(select(RunUnit).where(RunUnit.run_id == run.id).order_by(RunUnit.slot)).all()
        assert [u.outcome for u in units] == ["PASS", "REFUSED"]
        assert "power-on counter changed" in units[1].message  # the record says why
        assert s.scalars(select(StepTiming).where(StepTiming.run_id == run.id)).all()
        writes = s.scalars(select(EepromWrite)).all()
        assert len(writes) == 1 and writes[0].run_unit_id == units[0].id
        assert writes[0].written and writes[0].read_back_ok and writes[0].verified_on_rig


def test_the_rig_role_takes_the_rig_lock(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Two rig roles cannot drive one rig: with the rig held, the line's rig role is refused before it moves."""
    from station.compose import Station, StationConfig
    from station.kernel.line_plan import load_line_plan_file
    from station.sim.fakes import FakeStation

    monkeypatch.setenv("STATION_LOCK_DIR", str(tmp_path / "locks"))
    db_url = f"sqlite:///{tmp_path / 'line.sqlite'}"
    with FakeStation(1, seed=1) as sim:
        config = StationConfig(sim.rig_url, tuple(sim.sensor_urls), db_url=db_url, out_dir=None,
                               line=load_line_plan_file(None))
        station = Station(config, clock=sim.clock)
        with RigLock(sim.rig_url, "other-rig-role"), pytest.raises(RigBusy):
            station.run()
