"""The rig's Modbus register map (map version 1.0) as code.

One source of truth for the station client (:mod:`station.rig.modbus`) and the
simulated rig (:mod:`station.sim.rig_server`); ``station/rig/register-map.md`` is the same
table for people. Addresses are 0-based protocol (PDU) addresses; tools that count
from 1 (mbpoll, most SCADA "4xxxx/3xxxx" references) use ``address + 1``.

Encoding: 16-bit registers are unsigned. 32-bit values (float32, uint32) occupy two
consecutive registers, **high word first** (big-endian bytes and big-endian word
order, "ABCD"); mbpoll needs ``-B`` to read them. Strings are ASCII, two characters
per register, first character in the high byte, NUL padded. Angles on the wire are
in degrees and rates in deg/s (float32); convert to rad inside the station.
"""

from __future__ import annotations

import math
import struct
from enum import IntEnum, IntFlag

MAP_VERSION_MAJOR = 1
MAP_VERSION_MINOR = 0
MAP_VERSION = (MAP_VERSION_MAJOR << 8) | MAP_VERSION_MINOR


class HR(IntEnum):
    """Holding registers (function codes 3 read, 6/16 write): what the station commands."""

    COMMAND = 0  # uint16, a :class:`Command`
    COMMAND_SEQ = 1  # uint16; a write that changes it executes COMMAND (see docs)
    TARGET_ROLL = 2  # float32 deg, registers 2-3
    TARGET_PITCH = 4  # float32 deg, registers 4-5
    TARGET_RATE = 6  # float32 deg/s, registers 6-7 (table rate about world vertical)
    HEARTBEAT = 8  # uint16 counter written by the station
    WATCHDOG_MS = 9  # uint16 watchdog timeout in ms (rig time), WATCHDOG_MS_RANGE


HOLDING_START = 0
HOLDING_COUNT = 10
#: Allowed watchdog timeouts (ms); other values are answered with ILLEGAL_DATA_VALUE.
WATCHDOG_MS_RANGE = (100, 60000)
WATCHDOG_MS_DEFAULT = 2000


class IR(IntEnum):
    """Input registers (function code 4): what the rig reports."""

    STATUS = 0  # uint16 :class:`Status` bits
    FAULT_CODE = 1  # uint16 :class:`FaultCode` (0 when no fault is latched)
    ACK_SEQ = 2  # uint16 COMMAND_SEQ of the last command the rig processed
    ACK_RESULT = 3  # uint16 :class:`AckResult` of that command
    ALIVE = 4  # uint16 rig counter, +1 every ALIVE_PERIOD_S of rig time, wraps
    HEARTBEAT_ECHO = 5  # uint16 last HEARTBEAT value the rig accepted
    RIG_TIME_MS = 6  # uint32 ms since rig power-up, registers 6-7, wraps
    ACTUAL_ROLL = 8  # float32 deg, registers 8-9 (measured)
    ACTUAL_PITCH = 10  # float32 deg, registers 10-11
    ACTUAL_YAW = 12  # float32 deg in [-180, 180), registers 12-13
    ACTUAL_RATE = 14  # float32 deg/s table rate, registers 14-15
    MAP_VERSION = 100  # uint16 major << 8 | minor
    FIRMWARE_VERSION = 101  # uint16 major << 8 | minor
    FIRMWARE_ID = 102  # ASCII, 16 characters in registers 102-109
    MAX_RATE = 110  # float32 deg/s, largest |TARGET_RATE| accepted, registers 110-111


#: Input registers read together for a state snapshot (one FC4 request).
STATE_START = 0
STATE_COUNT = 16
#: Input registers read together by identify().
IDENT_START = 100
IDENT_COUNT = 12
FIRMWARE_ID_REGS = 8

ALIVE_PERIOD_S = 0.1


class Command(IntEnum):
    """Values of :attr:`HR.COMMAND`."""

    NOP = 0
    MOVE_TO_ORIENTATION = 1  # tumble roll/pitch to TARGET_ROLL/TARGET_PITCH; table must be at rest
    SPIN = 2  # ramp the table to TARGET_RATE; tumble axes must be still
    STOP = 3  # bring every axis to rest (always accepted, also in fault)
    RESET_FAULT = 4  # clear a latched fault whose cause is gone
    HOME = 5  # roll = pitch = 0, yaw to the nearest multiple of 360 deg; table must be at rest


