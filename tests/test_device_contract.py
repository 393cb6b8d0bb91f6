"""One behavioural contract, two implementations: the wire peers and the in-process fakes.

Every test runs twice: on a :class:`~station.sim.station_sim.SimStation` (a Modbus/TCP rig server
on 127.0.0.1, sensors on ptys, the station's Modbus and serial clients) and on a
:class:`~station.sim.fakes.FakeStation` (the same simulated rig and sensors, reached in process by
``fake-rig://`` and ``fake-sensor://`` URLs). Devices are opened by URL through the scheme
registries, as the station opens them, and both must pass the same assertions: what the
sequence, provisioning and verification rely on from a rig and a sensor.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass
from datetime import UTC, datetime

import numpy as np
import pytest

from station.compose import Station, StationConfig
from station.eeprom.image import CalibrationImage
from station.eeprom.provision import read_current_image, write_image
from station.kernel.clock import ManualClock
from station.kernel.geometry import POSE_ANGLES_DEG, up_vector
from station.kernel.plan import RigPlan
from station.rig import Rig, RigCommandRejected, RigFault, RigMotionTimeout, RigState, open_rig
from station.rig import registers as reg
from station.rig.registers import AckResult, FaultCode
from station.sensor import NakCode, OutputMode, SampleBlock, SampleFlag, Sensor, SensorNak, SensorTimeout, open_sensor
from station.sequence.records import Outcome
from station.sim.fakes import FakeStation
from station.sim.firmware import install_firmware
from station.sim.station_sim import SimStation, SimulatedStation, SimUnit

SCALE = 50.0
SEED = 21
SENSOR_OPTIONS = {"command_timeout_s": 0.3, "attempts": 2}


@dataclass
class Bench:
    """One simulated station and the station's clients of its rig and first sensor, opened by URL."""

    kind: str
    station: SimulatedStation
    rig: Rig
    sensor: Sensor

    @property
    def unit(self) -> SimUnit:
        return self.station.units[0]

    def stop_and_drain(self) -> SampleBlock:
        """Stop streaming; everything sent before the STOP answer has arrived by then."""
        self.sensor.stop_stream()
        return self.sensor.drain()


@pytest.fixture(params=[pytest.param("wire", marks=pytest.mark.integration), "fake"])
def bench(request: pytest.FixtureRequest) -> Iterator[Bench]:
    cls = SimStation if request.param == "wire" else FakeStation
    with cls(1, SCALE, SEED) as station:
        rig = open_rig(station.rig_url, station.clock, **station.rig_client_options())
        sensor = open_sensor(station.sensor_urls[0], station.clock, **SENSOR_OPTIONS)  # type: ignore[arg-type]
        try:
            yield Bench(request.param, station, rig, sensor)
        finally:
            sensor.close()
            rig.close()


def test_urls_select_the_implementation(bench: Bench) -> None:
    scheme = {"wire": ("modbus-tcp://", "serial://"), "fake": ("fake-rig://", "fake-sensor://")}[bench.kind]
    assert bench.station.rig_url.startswith(scheme[0]) and bench.station.sensor_urls[0].startswith(scheme[1])
    assert isinstance(bench.rig, Rig) and isinstance(bench.sensor, Sensor)
    assert bench.sensor.url == bench.station.sensor_urls[0]


# --- the rig ------------------------------------------------------------------------------------------


def test_rig_identify(bench: Bench) -> None:
    ident = bench.rig.identify()
    assert ident.firmware_id == "STATION-SIMRIG"
    assert ident.map_version == "1.0" and ident.firmware_version == "1.0"
    assert ident.max_rate_dps == 500.0
    st = bench.rig.state()
    assert st.ready and st.at_rest and not st.fault and st.remote and st.fault_code == 0


