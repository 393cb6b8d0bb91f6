"""The climate chamber over Modbus: map helpers, URLs, the thermal model of the simulated chamber,
and the station client against the simulated chamber (real pymodbus server on 127.0.0.1, a free
port, stopped by each test): identification, setpoints confirmed from status and readback, and the
faults (no answer, exception replies, alarm, setpoint not reached in time, watchdog, stalled alive
counter, a chamber that is not there)."""

from __future__ import annotations

import math
import socket
from collections.abc import Iterator

import numpy as np
import pytest

from station.chamber import (
    CHAMBERS,
    ChamberAlarm,
    ChamberProtocolError,
    ChamberSetpointTimeout,
    ChamberTimeout,
    ChamberUrlError,
    ModbusChamber,
    open_chamber,
    parse_chamber_url,
)
from station.chamber import registers as reg
from station.chamber.registers import HR, AlarmCode, Mode, Status
from station.kernel.clock import SimClock
from station.kernel.errors import HardwareError
from station.sim.chamber_server import ChamberModel, SimulatedChamber

pytestmark = pytest.mark.integration

SCALE = 400.0  # chamber seconds per wall second
WATCHDOG_S = 120  # chamber s (0.3 s wall); the client beats every 10 chamber s
CLIENT_OPTIONS = {"heartbeat_period_s": 10.0, "poll_s": 5.0, "alive_timeout_s": 60.0}


class ManualClock:
    """A clock that only moves when told (deterministic model tests)."""

    scale = 1.0

    def __init__(self, t: float = 0.0) -> None:
        self.t = t

    def now(self) -> float:
        return self.t

    def sleep(self, seconds: float) -> None:
        self.t += max(seconds, 0.0)


# ---------------------------------------------------------------------------- map helpers and URLs


@pytest.mark.parametrize("value", [0.0, -40.0, 23.5, 85.125, -1e-3])
def test_float32_round_trip(value: float) -> None:
    assert reg.regs_to_float32(reg.float32_to_regs(value)) == pytest.approx(value, rel=1e-7)


def test_float32_high_word_first() -> None:
    assert reg.float32_to_regs(1.0) == [0x3F80, 0x0000]
    assert reg.regs_to_uint32(reg.uint32_to_regs(0x12345678)) == 0x12345678
    assert reg.regs_to_ascii(reg.ascii_to_regs("CHAMBER", 8)) == "CHAMBER"


def test_parse_urls() -> None:
    u = parse_chamber_url("modbus-tcp://10.0.0.7:1502?unit=3&timeout=0.5&retries=1")
    assert (u.host, u.port, u.unit, u.timeout_s, u.retries) == ("10.0.0.7", 1502, 3, 0.5, 1)
    r = parse_chamber_url("modbus-rtu:///dev/ttyUSB1?baud=19200&parity=N")
    assert (r.device, r.baud, r.parity) == ("/dev/ttyUSB1", 19200, "N")
    assert set(CHAMBERS.schemes) >= {"modbus-tcp", "modbus-rtu"}


@pytest.mark.parametrize("url", ["http://x", "modbus-tcp://", "modbus-tcp://h:0", "modbus-tcp://h?speed=1",
                                 "modbus-tcp://h?unit=300", "modbus-rtu://", "modbus-rtu:///dev/x?parity=Q"])
def test_bad_urls(url: str) -> None:
    with pytest.raises(ChamberUrlError):
        CHAMBERS.open(url) if url.startswith("http") else parse_chamber_url(url)


def test_errors_are_hardware_errors() -> None:
    for cls in (ChamberTimeout, ChamberSetpointTimeout, ChamberProtocolError):
        assert issubclass(cls, HardwareError)
    assert isinstance(ChamberAlarm(2), HardwareError)
    assert ChamberAlarm(2).alarm_name == "OVER_TEMPERATURE"


# ---------------------------------------------------------------------------- the thermal model


def _write_setpoint(model: ChamberModel, degc: float, ramp: float = 0.0) -> None:
    assert model.write_holding(HR.SETPOINT, [*reg.float32_to_regs(degc), *reg.float32_to_regs(ramp)]) is None


def test_model_air_is_slew_limited_and_load_lags_air() -> None:
    clock = ManualClock()
    model = ChamberModel(clock, ambient_degc=23.0, heat_k_per_min=5.0, cool_k_per_min=3.0, air_tau_s=60.0,
                         load_tau_s=240.0)
    _write_setpoint(model, -17.0)
    model.write_holding(HR.MODE, [int(Mode.RUN)])
    clock.sleep(300.0)
    model.update()
    air = model.air_temperature(np.array([60.0, 300.0]))
    # cooling at most 3 K/min: after 60 s the air is at most 3 K colder
    assert air[0] == pytest.approx(20.0, abs=0.05)
    assert air[1] >= 23.0 - 3.0 * 5.0 - 1e-9
    load = model.load_temperature(np.array([300.0]))
    assert load[0] > air[1] + 2.0  # the load lags the air
    clock.sleep(3000.0)
    assert model.air_temperature(np.array([3300.0]))[0] == pytest.approx(-17.0, abs=0.01)
    assert model.load_temperature(np.array([3300.0]))[0] == pytest.approx(-17.0, abs=0.05)
    assert Status(model.input_registers()[0]) & Status.AT_SETPOINT


