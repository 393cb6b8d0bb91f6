"""The rig over Modbus: register map helpers, URL parsing, the rig model, and the
station client against the simulated rig (real pymodbus server on 127.0.0.1)."""

from __future__ import annotations

import logging
import math
import os
import socket
import warnings
from collections.abc import Iterator

import numpy as np
import pytest

from station.kernel.clock import SimClock
from station.kernel.errors import HardwareError, StationError
from station.kernel.geometry import POSE_ANGLES_DEG, up_vector
from station.physics.motion import AxisTrajectory
from station.rig import (
    ModbusRig,
    Rig,
    RigCommandRejected,
    RigFault,
    RigMotionTimeout,
    RigProtocolError,
    RigTimeout,
    RigUrlError,
    open_rig,
    parse_rig_url,
)
from station.rig import registers as reg
from station.rig.registers import HR, AckResult, Command, FaultCode, Status
from station.sim.rig_server import RigModel, SimulatedRig

pytestmark = pytest.mark.integration

SCALE = 50.0  # rig seconds per wall second
WATCHDOG_S = 60.0  # rig s (1.2 s wall); the client beats every 2 rig s
CLIENT_OPTIONS = {"heartbeat_period_s": 2.0, "poll_s": 0.25}


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


@pytest.mark.parametrize("value", [0.0, 1.5, -90.0, 180.0, 123.456, -1e-3, math.inf])
def test_float32_round_trip_high_word_first(value: float) -> None:
    regs = reg.float32_to_regs(value)
    assert all(0 <= r <= 0xFFFF for r in regs)
    assert reg.regs_to_float32(regs) == pytest.approx(value, rel=1e-7)


def test_float32_word_order_is_big_endian() -> None:
    # 1.0f = 0x3F800000: high word first
    assert reg.float32_to_regs(1.0) == [0x3F80, 0x0000]
    assert reg.uint32_to_regs(0x12345678) == [0x1234, 0x5678]
    assert reg.regs_to_uint32([0x1234, 0x5678]) == 0x12345678


def test_ascii_registers() -> None:
    regs = reg.ascii_to_regs("SIM-1", 4)
    assert regs == [0x5349, 0x4D2D, 0x3100, 0x0000]
    assert reg.regs_to_ascii(regs) == "SIM-1"


def test_angle_error_wraps() -> None:
    assert reg.angle_error_deg(-180.0, 180.0) == 0.0
    assert reg.angle_error_deg(179.0, -179.0) == pytest.approx(-2.0)
    assert math.isnan(reg.angle_error_deg(math.nan, 0.0))


def test_parse_tcp_url() -> None:
    u = parse_rig_url("modbus-tcp://10.0.0.5:1502?unit=7&timeout=0.5&retries=1")
    assert (u.host, u.port, u.unit, u.timeout_s, u.retries) == ("10.0.0.5", 1502, 7, 0.5, 1)
    assert parse_rig_url("modbus-tcp://rig.local").port == 502


def test_parse_rtu_url() -> None:
    u = parse_rig_url("modbus-rtu:///dev/ttyX?baud=115200&parity=N&unit=1")
    assert (u.device, u.baud, u.parity, u.unit, u.stopbits, u.bytesize) == ("/dev/ttyX", 115200, "N", 1, 1, 8)
    assert parse_rig_url("modbus-rtu:///dev/ttyUSB0").parity == "E"  # Modbus serial default 8E1


@pytest.mark.parametrize(
    "url",
    [
        "http://host",
        "modbus-tcp://",
        "modbus-tcp://host?unit=300",
        "modbus-tcp://host?speed=9",
        "modbus-rtu://?baud=9600",
        "modbus-rtu:///dev/ttyS0?parity=X",
        "modbus-rtu:///dev/ttyS0?baud=fast",
    ],
)
def test_bad_urls(url: str) -> None:
    with pytest.raises(RigUrlError) as info:
        parse_rig_url(url)
    assert isinstance(info.value, StationError)


def test_errors_are_hardware_errors() -> None:
    for cls in (RigTimeout, RigMotionTimeout, RigProtocolError, RigCommandRejected, RigFault):
        assert issubclass(cls, HardwareError)
    assert RigFault(4).fault_name == "DRIVE_PITCH"


