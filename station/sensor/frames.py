"""Binary framing of the IMU serial protocol: CRC, frame encode/decode and a resynchronizing stream parser.

Every frame on the wire (both directions) is, little-endian (station/sensor/protocol.md):

    sync 0xA5 0x5A | type u8 | length u16 | payload (length bytes) | crc u16

The CRC is CRC-16/CCITT-FALSE (poly 0x1021, init 0xFFFF, not reflected, no final
XOR; check value 0x29B1 for b"123456789") over type, length and payload.

A SAMPLE payload is 40 bytes: sequence counter u16, flags u8, reserved u8, sensor
time u64 in microseconds since power-on, accel x/y/z float32 (m/s^2), gyro x/y/z
float32 (rad/s), temperature float32 (degC, NaN when the sensor has none).

:class:`FrameParser` accepts arbitrary byte chunks, resynchronizes after garbage and
never raises on bad input; it only returns valid frames and updates counters.
"""

from __future__ import annotations

import binascii
import struct
from collections.abc import Sequence
from dataclasses import dataclass
from enum import IntEnum, IntFlag

import numpy as np

from station.kernel.errors import FormatError

SYNC = b"\xa5\x5a"
HEADER_SIZE = 5  # sync (2) + type (1) + length (2)
CRC_SIZE = 2
FRAME_OVERHEAD = HEADER_SIZE + CRC_SIZE
MAX_PAYLOAD = 320  # bytes; longer length fields are treated as a false sync
SEQ_MODULUS = 1 << 16


class FrameType(IntEnum):
    """The frame type byte."""

    SAMPLE = 0x01  # sensor -> host, one sample
    ACK = 0x02  # sensor -> host, command accepted (+ reply data)
    NAK = 0x03  # sensor -> host, command refused (+ error code)
    EVENT = 0x04  # sensor -> host, unsolicited event (boot)
    COMMAND = 0x10  # host -> sensor


class EventCode(IntEnum):
    """First payload byte of an EVENT frame."""

    BOOT = 0x01  # the sensor (re)started: sequence counter and time base restart at 0


class SampleFlag(IntFlag):
    """Bits of a SAMPLE frame's flags byte."""

    CORRECTED = 0x01  # values went through the on-sensor correction (Algorithm 1); else raw
    STREAM_START = 0x02  # first sample after START_STREAM
    RATE_CHANGED = 0x04  # first sample after a rate change while streaming


SAMPLE_PAYLOAD_DTYPE = np.dtype(
    [
        ("seq", "<u2"),
        ("flags", "u1"),
        ("reserved", "u1"),
        ("t_us", "<u8"),
        ("accel", "<f4", (3,)),
        ("gyro", "<f4", (3,)),
        ("temp", "<f4"),
    ]
)
SAMPLE_PAYLOAD_SIZE = SAMPLE_PAYLOAD_DTYPE.itemsize  # 40
SAMPLE_FRAME_SIZE = SAMPLE_PAYLOAD_SIZE + FRAME_OVERHEAD  # 47

_SAMPLE_FRAME_DTYPE = np.dtype(
    [
        ("sync", "u1", (2,)),
        ("type", "u1"),
        ("length", "<u2"),
        ("payload", SAMPLE_PAYLOAD_DTYPE),
        ("crc", "<u2"),
    ]
)
assert _SAMPLE_FRAME_DTYPE.itemsize == SAMPLE_FRAME_SIZE

_KNOWN_TYPES = frozenset(int(t) for t in FrameType)
# Plain ints for the parser's hot path (enum operators cost microseconds per call).
_T_SAMPLE = int(FrameType.SAMPLE)
_T_EVENT = int(FrameType.EVENT)
_NOT_CONTIGUOUS = int(SampleFlag.STREAM_START | SampleFlag.RATE_CHANGED)
_SEQ_FLAGS_TIME = struct.Struct("<HBxQ")


def crc16_ccitt_false(data: bytes | bytearray | memoryview, crc: int = 0xFFFF) -> int:
    """CRC-16/CCITT-FALSE of ``data`` (poly 0x1021, init 0xFFFF); ``crc`` continues a running value."""
    return binascii.crc_hqx(data, crc)


@dataclass(frozen=True, slots=True)
class Frame:
    """One valid frame: its type byte and payload."""

    type: int
    payload: bytes


def encode_frame(frame_type: int, payload: bytes = b"") -> bytes:
    """The wire bytes of one frame."""
    if not 0 <= frame_type <= 0xFF:
        raise ValueError(f"frame type {frame_type} out of range")
    if len(payload) > MAX_PAYLOAD:
        raise ValueError(f"payload of {len(payload)} bytes exceeds {MAX_PAYLOAD}")
    body = bytes((frame_type, len(payload) & 0xFF, len(payload) >> 8)) + payload
    return SYNC + body + crc16_ccitt_false(body).to_bytes(2, "little")


