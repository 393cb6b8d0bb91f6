"""Retest policy: a unit's own failures count; over its attempts it is REFUSED before anything moves.

A simulated station (the in-process fakes: fake-rig:// and fake-sensor:// URLs, no port, no pty; a
virtual clock) runs one unit with a limits file it cannot meet, so every run FAILs: two failed attempts,
then the third run refuses the unit before the rig moves (REFUSED, its own exit code), until a
disposition is recorded.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

from station.compose import Station, StationConfig
from station.kernel.limits import table1_limits
from station.kernel.limits_file import LimitsFile, RetestPolicy, load_limits
from station.kernel.plan import RigPlan
from station.kernel.virtual_clock import VirtualClock, acting
from station.rig import open_rig
from station.sensor import open_sensor
from station.sequence import Outcome, RigReading, SequenceRunner, StepStarted
from station.sim.fakes import FakeStation
from station.store.queries import attempt_count
from station.store.recorder import record_disposition

PLAN = RigPlan(sample_rate_hz=50.0, rest_s=60.0, pose_hold_s=4.0,
               rate_steps=(("x", 100.0), ("y", 100.0), ("z", 100.0)), rate_hold_s=3.0)


def unmeetable_limits() -> LimitsFile:
    """Table 1, but a gyro static bias of 10-11 rad/s: every unit FAILs on its own merits."""
    base = load_limits()
    t1 = table1_limits()
    product = replace(t1, name="unmeetable", gyro=replace(t1.gyro, bias_static=(10.0, 11.0)))
    return replace(base, product=product, retest=RetestPolicy(max_attempts=2))


def test_failures_count_and_the_refusal_comes_before_any_motion(tmp_path: Path) -> None:
    url = f"sqlite:///{tmp_path / 'retest.sqlite'}"
    results = []
    clock = VirtualClock()
    with acting(clock, name="test"), FakeStation(1, clock.scale, 5, plan=PLAN, clock=clock) as sim:
        serial = sim.units[0].truth.serial
        config = StationConfig(sim.rig_url, tuple(sim.sensor_urls), station_id="pytest", db_url=url, out_dir=None,
                               plan=PLAN, rig_options=sim.rig_client_options(), provision=False)
        station = Station(config, clock=sim.clock, limits=unmeetable_limits())
        assert station.recorder is not None
        db = station.recorder.db
        for attempt in range(4):
            if attempt == 3:
                record_disposition(db, serial, "retest", operator="qa", note="fixture cleaned")
            results.append(station.run())
    first, second, third, fourth = results
    assert [r.units[0].outcome for r in (first, second)] == [Outcome.FAIL, Outcome.FAIL]
    refused = third.units[0]
    assert refused.outcome == Outcome.REFUSED and third.outcome == Outcome.REFUSED and third.outcome.exit_code == 3
    assert "retest policy" in refused.message and "failed 2 attempt(s)" in refused.message
    assert refused.serial == serial and refused.session is None and refused.params is None
    # refused before anything moved: no step started, the rig never left rest
    assert not [r for r in third.records if isinstance(r, StepStarted)]
    assert all(r.rate_dps == 0.0 and "MOVING" not in r.status for r in third.records if isinstance(r, RigReading))
    assert third.rig_at_rest
    assert fourth.units[0].outcome == Outcome.FAIL  # admitted again after the disposition
    assert attempt_count(db, serial) == 1  # the failed run after the disposition
    assert attempt_count(db, serial, since_disposition=False) == 3  # the refusal is no attempt


class _RoutingRunner(SequenceRunner):
    """A runner that decides per unit itself (as the line's rig role does), with no retest policy at all."""

    routes_units = True

    def refusal(self, serial: str) -> str | None:
        return f"refused by the router: {serial} belongs elsewhere" if serial == self.refuse else None

    refuse = ""


def test_a_runner_that_routes_units_refuses_them_before_any_motion_without_a_retest_policy() -> None:
    clock = VirtualClock()
    with acting(clock, name="test"), FakeStation(2, clock.scale, 6, plan=PLAN, clock=clock) as sim:
        rig = open_rig(sim.rig_url, sim.clock, **sim.rig_client_options())
        sensors = [open_sensor(url, sim.clock) for url in sim.sensor_urls]
        try:
            runner = _RoutingRunner(rig, sensors, sim.clock, plan=PLAN, limits=table1_limits())
            runner.refuse = other = sim.units[1].truth.serial
            result = runner.run()
        finally:
            for s in sensors:
                s.close()
            rig.close()
    kept, refused = result.units
    assert refused.outcome == Outcome.REFUSED and "belongs elsewhere" in refused.message
    assert refused.serial == other and refused.session is None
    assert kept.outcome != Outcome.REFUSED and kept.session is not None