# ---------------------------------------------------------------------------- the rig model (no network)


def _command(
    model: RigModel, seq: int, command: Command, roll: float = 0.0, pitch: float = 0.0, rate: float = 0.0
) -> None:
    values = [int(command), seq, *reg.float32_to_regs(roll), *reg.float32_to_regs(pitch), *reg.float32_to_regs(rate)]
    assert model.write_holding(HR.COMMAND, values) is None


def test_model_status_follows_trapezoid_and_settle() -> None:
    clock = ManualClock()
    model = RigModel(clock, tumble_rate_dps=30.0, tumble_accel_dps2=60.0, settle_s=0.5)
    _command(model, 1, Command.MOVE_TO_ORIENTATION, roll=0.0, pitch=-90.0)
    assert model.ack_seq == 1 and model.ack_result == AckResult.OK
    # pitch: 0.5 s accel (7.5 deg), 2.5 s coast (75 deg), 0.5 s decel: ends at 3.5 s
    clock.t = 1.0
    _, pitch, _, _, status = model.readback()
    assert pitch == pytest.approx(-(7.5 + 15.0))
    assert status & Status.MOVING and not status & (Status.IN_POSITION | Status.AT_REST)
    clock.t = 3.7
    _, pitch, _, _, status = model.readback()
    assert pitch == pytest.approx(-90.0)
    assert status & Status.AT_REST and not status & Status.IN_POSITION  # still settling
    clock.t = 4.01
    assert model.readback()[4] & Status.IN_POSITION
    kin = model.kinematics(np.array([4.01]))
    np.testing.assert_allclose(kin.up_in_sensor()[0], up_vector("+x"), atol=1e-12)


def test_model_kinematics_match_trajectory() -> None:
    clock = ManualClock()
    model = RigModel(clock, table_accel_dps2=50.0, settle_s=0.5)
    _command(model, 1, Command.SPIN, rate=100.0)
    ref = AxisTrajectory()
    ref.ramp_rate(math.radians(100.0), math.radians(50.0))
    t = np.linspace(0.0, 3.0, 31)
    clock.t = 3.0
    angle, rate, _ = model.axis_states(t)
    p, v, _ = ref.state(t)
    np.testing.assert_allclose(angle[:, 2], p, atol=1e-12)
    np.testing.assert_allclose(rate[:, 2], v, atol=1e-12)
    kin = model.kinematics(t)
    np.testing.assert_allclose(kin.omega_radps[:, 2], v, atol=1e-12)  # pose +z: the z gyro sees the table
    assert model.readback()[4] & Status.RATE_SETTLED


def test_model_repeated_sequence_number_runs_once() -> None:
    clock = ManualClock()
    model = RigModel(clock)
    _command(model, 5, Command.MOVE_TO_ORIENTATION, roll=90.0)
    clock.t = 20.0
    _command(model, 5, Command.MOVE_TO_ORIENTATION, roll=-90.0)  # retried write: ignored
    assert len(model.commands) == 1
    assert model.readback()[0] == pytest.approx(90.0)


def test_model_watchdog_trips_at_deadline_and_stops_mid_move() -> None:
    clock = ManualClock()
    model = RigModel(clock, tumble_rate_dps=30.0, tumble_accel_dps2=60.0, watchdog_s=2.0)
    assert model.write_holding(HR.HEARTBEAT, [1]) is None
    clock.t = 1.0
    _command(model, 1, Command.MOVE_TO_ORIENTATION, roll=180.0)
    clock.t = 10.0  # nothing heard since t = 0: tripped at t = 2, 1 s into the move
    roll, _, _, _, status = model.readback()
    assert model.fault_code == FaultCode.WATCHDOG and model.fault_time == 2.0
    # at t=2: 7.5 deg (accel) + 15 deg (coast) at 30 deg/s; decel 0.5 s adds 7.5 deg
    assert roll == pytest.approx(30.0)
    assert status & Status.FAULT and status & Status.AT_REST and not status & Status.READY
    _command(model, 2, Command.MOVE_TO_ORIENTATION, roll=180.0)
    assert model.ack_result == AckResult.FAULTED
    _command(model, 3, Command.RESET_FAULT)
    assert model.ack_result == AckResult.OK and model.fault_code == 0


