"""Framing, CRC, payload codecs, the resynchronizing FrameParser and sensor URLs (no I/O)."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from station.kernel.errors import FormatError
from station.sensor.commands import (
    BootEvent,
    BootReason,
    Command,
    EepromInfo,
    NakCode,
    OutputMode,
    SensorIdentity,
    SensorStatus,
    decode_command,
    decode_reply,
    encode_ack,
    encode_command,
    encode_nak,
    pack_eeprom_read,
    pack_eeprom_write,
    pack_rate,
    unpack_eeprom_read,
    unpack_eeprom_write,
)
from station.sensor.frames import (
    MAX_PAYLOAD,
    SAMPLE_FRAME_SIZE,
    Frame,
    FrameParser,
    FrameType,
    SampleFlag,
    crc16_ccitt_false,
    decode_frame,
    decode_sample_payload,
    decode_sample_payloads,
    encode_frame,
    encode_sample_frames,
    encode_sample_payload,
)
from station.sensor.serial_url import SensorUrlError, SerialUrl, parse_sensor_url

PROPS = settings(max_examples=150, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow])


def crc16_bitwise(data: bytes) -> int:
    """Reference CRC-16/CCITT-FALSE, bit by bit (poly 0x1021, init 0xFFFF, MSB first)."""
    crc = 0xFFFF
    for byte in data:
        crc ^= byte << 8
        for _ in range(8):
            crc = ((crc << 1) ^ 0x1021) & 0xFFFF if crc & 0x8000 else (crc << 1) & 0xFFFF
    return crc


# --- CRC and golden frames ----------------------------------------------------------------------


def test_crc_check_value() -> None:
    assert crc16_ccitt_false(b"123456789") == 0x29B1
    assert crc16_bitwise(b"123456789") == 0x29B1


@given(st.binary(max_size=200))
@PROPS
def test_crc_matches_bitwise_reference(data: bytes) -> None:
    assert crc16_ccitt_false(data) == crc16_bitwise(data)


def test_golden_frames_from_the_protocol_document() -> None:
    assert encode_command(1, Command.IDENTIFY).hex(" ") == "a5 5a 10 03 00 01 00 01 57 dd"
    assert encode_command(2, Command.START_STREAM, pack_rate(100)).hex(" ") == "a5 5a 10 05 00 02 00 03 64 00 10 af"
    assert encode_ack(2, Command.START_STREAM).hex(" ") == "a5 5a 02 03 00 02 00 03 81 35"
    assert encode_nak(3, Command.SET_RATE, NakCode.UNSUPPORTED_RATE).hex(" ") == "a5 5a 03 04 00 03 00 05 04 40 0b"
    sample = encode_sample_frames(
        7, np.array([1_500_000]), np.array([[0.0, 0.0, 9.80665]]), np.array([[0.0, 0.0, 0.0175]]), np.array([25.0]), 1
    )
    assert sample.tobytes().hex(" ") == (
        "a5 5a 01 28 00 07 00 01 00 60 e3 16 00 00 00 00 00 00 00 00 00 00 00 00 00 0a e8 1c 41 "
        "00 00 00 00 00 00 00 00 29 5c 8f 3c 00 00 c8 41 b9 9c"
    )
    s = decode_sample_payload(decode_frame(sample.tobytes()).payload)
    assert (s.seq, s.t_us, s.flags) == (7, 1_500_000, SampleFlag.CORRECTED)
    assert s.t_s == 1.5
    assert s.accel[2] == float(np.float32(9.80665))
    assert s.gyro[2] == float(np.float32(0.0175))
    assert s.temp == 25.0


# --- frame and payload codecs -------------------------------------------------------------------


def test_frame_round_trip_and_rejections() -> None:
    raw = encode_frame(FrameType.ACK, b"\x01\x02\x03")
    assert decode_frame(raw) == Frame(FrameType.ACK, b"\x01\x02\x03")
    assert len(raw) == 3 + 7
    bad = bytearray(raw)
    bad[6] ^= 0x10
    with pytest.raises(FormatError, match="CRC"):
        decode_frame(bytes(bad))
    with pytest.raises(FormatError):
        decode_frame(raw[:-1])
    with pytest.raises(FormatError):
        decode_frame(b"\x00" + raw[1:])
    with pytest.raises(ValueError):
        encode_frame(FrameType.ACK, bytes(MAX_PAYLOAD + 1))


def test_vectorized_sample_encoding_equals_single_encoding() -> None:
    rng = np.random.default_rng(1)
    n = 5
    t_us = np.arange(n, dtype=np.int64) * 1000 + 123
    accel = rng.normal(0, 10, (n, 3))
    gyro = rng.normal(0, 1, (n, 3))
    temp = np.array([20.0, 21.0, math.nan, 23.0, 24.0])
    flags = np.array([2, 0, 0, 1, 5], dtype=np.uint8)
    frames = encode_sample_frames(65534, t_us, accel, gyro, temp, flags)
    assert frames.shape == (n, SAMPLE_FRAME_SIZE)
    for k in range(n):
        payload = encode_sample_payload((65534 + k) % 65536, int(t_us[k]), accel[k], gyro[k], temp[k], int(flags[k]))
        assert frames[k].tobytes() == encode_frame(FrameType.SAMPLE, payload)
    rec = decode_sample_payloads([decode_frame(f.tobytes()).payload for f in frames])
    assert rec["seq"].tolist() == [65534, 65535, 0, 1, 2]
    np.testing.assert_array_equal(rec["t_us"], t_us)
    np.testing.assert_array_equal(rec["accel"], accel.astype(np.float32))
    np.testing.assert_array_equal(rec["gyro"], gyro.astype(np.float32))
    assert math.isnan(float(rec["temp"][2]))
    with pytest.raises(FormatError):
        decode_sample_payload(b"\x00" * 39)


def test_command_and_reply_payloads_round_trip() -> None:
    ident = SensorIdentity("SN-000123", "fw-2.4.1", (100, 1000), 100, 156.9, 34.9, 0.0047884, 0.00106526)
    back = SensorIdentity.decode(ident.encode())
    assert back.serial == "SN-000123" and back.firmware == "fw-2.4.1"
    assert back.rates_hz == (100, 1000) and back.default_rate_hz == 100
    assert back.accel_resolution_mps2 == pytest.approx(0.0047884, rel=1e-7)
    status = SensorStatus(True, OutputMode.CORRECTED, 200, 12.345678, 65535, 3, 7)
    assert SensorStatus.decode(status.encode()) == status
    info = EepromInfo(4096, 32, True, 0.005)
    assert EepromInfo.decode(info.encode()) == info
    boot = BootEvent(BootReason.RESET_COMMAND, 42)
    assert BootEvent.decode(boot.encode()) == boot
    assert unpack_eeprom_read(pack_eeprom_read(4000, 96)) == (4000, 96)
    assert unpack_eeprom_write(pack_eeprom_write(64, b"abc")) == (64, b"abc")
    seq, code, args = decode_command(decode_frame(encode_command(0xBEEF, Command.SET_RATE, pack_rate(500))).payload)
    assert (seq, code, args) == (0xBEEF, Command.SET_RATE, b"\xf4\x01")
    ack = decode_reply(decode_frame(encode_ack(9, Command.IDENTIFY, b"xyz")))
    assert (ack.seq, ack.command, ack.ok, ack.data) == (9, Command.IDENTIFY, True, b"xyz")
    nak = decode_reply(decode_frame(encode_nak(10, Command.EEPROM_WRITE_PAGE, NakCode.WRITE_PROTECTED)))
    assert (nak.seq, nak.ok, nak.error) == (10, False, NakCode.WRITE_PROTECTED)
    with pytest.raises(FormatError):
        SensorIdentity.decode(ident.encode()[:-1])
    with pytest.raises(FormatError):
        decode_command(b"\x01")
    with pytest.raises(ValueError):
        SensorIdentity("X" * 17, "fw", (100,), 100, 1.0, 1.0).encode()


# --- stream parser --------------------------------------------------------------------------------


def sample_frame(seq: int, t_us: int, value: float = 1.0, flags: int = 0) -> bytes:
    return encode_frame(
        FrameType.SAMPLE, encode_sample_payload(seq, t_us, (value, 0.0, 9.81), (0.0, value, 0.0), 25.0, flags)
    )


@st.composite
def frames_st(draw: st.DrawFn) -> bytes:
    kind = draw(st.sampled_from(["sample", "ack", "nak", "event", "command"]))
    if kind == "sample":
        seq = draw(st.integers(0, 65535))
        t_us = draw(st.integers(0, 2**40))
        value = draw(st.floats(-100, 100, width=32))
        return sample_frame(seq, t_us, value)
    payload = draw(st.binary(min_size=3, max_size=64))
    ftype = {"ack": FrameType.ACK, "nak": FrameType.NAK, "event": FrameType.EVENT, "command": FrameType.COMMAND}[kind]
    if ftype == FrameType.EVENT:
        payload = b"\x02" + payload[1:]  # not a BOOT event (that resets sequence tracking)
    return encode_frame(ftype, payload)


garbage_st = st.lists(
    st.one_of(
        st.binary(max_size=40),
        st.sampled_from([b"\xa5", b"\x5a", b"\xa5\x5a", b"\xa5\x5a\x01\x28\x00", b"\xa5\x5a\x02\x40\x01", b"\xa5\xa5"]),
    ),
    max_size=6,
).map(b"".join)

# Enough non-sync bytes to complete any false frame candidate the garbage may have started.
FLUSH = b"\x00" * (MAX_PAYLOAD + 8)


def feed_chunks(parser: FrameParser, data: bytes, cuts: list[int]) -> list[Frame]:
    out: list[Frame] = []
    bounds = sorted({0, len(data), *(c % (len(data) + 1) for c in cuts)})
    for a, b in itertools.pairwise(bounds):
        out += parser.feed(data[a:b])
    return out


def check_invariants(parser: FrameParser, got: list[Frame]) -> None:
    s = parser.stats()
    assert s.bytes_in == s.bytes_framed + s.bytes_discarded + s.bytes_buffered
    assert s.frames == len(got)
    assert s.bytes_framed == sum(len(f.payload) + 7 for f in got)
    assert s.bytes_buffered == parser.bytes_buffered
    assert min(s.crc_errors, s.bad_headers, s.resyncs, s.gaps, s.lost_frames) >= 0


@given(st.binary(max_size=2000), st.lists(st.integers(0, 5000), max_size=20))
@PROPS
def test_random_garbage_never_crashes(data: bytes, cuts: list[int]) -> None:
    parser = FrameParser()
    got = feed_chunks(parser, data, cuts)
    check_invariants(parser, got)
    for f in got:
        assert f.type in {int(t) for t in FrameType}


@given(st.lists(st.tuples(garbage_st, frames_st()), min_size=1, max_size=12), garbage_st, st.lists(st.integers()))
@PROPS
def test_frames_around_garbage_are_recovered(pairs: list[tuple[bytes, bytes]], tail: bytes, cuts: list[int]) -> None:
    stream = b"".join(g + f for g, f in pairs) + tail + FLUSH
    parser = FrameParser(track_sequence=False)
    got = feed_chunks(parser, stream, cuts)
    assert [encode_frame(f.type, f.payload) for f in got] == [f for _, f in pairs]
    check_invariants(parser, got)
    assert parser.stats().bytes_discarded == len(stream) - sum(len(f) for _, f in pairs) - parser.bytes_buffered


@given(st.lists(st.tuples(frames_st(), st.booleans(), st.integers(1, 200)), min_size=1, max_size=12))
@PROPS
def test_truncated_frames_do_not_hide_the_next_ones(items: list[tuple[bytes, bool, int]]) -> None:
    stream = b""
    expected = []
    for frame, truncate, cut in items:
        if truncate:
            stream += frame[: cut % len(frame)]
        else:
            stream += frame
            expected.append(frame)
    parser = FrameParser(track_sequence=False)
    got = parser.feed(stream + FLUSH)
    assert [encode_frame(f.type, f.payload) for f in got] == expected
    check_invariants(parser, got)


@given(st.lists(frames_st(), min_size=1, max_size=15), st.lists(st.integers(0, 10**6), min_size=1, max_size=3))
@PROPS
def test_bit_flips_lose_only_the_hit_frames(frames: list[bytes], flips: list[int]) -> None:
    stream = bytearray(b"".join(frames))
    nbits = len(stream) * 8
    hit_bytes = set()
    for f in {x % nbits for x in flips}:
        stream[f // 8] ^= 1 << (f % 8)
        hit_bytes.add(f // 8)
    expected = []
    start = 0
    for fr in frames:
        if not any(start <= b < start + len(fr) for b in hit_bytes):
            expected.append(fr)
        start += len(fr)
    parser = FrameParser(track_sequence=False)
    got = parser.feed(bytes(stream) + FLUSH)
    assert [encode_frame(f.type, f.payload) for f in got] == expected
    check_invariants(parser, got)
    if len(expected) < len(frames):
        assert parser.stats().bytes_discarded > 0


@given(
    st.integers(0, 65535),
    st.integers(2, 400),
    st.sets(st.integers(0, 399), max_size=120),
    st.lists(st.integers(), max_size=10),
)
@PROPS
def test_sequence_gaps_and_u16_wraparound(seq0: int, n: int, removed: set[int], cuts: list[int]) -> None:
    kept = [k for k in range(n) if k not in removed]
    stream = b"".join(sample_frame(seq0 + k, 1000 * k) for k in kept)
    parser = FrameParser()
    got = feed_chunks(parser, stream, cuts)
    assert len(got) == len(kept)
    s = parser.stats()
    if not kept:
        assert (s.gaps, s.lost_frames) == (0, 0)
        return
    inner = [k for k in range(kept[0], kept[-1] + 1) if k in removed]
    runs = sum(1 for k in inner if k - 1 not in inner)
    assert s.lost_frames == len(inner)
    assert s.gaps == runs
    assert s.duplicates == 0 and s.restarts == 0


def test_loss_longer_than_the_counter_range_is_recovered_from_timestamps() -> None:
    # 1 kHz, 70 000 frames lost: the u16 counter only shows 70 000 - 65 536 of them.
    parser = FrameParser()
    frames = [sample_frame(k, 1000 * k) for k in range(3)]
    frames.append(sample_frame(3 + 70_000, 1000 * (3 + 70_000)))
    frames.append(sample_frame(4 + 70_000, 1000 * (4 + 70_000)))
    parser.feed(b"".join(frames))
    s = parser.stats()
    assert (s.gaps, s.lost_frames) == (1, 70_000)


def test_stream_restart_rate_change_duplicate_and_boot() -> None:
    parser = FrameParser()
    stream = [sample_frame(k, 10_000 * k) for k in range(5)]
    stream.append(sample_frame(4, 40_000))  # duplicate
    # stop/start: time jumps, sequence continues, STREAM_START flag: no gap
    stream.append(sample_frame(5, 900_000, flags=SampleFlag.STREAM_START))
    stream.append(sample_frame(6, 910_000))
    # rate change to 1 kHz
    stream.append(sample_frame(7, 911_000, flags=SampleFlag.RATE_CHANGED))
    stream.append(sample_frame(8, 912_000))
    # reboot with the BOOT event lost: the time base goes backwards
    stream.append(sample_frame(0, 5_000))
    stream.append(sample_frame(1, 15_000))
    # reboot announced by a BOOT event
    stream.append(encode_frame(FrameType.EVENT, BootEvent(BootReason.RESET_COMMAND, 3).encode()))
    stream.append(sample_frame(0, 1_000_000))  # time larger than before: only the BOOT event tells
    got = parser.feed(b"".join(stream))
    assert len(got) == len(stream)
    s = parser.stats()
    assert (s.gaps, s.lost_frames, s.duplicates, s.restarts) == (0, 0, 1, 2)


def test_byte_by_byte_feed_equals_one_feed() -> None:
    rng = np.random.default_rng(7)
    parts = []
    for k in range(30):
        parts.append(rng.integers(0, 256, size=int(rng.integers(0, 20)), dtype=np.uint8).tobytes())
        parts.append(sample_frame(k, 1000 * k, float(k)))
    stream = b"".join(parts)
    whole = FrameParser()
    a = whole.feed(stream)
    single = FrameParser()
    b = [f for i in range(len(stream)) for f in single.feed(stream[i : i + 1])]
    assert a == b
    assert whole.stats() == single.stats()


# --- URLs -----------------------------------------------------------------------------------------


def test_sensor_urls() -> None:
    assert parse_sensor_url("serial:///dev/ttyUSB0?baud=115200") == SerialUrl("/dev/ttyUSB0", 115200)
    assert parse_sensor_url("serial:///dev/pts/7") == SerialUrl("/dev/pts/7", 921600)
    assert str(SerialUrl("/dev/ttyACM1", 921600)) == "serial:///dev/ttyACM1?baud=921600"
    for bad in (
        "tcp://localhost:5020",
        "serial://dev/ttyUSB0",
        "serial:///",
        "serial:///dev/ttyUSB0?baud=fast",
        "serial:///dev/ttyUSB0?baud=0",
        "serial:///dev/ttyUSB0?baud=9600&baud=19200",
        "serial:///dev/ttyUSB0?parity=N",
        "/dev/ttyUSB0",
    ):
        with pytest.raises(SensorUrlError):
            parse_sensor_url(bad)
