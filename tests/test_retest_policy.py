"""Retest policy: at most N attempts per unit, then the station refuses it until a disposition is recorded."""

from __future__ import annotations

from pathlib import Path

from station.compose import attach_recorder
from station.kernel.plan import RigPlan
from station.rig import open_rig
from station.sensor import open_sensor
from station.sequence import Outcome, SequenceOptions, SequenceRunner
from station.sim.station_sim import SimStation
from station.store.db import open_database
from station.store.queries import attempt_count, retest_gate
from station.store.recorder import record_disposition

SCALE = 200.0
PLAN = RigPlan(sample_rate_hz=50.0, rest_s=60.0, pose_hold_s=4.0,
               rate_steps=(("x", 100.0), ("y", 100.0), ("z", 100.0)), rate_hold_s=3.0)


def test_third_attempt_refused_until_disposition(tmp_path: Path) -> None:
    url = f"sqlite:///{tmp_path / 'retest.sqlite'}"
    db = open_database(url)
    outcomes = []
    with SimStation(1, SCALE, 5, plan=PLAN) as sim:
        serial = sim.units[0].truth.serial
        for attempt in range(4):
            if attempt == 3:
                record_disposition(db, serial, "retest", operator="qa", note="fixture cleaned")
            rig = open_rig(sim.rig_url, sim.clock, **sim.rig_client_options())
            sensors = [open_sensor(u, sim.clock) for u in sim.sensor_urls]
            try:
                runner = SequenceRunner(rig, sensors, sim.clock, plan=PLAN, options=SequenceOptions().for_scale(SCALE),
                                        station="pytest", sensor_urls=sim.sensor_urls)
                attach_recorder(runner, url, station_name="pytest")
                runner.admit = retest_gate(db, max_attempts=2)
                result = runner.run()
            finally:
                for s in sensors:
                    s.close()
                rig.close()
            outcomes.append((result.units[0].outcome, result.units[0].message, result.rig_at_rest))
    first, second, third, fourth = outcomes
    assert first[0] != Outcome.ABORTED and second[0] != Outcome.ABORTED
    assert third[0] == Outcome.ABORTED and "retest policy" in third[1] and "2 attempt(s)" in third[1]
    assert third[2]  # the rig still ends at rest
    assert fourth[0] != Outcome.ABORTED  # admitted again after the disposition
    assert attempt_count(db, serial) == 1  # the run after the disposition
    assert attempt_count(db, serial, since_disposition=False) == 4
