"""A capture that fails because of the station is ERROR, not the unit's FAIL, and the retest policy does not count it.

The station's own gates (``station.sequence.gates``): the sensor's sample time base against the station clock
(``sensor_clock_rate``), a stream that runs behind the station clock (``frame_lateness``), and a rig that did not
report the step's pose and rate settled during the capture (``rig_settled_fraction``). The integration tests use
the real peers (a Modbus/TCP rig server on 127.0.0.1, sensors on ptys): a rig and sensors simulated at one clock
scale and a station at another (the clocks of ``station sim --scale 60`` and ``station run --scale 240``), with
ONE unit in the fixture, where the rule "every unit failed the same gate" cannot apply.
"""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path
from typing import Any

import pytest

from station.compose import Station, StationConfig
from station.kernel.limits import table1_limits
from station.kernel.limits_file import LimitsFile, RetestPolicy, load_limits
from station.kernel.plan import RigPlan
from station.rig import open_rig, rig_client_options
from station.rig.protocol import RigState
from station.rig.registers import Status
from station.sensor import open_sensor
from station.sequence import Outcome, Record, SequenceOptions, SequenceRunner, StepFinished, StepStarted
from station.sequence.gates import clock_rate_gate, frame_lateness_gate, rig_gate, station_fault_text
from station.sim.station_sim import SimStation
from station.store.queries import attempt_count

OPT = SequenceOptions()
PLAN = RigPlan(sample_rate_hz=50.0, rest_s=30.0, pose_hold_s=4.0,
               rate_steps=(("x", 100.0), ("y", 100.0), ("z", 100.0)), rate_hold_s=3.0)
SETTLED = Status.READY | Status.IN_POSITION | Status.RATE_SETTLED | Status.AT_REST | Status.REMOTE


def _state(status: Status = SETTLED, roll: float = 0.0, pitch: float = 0.0, rate: float = 0.0) -> RigState:
    return RigState(t_s=0.0, rig_time_s=0.0, roll_deg=roll, pitch_deg=pitch, yaw_deg=0.0, rate_dps=rate,
                    status=status, fault_code=0, ack_seq=0, ack_result=0, alive=0, heartbeat_echo=0)


# --- the gates -------------------------------------------------------------------------------------------


def test_clock_rate_gate_judges_station_seconds_per_sensor_second() -> None:
    first = (100.0, 5.0, 0.001)
    same = clock_rate_gate(first, (400.03, 305.0, 0.001), OPT)  # 1e-4 off: quartz
    assert same is not None and same.passed and same.link and same.value == pytest.approx(1.0001)
    four = clock_rate_gate(first, (1300.0, 305.0, 0.001), OPT)  # station at 240x, sensor at 60x
    assert four is not None and not four.passed and four.value == pytest.approx(4.0)
    assert "different rates" in station_fault_text(four)
    assert clock_rate_gate(first, (103.0, 8.0, 0.001), OPT) is None  # 3 s apart: too short to judge
    # what the syncs cannot resolve widens the limits: 0.5 s half round trips over 10 s
    wide = clock_rate_gate((0.0, 0.0, 0.5), (10.5, 10.0, 0.5), OPT)
    assert wide is not None and wide.passed and wide.high == pytest.approx(1.0 + OPT.max_clock_rate_error + 0.1)


def test_frame_lateness_gate() -> None:
    ok = frame_lateness_gate(1.1, 60.0, OPT)
    late = frame_lateness_gate(900.0, 60.0, OPT)
    assert ok.passed and ok.link and ok.high == OPT.max_frame_lateness_s + 60.0
    assert not late.passed and late.link and "ran behind" in station_fault_text(late)


def test_rig_gate_reads_the_rigs_own_report() -> None:
    settled = [_state(roll=0.0, pitch=0.0) for _ in range(4)]
    ok = rig_gate(settled, "+z", 0.0, OPT)
    assert ok is not None and ok.passed and ok.value == 1.0
    unsettled = [*settled[:3], _state(SETTLED & ~Status.IN_POSITION)]
    bad = rig_gate(unsettled, "+z", 0.0, OPT)
    assert bad is not None and not bad.passed and bad.link and bad.value == pytest.approx(0.75)
    spinning = [_state(SETTLED & ~Status.RATE_SETTLED, rate=99.0)]
    assert not rig_gate(spinning, "+z", 100.0, OPT).passed  # type: ignore[union-attr]
    assert rig_gate([], "+z", 0.0, OPT) is None
    off_pose = [_state(roll=0.2)]
    assert not rig_gate(off_pose, "+z", 0.0, OPT).passed  # type: ignore[union-attr]


# --- real peers ------------------------------------------------------------------------------------------