def test_model_home_returns_yaw_to_zero_mark() -> None:
    clock = ManualClock()
    model = RigModel(clock, table_accel_dps2=50.0)
    _command(model, 1, Command.SPIN, rate=100.0)
    clock.t = 5.3
    _command(model, 2, Command.MOVE_TO_ORIENTATION, roll=90.0)
    assert model.ack_result == AckResult.NOT_AT_REST  # table still spinning
    _command(model, 3, Command.STOP)
    clock.t = 20.0
    yaw_before = model.axis_states(np.array([20.0]))[0][0, 2]
    assert abs(math.remainder(yaw_before, 2 * math.pi)) > 0.1
    _command(model, 4, Command.HOME)
    assert model.ack_result == AckResult.OK
    clock.t = 60.0
    roll, pitch, yaw, rate, status = model.readback()
    assert (roll, pitch, rate) == (0.0, 0.0, 0.0)
    assert yaw == pytest.approx(0.0, abs=1e-9)
    yaw_after = model.axis_states(np.array([60.0]))[0][0, 2]
    assert yaw_after == pytest.approx(2 * math.pi * round(yaw_before / (2 * math.pi)), abs=1e-12)
    assert status & Status.IN_POSITION and status & Status.AT_REST


def test_model_rejects_bad_targets_and_watchdog_values() -> None:
    clock = ManualClock()
    model = RigModel(clock, max_rate_dps=200.0)
    _command(model, 1, Command.MOVE_TO_ORIENTATION, roll=math.nan)
    assert model.ack_result == AckResult.OUT_OF_RANGE
    _command(model, 2, Command.SPIN, rate=250.0)
    assert model.ack_result == AckResult.OUT_OF_RANGE
    _command(model, 3, 99)  # type: ignore[arg-type]
    assert model.ack_result == AckResult.UNKNOWN_COMMAND
    assert model.write_holding(HR.WATCHDOG_MS, [50]) is not None
    assert model.watchdog_s == 2.0


# ---------------------------------------------------------------------------- client against the server


@pytest.fixture
def clock() -> SimClock:
    return SimClock(scale=SCALE)


@pytest.fixture
def sim(clock: SimClock) -> Iterator[SimulatedRig]:
    server = SimulatedRig(clock, watchdog_s=WATCHDOG_S)
    server.start()
    try:
        yield server
    finally:
        server.stop()


@pytest.fixture
def rig(sim: SimulatedRig, clock: SimClock) -> Iterator[ModbusRig]:
    client = open_rig(sim.url + "&timeout=0.3", clock, **CLIENT_OPTIONS)
    try:
        yield client
    finally:
        client.close()


def _recover(rig: ModbusRig, sim: SimulatedRig) -> None:
    """stop() brings the rig to rest after a fault."""
    rig.stop()
    st = rig.wait_at_rest(60.0)
    assert st.at_rest and abs(st.rate_dps) <= rig.rate_tol_dps
    assert sim.readback()[4] & Status.AT_REST


def test_identify(rig: ModbusRig) -> None:
    ident = rig.identify()
    assert ident.firmware_id == "STATION-SIMRIG"
    assert ident.map_version == "1.0" and ident.firmware_version == "1.0"
    assert ident.max_rate_dps == 500.0
    assert isinstance(rig, Rig)


def test_six_poses_confirmed_by_readbacks(rig: ModbusRig, sim: SimulatedRig, clock: SimClock) -> None:
    for pose, (roll, pitch) in POSE_ANGLES_DEG.items():
        rig.move_to(pose)
        st = rig.wait_in_position(60.0)
        assert st.in_position and not st.moving and not st.fault
        assert abs(reg.angle_error_deg(st.roll_deg, roll)) <= 1e-4
        assert abs(reg.angle_error_deg(st.pitch_deg, pitch)) <= 1e-4
        # the rig really is there: the sensor's pose axis points up
        kin = sim.kinematics(np.array([clock.now()]))
        np.testing.assert_allclose(kin.up_in_sensor()[0], up_vector(pose), atol=1e-9)
    assert [c[2] for c in sim.model.commands] == [0] * 6