def decode_frame(data: bytes) -> Frame:
    """Decode exactly one complete frame; raises :class:`FormatError` if it is not one."""
    if len(data) < FRAME_OVERHEAD or data[:2] != SYNC:
        raise FormatError("not a frame: missing sync or too short")
    length = int.from_bytes(data[3:5], "little")
    if len(data) != length + FRAME_OVERHEAD:
        raise FormatError(f"frame length field says {length} payload bytes, got {len(data) - FRAME_OVERHEAD}")
    if crc16_ccitt_false(data[2:-2]) != int.from_bytes(data[-2:], "little"):
        raise FormatError("frame CRC mismatch")
    return Frame(data[2], bytes(data[5:-2]))


@dataclass(frozen=True, slots=True)
class Sample:
    """One decoded sample (accel m/s^2, gyro rad/s, temperature degC, time µs since power-on)."""

    seq: int
    flags: SampleFlag
    t_us: int
    accel: tuple[float, float, float]
    gyro: tuple[float, float, float]
    temp: float

    @property
    def t_s(self) -> float:
        """Sensor time since power-on (s)."""
        return self.t_us * 1e-6


def sample_records(
    seq0: int,
    t_us: np.ndarray,
    accel: np.ndarray,
    gyro: np.ndarray,
    temp: np.ndarray,
    flags: np.ndarray | int = 0,
) -> np.ndarray:
    """``n`` consecutive samples as SAMPLE payloads: a structured array of :data:`SAMPLE_PAYLOAD_DTYPE`.

    Args:
        seq0: sequence number of the first sample; the counter wraps modulo 2^16.
        t_us: (n,) sensor times, µs since power-on.
        accel: (n, 3) specific force (m/s^2); stored as float32.
        gyro: (n, 3) angular rate (rad/s); stored as float32.
        temp: (n,) temperature (degC), NaN for none.
        flags: (n,) or scalar :class:`SampleFlag` bits.
    """
    t = np.asarray(t_us, dtype=np.int64)
    n = t.shape[0]
    p = np.zeros(n, dtype=SAMPLE_PAYLOAD_DTYPE)
    p["seq"] = (seq0 + np.arange(n, dtype=np.int64)) % SEQ_MODULUS
    p["flags"] = flags
    p["t_us"] = t
    p["accel"] = np.asarray(accel, dtype=np.float64).reshape(n, 3)
    p["gyro"] = np.asarray(gyro, dtype=np.float64).reshape(n, 3)
    p["temp"] = np.asarray(temp, dtype=np.float64).reshape(n)
    return p


def frame_sample_records(records: np.ndarray) -> np.ndarray:
    """SAMPLE frames of payload records (:func:`sample_records`): (n, 47) uint8, one frame per row."""
    n = records.shape[0]
    frames = np.zeros(n, dtype=_SAMPLE_FRAME_DTYPE)
    frames["sync"] = np.frombuffer(SYNC, dtype=np.uint8)
    frames["type"] = FrameType.SAMPLE
    frames["length"] = SAMPLE_PAYLOAD_SIZE
    frames["payload"] = records
    raw = frames.view(np.uint8).reshape(n, SAMPLE_FRAME_SIZE)
    crc_span = raw[:, 2:-2]
    frames["crc"] = [binascii.crc_hqx(row.tobytes(), 0xFFFF) for row in crc_span]
    return raw


def encode_sample_frames(
    seq0: int,
    t_us: np.ndarray,
    accel: np.ndarray,
    gyro: np.ndarray,
    temp: np.ndarray,
    flags: np.ndarray | int = 0,
) -> np.ndarray:
    """Encode ``n`` consecutive samples as SAMPLE frames, vectorized (arguments of :func:`sample_records`).

    Returns:
        (n, 47) uint8 array, one frame per row (``.tobytes()`` is the wire stream).
    """
    return frame_sample_records(sample_records(seq0, t_us, accel, gyro, temp, flags))


def encode_sample_payload(
    seq: int,
    t_us: int,
    accel: Sequence[float],
    gyro: Sequence[float],
    temp: float,
    flags: int = 0,
) -> bytes:
    """The 40-byte payload of one SAMPLE frame (units as in :class:`Sample`)."""
    rec = np.zeros(1, dtype=SAMPLE_PAYLOAD_DTYPE)
    rec["seq"] = seq % SEQ_MODULUS
    rec["flags"] = flags
    rec["t_us"] = t_us
    rec["accel"] = accel
    rec["gyro"] = gyro
    rec["temp"] = temp
    return rec.tobytes()