def test_rig_moves_to_every_pose(bench: Bench) -> None:
    rig, sim = bench.rig, bench.station.rig
    for pose, (roll, pitch) in POSE_ANGLES_DEG.items():
        rig.move_to(pose)
        st = rig.wait_in_position(60.0)
        assert st.in_position and not st.moving and not st.fault
        assert abs(reg.angle_error_deg(st.roll_deg, roll)) <= 1e-4
        assert abs(reg.angle_error_deg(st.pitch_deg, pitch)) <= 1e-4
        kin = sim.kinematics(np.array([bench.station.clock.now()]))  # the sensor's pose axis points up
        np.testing.assert_allclose(kin.up_in_sensor()[0], up_vector(pose), atol=1e-9)
    assert [c[2] for c in sim.model.commands] == [AckResult.OK] * 6
    with pytest.raises(ValueError):
        rig.move_to((0.0, 95.0))  # beyond the gimbal: refused before anything is sent


def test_rig_spins_and_comes_to_rest(bench: Bench) -> None:
    rig = bench.rig
    rig.move_to("+x")
    rig.wait_in_position(60.0)
    for rate in (100.0, -100.0):
        rig.spin(rate)
        st = rig.wait_rate_settled(60.0)
        assert st.rate_dps == pytest.approx(rate, abs=1e-4) and st.rate_settled
        kin = bench.station.rig.kinematics(np.array([bench.station.clock.now()]))
        np.testing.assert_allclose(kin.omega_radps[0], [math.radians(rate), 0.0, 0.0], atol=1e-9)
    with pytest.raises(RigCommandRejected) as info:
        rig.move_to("+z")  # tumbling while the table spins is refused
    assert info.value.result == AckResult.NOT_AT_REST
    with pytest.raises(ValueError):
        rig.spin(600.0)  # beyond the rig's maximum rate
    rig.stop()
    st = rig.wait_at_rest(60.0)
    assert st.rate_dps == 0.0 and st.at_rest and not st.moving


def test_rig_fault_latches_until_reset(bench: Bench) -> None:
    rig, faults = bench.rig, bench.station.rig.faults
    rig.move_to("-z")
    faults.fault_code = FaultCode.DRIVE_PITCH
    with pytest.raises(RigFault) as info:
        rig.wait_in_position(60.0)
    assert info.value.fault_code == FaultCode.DRIVE_PITCH and info.value.fault_name == "DRIVE_PITCH"
    st = rig.wait_at_rest(60.0)  # stop() is not even needed: a fault brings every axis to rest
    assert st.fault and not st.ready and st.fault_code == FaultCode.DRIVE_PITCH
    with pytest.raises(RigFault):
        rig.move_to("+x")  # nothing moves while a fault is latched
    rig.stop()  # accepted also while faulted
    with pytest.raises(RigFault):
        rig.reset_fault()  # its cause persists
    faults.fault_code = 0
    rig.reset_fault()
    assert rig.state().ready
    rig.move_to("-z")
    assert rig.wait_in_position(60.0).roll_deg == pytest.approx(180.0)


def test_rig_estop_and_motion_timeout(bench: Bench) -> None:
    rig, faults = bench.rig, bench.station.rig.faults
    rig.spin(100.0)
    faults.estop = True
    with pytest.raises(RigFault) as info:
        rig.wait_rate_settled(60.0)
    assert info.value.fault_code == FaultCode.ESTOP
    st = rig.wait_at_rest(60.0)
    assert st.estop and st.fault and not st.ready
    faults.estop = False
    rig.reset_fault()
    faults.stuck_in_position = True
    rig.move_to("+y")
    with pytest.raises(RigMotionTimeout) as timeout:
        rig.wait_in_position(15.0)
    last = timeout.value.state
    assert last is not None and not last.in_position and last.roll_deg == pytest.approx(90.0)


def test_rig_listeners_and_reconnects(bench: Bench) -> None:
    rig = bench.rig
    seen: list[RigState] = []
    rig.listeners.append(seen.append)
    rig.move_to("+y")
    rig.wait_in_position(60.0)
    assert seen and all(isinstance(s, RigState) for s in seen) and seen[-1].in_position
    assert [s.t_s for s in seen] == sorted(s.t_s for s in seen)
    assert rig.reconnects == 0
    rig.listeners.remove(seen.append)
    bench.station.rig.faults.drop_connection_mid_motion = True
    rig.move_to("-z")
    st = rig.wait_in_position(60.0)
    assert st.roll_deg == pytest.approx(180.0)  # the motion survives the dropped link ...
    assert rig.reconnects >= 1 and bench.station.rig.connections_dropped >= 1  # ... which is counted
    assert not bench.station.rig.faults.drop_connection_mid_motion  # one shot


