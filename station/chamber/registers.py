"""The climate chamber's Modbus register map (map version 1.0) as code.

One source of truth for the station client (:mod:`station.chamber.client`) and the simulated
chamber (:mod:`station.sim.chamber_server`); ``station/chamber/register-map.md`` is the same table
for people. It follows the common layout of chamber controllers: a process value (air), a
product probe, a setpoint with a ramp rate, a RUN/STOP mode, status and alarm words, and a
watchdog the supervising computer must feed. Addresses are 0-based protocol (PDU) addresses.

Encoding as in the rig's map: 16-bit registers unsigned; float32 and uint32 in two registers,
high word first ("ABCD"); ASCII two characters per register, first in the high byte.
Temperatures degC, ramp rates K/min, times s.
"""

from __future__ import annotations

import struct
from enum import IntEnum, IntFlag

MAP_VERSION_MAJOR = 1
MAP_VERSION_MINOR = 0
MAP_VERSION = (MAP_VERSION_MAJOR << 8) | MAP_VERSION_MINOR


class HR(IntEnum):
    """Holding registers (FC 3 read, FC 6/16 write): what the station commands."""

    SETPOINT = 0  # float32 degC, registers 0-1
    RAMP_RATE = 2  # float32 K/min, registers 2-3; 0 = as fast as the plant can
    MODE = 4  # uint16 :class:`Mode`
    HEARTBEAT = 5  # uint16 counter; each new value refreshes the watchdog
    WATCHDOG_S = 6  # uint16 watchdog timeout (s of chamber time), WATCHDOG_S_RANGE
    ALARM_ACK = 7  # uint16: writing 1 acknowledges (clears) the latched alarm when its cause is gone


HOLDING_START = 0
HOLDING_COUNT = 8
WATCHDOG_S_RANGE = (1, 3600)
WATCHDOG_S_DEFAULT = 30


class IR(IntEnum):
    """Input registers (FC 4): what the chamber reports."""

    STATUS = 0  # uint16 :class:`Status` bits
    ALARM_CODE = 1  # uint16 :class:`AlarmCode`, the first latched alarm (0 = none)
    ALIVE = 2  # uint16 counter, +1 every ALIVE_PERIOD_S of chamber time, wraps
    HEARTBEAT_ECHO = 3  # uint16 last HEARTBEAT accepted
    UPTIME_MS = 4  # uint32 ms since power-up, registers 4-5, wraps
    AIR_PV = 6  # float32 degC, the controlled air temperature (process value), registers 6-7
    WORKING_SETPOINT = 8  # float32 degC, the ramped setpoint the controller follows now, registers 8-9
    PRODUCT_PV = 10  # float32 degC, the product (load) probe, registers 10-11
    SETPOINT_ECHO = 12  # float32 degC, the accepted target setpoint, registers 12-13
    MAP_VERSION = 100  # uint16 major << 8 | minor
    FIRMWARE_VERSION = 101  # uint16 major << 8 | minor
    FIRMWARE_ID = 102  # ASCII, 16 characters, registers 102-109
    MIN_TEMP = 110  # float32 degC, lowest accepted setpoint, registers 110-111
    MAX_TEMP = 112  # float32 degC, highest accepted setpoint, registers 112-113
    MAX_RAMP = 114  # float32 K/min, fastest ramp the plant achieves, registers 114-115


STATE_START = 0
STATE_COUNT = 14
IDENT_START = 100
IDENT_COUNT = 16
FIRMWARE_ID_REGS = 8
ALIVE_PERIOD_S = 0.1


class Mode(IntEnum):
    """Values of :attr:`HR.MODE`."""

    STOP = 0  # conditioning off: the air drifts to the room temperature
    RUN = 1  # control the air to the (ramped) setpoint


class Status(IntFlag):
    """Bits of :attr:`IR.STATUS`."""

    RUNNING = 0x0001  # conditioning on (MODE = RUN and no alarm)
    RAMPING = 0x0002  # the working setpoint has not reached the target yet
    AT_SETPOINT = 0x0004  # running, ramp ended, |air - setpoint| within the band for the hold time
    ALARM = 0x0008  # an alarm is latched (ALARM_CODE != 0)
    WATCHDOG_ARMED = 0x0010  # a heartbeat arrived since power-up
    REMOTE = 0x0020  # remote operation enabled (local panel not in control)
    DOOR_OPEN = 0x0040  # door switch open


STATUS_DEFINED = 0x007F


class AlarmCode(IntEnum):
    """Values of :attr:`IR.ALARM_CODE`."""

    NONE = 0
    WATCHDOG = 1  # HEARTBEAT not refreshed within WATCHDOG_S
    OVER_TEMPERATURE = 2  # independent over-temperature protection tripped
    UNDER_TEMPERATURE = 3
    SENSOR_BREAK = 4  # air probe open or shorted
    COMPRESSOR = 5  # refrigeration fault
    DOOR = 6  # door opened while running
    WATER = 7  # humidifier / cooling water missing
    INTERNAL = 8


def alarm_name(code: int) -> str:
    try:
        return AlarmCode(code).name
    except ValueError:
        return f"VENDOR_{code}" if code >= 100 else f"UNKNOWN_{code}"


#: Readbacks outside these bounds are nonsense (degC).
SANE_TEMP_DEGC = (-100.0, 250.0)


def float32_to_regs(value: float) -> list[int]:
    hi, lo = struct.unpack(">HH", struct.pack(">f", value))
    return [hi, lo]


def regs_to_float32(regs: list[int]) -> float:
    return float(struct.unpack(">f", struct.pack(">HH", regs[0] & 0xFFFF, regs[1] & 0xFFFF))[0])


def uint32_to_regs(value: int) -> list[int]:
    value &= 0xFFFFFFFF
    return [value >> 16, value & 0xFFFF]


def regs_to_uint32(regs: list[int]) -> int:
    return ((regs[0] & 0xFFFF) << 16) | (regs[1] & 0xFFFF)


def ascii_to_regs(text: str, count: int) -> list[int]:
    data = text.encode("ascii")[: 2 * count].ljust(2 * count, b"\0")
    return [(data[2 * i] << 8) | data[2 * i + 1] for i in range(count)]


def regs_to_ascii(regs: list[int]) -> str:
    data = b"".join(bytes(((r >> 8) & 0xFF, r & 0xFF)) for r in regs)
    return data.split(b"\0", 1)[0].decode("ascii", errors="replace")


def version_string(word: int) -> str:
    return f"{word >> 8}.{word & 0xFF}"