def _limits(max_attempts: int) -> LimitsFile:
    """Table 1 with a gyro static bias of 10-11 rad/s: a unit measured to the end FAILs on its own merits."""
    t1 = table1_limits()
    product = replace(t1, name="unmeetable", gyro=replace(t1.gyro, bias_static=(10.0, 11.0)))
    return replace(load_limits(), product=product, retest=RetestPolicy(max_attempts=max_attempts))


def test_a_station_clock_at_another_rate_is_a_station_fault_with_one_unit(tmp_path: Path,
                                                                          monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("STATION_LOCK_DIR", str(tmp_path / "locks"))
    url = f"sqlite:///{tmp_path / 'faults.sqlite'}"
    with SimStation(1, 60.0, 11, plan=PLAN) as sim:
        serial = sim.units[0].truth.serial
        # the station at 240x against peers at 60x: its own clock, as `station run --scale 240` makes it
        fast = StationConfig(sim.rig_url, tuple(sim.sensor_urls), station_id="fast", db_url=url, out_dir=None,
                             plan=PLAN, clock_scale=240.0, rig_options=rig_client_options(240.0), provision=False)
        station = Station(fast, limits=_limits(max_attempts=1))
        assert station.recorder is not None
        db = station.recorder.db
        runs = [station.run(), station.run()]
        faults_counted = attempt_count(db, serial)
        # the same unit on the peers' clock: measured to the end, FAIL on the unmeetable limit, counted
        matched = replace(fast, station_id="matched", clock_scale=60.0, rig_options=sim.rig_client_options())
        station2 = Station(matched, clock=sim.clock, limits=_limits(max_attempts=1))
        counted, refused = station2.run(), station2.run()
    for r in runs:
        unit = r.units[0]
        assert unit.outcome == Outcome.ERROR and r.outcome == Outcome.ERROR, unit.message
        assert "sensor_clock_rate" in unit.message and "different rates" in unit.message, unit.message
        assert "station fault" in unit.message
        rate = [m.measurement for m in unit.measurements if m.measurement.name == "sensor_clock_rate"]
        # 4 station s per sensor s; the estimate is coarse at such a mismatch (the syncs assume equal rates
        # over their round trips), the verdict is not: far outside its limits either way
        assert rate and rate[-1].value > 2.0 and not rate[-1].passed
    assert faults_counted == 0  # two station faults: no attempt counted, the second run admitted
    unit = counted.units[0]
    assert unit.outcome == Outcome.FAIL and "bias_static" in unit.message, unit.message
    gates = {m.measurement.name: m.measurement for m in unit.measurements}
    assert gates["sensor_clock_rate"].passed and abs(gates["sensor_clock_rate"].value - 1.0) < 0.01
    assert gates["frame_lateness"].passed and gates["rig_settled_fraction"].value == 1.0
    assert attempt_count(db, serial) == 1
    assert refused.units[0].outcome == Outcome.REFUSED  # the policy counts the unit's own failure


class UnsettledRig:
    """The station's client of the real rig, except that while ``armed`` the rig's readings lack IN_POSITION:
    a rig that reports its pose not settled while its readbacks stay within the capture tolerances."""

    def __init__(self, rig: Any) -> None:
        self._rig = rig
        self.armed = False
        self.served = 0

    def state(self) -> RigState:
        st: RigState = self._rig.state()
        if self.armed:
            self.served += 1
            return replace(st, status=st.status & ~Status.IN_POSITION)
        return st

    def __getattr__(self, name: str) -> Any:
        return getattr(self._rig, name)


def test_a_rig_that_does_not_report_itself_settled_is_a_station_fault(tmp_path: Path) -> None:
    with SimStation(1, 100.0, 12, plan=PLAN) as sim:
        rig = UnsettledRig(open_rig(sim.rig_url, sim.clock, **sim.rig_client_options()))
        sensors = [open_sensor(u, sim.clock) for u in sim.sensor_urls]

        def during_pose_x(record: Record) -> None:
            if isinstance(record, StepStarted | StepFinished) and record.name == "pose +x":
                rig.armed = isinstance(record, StepStarted)

        try:
            runner = SequenceRunner(rig, sensors, sim.clock, plan=PLAN,  # type: ignore[arg-type]
                                    options=SequenceOptions().for_scale(sim.scale), out_dir=None,
                                    subscribers=[during_pose_x], limits=table1_limits())
            result = runner.run()
        finally:
            for s in sensors:
                s.close()
            rig._rig.close()
    unit = result.units[0]
    assert rig.served > 0
    assert unit.outcome == Outcome.ERROR and "pose +x" in unit.message, unit.message
    assert "rig_settled_fraction" in unit.message and "did not report" in unit.message, unit.message
    settled = [m.measurement for m in unit.measurements if m.measurement.name == "rig_settled_fraction"]
    assert [m.step for m in unit.measurements if m.measurement.name == "rig_settled_fraction"][-1] == "pose +x"
    assert all(m.passed for m in settled[:-1]) and settled[-1].value < 1.0
    assert not math.isnan(settled[-1].value)