# --- the sensor -----------------------------------------------------------------------------------------


def test_sensor_identify_and_status(bench: Bench) -> None:
    ident = bench.sensor.identify()
    assert ident.serial == bench.unit.truth.serial
    assert ident.rates_hz == (10, 50, 100, 200, 250, 500, 1000)
    assert ident.default_rate_hz == int(bench.station.plan.sample_rate_hz)
    assert ident.accel_range_mps2 == pytest.approx(16 * 9.80665, rel=1e-6)
    status = bench.sensor.status()
    assert not status.streaming and status.output == OutputMode.RAW and status.boot_count == 1
    with pytest.raises(SensorNak) as err:
        bench.sensor.start_stream(123)
    assert err.value.code == NakCode.UNSUPPORTED_RATE and bench.sensor.stats().naks == 1


def test_sensor_streams_at_the_requested_rate(bench: Bench) -> None:
    c, clock = bench.sensor, bench.station.clock
    c.start_stream(100)
    first = c.read_samples(duration_s=5.0)  # five sensor seconds
    assert len(first) == 500
    np.testing.assert_array_equal(np.diff(np.round(first.t_s * 1e6).astype(np.int64)), 10_000)
    assert first.flags[0] == SampleFlag.STREAM_START and not first.flags[1:].any()
    more = c.read_samples(n=50)
    assert len(more) == 50
    clock.sleep(2.0)
    uptime = c.status().uptime_s  # the sensor's own clock, sampled mid-stream
    assert c.status().streaming
    rest = bench.stop_and_drain()
    assert not c.status().streaming
    block = SampleBlock.concat([first, more, rest])
    t0 = block.t_s[0]
    assert uptime - t0 >= 7.0
    # the sensor sent exactly the samples whose time had come by its clock
    assert np.count_nonzero(block.t_s <= uptime + 1e-9) == int((uptime - t0 + 1e-9) / 0.01) + 1
    np.testing.assert_array_equal(np.diff(block.seq.astype(np.int64)) % 65536, 1)
    assert not block.corrected.any()
    mean_a = block.accel_mps2.mean(axis=0)  # at rest, +z up
    assert abs(np.linalg.norm(mean_a) / bench.station.plan.gravity_mps2 - 1.0) < 0.05 and mean_a[2] > 9.0
    s = c.stats()
    assert (s.gaps, s.lost_frames, s.crc_errors, s.timeouts, s.naks) == (0, 0, 0, 0, 0)
    assert s.samples == len(block) and s.frames >= s.samples
    with pytest.raises(ValueError):
        c.read_samples()
    with pytest.raises(SensorTimeout):
        c.read_samples(n=10, timeout_s=1.0)  # not streaming: nothing comes


def test_sensor_samples_follow_the_rig(bench: Bench) -> None:
    bench.rig.move_to("+x")
    bench.rig.wait_in_position(60.0)
    bench.rig.spin(90.0)
    bench.rig.wait_rate_settled(60.0)
    c = bench.sensor
    c.drain()
    c.start_stream(100)
    block = c.read_samples(duration_s=2.0)
    bench.stop_and_drain()
    bench.rig.stop()
    bench.rig.wait_at_rest(60.0)
    g = bench.station.plan.gravity_mps2
    np.testing.assert_allclose(block.accel_mps2.mean(axis=0), [g, 0.0, 0.0], atol=0.6)  # +x up
    np.testing.assert_allclose(np.degrees(block.gyro_radps.mean(axis=0)), [90.0, 0.0, 0.0], atol=3.0)