def decode_sample_payload(payload: bytes) -> Sample:
    """Decode one SAMPLE payload; raises :class:`FormatError` on a wrong size."""
    if len(payload) != SAMPLE_PAYLOAD_SIZE:
        raise FormatError(f"sample payload must be {SAMPLE_PAYLOAD_SIZE} bytes, got {len(payload)}")
    rec = np.frombuffer(payload, dtype=SAMPLE_PAYLOAD_DTYPE)[0]
    return Sample(
        seq=int(rec["seq"]),
        flags=SampleFlag(int(rec["flags"]) & 0x07),
        t_us=int(rec["t_us"]),
        accel=(float(rec["accel"][0]), float(rec["accel"][1]), float(rec["accel"][2])),
        gyro=(float(rec["gyro"][0]), float(rec["gyro"][1]), float(rec["gyro"][2])),
        temp=float(rec["temp"]),
    )


def decode_sample_payloads(payloads: Sequence[bytes]) -> np.ndarray:
    """Decode many SAMPLE payloads at once into a structured array of :data:`SAMPLE_PAYLOAD_DTYPE`."""
    joined = b"".join(payloads)
    if len(joined) != SAMPLE_PAYLOAD_SIZE * len(payloads):
        raise FormatError("sample payloads must be 40 bytes each")
    return np.frombuffer(joined, dtype=SAMPLE_PAYLOAD_DTYPE)


class SequenceTracker:
    """SAMPLE sequence accounting of one stream: gaps, lost frames, duplicates, restarts.

    Fed with every sample in arrival order (:meth:`sample`) and every BOOT event (:meth:`boot`).
    A gap of ``k`` lost frames wraps modulo 2^16, and a wrap of the 16-bit counter during a long
    outage is recovered from the sensor timestamps when the sample period is known.
    """

    def __init__(self) -> None:
        self.reset_counts()
        self.forget()

    def reset_counts(self) -> None:
        """Zero the counters."""
        self.gaps = 0
        self.lost = 0
        self.duplicates = 0
        self.restarts = 0

    def forget(self) -> None:
        """Forget the last sequence number (the sensor restarted its counter)."""
        self._last_seq: int | None = None
        self._last_t_us = 0
        self._period_us = 0

    def boot(self) -> None:
        """A BOOT event: the sensor restarted."""
        self.restarts += 1
        self.forget()

    def sample(self, seq: int, flags: int, t_us: int) -> None:
        """Account for one sample (sequence number, flags, sensor time in µs)."""
        last = self._last_seq
        if last is not None and seq == (last + 1) & 0xFFFF and t_us - self._last_t_us == self._period_us:
            self._last_seq = seq  # the common case: the next frame, one period later
            self._last_t_us = t_us
            return
        if last is not None and t_us < self._last_t_us:
            # The time base went backwards: the sensor restarted and its BOOT event was lost.
            self.restarts += 1
            last = None
            self._period_us = 0
        if last is not None:
            dt = t_us - self._last_t_us
            delta = (seq - last) % SEQ_MODULUS
            if delta == 0 and dt == 0:
                self.duplicates += 1
                return
            missing = (delta - 1) % SEQ_MODULUS
            if self._period_us and not flags & _NOT_CONTIGUOUS:
                # A long outage can hide whole 2^16 wraps of the counter; the time stamps show them.
                excess = round(dt / self._period_us) - 1 - missing
                if excess >= SEQ_MODULUS // 2:
                    missing += SEQ_MODULUS * round(excess / SEQ_MODULUS)
            if missing:
                self.gaps += 1
                self.lost += missing
            elif not flags & _NOT_CONTIGUOUS and dt > 0:
                self._period_us = dt
        self._last_seq = seq
        self._last_t_us = t_us

    def feed_records(self, records: np.ndarray) -> None:
        """Account for decoded samples (:data:`SAMPLE_PAYLOAD_DTYPE` records) in order."""
        for seq, flags, t_us in zip(records["seq"].tolist(), records["flags"].tolist(), records["t_us"].tolist(),
                                    strict=True):
            self.sample(seq, flags, t_us)


@dataclass(frozen=True, slots=True)
class ParserStats:
    """Counters of a :class:`FrameParser` (all since construction or :meth:`FrameParser.reset_stats`).

    Invariant: ``bytes_in == bytes_framed + bytes_discarded + bytes_buffered``.

    Attributes:
        bytes_in: bytes fed.
        bytes_framed: bytes that belonged to valid frames.
        bytes_discarded: bytes thrown away while hunting for a frame.
        bytes_buffered: bytes held back waiting for the rest of a frame.
        frames: valid frames returned.
        crc_errors: complete frame candidates (sync, known type, plausible length) whose CRC failed.
        bad_headers: sync words followed by an unknown type or implausible length.
        resyncs: times the parser lost frame lock and had to hunt for a sync word.
        gaps: SAMPLE sequence discontinuities (one per run of lost frames).
        lost_frames: SAMPLE frames missing according to the sequence counter (u16 wrap handled).
        duplicates: SAMPLE frames repeating the previous sequence number and time.
        restarts: sensor restarts seen (BOOT event or the time base going backwards).
    """

    bytes_in: int = 0
    bytes_framed: int = 0
    bytes_discarded: int = 0
    bytes_buffered: int = 0
    frames: int = 0
    crc_errors: int = 0
    bad_headers: int = 0
    resyncs: int = 0
    gaps: int = 0
    lost_frames: int = 0
    duplicates: int = 0
    restarts: int = 0