def test_spin_both_ways_and_back_to_rest(rig: ModbusRig, sim: SimulatedRig, clock: SimClock) -> None:
    rig.move_to("+x")
    rig.wait_in_position(60.0)
    for rate in (100.0, -100.0):
        rig.spin(rate)
        st = rig.wait_rate_settled(60.0)
        assert st.rate_dps == pytest.approx(rate, abs=1e-4)
        kin = sim.kinematics(np.array([clock.now()]))
        # pose +x: the x gyro sees the table rate
        np.testing.assert_allclose(kin.omega_radps[0], [math.radians(rate), 0.0, 0.0], atol=1e-9)
    with pytest.raises(RigCommandRejected) as info:
        rig.move_to("+z")  # tumbling while the table spins is refused
    assert info.value.result == AckResult.NOT_AT_REST
    rig.stop()
    st = rig.wait_at_rest(60.0)
    assert st.rate_dps == 0.0 and st.at_rest


def test_heartbeat_keeps_watchdog_quiet_then_trip_stops_motion(
    rig: ModbusRig, sim: SimulatedRig, clock: SimClock
) -> None:
    rig.heartbeat_period_s = 1.0
    rig.write_watchdog(10.0)
    clock.sleep(30.0)  # three watchdog periods with the heartbeat thread running: no trip
    st = rig.state()
    assert st.has(Status.WATCHDOG_ARMED) and not st.fault and st.heartbeat_echo > 0
    rig.stop_heartbeat()
    rig.beat()
    rig.write_watchdog(2.0)
    with pytest.raises(RigFault) as info:
        rig.move_to("-z")  # 6.5 s move; the watchdog trips after 2 s
        rig.wait_in_position(60.0)
    assert info.value.fault_code == FaultCode.WATCHDOG
    _recover(rig, sim)
    assert sim.readback()[0] < 179.0  # stopped on the way
    rig.start_heartbeat()
    rig.write_watchdog(WATCHDOG_S)
    rig.reset_fault()
    rig.move_to("-z")
    assert rig.wait_in_position(60.0).roll_deg == pytest.approx(180.0)


def test_fault_no_answer_is_timeout(rig: ModbusRig, sim: SimulatedRig) -> None:
    sim.faults.no_answer = True
    with pytest.raises(RigTimeout) as info:
        rig.state()
    assert not isinstance(info.value, RigMotionTimeout)
    sim.faults.no_answer = False
    _recover(rig, sim)


def test_fault_exception_replies_are_protocol_errors(rig: ModbusRig, sim: SimulatedRig) -> None:
    sim.faults.exception_replies = 4  # SLAVE_DEVICE_FAILURE
    with pytest.raises(RigProtocolError) as info:
        rig.move_to("+y")
    assert info.value.exception_code == 4
    sim.faults.exception_replies = 0
    _recover(rig, sim)


def test_fault_stuck_in_position_is_motion_timeout(rig: ModbusRig, sim: SimulatedRig) -> None:
    sim.faults.stuck_in_position = True
    rig.move_to("+y")
    with pytest.raises(RigMotionTimeout) as info:
        rig.wait_in_position(15.0)
    last = info.value.state
    assert last is not None and not last.in_position
    assert last.roll_deg == pytest.approx(90.0)  # there, but never confirmed
    _recover(rig, sim)


def test_fault_bit_raises_rig_fault_with_code(rig: ModbusRig, sim: SimulatedRig) -> None:
    rig.move_to("-z")
    sim.faults.fault_code = FaultCode.DRIVE_PITCH
    with pytest.raises(RigFault) as info:
        rig.wait_in_position(60.0)
    assert info.value.fault_code == FaultCode.DRIVE_PITCH
    _recover(rig, sim)
    with pytest.raises(RigFault):  # cause persists
        rig.reset_fault()
    sim.faults.fault_code = 0
    rig.reset_fault()
    rig.move_to("-z")
    assert rig.wait_in_position(60.0).roll_deg == pytest.approx(180.0)


def test_fault_dropped_connection_is_survived(rig: ModbusRig, sim: SimulatedRig) -> None:
    sim.faults.drop_connection_mid_motion = True
    rig.move_to("-z")
    st = rig.wait_in_position(60.0)
    assert st.roll_deg == pytest.approx(180.0)
    assert sim.connections_dropped >= 1 and rig.reconnects >= 1
    assert not sim.faults.drop_connection_mid_motion  # one shot


