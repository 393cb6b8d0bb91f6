"""The simulated sensor on a real pty, driven by the real pyserial client; plus the emulated EEPROM."""

from __future__ import annotations

import time
from collections.abc import Iterator

import numpy as np
import pytest
import serial

from station.kernel.clock import SimClock
from station.sensor.client import (
    CrcStormError,
    SampleBlock,
    SensorLinkError,
    SensorNak,
    SensorTimeout,
    SerialSensor,
    open_sensor,
)
from station.sensor.commands import (
    Command,
    NakCode,
    OutputMode,
    Reply,
    decode_reply,
    encode_command,
    pack_eeprom_write,
)
from station.sensor.frames import FrameParser, FrameType, SampleFlag
from station.sim.eeprom import (
    Eeprom,
    EepromAddressError,
    EepromBusyError,
    EepromPageBoundaryError,
    EepromWriteProtectedError,
)
from station.sim.sensor_peer import SimulatedSensor

SCALE = 20.0
GRAVITY = 9.80665


class GravitySine:
    """Deterministic test physics: gravity on z, a 0.5 Hz sine on accel x and gyro y, a temperature ramp."""

    def __init__(self) -> None:
        self.power_ons = 0

    def power_on(self) -> None:
        self.power_ons += 1

    def render(self, t_s: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        n = t_s.shape[0]
        w = 2 * np.pi * 0.5
        accel = np.zeros((n, 3))
        accel[:, 0] = 0.2 * np.sin(w * t_s)
        accel[:, 2] = GRAVITY
        gyro = np.zeros((n, 3))
        gyro[:, 1] = 0.05 * np.cos(w * t_s) + 0.001
        return accel, gyro, 25.0 + 0.01 * t_s


def expected_values(block: SampleBlock) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """What the source renders at the block's times, after the float32 trip over the wire."""
    a, g, t = GravitySine().render(block.t_s)
    return (a.astype(np.float32).astype(np.float64), g.astype(np.float32).astype(np.float64), t.astype(np.float32))


def assert_values_match_source(block: SampleBlock) -> None:
    a, g, t = expected_values(block)
    np.testing.assert_array_equal(block.accel_mps2, a)
    np.testing.assert_array_equal(block.gyro_radps, g)
    np.testing.assert_array_equal(block.temp_degc, t)


class Rig:
    def __init__(self, **client_kw: float) -> None:
        self.clock = SimClock(scale=SCALE)
        self.source = GravitySine()
        self.sim = SimulatedSensor(self.source, self.clock, serial="SN-000123", firmware="fw-1.2.3", seed=11)
        self.client: SerialSensor = open_sensor(self.sim.url, self.clock, **client_kw)  # type: ignore[arg-type]

    def stop_and_drain(self) -> SampleBlock:
        """Stop streaming; everything sent before the STOP ack has arrived by then."""
        self.client.stop_stream()
        return self.client.drain()

    def close(self) -> None:
        self.client.close()
        self.sim.close()


@pytest.fixture
def rig() -> Iterator[Rig]:
    r = Rig(command_timeout_s=0.3, attempts=3)
    yield r
    r.close()


pytestmark = pytest.mark.integration


# --- protocol over the pty ----------------------------------------------------------------------


def test_url_and_identify(rig: Rig) -> None:
    assert rig.sim.url.startswith("serial:///dev/pts/")
    ident = rig.client.identify()
    assert ident.serial == "SN-000123"
    assert ident.firmware == "fw-1.2.3"
    assert ident.rates_hz == (10, 50, 100, 200, 250, 500, 1000)
    assert ident.default_rate_hz == 100
    assert ident.accel_range_mps2 == pytest.approx(16 * GRAVITY, rel=1e-6)
    status = rig.client.status()
    assert not status.streaming and status.output == OutputMode.RAW and status.boot_count == 1


def test_stream_100hz_count_spacing_and_values(rig: Rig) -> None:
    c = rig.client
    c.start_stream(100)
    first = c.read_samples(duration_s=10.0)  # ten sensor seconds
    assert len(first) == 1000
    np.testing.assert_array_equal(np.diff(np.round(first.t_s * 1e6).astype(np.int64)), 10_000)
    assert first.flags[0] == SampleFlag.STREAM_START and not first.flags[1:].any()
    assert_values_match_source(first)

    rig.clock.sleep(2.0)
    uptime = c.status().uptime_s  # the sensor's own clock, sampled mid-stream
    rest = rig.stop_and_drain()
    block = SampleBlock.concat([first, rest])
    t0 = block.t_s[0]
    assert uptime - t0 >= 12.0
    # The sensor sent exactly the samples whose time had come by its clock.
    assert np.count_nonzero(block.t_s <= uptime + 1e-9) == int((uptime - t0 + 1e-9) / 0.01) + 1
    seq = block.seq.astype(np.int64)
    np.testing.assert_array_equal(np.diff(seq) % 65536, 1)
    assert_values_match_source(block)
    s = c.stats()
    assert (s.gaps, s.lost_frames, s.crc_errors, s.bytes_discarded) == (0, 0, 0, 0)
    assert s.samples == len(block)


def test_commands_interleave_with_samples_and_rate_change(rig: Rig) -> None:
    c = rig.client
    c.start_stream(200)
    blocks = [c.read_samples(n=100)]
    for _ in range(5):
        assert c.identify().serial == "SN-000123"
        assert c.status().streaming
        blocks.append(c.read_samples(n=50))
    c.set_rate(500)
    assert c.status().rate_hz == 500
    blocks.append(c.read_samples(duration_s=1.0))
    blocks.append(rig.stop_and_drain())
    block = SampleBlock.concat(blocks)
    dt_us = np.diff(np.round(block.t_s * 1e6).astype(np.int64))
    changed = np.flatnonzero(block.flags & SampleFlag.RATE_CHANGED)
    assert changed.size == 1
    k = int(changed[0])
    assert set(dt_us[: k - 1].tolist()) == {5000}
    assert set(dt_us[k - 1 :].tolist()) == {2000}
    np.testing.assert_array_equal(np.diff(block.seq.astype(np.int64)) % 65536, 1)
    assert_values_match_source(block)
    assert c.stats().gaps == 0


def test_corrected_output_applies_the_corrector(rig: Rig) -> None:
    def remove_gravity_and_bias(accel: np.ndarray, gyro: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return accel - [0.0, 0.0, GRAVITY], gyro - 0.001

    rig.sim.corrector = remove_gravity_and_bias
    c = rig.client
    c.set_output("corrected")
    assert c.status().output == OutputMode.CORRECTED
    c.start_stream(100)
    first = c.read_samples(n=50)
    c.set_output(OutputMode.RAW)
    # The buffer now holds every sample sent before the SET_OUTPUT ack (corrected), maybe a few after it.
    rest = c.read_samples(duration_s=1.0)
    rig.stop_and_drain()
    both = SampleBlock.concat([first, rest])
    k = int(np.count_nonzero(both.corrected))
    assert k >= 50 and both.corrected[:k].all() and not both.corrected[k:].any()  # one switch, then raw
    assert len(both) - k >= 50
    block, raw = both.split(k)
    a, g, _ = GravitySine().render(block.t_s)
    np.testing.assert_array_equal(block.accel_mps2, (a - [0, 0, GRAVITY]).astype(np.float32))
    np.testing.assert_array_equal(block.gyro_radps, (g - 0.001).astype(np.float32))
    assert_values_match_source(raw)
    with pytest.raises(ValueError):
        c.set_output("smoothed")


def test_bad_rate_is_naked(rig: Rig) -> None:
    with pytest.raises(SensorNak) as err:
        rig.client.start_stream(123)
    assert err.value.code == NakCode.UNSUPPORTED_RATE
    assert rig.client.stats().naks == 1


def test_power_cycle_restarts_time_base_and_physics(rig: Rig) -> None:
    c = rig.client
    c.identify()
    # The power-on BOOT event of the fixture may or may not reach the client (it races with the
    # input flush at open), so count from here.
    boots0, restarts0 = c.stats().boots, c.stats().restarts
    c.start_stream(100)
    before = c.read_samples(duration_s=3.0)
    assert rig.source.power_ons == 1
    c.power_cycle()
    assert rig.source.power_ons == 2
    status = c.status()
    assert not status.streaming and status.boot_count == 2 and status.uptime_s < before.t_s[-1]
    c.drain()
    c.start_stream(100)
    after = c.read_samples(n=20)
    rig.stop_and_drain()
    assert after.seq[0] == 0 and after.t_s[0] < before.t_s[-1]
    assert_values_match_source(after)
    s = c.stats()
    assert (s.boots - boots0, s.restarts - restarts0, s.gaps) == (1, 1, 0)


# --- EEPROM over the link ---------------------------------------------------------------------------


def test_eeprom_round_trip(rig: Rig) -> None:
    c = rig.client
    info = c.eeprom_info()
    assert (info.size, info.page_size, info.write_protect, info.write_cycle_s) == (4096, 32, False, 0.005)
    data = bytes((7 * i + 3) % 256 for i in range(300))
    c.start_stream(100)  # EEPROM traffic while streaming
    c.eeprom_write(1000, data)
    assert c.eeprom_read(1000, 300) == data
    assert c.eeprom_read(990, 10) == b"\xff" * 10
    rig.stop_and_drain()
    image = rig.sim.eeprom.image()
    assert image[1000:1300] == data
    assert rig.sim.eeprom.page_writes == 10  # 1000 is 8 bytes into page 31: 24 + 8 * 32 + 20 bytes
    assert c.stats().gaps == 0


def test_eeprom_refusals(rig: Rig) -> None:
    c = rig.client
    rig.sim.eeprom.write_protect = True
    assert c.eeprom_info().write_protect
    with pytest.raises(SensorNak) as err:
        c.eeprom_write_page(0, b"calib")
    assert err.value.code == NakCode.WRITE_PROTECTED
    assert c.eeprom_read(0, 5) == b"\xff" * 5
    rig.sim.eeprom.write_protect = False
    with pytest.raises(SensorNak) as err:
        c.eeprom_write_page(30, b"abcd")
    assert err.value.code == NakCode.PAGE_BOUNDARY
    with pytest.raises(SensorNak) as err:
        c.eeprom_read(4090, 10)
    assert err.value.code == NakCode.ADDRESS_RANGE
    c.eeprom_write_page(0, b"calib")
    assert c.eeprom_read(0, 5) == b"calib"


def test_power_loss_mid_write_leaves_a_partial_page() -> None:
    r = Rig(command_timeout_s=0.15, attempts=2)
    try:
        c = r.client
        c.eeprom_write_page(64, b"\x22" * 32)
        boots0 = c.stats().boots
        r.sim.eeprom.power_loss_after(5)
        with pytest.raises(SensorTimeout):
            c.eeprom_write_page(72, bytes(range(16)))
        assert not r.sim.powered
        r.sim.power_on()
        page = c.eeprom_read(64, 32)
        assert page[:8] == b"\x22" * 8  # before the written range: old content
        assert page[8:13] == bytes(range(5))  # programmed before the power failed
        assert page[13:24] == b"\xff" * 11  # erased, never programmed
        assert page[24:] == b"\x22" * 8  # after the written range: old content
        assert r.source.power_ons == 2
        assert c.stats().boots == boots0 + 1
    finally:
        r.close()


def test_retransmitted_command_is_answered_from_cache_not_executed_twice(rig: Rig) -> None:
    rig.client.close()
    port = serial.Serial(rig.sim.device, timeout=0.1)
    try:
        port.reset_input_buffer()
        cmd = encode_command(77, Command.EEPROM_WRITE_PAGE, pack_eeprom_write(128, b"once"))
        parser = FrameParser()

        def next_ack() -> list[Reply]:
            deadline = time.monotonic() + 2.0
            while time.monotonic() < deadline:
                acks = [decode_reply(f) for f in parser.feed(port.read(64)) if f.type == FrameType.ACK]
                if acks:
                    return acks
            return []

        replies = []
        for _ in range(2):  # the second copy looks like a retry after a lost ACK
            port.write(cmd)
            replies += next_ack()
        assert [(r.seq, r.command, r.ok) for r in replies] == [(77, Command.EEPROM_WRITE_PAGE, True)] * 2
        assert rig.sim.eeprom.page_writes == 1
        assert rig.sim.stats().commands == 2
    finally:
        port.close()


# --- link faults ----------------------------------------------------------------------------------


def test_bit_errors_are_counted_and_the_parser_resyncs(rig: Rig) -> None:
    c = rig.client
    rig.sim.bit_error_rate = 5e-5  # about 1.9 % of the 47-byte sample frames get hit
    c.start_stream(200)
    noisy = c.read_samples(duration_s=15.0)
    assert c.status().streaming  # commands still get through (retried if an answer is hit)
    noisy_rest = rig.stop_and_drain()
    rig.sim.bit_error_rate = 0.0
    c.start_stream(200)
    clean = c.read_samples(n=20)
    rest = rig.stop_and_drain()
    block = SampleBlock.concat([noisy, noisy_rest, clean, rest])
    s = c.stats()
    produced = rig.sim.stats().sample_frames
    assert s.crc_errors > 10
    assert s.gaps > 0 and s.resyncs > 0
    assert s.samples == len(block)
    assert s.samples + s.lost_frames == produced  # every lost frame shows up in the sequence accounting
    assert not s.crc_storm
    assert_values_match_source(block)  # nothing corrupted got through


def test_crc_storm_raises_a_station_fault() -> None:
    r = Rig(command_timeout_s=0.2, attempts=3, crc_window_frames=100, crc_error_threshold=0.1)
    try:
        r.sim.bit_error_rate = 3e-3  # two thirds of the frames are hit
        r.client.start_stream(200)
        with pytest.raises(CrcStormError, match="CRC storm"):
            r.client.read_samples(duration_s=30.0)
        with pytest.raises(CrcStormError):
            r.client.status()
        assert r.client.stats().crc_storm
        r.sim.bit_error_rate = 0.0
        r.client.clear_fault()
        r.client.stop_stream()
        assert not r.client.status().streaming
    finally:
        r.close()


def test_dropped_frames_are_counted_as_gaps(rig: Rig) -> None:
    c = rig.client
    rig.sim.drop_frame_rate = 0.05
    c.start_stream(200)
    c.read_samples(duration_s=10.0)
    c.stop_stream()
    rig.sim.drop_frame_rate = 0.0
    c.start_stream(200)
    c.read_samples(n=10)  # the last frames arrive: every earlier drop is visible
    rig.stop_and_drain()
    sim = rig.sim.stats()
    s = c.stats()
    assert sim.frames_dropped > 30
    assert s.lost_frames == sim.frames_dropped
    assert 0 < s.gaps <= s.lost_frames
    assert s.samples + s.lost_frames == sim.sample_frames
    assert s.crc_errors == 0


def test_silent_sensor_times_out() -> None:
    r = Rig(command_timeout_s=0.1, attempts=2)
    try:
        r.client.start_stream(100)
        r.client.read_samples(n=10)
        before = r.client.stats()
        r.sim.go_silent = True
        with pytest.raises(SensorTimeout):
            r.client.identify()
        r.client.drain()
        with pytest.raises(SensorTimeout):
            r.client.read_samples(n=50, timeout_s=2.0)
        s = r.client.stats()
        assert (s.timeouts - before.timeouts, s.retries - before.retries) == (1, 1)
        r.sim.go_silent = False
        assert r.client.identify().serial == "SN-000123"
        r.client.stop_stream()
    finally:
        r.close()


def test_open_errors() -> None:
    with pytest.raises(SensorLinkError):
        open_sensor("serial:///dev/does-not-exist-42")


# --- the emulated EEPROM alone --------------------------------------------------------------------


class ManualClock:
    scale = 1.0

    def __init__(self) -> None:
        self.t = 0.0

    def now(self) -> float:
        return self.t

    def sleep(self, seconds: float) -> None:
        self.t += max(0.0, seconds)


def test_eeprom_write_cycle_protect_boundaries_and_power_loss() -> None:
    clock = ManualClock()
    ee = Eeprom(size=256, page_size=16, write_cycle_s=0.005, clock=clock)
    assert ee.image() == b"\xff" * 256
    assert ee.write_page(16, b"ABCDEFGHIJKLMNOP") == 16
    assert ee.is_busy()
    with pytest.raises(EepromBusyError):
        ee.read(16, 4)
    with pytest.raises(EepromBusyError):
        ee.write_page(32, b"x")
    clock.sleep(0.005)
    assert not ee.is_busy()
    assert ee.read(16, 16) == b"ABCDEFGHIJKLMNOP"
    with pytest.raises(EepromPageBoundaryError):
        ee.write_page(30, b"xyz")
    with pytest.raises(EepromAddressError):
        ee.read(250, 7)
    with pytest.raises(EepromAddressError):
        ee.write_page(-1, b"x")
    ee.write_protect = True
    with pytest.raises(EepromWriteProtectedError):
        ee.write_page(0, b"x")
    ee.write_protect = False
    # power fails in the second page write from now, after 3 of its 8 bytes
    ee.power_loss_after(3, pages_before=1)
    assert ee.write_page(0, b"first") == 5
    clock.sleep(0.005)
    assert ee.write_page(18, b"12345678") == 3
    assert not ee.is_busy()  # no write cycle survives the power loss
    assert ee.read(16, 16) == b"AB123" + b"\xff" * 5 + b"KLMNOP"
    assert ee.write_page(18, b"12345678") == 8  # the fault fired once
    assert ee.page_writes == 4
    with pytest.raises(ValueError):
        Eeprom(size=100, page_size=32)
