"""The thermal sequence in a climate chamber, with real peers: the simulated rig (Modbus/TCP), the
simulated chamber (Modbus/TCP) and sensors on ptys, each on a free port of 127.0.0.1 and stopped by
the test. A short plateau plan on a fast clock: the steps a plan expands to; the soak gate; the units'
temperatures following the chamber; the verification of the written image at a temperature the fit
did not use; and the chamber's faults (alarm, no answer, setpoint not reached, its watchdog, an
operator abort), each a station ERROR (never a unit FAIL) with the rig at rest, no EEPROM write, and
the chamber sent back to ambient."""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Iterator
from dataclasses import replace

import numpy as np
import pytest

from station.chamber import chamber_client_options, open_chamber
from station.chamber.registers import AlarmCode, Mode
from station.kernel.clock import Clock
from station.kernel.limits import table1_limits
from station.kernel.plan import PlanError, RigPlan
from station.kernel.thermal_plan import ThermalPlan
from station.kernel.virtual_clock import VirtualClock, acting
from station.rig import open_rig
from station.sensor import open_sensor
from station.sequence import Measured, Outcome, Record, RunResult, SequenceOptions, StepStarted
from station.sequence.provision import EepromProvisioner
from station.sequence.runner import SequenceRunner
from station.sequence.thermal_sequence import (
    ChamberStep,
    RampStep,
    SoakStep,
    ThermalSequence,
    temperature_slope_k_per_min,
    thermal_runner,
    thermal_steps,
)
from station.sequence.verify import RigVerifier
from station.session.model import Kind
from station.sim.eeprom import ERASED
from station.sim.firmware import install_firmware
from station.sim.station_sim import SimStation

pytestmark = pytest.mark.integration

BASE = RigPlan(sample_rate_hz=50.0, rest_s=30.0, pose_hold_s=4.0, rate_hold_s=3.0, settle_s=1.0,
               rate_steps=(("x", 100.0), ("x", -100.0), ("y", 100.0), ("y", -100.0), ("z", 100.0), ("z", -100.0)))
# a small, quick chamber: the load follows within minutes
CHAMBER = {"ambient_degc": 23.0, "air_tau_s": 20.0, "heat_k_per_min": 20.0, "cool_k_per_min": 15.0,
           "load_tau_s": 60.0, "hold_s": 10.0}
PLAN = ThermalPlan(base=BASE, plateaus_degc=(10.0, 40.0), verify_degc=30.0, soak_rate_k_per_min=0.3,
                   soak_window_s=60.0, soak_poll_s=10.0, soak_timeout_s=1800.0, setpoint_timeout_s=1200.0,
                   ambient_timeout_s=1200.0)
OPTIONS = SequenceOptions(move_timeout_s=30.0, spin_timeout_s=30.0, rest_timeout_s=60.0)


def test_plateau_plan_expands_to_chamber_soak_and_rig_steps() -> None:
    steps = thermal_steps(replace(PLAN, raw_check=True))
    names = [s.name for s in steps]
    assert names[0] == "rest" and steps[0].kind == Kind.REST
    assert names[1:3] == ["chamber @10C", "soak @10C"]
    assert isinstance(steps[1], ChamberStep) and steps[1].degc == 10.0 and isinstance(steps[2], SoakStep)
    per_plateau = 2 + len(BASE.poses) + len(BASE.rate_steps)
    assert names[3] == "pose +z @10C" and names[1 + per_plateau] == "chamber @40C"
    assert names[-1] == "check rate z -100 @30C"
    assert [s.index for s in steps] == list(range(len(steps)))
    assert len(steps) == 1 + 3 * per_plateau