def test_fault_dropped_connection_then_silence_is_timeout(rig: ModbusRig, sim: SimulatedRig) -> None:
    sim.faults.drop_connection_mid_motion = True
    rig.move_to("-z")
    with pytest.raises(RigTimeout):
        while True:  # the drop fires halfway; then the rig stays silent
            st = rig.state()
            if sim.connections_dropped:
                sim.faults.no_answer = True
            if st.in_position and st.roll_deg == pytest.approx(180.0):
                pytest.fail("the move finished before the connection dropped")
            rig.clock.sleep(rig.poll_s)
    sim.faults.no_answer = False
    _recover(rig, sim)


def test_fault_estop(rig: ModbusRig, sim: SimulatedRig) -> None:
    rig.spin(100.0)
    sim.faults.estop = True
    with pytest.raises(RigFault) as info:
        rig.wait_rate_settled(60.0)
    assert info.value.fault_code == FaultCode.ESTOP
    st = rig.wait_at_rest(60.0)  # the rig stops by itself
    assert st.estop and st.fault and not st.ready
    with pytest.raises(RigFault):
        rig.reset_fault()  # still pressed
    sim.faults.estop = False
    rig.reset_fault()
    assert rig.state().ready
    _recover(rig, sim)


def test_fault_local_mode_refuses_commands(rig: ModbusRig, sim: SimulatedRig) -> None:
    sim.faults.local_mode = True
    with pytest.raises(RigCommandRejected) as info:
        rig.move_to("+x")
    assert info.value.result == AckResult.NOT_REMOTE
    sim.faults.local_mode = False
    _recover(rig, sim)


def test_fault_alive_counter_stalled_is_timeout(rig: ModbusRig, sim: SimulatedRig, clock: SimClock) -> None:
    sim.faults.alive_stalled = True
    with pytest.raises(RigTimeout, match="alive"):
        for _ in range(200):
            rig.state()
            clock.sleep(0.5)
    sim.faults.alive_stalled = False
    _recover(rig, sim)


def test_nan_readback_is_protocol_error(rig: ModbusRig, sim: SimulatedRig) -> None:
    sim.faults.nan_angle = True
    with pytest.raises(RigProtocolError, match="nonsense roll"):
        rig.state()
    sim.faults.nan_angle = False
    _recover(rig, sim)


def test_illegal_watchdog_value_gets_exception_reply(rig: ModbusRig) -> None:
    with pytest.raises(RigProtocolError) as info:
        rig._write(HR.WATCHDOG_MS, [50], "watchdog")
    assert info.value.exception_code == 3  # ILLEGAL_DATA_VALUE


def test_no_rig_is_timeout(clock: SimClock) -> None:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    with pytest.raises(RigTimeout):
        open_rig(f"modbus-tcp://127.0.0.1:{port}?timeout=0.2&retries=1", clock)


def test_no_deprecation_warnings(clock: SimClock, caplog: pytest.LogCaptureFixture) -> None:
    caplog.set_level(logging.WARNING)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        with SimulatedRig(clock, watchdog_s=WATCHDOG_S) as server:
            client = open_rig(server.url, clock, **CLIENT_OPTIONS)
            try:
                client.move_to("+y")
                client.wait_in_position(60.0)
            finally:
                client.close()
    deprecations = [w for w in caught if issubclass(w.category, DeprecationWarning | PendingDeprecationWarning)]
    assert deprecations == []
    assert not [r for r in caplog.records if "deprecat" in r.getMessage().lower()]


@pytest.mark.skipif(os.name != "posix", reason="needs a pty pair")
def test_rtu_over_pty(clock: SimClock) -> None:
    with SimulatedRig(clock, transport="rtu", watchdog_s=WATCHDOG_S) as server:
        assert server.url.startswith("modbus-rtu:///dev/")
        client = open_rig(server.url + "&timeout=0.3", clock, **CLIENT_OPTIONS)
        try:
            assert client.identify().map_version == "1.0"
            client.move_to("-x")
            assert client.wait_in_position(60.0).pitch_deg == pytest.approx(90.0)
            client.spin(50.0)
            assert client.wait_rate_settled(60.0).rate_dps == pytest.approx(50.0)
            client.stop()
            assert client.wait_at_rest(60.0).at_rest
        finally:
            client.close()