def test_power_cycle_restarts_sensor_time(bench: Bench) -> None:
    c = bench.sensor
    c.identify()
    boots0, restarts0 = c.stats().boots, c.stats().restarts
    c.start_stream(100)
    before = c.read_samples(duration_s=3.0)
    c.power_cycle()
    status = c.status()
    assert not status.streaming and status.boot_count == 2 and status.uptime_s < before.t_s[-1]
    c.drain()
    c.start_stream(100)
    after = c.read_samples(n=20)
    bench.stop_and_drain()
    assert after.seq[0] == 0 and after.t_s[0] < before.t_s[-1]
    assert after.flags[0] == SampleFlag.STREAM_START
    s = c.stats()
    assert (s.boots - boots0, s.restarts - restarts0, s.gaps) == (1, 1, 0)
    assert bench.unit.source.boots == 2  # the physics restarted with the power (drift g(0) = 1)


def test_eeprom_info_and_page_round_trip(bench: Bench) -> None:
    c, eeprom = bench.sensor, bench.unit.sensor.eeprom
    info = c.eeprom_info()
    assert (info.size, info.page_size, info.write_protect, info.write_cycle_s) == (4096, 32, False, 0.005)
    data = bytes((7 * i + 3) % 256 for i in range(300))
    c.start_stream(100)  # EEPROM traffic while streaming
    c.eeprom_write_page(64, b"\x22" * 32)
    assert c.eeprom_read(64, 32) == b"\x22" * 32
    c.eeprom_write(1000, data, info.page_size)
    assert c.eeprom_read(1000, 300) == data
    assert c.eeprom_read(990, 10) == b"\xff" * 10
    bench.stop_and_drain()
    assert eeprom.image()[1000:1300] == data
    assert eeprom.page_writes == 1 + 10  # 1000 is 8 bytes into page 31: 24 + 8 * 32 + 20 bytes
    assert c.stats().gaps == 0


def test_eeprom_refusals(bench: Bench) -> None:
    c, eeprom = bench.sensor, bench.unit.sensor.eeprom
    eeprom.write_protect = True
    assert c.eeprom_info().write_protect
    with pytest.raises(SensorNak) as err:
        c.eeprom_write_page(0, b"calib")
    assert err.value.code == NakCode.WRITE_PROTECTED
    eeprom.write_protect = False
    with pytest.raises(SensorNak) as err:
        c.eeprom_write_page(30, b"abcd")
    assert err.value.code == NakCode.PAGE_BOUNDARY
    with pytest.raises(SensorNak) as err:
        c.eeprom_read(4090, 10)
    assert err.value.code == NakCode.ADDRESS_RANGE
    assert eeprom.page_writes == 0 and c.stats().naks == 3


def test_eeprom_power_loss_mid_write(bench: Bench) -> None:
    c, peer = bench.sensor, bench.unit.sensor
    c.eeprom_write_page(64, b"\x22" * 32)
    boots0 = c.stats().boots
    peer.eeprom.power_loss_after(5)
    with pytest.raises(SensorTimeout):
        c.eeprom_write_page(72, bytes(range(16)))
    assert not peer.powered
    peer.power_on()
    page = c.eeprom_read(64, 32)
    assert page == b"\x22" * 8 + bytes(range(5)) + b"\xff" * 11 + b"\x22" * 8
    assert c.stats().boots == boots0 + 1 and c.stats().timeouts == 1


def test_silent_sensor_times_out_and_recovers_with_a_gap(bench: Bench) -> None:
    c, peer = bench.sensor, bench.unit.sensor
    c.start_stream(100)
    c.read_samples(n=10)
    before = c.stats()
    peer.go_silent = True
    with pytest.raises(SensorTimeout):
        c.identify()
    c.drain()
    with pytest.raises(SensorTimeout):
        c.read_samples(n=50, timeout_s=2.0)
    s = c.stats()
    assert (s.timeouts - before.timeouts, s.retries - before.retries) == (1, SENSOR_OPTIONS["attempts"] - 1)
    assert peer.stats().frames_silenced > 0
    peer.go_silent = False
    assert c.identify().serial == bench.unit.truth.serial
    c.read_samples(n=10)
    bench.stop_and_drain()
    assert c.stats().gaps >= 1  # the sample counter ran on while the firmware hung