def test_ramp_plan_has_cold_soak_ramp_and_final_plateau() -> None:
    plan = replace(PLAN, mode="ramp", ramp_from_degc=0.0, ramp_to_degc=50.0, ramp_k_per_min=1.0,
                   ramp_rate_steps=(("z", 50.0),))
    steps = thermal_steps(plan)
    ramp = next(s for s in steps if isinstance(s, RampStep))
    assert (ramp.from_degc, ramp.to_degc, ramp.k_per_min) == (0.0, 50.0, 1.0)
    assert [s.name for s in ramp.cycle][:2] == ["ramp pose +z", "ramp pose -z"]
    assert ramp.cycle[-1].name == "ramp rate z +50"
    names = [s.name for s in steps]
    assert names.index("soak @0C") < names.index(ramp.name) < names.index("soak @50C")


@pytest.mark.parametrize("changes", [{"verify_degc": 41.0}, {"plateaus_degc": ()}, {"mode": "zigzag"},
                                     {"soak_rate_k_per_min": 0.0}, {"poses": ("+w",)},
                                     {"raw_check": True, "verify_degc": None}])
def test_bad_thermal_plans_are_refused(changes: dict) -> None:
    with pytest.raises(PlanError):
        replace(PLAN, **changes)


def test_temperature_slope() -> None:
    t = np.linspace(0.0, 120.0, 601)
    assert temperature_slope_k_per_min(t, 20.0 + 0.5 / 60.0 * t) == pytest.approx(0.5)
    assert math.isnan(temperature_slope_k_per_min(t[:2], t[:2]))


# ---------------------------------------------------------------------------- runs with real peers


@pytest.fixture
def sim() -> Iterator[SimStation]:
    clock = VirtualClock()  # discrete events: hours of chamber time in seconds, whatever the host's load
    with SimStation(2, clock.scale, seed=11, plan=BASE, chamber=CHAMBER, clock=clock) as station:
        for u in station.units:
            install_firmware(u.sensor, station.clock)
        yield station


def seq(runner: SequenceRunner) -> ThermalSequence:
    assert isinstance(runner.sequence, ThermalSequence)
    return runner.sequence


def at_step(name: str, action: Callable[[], None]) -> Callable[[Record], None]:
    fired: list[bool] = []

    def subscriber(record: Record) -> None:
        if isinstance(record, StepStarted) and record.name == name and not fired:
            fired.append(True)
            action()

    return subscriber


def run(sim: SimStation, *subscribers: Callable[[Record], None], plan: ThermalPlan = PLAN,
        on_runner: Callable[[SequenceRunner], None] | None = None) -> tuple[RunResult, SequenceRunner]:
    clock = sim.clock
    with acting(clock, name="test"):  # no time passes while the test opens the station
        return _run(sim, clock, subscribers, plan, on_runner)


def _run(sim: SimStation, clock: Clock, subscribers: tuple[Callable[[Record], None], ...], plan: ThermalPlan,
         on_runner: Callable[[SequenceRunner], None] | None) -> tuple[RunResult, SequenceRunner]:
    # wall-clock I/O timeouts, short so that a peer that does not answer fails fast, long enough for a host under
    # heavy load (0.2 s tripped at a load average of 40 on 2 cores; the virtual clock waits for nothing in wall time)
    rig = open_rig(sim.rig_url + "&timeout=2&retries=1", clock, **sim.rig_client_options())
    chamber = open_chamber(sim.chamber_url + "&timeout=2&retries=1", clock, **chamber_client_options(clock.scale))
    sensors = [open_sensor(url, clock, command_timeout_s=1.0, attempts=2) for url in sim.sensor_urls]
    try:
        options = OPTIONS.for_scale(clock.scale)
        verifier = RigVerifier(rig, clock, gravity_mps2=plan.base.gravity_mps2, sample_rate_hz=50, options=options)
        runner = thermal_runner(rig, sensors, clock, chamber, plan,
                                provisioner=EepromProvisioner("test", verifier=verifier), options=options,
                                limits=table1_limits(), subscribers=list(subscribers))
        if on_runner is not None:
            on_runner(runner)
        return runner.run(), runner
    finally:
        for s in sensors:
            s.close()
        chamber.close()
        rig.close()


