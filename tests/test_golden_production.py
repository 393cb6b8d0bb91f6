"""A golden unit that fails its check stops production on its station until a golden run passes.

On the real peers (a Modbus/TCP rig server on 127.0.0.1, sensors on ptys), a station configured with
``golden = "per-shift"`` (one shift a day from 00:00 UTC): the golden unit is registered with a reference it
cannot meet on one parameter, its run fails the check, and the next production unit is REFUSED before the rig
moves ("production is stopped"); after a registration it meets, its run passes and the production unit is
measured.
"""

from __future__ import annotations

from dataclasses import replace
from datetime import UTC, datetime
from pathlib import Path

import pytest

from station.compose import Station, StationConfig
from station.kernel.golden import GoldenReference, GoldenUnit
from station.kernel.plan import RigPlan
from station.sequence import Outcome, StepStarted
from station.sequence.limits import check_limits
from station.sim.station_sim import SimStation
from station.store.golden_records import golden_checks, save_golden

pytestmark = pytest.mark.integration

SCALE = 15.0  # the rig's watchdog (60 rig s) is 4 wall s: a loaded host does not trip it
PLAN = RigPlan(sample_rate_hz=50.0, rest_s=30.0, pose_hold_s=4.0,
               rate_steps=(("x", 100.0), ("y", 100.0), ("z", 100.0)), rate_hold_s=3.0)
GOLDEN, PRODUCTION = 41, 42  # which units of the seed sit in the nest


def _station(sim: SimStation, url: str, *, golden: str) -> Station:
    config = StationConfig(sim.rig_url, tuple(sim.sensor_urls), station_id="st-gold", db_url=url, out_dir=None,
                           plan=PLAN, rig_options=sim.rig_client_options(), provision=False, golden=golden,
                           shifts="A=00:00")
    return Station(config, clock=sim.clock)


def test_a_failed_golden_check_stops_production(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("STATION_LOCK_DIR", str(tmp_path / "locks"))
    if datetime.now(UTC).hour == 23 and datetime.now(UTC).minute >= 58:
        pytest.skip("the one-shift calendar turns over at 00:00 UTC during the test")
    url = f"sqlite:///{tmp_path / 'golden.sqlite'}"
    # the golden unit's references: its simulated truth (what a laboratory would have given it)
    with SimStation(1, SCALE, 5, plan=PLAN, unit_keys=[GOLDEN]) as sim:
        truth = sim.units[0].truth
        station = _station(sim, url, golden="off")
    serial = truth.serial
    measured = {m.name: m.value for m in check_limits(truth.as_parameter_set(1.0 / PLAN.sample_rate_hz),
                                                      station.limits.product)}
    good = GoldenUnit(serial, datetime.now(UTC).isoformat(), (
        GoldenReference("accel.bias_static.x", "m/s^2", measured["accel.bias_static.x"], 0.01, 1e-3, 5),
        GoldenReference("gyro.M.xx", "1", measured["gyro.M.xx"], 1e-3, 1e-4, 5),
    ))
    # a reference 0.1 m/s^2 away with an allowance of 0.01: the golden run must fail its check
    bad = replace(good, references=(replace(good.references[0], value=good.references[0].value + 0.1),
                                     good.references[1]))
    assert station.recorder is not None
    save_golden(station.recorder.db, bad)

    with SimStation(1, SCALE, 5, plan=PLAN, unit_keys=[PRODUCTION]) as sim:
        no_golden_yet = _station(sim, url, golden="per-shift").run()
    refused = no_golden_yet.units[0]
    assert refused.outcome == Outcome.REFUSED and "no golden-unit run" in refused.message, refused.message

    with SimStation(1, SCALE, 5, plan=PLAN, unit_keys=[GOLDEN]) as sim:
        gold = _station(sim, url, golden="per-shift")
        gold_run = gold.run()
    assert gold_run.units[0].params is not None, gold_run.units[0].message
    assert [c.passed for c in gold.golden_checks] == [False]
    assert [d.parameter for d in gold.golden_checks[0].failed] == ["accel.bias_static.x"]

    with SimStation(1, SCALE, 5, plan=PLAN, unit_keys=[PRODUCTION]) as sim:
        stopped = _station(sim, url, golden="per-shift").run()
    unit = stopped.units[0]
    assert unit.outcome == Outcome.REFUSED and "production is stopped" in unit.message, unit.message
    assert not [r for r in stopped.records if isinstance(r, StepStarted)]  # refused before the rig moved

    save_golden(station.recorder.db, good)  # registration v2: the unit's own values
    with SimStation(1, SCALE, 5, plan=PLAN, unit_keys=[GOLDEN]) as sim:
        gold = _station(sim, url, golden="per-shift")
        gold.run()
    assert [c.passed for c in gold.golden_checks] == [True]
    with SimStation(1, SCALE, 5, plan=PLAN, unit_keys=[PRODUCTION]) as sim:
        resumed = _station(sim, url, golden="per-shift").run()
    # admitted again: measured, not refused (its own outcome is the unit's business)
    assert resumed.units[0].outcome != Outcome.REFUSED, resumed.units[0].message
    assert [r for r in resumed.records if isinstance(r, StepStarted)]
    assert [c.passed for c in golden_checks(station.recorder.db, station="st-gold")] == [False, True]