def test_model_ramp_follows_the_commanded_rate() -> None:
    clock = ManualClock()
    model = ChamberModel(clock, ambient_degc=20.0, air_tau_s=30.0)
    model.write_holding(HR.MODE, [int(Mode.RUN)])
    _write_setpoint(model, 40.0, 1.0)  # 1 K/min, far below the plant's limits
    clock.sleep(600.0)
    model.update()
    status = Status(model.input_registers()[0])
    assert status & Status.RAMPING and not status & Status.AT_SETPOINT
    # the working setpoint is at 30 degC after 10 min; the air lags it by rate * tau = 0.5 K
    assert reg.regs_to_float32([model.input_registers()[8], model.input_registers()[9]]) == pytest.approx(30.0)
    assert model.air_temperature(np.array([600.0]))[0] == pytest.approx(29.5, abs=0.05)


def test_model_watchdog_trips_at_deadline_and_stops_conditioning() -> None:
    clock = ManualClock()
    model = ChamberModel(clock, ambient_degc=23.0, watchdog_s=30)
    _write_setpoint(model, 60.0)
    model.write_holding(HR.MODE, [int(Mode.RUN)])
    model.write_holding(HR.HEARTBEAT, [1])
    clock.sleep(200.0)
    model.update()
    assert model.alarm_code == AlarmCode.WATCHDOG
    assert model.log[-1][0] == pytest.approx(30.0, abs=1.0)
    peak = float(model.air_temperature(np.array([30.0]))[0])
    assert model.air_temperature(np.array([200.0]))[0] < peak  # conditioning off: back towards the room
    assert not Status(model.input_registers()[0]) & Status.RUNNING


def test_model_refuses_bad_values() -> None:
    model = ChamberModel(ManualClock(), min_temp_degc=-40.0, max_temp_degc=120.0)
    assert model.write_holding(HR.SETPOINT, reg.float32_to_regs(150.0)) is not None
    assert model.write_holding(HR.RAMP_RATE, reg.float32_to_regs(-1.0)) is not None
    assert model.write_holding(HR.MODE, [7]) is not None
    assert model.write_holding(HR.WATCHDOG_S, [0]) is not None
    assert model.setpoint_degc == model.ambient_degc


# ---------------------------------------------------------------------------- client against the server


@pytest.fixture
def clock() -> SimClock:
    return SimClock(SCALE)


@pytest.fixture
def sim(clock: SimClock) -> Iterator[SimulatedChamber]:
    server = SimulatedChamber(clock, watchdog_s=WATCHDOG_S).start()
    try:
        yield server
    finally:
        server.stop()


@pytest.fixture
def chamber(sim: SimulatedChamber, clock: SimClock) -> Iterator[ModbusChamber]:
    client = open_chamber(sim.url + "&timeout=0.3", clock, **CLIENT_OPTIONS)
    try:
        yield client  # type: ignore[misc]
    finally:
        client.close()


def test_identify_and_state(chamber: ModbusChamber) -> None:
    ident = chamber.identify()
    assert ident.firmware_id == "STATION-SIMCHAMB" and ident.map_version == "1.0"
    assert (ident.min_temp_degc, ident.max_temp_degc) == (-40.0, 120.0)
    st = chamber.state()
    assert st.air_degc == pytest.approx(23.0) and not st.running and not st.alarm


def test_setpoint_confirmed_by_status_and_readback(chamber: ModbusChamber, sim: SimulatedChamber) -> None:
    chamber.set_setpoint(-10.0)
    chamber.run()
    st = chamber.wait_at_setpoint(3600.0)
    assert st.at_setpoint and abs(st.air_degc + 10.0) <= chamber.setpoint_tol_k
    # the air cannot cool faster than 3.5 K/min: 33 K took at least 9.4 min
    assert st.t_s >= 33.0 / 3.5 * 60.0
    assert sim.model.load_temperature(np.array([st.t_s]))[0] > st.air_degc  # the load still lags
    with pytest.raises(ValueError):
        chamber.set_setpoint(200.0)


def test_go_ambient_returns_the_chamber(chamber: ModbusChamber, sim: SimulatedChamber) -> None:
    chamber.set_setpoint(60.0)
    chamber.run()
    chamber.wait_at_setpoint(3600.0)
    chamber.go_ambient(23.0)
    st = chamber.wait_at_setpoint(3600.0)
    assert st.setpoint_degc == 23.0 and abs(st.air_degc - 23.0) <= 0.5