def assert_no_eeprom_write(sim: SimStation) -> None:
    for u in sim.units:
        assert u.sensor.eeprom.page_writes == 0
        assert u.sensor.eeprom.image() == bytes([ERASED]) * u.sensor.eeprom.size


def chamber_sent_to_ambient(sim: SimStation) -> bool:
    model = sim.chamber.model  # type: ignore[union-attr]
    return model.setpoint_degc == CHAMBER["ambient_degc"] or (model.alarm_code != 0 and model.mode == Mode.STOP)


def test_plateaus_soak_fit_write_and_verify_at_another_temperature(sim: SimStation) -> None:
    records: list[Record] = []
    result, runner = run(sim, records.append, plan=replace(PLAN, raw_check=True))
    assert result.outcome == Outcome.PASS, result.message or [u.message for u in result.units]
    soak = {(m.slot, m.step): m.measurement for m in records if isinstance(m, Measured)
            and m.measurement.name in ("soak_rate", "soak_temperature")}
    for slot, unit in enumerate(sim.units):
        # the unit soaked at each plateau: its own temperature = the chamber's plus its self-heating
        for degc in (10.0, 40.0):
            t_unit = soak[(slot, f"soak @{degc:g}C")]
            assert degc <= t_unit.value <= degc + unit.truth.self_heating_k + 0.5
        # verified at 30 degC: a temperature the fit did not use
        t_verify = soak[(slot, "verify soak @30C")]
        assert 30.0 <= t_verify.value <= 30.0 + unit.truth.self_heating_k + 0.5
        assert runner.verification[slot].passed
        assert unit.sensor.eeprom.page_writes > 0
        # the fit's recording spans both plateaus; the check recording holds the raw check at 30 degC only
        session = result.units[slot].session
        assert session is not None and session.temp_degc.min() < 15.0 and session.temp_degc.max() > 40.0
        # a thermal plan fits the temperature polynomials (the plan moves the temperature far enough)
        params = result.units[slot].params
        assert params is not None and params.thermal.status == "fitted", params and params.thermal.reason
        check = seq(runner).check_sessions[slot]
        windows = check.segments_of(Kind.POSE, Kind.RATE)
        assert len(windows) == len(BASE.poses) + len(BASE.rate_steps)
        assert all(abs(check.temp_degc[w.slice].mean() - 30.0) < unit.truth.self_heating_k + 1.0 for w in windows)
    assert seq(runner).chamber_at_ambient and chamber_sent_to_ambient(sim)
    assert result.rig_at_rest
    t = seq(runner).timing
    assert t is not None and t.cycle_s >= t.sequence_s > 0 and t.verify_s > 0 and t.ambient_s > 0


def run_and_check(sim: SimStation, step: str, inject: Callable[[], None],
                  on_runner: Callable[[SequenceRunner], None] | None = None,
                  reachable: bool = True) -> tuple[RunResult, SequenceRunner]:
    """Run with ``inject`` when ``step`` starts; every unit ERROR, rig at rest, no write, chamber to ambient
    (when it can still be reached)."""
    result, runner = run(sim, at_step(step, inject), on_runner=on_runner)
    assert result.outcome == Outcome.ERROR, result.message
    assert all(u.outcome == Outcome.ERROR for u in result.units), [u.message for u in result.units]
    assert result.rig_at_rest
    assert_no_eeprom_write(sim)
    if reachable:
        assert chamber_sent_to_ambient(sim)
    return result, runner


def test_chamber_alarm_during_a_plateau_is_a_station_error(sim: SimStation) -> None:
    result, runner = run_and_check(sim, "pose -z @10C", lambda: setattr(sim.chamber.faults, "alarm_code",
                                                                      int(AlarmCode.COMPRESSOR)))
    assert "station fault: chamber alarm 5 (COMPRESSOR)" in result.message
    assert not seq(runner).chamber_at_ambient  # an alarmed chamber is stopped, not driven