class Status(IntFlag):
    """Bits of :attr:`IR.STATUS`."""

    READY = 1 << 0  # powered, remote enabled, no fault: accepts motion commands
    MOVING = 1 << 1  # some axis has a non-zero rate or is in a motion phase
    IN_POSITION = 1 << 2  # roll/pitch at the commanded orientation and settled
    RATE_SETTLED = 1 << 3  # table ramp finished and settled at TARGET_RATE
    AT_REST = 1 << 4  # every axis still (table rate 0)
    FAULT = 1 << 5  # a fault is latched; FAULT_CODE says which
    ESTOP = 1 << 6  # emergency stop button pressed
    REMOTE = 1 << 7  # local/remote switch in remote: Modbus commands accepted
    WATCHDOG_ARMED = 1 << 8  # a heartbeat was seen; the watchdog is supervising


STATUS_DEFINED = Status(0x01FF)


class FaultCode(IntEnum):
    """Values of :attr:`IR.FAULT_CODE`; codes >= 100 are vendor specific drive codes."""

    NONE = 0
    WATCHDOG = 1  # heartbeat not refreshed within WATCHDOG_MS
    ESTOP = 2  # emergency stop pressed
    DRIVE_ROLL = 3
    DRIVE_PITCH = 4
    DRIVE_YAW = 5
    OVERSPEED = 6
    LIMIT_SWITCH = 7
    INTERNAL = 8


class AckResult(IntEnum):
    """Values of :attr:`IR.ACK_RESULT`."""

    OK = 0
    UNKNOWN_COMMAND = 1
    OUT_OF_RANGE = 2  # target NaN or beyond ROLL/PITCH limits or MAX_RATE
    BUSY = 3  # the axes this command needs are still moving
    FAULTED = 4  # a fault is latched (or its cause persists on RESET_FAULT)
    NOT_AT_REST = 5  # MOVE/HOME while the table spins
    NOT_REMOTE = 6  # rig in local mode


#: Mechanical limits of the tumble gimbal (deg); targets beyond are OUT_OF_RANGE.
ROLL_LIMIT_DEG = 180.0
PITCH_LIMIT_DEG = 90.0
#: Readbacks beyond these are nonsense (a protocol error), not a position.
SANE_ANGLE_DEG = 360.0
SANE_RATE_DPS = 5000.0


def fault_name(code: int) -> str:
    """Readable name of a fault code (``'DRIVE_PITCH'``, ``'VENDOR_123'``)."""
    try:
        return FaultCode(code).name
    except ValueError:
        return f"VENDOR_{code}"


def float32_to_regs(value: float) -> list[int]:
    """Two registers (high word first) holding ``value`` as IEEE-754 float32."""
    hi, lo = struct.unpack(">HH", struct.pack(">f", value))
    return [hi, lo]


def regs_to_float32(regs: list[int] | tuple[int, ...]) -> float:
    """The float32 in two registers (high word first)."""
    return float(struct.unpack(">f", struct.pack(">HH", regs[0], regs[1]))[0])


def uint32_to_regs(value: int) -> list[int]:
    """Two registers (high word first) holding an unsigned 32-bit integer (wrapped)."""
    value &= 0xFFFFFFFF
    return [value >> 16, value & 0xFFFF]


def regs_to_uint32(regs: list[int] | tuple[int, ...]) -> int:
    """The unsigned 32-bit integer in two registers (high word first)."""
    return (regs[0] << 16) | regs[1]


def ascii_to_regs(text: str, n_regs: int) -> list[int]:
    """``text`` as ASCII, two characters per register (first in the high byte), NUL padded."""
    raw = text.encode("ascii")[: 2 * n_regs].ljust(2 * n_regs, b"\0")
    return [int.from_bytes(raw[i : i + 2], "big") for i in range(0, len(raw), 2)]


def regs_to_ascii(regs: list[int] | tuple[int, ...]) -> str:
    """The NUL-padded ASCII string in ``regs``; non-ASCII bytes become '?'."""
    raw = b"".join(int(r).to_bytes(2, "big") for r in regs).split(b"\0", 1)[0]
    return raw.decode("ascii", errors="replace").replace("\ufffd", "?")


def version_string(word: int) -> str:
    """``major << 8 | minor`` as ``'major.minor'``."""
    return f"{word >> 8}.{word & 0xFF}"


def wrap_deg(angle_deg: float) -> float:
    """Angle wrapped into [-180, 180) deg."""
    return (angle_deg + 180.0) % 360.0 - 180.0


def angle_error_deg(actual_deg: float, target_deg: float) -> float:
    """Smallest signed difference ``actual - target`` (deg), so -180 matches +180."""
    if not (math.isfinite(actual_deg) and math.isfinite(target_deg)):
        return math.nan
    return wrap_deg(actual_deg - target_deg)