def test_corrected_output_after_an_image_is_written(bench: Bench) -> None:
    c, unit = bench.sensor, bench.unit
    fw = install_firmware(unit.sensor, bench.station.clock)
    params = unit.truth.as_parameter_set(0.01)
    assert not fw.loaded and read_current_image(c) is None
    report = write_image(c, CalibrationImage.from_params(params, "contract", datetime(2026, 1, 2, tzinfo=UTC)))
    assert (report.slot, report.update_count) == ("A", 1)
    current = read_current_image(c)
    assert current is not None and current.same_as(report.image)
    assert not fw.loaded  # the firmware reads its image at power-on only
    c.power_cycle()
    assert fw.loaded and fw.image is not None and fw.image.update_count == 1
    c.drain()
    c.start_stream(100)
    raw = c.read_samples(n=200)
    c.set_output("corrected")
    assert c.status().output == OutputMode.CORRECTED
    c.drain()  # samples sent before the switch are raw
    corrected = c.read_samples(n=400)
    bench.stop_and_drain()
    assert not raw.corrected.any() and corrected.corrected.all()
    f_true = np.array([0.0, 0.0, bench.station.plan.gravity_mps2])  # at rest, +z up
    settled = corrected.split(params.moving_average_length)[1]
    assert np.abs(settled.accel_mps2.mean(axis=0) - f_true).max() < 0.01
    assert np.abs(settled.gyro_radps.mean(axis=0)).max() < 2e-4
    assert np.abs(raw.accel_mps2.mean(axis=0) - f_true).max() > np.abs(settled.accel_mps2.mean(axis=0) - f_true).max()


# --- the fakes alone: determinism, and a whole station by URL ------------------------------------------


def _capture(seed: int) -> SampleBlock:
    """A scripted capture on a FakeStation on a manual clock: rest, a tumble, a spin."""
    with FakeStation(2, seed=seed, clock=ManualClock()) as fake:
        rig = open_rig(fake.rig_url, fake.clock)
        sensors = [open_sensor(u, fake.clock) for u in fake.sensor_urls]
        try:
            blocks = []
            for s in sensors:
                s.power_cycle()
                s.drain()
                s.start_stream(200)
            blocks += [s.read_samples(n=300) for s in sensors]
            rig.move_to("-y")
            rig.wait_in_position(60.0)
            rig.spin(-45.0)
            rig.wait_rate_settled(60.0)
            blocks += [s.read_samples(duration_s=1.5) for s in sensors]
            blocks += [s.drain() for s in sensors]
            return SampleBlock.concat(blocks)
        finally:
            for s in sensors:
                s.close()
            rig.close()


def test_same_seed_same_samples() -> None:
    a, b, other = _capture(5), _capture(5), _capture(6)
    assert len(a) > 1000
    for name in SampleBlock.__dataclass_fields__:
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)
    assert not np.array_equal(a.accel_mps2[: len(other)], other.accel_mps2[: len(a)])


def test_a_station_runs_a_sequence_on_fake_urls() -> None:
    plan = RigPlan(sample_rate_hz=50.0, rest_s=20.0, pose_hold_s=2.0,
                   rate_steps=(("x", 100.0), ("y", 100.0), ("z", 100.0)), rate_hold_s=2.0)
    with FakeStation(2, 500.0, seed=3, plan=plan) as fake:
        config = StationConfig(rig_url=fake.rig_url, sensor_urls=tuple(fake.sensor_urls), record=False, out_dir=None,
                               clock_scale=fake.scale, plan=plan)
        result = Station(config, clock=fake.clock).run()
        assert result.message == "" and result.rig_at_rest
        assert [u.serial for u in result.units] == [u.truth.serial for u in fake.units]
        assert all(u.outcome in (Outcome.PASS, Outcome.FAIL) and u.params is not None for u in result.units)
        _, _, _, rate, status = fake.rig.readback()
        assert rate == 0.0 and status & reg.Status.AT_REST