def test_chamber_not_answering_is_a_station_error(sim: SimStation) -> None:
    result, _ = run_and_check(sim, "soak @10C", lambda: setattr(sim.chamber.faults, "no_answer", True),
                                   reachable=False)
    assert "station fault: chamber" in result.message and "no answer from" in result.message
    assert "could not bring the chamber back to ambient" in result.message
    # unreachable, it is left to its own watchdog: the station's heartbeats do not arrive, it stops conditioning
    model = sim.chamber.model  # type: ignore[union-attr]
    deadline = time.monotonic() + 10.0
    while model.alarm_code != AlarmCode.WATCHDOG and time.monotonic() < deadline:
        sim.clock.sleep(5.0)  # chamber time passes (nobody else acts on the virtual clock now)
        model.update()
    assert model.alarm_code == AlarmCode.WATCHDOG and not model.running


def test_setpoint_not_reached_in_time_is_a_station_error(sim: SimStation) -> None:
    plan = replace(PLAN, setpoint_timeout_s=600.0)
    sim.chamber.faults.air_limits_degc = (15.0, 100.0)  # the plant cannot get the air below 15 degC
    result, _ = run(sim, plan=plan)
    assert result.outcome == Outcome.ERROR
    assert "station fault: chamber did not reach 10 degC within 600 s" in result.message
    assert_no_eeprom_write(sim)
    assert sim.chamber.model.setpoint_degc == CHAMBER["ambient_degc"]


def test_chamber_watchdog_trips_when_the_station_stops_beating(sim: SimStation) -> None:
    holder: list[SequenceRunner] = []
    # the Chamber protocol has no heartbeat switch: the Modbus chamber client (a HeartbeatClient) has
    result, _ = run_and_check(sim, "pose +x @10C",
                              lambda: seq(holder[0]).chamber.stop_heartbeat(),  # type: ignore[attr-defined]
                              on_runner=holder.append)
    assert "station fault: chamber alarm 1 (WATCHDOG)" in result.message


def test_abort_brings_the_chamber_back_to_ambient(sim: SimStation) -> None:
    holder: list[SequenceRunner] = []
    result, runner = run(sim, at_step("soak @10C", lambda: holder[0].abort("test abort")), on_runner=holder.append)
    assert result.outcome == Outcome.ABORTED and result.rig_at_rest
    assert_no_eeprom_write(sim)
    assert seq(runner).chamber_at_ambient and sim.chamber.model.setpoint_degc == CHAMBER["ambient_degc"]


def test_continuous_ramp_cycles_the_poses_while_the_temperature_rises(sim: SimStation) -> None:
    plan = replace(PLAN, mode="ramp", ramp_from_degc=15.0, ramp_to_degc=35.0, ramp_k_per_min=2.0, verify_degc=25.0,
                   ramp_rate_steps=(("z", 100.0),))
    records: list[Record] = []
    result, runner = run(sim, records.append, plan=plan)
    assert result.outcome == Outcome.PASS, result.message or [u.message for u in result.units]
    ramp_steps = [r.name for r in records if isinstance(r, StepStarted) and r.name.startswith("ramp pose")]
    assert len(ramp_steps) >= 2 * len(BASE.poses)  # 10 min of ramp: the cycle ran more than once
    assert any(r.name.startswith("ramp rate z +100 #") for r in records if isinstance(r, StepStarted))
    for slot in range(2):
        session = result.units[slot].session
        assert session is not None
        poses = session.segments_of(Kind.POSE)
        means = np.array([session.temp_degc[p.slice].mean() for p in poses])
        # the pose windows sample the whole range, rising through the ramp (self-heating on top)
        heating = sim.units[slot].truth.self_heating_k
        assert means.min() < 15.0 + heating + 0.5 and means.max() > 35.0 - 0.5
        assert means.max() - means.min() > 10.0
        assert runner.verification[slot].passed
    assert seq(runner).chamber_at_ambient