class FrameParser:
    """Incremental frame parser: ``feed(chunk) -> list[Frame]``; never raises on bad input.

    After garbage or a failed CRC it drops one byte and hunts for the next sync word,
    so a valid frame that follows garbage, a truncated frame or a corrupted frame is
    recovered. SAMPLE sequence numbers are tracked for gap counting: a gap of ``k``
    lost frames wraps modulo 2^16, and a wrap of the 16-bit counter during a long
    outage is recovered from the sensor timestamps when the sample period is known.
    """

    def __init__(self, track_sequence: bool = True) -> None:
        self._buf = bytearray()
        self._track = track_sequence
        self._in_sync = True
        self._sequence = SequenceTracker()
        self.reset_stats()

    def reset_stats(self) -> None:
        """Zero all counters (the buffer content is kept and counted as new input)."""
        self._bytes_in = len(getattr(self, "_buf", b""))
        self._bytes_framed = 0
        self._bytes_discarded = 0
        self._frames = 0
        self._crc_errors = 0
        self._bad_headers = 0
        self._resyncs = 0
        self._sequence.reset_counts()

    def reset_sequence(self) -> None:
        """Forget the last sequence number (the sensor restarted its counter)."""
        self._sequence.forget()

    @property
    def frames(self) -> int:
        """Valid frames returned so far (cheap; :meth:`stats` has all counters)."""
        return self._frames

    @property
    def crc_errors(self) -> int:
        """Frame candidates that failed their CRC so far."""
        return self._crc_errors

    @property
    def bytes_buffered(self) -> int:
        """Bytes held back waiting for the rest of a frame."""
        return len(self._buf)

    def stats(self) -> ParserStats:
        """A snapshot of the counters."""
        return ParserStats(
            bytes_in=self._bytes_in,
            bytes_framed=self._bytes_framed,
            bytes_discarded=self._bytes_discarded,
            bytes_buffered=len(self._buf),
            frames=self._frames,
            crc_errors=self._crc_errors,
            bad_headers=self._bad_headers,
            resyncs=self._resyncs,
            gaps=self._sequence.gaps,
            lost_frames=self._sequence.lost,
            duplicates=self._sequence.duplicates,
            restarts=self._sequence.restarts,
        )

    def _discard(self, n: int) -> None:
        if n <= 0:
            return
        self._bytes_discarded += n
        if self._in_sync:
            self._in_sync = False
            self._resyncs += 1

    def feed(self, data: bytes | bytearray | memoryview) -> list[Frame]:
        """Append ``data`` and return every complete valid frame now available, in order."""
        buf = self._buf
        buf += data
        self._bytes_in += len(data)
        out: list[Frame] = []
        pos = 0
        n = len(buf)
        sync0 = SYNC[0]
        while True:
            i = buf.find(SYNC, pos)
            if i < 0:
                keep = 1 if n > pos and buf[n - 1] == sync0 else 0
                self._discard(n - keep - pos)
                pos = n - keep
                break
            if i > pos:
                self._discard(i - pos)
                pos = i
            if n - pos < HEADER_SIZE:
                break
            ftype = buf[pos + 2]
            length = buf[pos + 3] | (buf[pos + 4] << 8)
            if not (
                length == SAMPLE_PAYLOAD_SIZE
                if ftype == _T_SAMPLE
                else (ftype in _KNOWN_TYPES and length <= MAX_PAYLOAD)
            ):
                self._bad_headers += 1
                self._discard(1)
                pos += 1
                continue
            end = pos + HEADER_SIZE + length + CRC_SIZE
            if end > n:
                break
            if binascii.crc_hqx(buf[pos + 2 : end - 2], 0xFFFF) != buf[end - 2] | (buf[end - 1] << 8):
                self._crc_errors += 1
                self._discard(1)
                pos += 1
                continue
            payload = bytes(buf[pos + HEADER_SIZE : end - 2])
            self._bytes_framed += end - pos
            self._frames += 1
            self._in_sync = True
            pos = end
            if self._track:
                if ftype == _T_SAMPLE:
                    self._sequence.sample(*_SEQ_FLAGS_TIME.unpack_from(payload))
                elif ftype == _T_EVENT and payload[:1] == b"\x01":
                    self._sequence.boot()
            out.append(Frame(ftype, payload))
        del buf[:pos]
        return out
