"""The line plan: its rig part, its versioned file."""

from __future__ import annotations

import hashlib
import json
from dataclasses import replace
from pathlib import Path

import pytest

from station.kernel.line_plan import (
    LINE_PLAN_FORMAT,
    LinePlan,
    default_line_plan,
    line_plan_from_json,
    line_plan_to_json,
    load_line_plan_file,
)
from station.kernel.plan import PlanError


def test_the_plan_file_round_trips_and_carries_its_format() -> None:
    plan = replace(default_line_plan(), rack_s=2700.0)
    text = line_plan_to_json(plan)
    assert json.loads(text)["format"] == LINE_PLAN_FORMAT
    back = line_plan_from_json(text)
    assert back == plan
    assert back.rig.poses == ("+z", "+x", "+y", "-x", "-y", "-z")
    assert back.rig.rate_steps == plan.rig.rate_steps


def test_unknown_formats_keys_and_values_are_refused() -> None:
    doc = json.loads(line_plan_to_json(default_line_plan()))
    with pytest.raises(PlanError, match="format"):
        line_plan_from_json(json.dumps({**doc, "format": "station-line-plan/2"}))
    with pytest.raises(PlanError, match="unknown key"):
        line_plan_from_json(json.dumps({**doc, "rig": {**doc["rig"], "pose_hold": 3}}))
    with pytest.raises(PlanError, match="rack_s"):
        line_plan_from_json(json.dumps({**doc, "rack_s": -1}))
    with pytest.raises(PlanError, match="unknown pose"):
        line_plan_from_json(json.dumps({**doc, "rig": {**doc["rig"], "poses": ["+w"]}}))


def test_a_line_needs_poses_and_rate_steps_on_the_rig() -> None:
    with pytest.raises(PlanError, match="poses and rate steps"):
        LinePlan(rig=replace(default_line_plan().rig, rate_steps=()))


def test_the_designer_predicts_from_the_joint_fit_and_picks_the_shortest_plan_meeting_the_limits() -> None:
    from station.kernel.limits_file import load_limits
    from station.sim.plan_design import design, rig_time_s, throughput

    limits = load_limits()
    best, tried = design(limits, rack_times_s=(1800.0,), pose_holds_s=(20.0, 15.0), seeds=(31,))
    # the default limits file bounds the stds loosely: the shortest candidate meets them
    assert best is not None and best.plan.rig.pose_hold_s == 15.0 and best.plan.rack_s == 1800.0
    assert len(tried) == 1 and best.gyro_tc_resolved
    assert all(0.0 < v <= 0.8 for v in best.worst.values())
    # six 5 s shorter poses are 30 s less rig time
    longer = replace(best.plan, rig=replace(best.plan.rig, pose_hold_s=20.0))
    assert rig_time_s(longer) - rig_time_s(best.plan) == pytest.approx(30.0)
    t = throughput(best, 16, 64)
    assert t.rig_per_unit_s == pytest.approx(best.rig_s / 16)
    assert t.rack_units_per_h == pytest.approx(64 * 3600.0 / 1800.0)
    assert t.line_units_per_h == min(t.rig_units_per_h, t.rack_units_per_h)


def test_station_run_refuses_a_plan_file_of_another_version(tmp_path: Path) -> None:
    from typer.testing import CliRunner

    from station.cli import app

    doc = json.loads(line_plan_to_json(default_line_plan()))
    bad = tmp_path / "plan.json"
    bad.write_text(json.dumps({**doc, "format": "station-line-plan/9"}))
    out = CliRunner().invoke(app, ["run", "--rig", "fake-rig://1", "--sensor", "fake-sensor://1", "--plan", str(bad),
                                   "--db", f"sqlite:///{tmp_path / 'x.sqlite'}", "--yes"])
    assert out.exit_code == 2 and "station-line-plan/9" in out.output and "Traceback" not in out.output
    good = tmp_path / "good.json"
    good.write_text(line_plan_to_json(default_line_plan()))
    loaded = load_line_plan_file(good)
    assert loaded.name == "good.json" and loaded.plan == default_line_plan()
    assert loaded.sha256 == hashlib.sha256(good.read_bytes()).hexdigest()
    assert loaded.rig_plan().rest_s == 2.0