def test_fault_no_answer_is_timeout(chamber: ModbusChamber, sim: SimulatedChamber) -> None:
    sim.faults.no_answer = True
    with pytest.raises(ChamberTimeout) as info:
        chamber.state()
    assert not isinstance(info.value, ChamberSetpointTimeout)
    assert chamber.reconnects >= 1  # every attempt started over on a fresh connection
    sim.faults.no_answer = False
    # back after the outage (the chamber's watchdog may have tripped meanwhile: the heartbeats did not arrive)
    assert chamber.state().alarm_code in (0, AlarmCode.WATCHDOG)


def test_fault_exception_replies_are_protocol_errors(chamber: ModbusChamber, sim: SimulatedChamber) -> None:
    sim.faults.exception_replies = 4
    with pytest.raises(ChamberProtocolError) as info:
        chamber.state()
    assert info.value.exception_code == 4


def test_fault_alarm_stops_conditioning_and_raises(chamber: ModbusChamber, sim: SimulatedChamber,
                                                   clock: SimClock) -> None:
    chamber.set_setpoint(70.0)
    chamber.run()
    clock.sleep(120.0)
    sim.faults.alarm_code = AlarmCode.OVER_TEMPERATURE
    with pytest.raises(ChamberAlarm) as info:
        chamber.wait_at_setpoint(3600.0)
    assert info.value.alarm_code == AlarmCode.OVER_TEMPERATURE
    st = chamber.state()
    assert st.alarm and not st.running
    with pytest.raises(ChamberAlarm):  # the cause persists
        chamber.acknowledge_alarm()
    with pytest.raises(ChamberAlarm):
        chamber.run()
    chamber.go_ambient(23.0)  # works with the alarm latched: conditioning stays off
    assert sim.model.mode == Mode.STOP
    sim.faults.alarm_code = 0
    chamber.acknowledge_alarm()
    chamber.run()
    assert chamber.state().running


def test_fault_setpoint_not_reached_in_time(chamber: ModbusChamber, sim: SimulatedChamber) -> None:
    sim.faults.air_limits_degc = (0.0, 100.0)  # a weak compressor: 0 degC is as cold as it gets
    chamber.set_setpoint(-30.0)
    chamber.run()
    with pytest.raises(ChamberSetpointTimeout) as info:
        chamber.wait_at_setpoint(1800.0)
    st = info.value.state
    assert st is not None and st.air_degc == pytest.approx(0.0, abs=0.01) and not st.at_setpoint
    assert isinstance(info.value, HardwareError)


def test_watchdog_fed_by_the_client_then_trips_when_it_stops(chamber: ModbusChamber, sim: SimulatedChamber,
                                                              clock: SimClock) -> None:
    chamber.set_setpoint(40.0)
    chamber.run()
    clock.sleep(5 * WATCHDOG_S)  # 5 watchdog periods while the client beats
    st = chamber.state()
    assert st.has(Status.WATCHDOG_ARMED) and st.running and not st.alarm
    chamber.stop_heartbeat()
    clock.sleep(2 * WATCHDOG_S)
    st = chamber.state()
    assert st.alarm_code == AlarmCode.WATCHDOG and not st.running
    with pytest.raises(ChamberAlarm):
        chamber.check()
    chamber.acknowledge_alarm()  # the cause (no heartbeat) is gone once one arrives again
    chamber.start_heartbeat()
    chamber.run()
    assert chamber.check().running


def test_fault_alive_counter_stalled_is_timeout(chamber: ModbusChamber, sim: SimulatedChamber,
                                                clock: SimClock) -> None:
    chamber.state()
    sim.faults.alive_stalled = True
    chamber.state()
    clock.sleep(2 * chamber.alive_timeout_s)
    with pytest.raises(ChamberTimeout):
        chamber.state()


def test_nonsense_and_map_version_are_protocol_errors(chamber: ModbusChamber, sim: SimulatedChamber) -> None:
    sim.model._air[-1] = math.nan
    with pytest.raises(ChamberProtocolError):
        chamber.state()
    sim.model._air[-1] = 23.0
    sim.model.firmware_version = 0x0100
    old = reg.MAP_VERSION
    try:
        reg.MAP_VERSION = 0x0200
        with pytest.raises(ChamberProtocolError):
            chamber.identify()
    finally:
        reg.MAP_VERSION = old


def test_no_chamber_is_timeout(clock: SimClock) -> None:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    with pytest.raises(ChamberTimeout):
        open_chamber(f"modbus-tcp://127.0.0.1:{port}?timeout=0.2&retries=1", clock)
