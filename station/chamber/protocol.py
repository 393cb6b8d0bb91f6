"""What the station needs from a climate chamber: the :class:`Chamber` protocol, its state and errors.

The chamber conditions the air around the fixture; the units on the rig follow the air with
their own lag (and their own self-heating on top), so the station judges a plateau by the
units' temperatures, not by the chamber's. Temperatures degC, ramp rates K/min, times seconds
of the injected :class:`~station.kernel.clock.Clock` ("chamber seconds").

Every chamber error is a :class:`~station.kernel.errors.HardwareError`: the run's outcome is
ERROR (station fault), never a unit FAIL.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol, runtime_checkable

from station.chamber.registers import Status, alarm_name
from station.kernel.errors import HardwareError


class ChamberError(HardwareError):
    """Root of the chamber errors."""


class ChamberTimeout(ChamberError):
    """The chamber did not answer (no reply, refused or lost connection) after bounded retries,
    or its alive counter stopped."""


class ChamberSetpointTimeout(ChamberTimeout):
    """The chamber answers but its air did not reach the setpoint within the timeout (chamber s).

    ``state`` is the last :class:`ChamberState` read.
    """

    def __init__(self, message: str, state: ChamberState | None = None) -> None:
        super().__init__(message)
        self.state = state


class ChamberProtocolError(ChamberError):
    """A Modbus exception reply, a map version the station does not speak, or nonsense values."""

    def __init__(self, message: str, exception_code: int | None = None) -> None:
        super().__init__(message)
        self.exception_code = exception_code


class ChamberAlarm(ChamberError):
    """The chamber latched an alarm (``alarm_code``, ``alarm_name``) and stopped conditioning."""

    def __init__(self, alarm_code: int, message: str | None = None) -> None:
        self.alarm_code = int(alarm_code)
        self.alarm_name = alarm_name(self.alarm_code)
        super().__init__(message or f"chamber alarm {self.alarm_code} ({self.alarm_name})")


@dataclass(frozen=True)
class ChamberIdentity:
    """What the chamber says it is."""

    firmware_id: str
    firmware_version: str
    map_version: str
    min_temp_degc: float
    max_temp_degc: float
    max_ramp_k_per_min: float


@dataclass(frozen=True)
class ChamberState:
    """One consistent snapshot of the chamber's readbacks.

    Attributes:
        t_s: station clock time (s) when read.
        uptime_s: the chamber's own uptime (s).
        air_degc: the controlled air temperature (process value).
        working_setpoint_degc: the ramped setpoint the controller follows now.
        product_degc: the product (load) probe.
        setpoint_degc: the accepted target setpoint.
        status, alarm_code, alive, heartbeat_echo: as in the register map.
    """

    t_s: float
    uptime_s: float
    air_degc: float
    working_setpoint_degc: float
    product_degc: float
    setpoint_degc: float
    status: Status
    alarm_code: int
    alive: int
    heartbeat_echo: int

    def has(self, flag: Status) -> bool:
        return bool(self.status & flag)

    @property
    def running(self) -> bool:
        return self.has(Status.RUNNING)

    @property
    def at_setpoint(self) -> bool:
        return self.has(Status.AT_SETPOINT)

    @property
    def alarm(self) -> bool:
        return self.has(Status.ALARM)

    def describe(self) -> str:
        flags = "|".join(f.name or "" for f in Status if self.status & f) or "-"
        return (
            f"air={self.air_degc:.2f} degC product={self.product_degc:.2f} degC setpoint={self.setpoint_degc:.2f} "
            f"(working {self.working_setpoint_degc:.2f}) status={flags} alarm={self.alarm_code}"
        )


@runtime_checkable
class Chamber(Protocol):
    """The station's view of a climate chamber (:class:`station.chamber.client.ModbusChamber`).

    ``set_setpoint`` returns once the chamber accepted the target (read back from the chamber);
    ``wait_at_setpoint`` confirms from the AT_SETPOINT bit *and* the air readback within tolerance.
    Timeouts are chamber seconds of the injected clock. Any latched alarm raises :class:`ChamberAlarm`
    (``go_ambient`` and ``stop`` still work while one is latched).
    """

    reconnects: int

    def identify(self) -> ChamberIdentity: ...

    def state(self) -> ChamberState: ...

    def set_setpoint(self, degc: float, ramp_k_per_min: float = 0.0) -> ChamberState: ...

    def run(self) -> None: ...

    def stop(self) -> None: ...

    def wait_at_setpoint(self, timeout_s: float) -> ChamberState: ...

    def check(self) -> ChamberState: ...

    def acknowledge_alarm(self) -> None: ...

    def go_ambient(self, ambient_degc: float) -> None: ...

    def close(self) -> None: ...


__all__ = [
    "Chamber",
    "ChamberAlarm",
    "ChamberError",
    "ChamberIdentity",
    "ChamberProtocolError",
    "ChamberSetpointTimeout",
    "ChamberState",
    "ChamberTimeout",
]
