"""Commands, acknowledgements and their payloads (station/sensor/protocol.md).

A COMMAND frame's payload is ``seq u16 | command u8 | arguments``; the sensor answers
with an ACK (``seq u16 | command u8 | reply data``) or a NAK (``seq u16 | command u8 |
error u8``) echoing the host's command sequence number. Repeating a command with the
same sequence number and bytes makes the sensor resend its cached answer instead of
executing it again (safe retries). All integers little-endian; physical values SI
(m/s^2, rad/s, s).
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from enum import IntEnum

from station.kernel.errors import FormatError
from station.sensor.frames import Frame, FrameType, encode_frame

PROTOCOL_VERSION = 1
MAX_EEPROM_READ = 256  # bytes per EEPROM_READ command
_ID_LEN = 16  # serial and firmware fields, ASCII, NUL padded


class Command(IntEnum):
    """Command codes (third byte of a COMMAND payload)."""

    IDENTIFY = 0x01
    GET_STATUS = 0x02
    START_STREAM = 0x03
    STOP_STREAM = 0x04
    SET_RATE = 0x05
    SET_OUTPUT = 0x06
    EEPROM_INFO = 0x07
    EEPROM_READ = 0x08
    EEPROM_WRITE_PAGE = 0x09
    RESET = 0x0A


class NakCode(IntEnum):
    """Error codes of a NAK."""

    UNKNOWN_COMMAND = 0x01
    BAD_PAYLOAD = 0x02  # arguments too short / too long for the command
    BAD_ARGUMENT = 0x03  # argument out of its domain (output mode, read length)
    UNSUPPORTED_RATE = 0x04
    ADDRESS_RANGE = 0x05  # EEPROM address range outside the device
    PAGE_BOUNDARY = 0x06  # EEPROM page write crosses a page boundary
    WRITE_PROTECTED = 0x07
    BUSY = 0x08  # EEPROM write cycle in progress


class OutputMode(IntEnum):
    """Sample output: raw sensor values or values corrected on the sensor (Algorithm 1)."""

    RAW = 0
    CORRECTED = 1


class BootReason(IntEnum):
    """Why the sensor sent a BOOT event."""

    POWER_ON = 0
    RESET_COMMAND = 1


def _pad(text: str) -> bytes:
    raw = text.encode("ascii")
    if len(raw) > _ID_LEN:
        raise ValueError(f"{text!r} is longer than {_ID_LEN} ASCII characters")
    return raw.ljust(_ID_LEN, b"\0")


def _unpad(raw: bytes) -> str:
    return raw.split(b"\0", 1)[0].decode("ascii", errors="replace")


_ID_HEAD = struct.Struct("<BBH16s16sffff")


@dataclass(frozen=True)
class SensorIdentity:
    """IDENTIFY reply.

    Attributes:
        serial: serial number (ASCII, at most 16 characters).
        firmware: firmware version string (ASCII, at most 16 characters).
        rates_hz: supported sample rates (Hz); each divides 1e6 so sample times are whole µs.
        default_rate_hz: rate after power-on (Hz).
        accel_range_mps2: accelerometer full scale, +- (m/s^2).
        gyro_range_radps: gyroscope full scale, +- (rad/s).
        accel_resolution_mps2: accelerometer ADC scale factor, value of one LSB (m/s^2); 0 = not quantized.
        gyro_resolution_radps: gyroscope ADC scale factor, value of one LSB (rad/s); 0 = not quantized.
        protocol_version: protocol revision the firmware speaks.
    """

    serial: str
    firmware: str
    rates_hz: tuple[int, ...]
    default_rate_hz: int
    accel_range_mps2: float
    gyro_range_radps: float
    accel_resolution_mps2: float = 0.0
    gyro_resolution_radps: float = 0.0
    protocol_version: int = PROTOCOL_VERSION

    def encode(self) -> bytes:
        head = _ID_HEAD.pack(
            self.protocol_version,
            len(self.rates_hz),
            self.default_rate_hz,
            _pad(self.serial),
            _pad(self.firmware),
            self.accel_range_mps2,
            self.gyro_range_radps,
            self.accel_resolution_mps2,
            self.gyro_resolution_radps,
        )
        return head + struct.pack(f"<{len(self.rates_hz)}H", *self.rates_hz)

    @classmethod
    def decode(cls, data: bytes) -> SensorIdentity:
        if len(data) < _ID_HEAD.size:
            raise FormatError(f"identify reply too short ({len(data)} bytes)")
        version, n_rates, default_rate, serial, firmware, ar, gr, ares, gres = _ID_HEAD.unpack_from(data)
        if len(data) != _ID_HEAD.size + 2 * n_rates:
            raise FormatError(f"identify reply announces {n_rates} rates but has {len(data)} bytes")
        rates = struct.unpack_from(f"<{n_rates}H", data, _ID_HEAD.size)
        return cls(
            serial=_unpad(serial),
            firmware=_unpad(firmware),
            rates_hz=tuple(rates),
            default_rate_hz=default_rate,
            accel_range_mps2=ar,
            gyro_range_radps=gr,
            accel_resolution_mps2=ares,
            gyro_resolution_radps=gres,
            protocol_version=version,
        )


_STATUS = struct.Struct("<BBHQHHII")


@dataclass(frozen=True)
class SensorStatus:
    """GET_STATUS reply.

    Attributes:
        streaming: samples are being sent.
        output: raw or corrected output.
        rate_hz: current sample rate (Hz).
        uptime_s: sensor time since power-on (s, µs resolution).
        next_seq: sequence number the next sample will carry.
        boot_count: power-ons and resets since the sensor was made (simulation: since construction).
        tx_overruns: sample frames the sensor dropped because its transmit buffer was full.
    """

    streaming: bool
    output: OutputMode
    rate_hz: int
    uptime_s: float
    next_seq: int
    boot_count: int
    tx_overruns: int

    def encode(self) -> bytes:
        return _STATUS.pack(
            int(self.streaming),
            int(self.output),
            self.rate_hz,
            round(self.uptime_s * 1e6),
            self.next_seq,
            0,
            self.boot_count,
            self.tx_overruns,
        )

    @classmethod
    def decode(cls, data: bytes) -> SensorStatus:
        if len(data) != _STATUS.size:
            raise FormatError(f"status reply must be {_STATUS.size} bytes, got {len(data)}")
        streaming, output, rate, uptime_us, next_seq, _, boots, overruns = _STATUS.unpack(data)
        try:
            mode = OutputMode(output)
        except ValueError as exc:
            raise FormatError(f"status reply: unknown output mode {output}") from exc
        return cls(bool(streaming), mode, rate, uptime_us * 1e-6, next_seq, boots, overruns)


_EEPROM_INFO = struct.Struct("<IHBBI")


@dataclass(frozen=True)
class EepromInfo:
    """EEPROM_INFO reply: size (bytes), page size (bytes), write protect state, write-cycle time (s)."""

    size: int
    page_size: int
    write_protect: bool
    write_cycle_s: float

    def encode(self) -> bytes:
        return _EEPROM_INFO.pack(self.size, self.page_size, int(self.write_protect), 0, round(self.write_cycle_s * 1e6))

    @classmethod
    def decode(cls, data: bytes) -> EepromInfo:
        if len(data) != _EEPROM_INFO.size:
            raise FormatError(f"EEPROM info reply must be {_EEPROM_INFO.size} bytes, got {len(data)}")
        size, page, wp, _, cycle_us = _EEPROM_INFO.unpack(data)
        return cls(size, page, bool(wp), cycle_us * 1e-6)


_BOOT = struct.Struct("<BBHI")


@dataclass(frozen=True)
class BootEvent:
    """EVENT/BOOT payload: the sensor restarted (time base, sequence counter and drift state reset)."""

    reason: BootReason
    boot_count: int

    def encode(self) -> bytes:
        return _BOOT.pack(0x01, int(self.reason), 0, self.boot_count)

    @classmethod
    def decode(cls, data: bytes) -> BootEvent:
        if len(data) != _BOOT.size or data[0] != 0x01:
            raise FormatError("not a BOOT event payload")
        _, reason, _, count = _BOOT.unpack(data)
        try:
            return cls(BootReason(reason), count)
        except ValueError as exc:
            raise FormatError(f"BOOT event: unknown reason {reason}") from exc


# --- command arguments ------------------------------------------------------------------------

_RATE = struct.Struct("<H")
_EEPROM_READ = struct.Struct("<IH")
_ADDR = struct.Struct("<I")
_WRITE_REPLY = struct.Struct("<IH")


def pack_rate(rate_hz: int) -> bytes:
    """START_STREAM / SET_RATE argument: rate u16 (Hz; 0 in START_STREAM keeps the current rate)."""
    return _RATE.pack(rate_hz)


def unpack_rate(args: bytes) -> int:
    if len(args) != _RATE.size:
        raise FormatError("rate argument must be 2 bytes")
    return int(_RATE.unpack(args)[0])


def pack_output(mode: OutputMode) -> bytes:
    """SET_OUTPUT argument: mode u8."""
    return bytes((int(mode),))


def pack_eeprom_read(addr: int, length: int) -> bytes:
    """EEPROM_READ arguments: address u32, length u16 (1..256 bytes)."""
    return _EEPROM_READ.pack(addr, length)


def unpack_eeprom_read(args: bytes) -> tuple[int, int]:
    if len(args) != _EEPROM_READ.size:
        raise FormatError("EEPROM read arguments must be 6 bytes")
    addr, length = _EEPROM_READ.unpack(args)
    return int(addr), int(length)


def pack_eeprom_write(addr: int, data: bytes) -> bytes:
    """EEPROM_WRITE_PAGE arguments: address u32, then the data (1..page size bytes, one page)."""
    return _ADDR.pack(addr) + bytes(data)


def unpack_eeprom_write(args: bytes) -> tuple[int, bytes]:
    if len(args) < _ADDR.size + 1:
        raise FormatError("EEPROM write needs an address and at least one data byte")
    return int(_ADDR.unpack_from(args)[0]), bytes(args[_ADDR.size :])


def pack_read_reply(addr: int, data: bytes) -> bytes:
    """EEPROM_READ reply: address u32, then the data."""
    return _ADDR.pack(addr) + data


def unpack_read_reply(reply: bytes) -> tuple[int, bytes]:
    if len(reply) < _ADDR.size:
        raise FormatError("EEPROM read reply too short")
    return int(_ADDR.unpack_from(reply)[0]), bytes(reply[_ADDR.size :])


def pack_write_reply(addr: int, length: int) -> bytes:
    """EEPROM_WRITE_PAGE reply: address u32, bytes written u16."""
    return _WRITE_REPLY.pack(addr, length)


def unpack_write_reply(reply: bytes) -> tuple[int, int]:
    if len(reply) != _WRITE_REPLY.size:
        raise FormatError("EEPROM write reply must be 6 bytes")
    addr, length = _WRITE_REPLY.unpack(reply)
    return int(addr), int(length)


# --- frames -----------------------------------------------------------------------------------

_PREFIX = struct.Struct("<HB")


def encode_command(seq: int, command: int, args: bytes = b"") -> bytes:
    """A COMMAND frame: seq u16, command u8, arguments."""
    return encode_frame(FrameType.COMMAND, _PREFIX.pack(seq & 0xFFFF, command) + args)


def decode_command(payload: bytes) -> tuple[int, int, bytes]:
    """(seq, command code, arguments) of a COMMAND payload; :class:`FormatError` if too short."""
    if len(payload) < _PREFIX.size:
        raise FormatError("command payload shorter than 3 bytes")
    seq, code = _PREFIX.unpack_from(payload)
    return int(seq), int(code), bytes(payload[_PREFIX.size :])


def encode_ack(seq: int, command: int, reply: bytes = b"") -> bytes:
    """An ACK frame echoing the command's seq and code, with reply data."""
    return encode_frame(FrameType.ACK, _PREFIX.pack(seq & 0xFFFF, command) + reply)


def encode_nak(seq: int, command: int, error: NakCode) -> bytes:
    """A NAK frame echoing the command's seq and code, with an error code."""
    return encode_frame(FrameType.NAK, _PREFIX.pack(seq & 0xFFFF, command) + bytes((int(error),)))


@dataclass(frozen=True)
class Reply:
    """A decoded ACK or NAK: ``ok`` with ``data``, or not ``ok`` with ``error``."""

    seq: int
    command: int
    ok: bool
    data: bytes = b""
    error: int = 0


def decode_reply(frame: Frame) -> Reply:
    """Decode an ACK or NAK frame; :class:`FormatError` for anything else."""
    if frame.type not in (FrameType.ACK, FrameType.NAK) or len(frame.payload) < _PREFIX.size:
        raise FormatError("not an ACK/NAK frame")
    seq, code = _PREFIX.unpack_from(frame.payload)
    rest = bytes(frame.payload[_PREFIX.size :])
    if frame.type == FrameType.ACK:
        return Reply(int(seq), int(code), True, data=rest)
    if len(rest) != 1:
        raise FormatError("NAK payload must carry exactly one error byte")
    return Reply(int(seq), int(code), False, error=rest[0])
