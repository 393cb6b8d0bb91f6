"""What the station needs from a test rig: the :class:`Rig` protocol, its state and its errors.

The rig is a tumble gimbal (roll about sensor x, pitch about y) on a rate table
spinning about the world vertical (yaw), see :mod:`station.kernel.geometry`. The API
speaks degrees and deg/s because the rig and ``POSE_ANGLES_DEG`` do; the
``*_rad`` properties give SI values for the rest of the station. Times are seconds
of the injected :class:`~station.kernel.clock.Clock` ("rig seconds").

Every rig error is a :class:`~station.kernel.errors.HardwareError`: the run's outcome is
ERROR (station fault), never a unit FAIL.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

from station.kernel.errors import HardwareError
from station.rig.registers import AckResult, Status, fault_name


class RigError(HardwareError):
    """Root of the rig errors."""


class RigTimeout(RigError):
    """The rig did not answer (no reply, connection refused or lost) after bounded retries."""


class RigMotionTimeout(RigTimeout):
    """The rig answers but did not confirm a motion within the timeout (rig seconds).

    ``state`` is the last :class:`RigState` read (or None).
    """

    def __init__(self, message: str, state: RigState | None = None) -> None:
        super().__init__(message)
        self.state = state


class RigProtocolError(RigError):
    """The rig answered with a Modbus exception or with values that make no sense.

    ``exception_code`` is the Modbus exception code when there was one.
    """

    def __init__(self, message: str, exception_code: int | None = None) -> None:
        super().__init__(message)
        self.exception_code = exception_code


class RigCommandRejected(RigProtocolError):
    """The rig acknowledged a command with a non-OK :class:`AckResult` (``result``)."""

    def __init__(self, message: str, result: int) -> None:
        super().__init__(message)
        self.result = result


class RigFault(RigError):
    """The rig latched a fault; ``fault_code`` is its FAULT_CODE register."""

    def __init__(self, fault_code: int, message: str | None = None) -> None:
        self.fault_code = int(fault_code)
        self.fault_name = fault_name(self.fault_code)
        super().__init__(message or f"rig fault {self.fault_code} ({self.fault_name})")


@dataclass(frozen=True)
class RigIdentity:
    """What the rig says it is."""

    firmware_id: str
    firmware_version: str  # 'major.minor'
    map_version: str  # 'major.minor'
    max_rate_dps: float  # largest table rate it accepts (deg/s)


@dataclass(frozen=True)
class RigState:
    """One consistent snapshot of the rig's readbacks.

    Attributes:
        t_s: station clock time (s) when the snapshot was read.
        rig_time_s: the rig's own uptime (s, wraps after ~49.7 days).
        roll_deg, pitch_deg, yaw_deg: measured axis angles (deg); yaw in [-180, 180).
        rate_dps: measured table rate about the world vertical (deg/s).
        status: the STATUS bits.
        fault_code: latched fault code (0 = none).
        ack_seq, ack_result: last processed command sequence number and its result.
        alive: the rig's alive counter.
        heartbeat_echo: last heartbeat value the rig accepted.
    """

    t_s: float
    rig_time_s: float
    roll_deg: float
    pitch_deg: float
    yaw_deg: float
    rate_dps: float
    status: Status
    fault_code: int
    ack_seq: int
    ack_result: int
    alive: int
    heartbeat_echo: int

    def has(self, flag: Status) -> bool:
        return bool(self.status & flag)

    @property
    def ready(self) -> bool:
        return self.has(Status.READY)

    @property
    def moving(self) -> bool:
        return self.has(Status.MOVING)

    @property
    def in_position(self) -> bool:
        return self.has(Status.IN_POSITION)

    @property
    def rate_settled(self) -> bool:
        return self.has(Status.RATE_SETTLED)

    @property
    def at_rest(self) -> bool:
        return self.has(Status.AT_REST)

    @property
    def fault(self) -> bool:
        return self.has(Status.FAULT)

    @property
    def estop(self) -> bool:
        return self.has(Status.ESTOP)

    @property
    def remote(self) -> bool:
        return self.has(Status.REMOTE)

    @property
    def ack(self) -> AckResult | int:
        try:
            return AckResult(self.ack_result)
        except ValueError:
            return self.ack_result

    @property
    def angles_rad(self) -> tuple[float, float, float]:
        """(roll, pitch, yaw) in rad."""
        return (math.radians(self.roll_deg), math.radians(self.pitch_deg), math.radians(self.yaw_deg))

    @property
    def rate_radps(self) -> float:
        """Table rate in rad/s."""
        return math.radians(self.rate_dps)

    def describe(self) -> str:
        """One line for error messages and logs."""
        flags = "|".join(f.name or "" for f in Status if self.status & f) or "-"
        return (
            f"roll={self.roll_deg:.3f} pitch={self.pitch_deg:.3f} yaw={self.yaw_deg:.3f} deg "
            f"rate={self.rate_dps:.3f} deg/s status={flags} fault={self.fault_code}"
        )


#: A target orientation: (roll_deg, pitch_deg) or a pose name of ``POSE_ANGLES_DEG`` ('+x', '-z', ...).
Orientation = tuple[float, float] | str


@runtime_checkable
class Rig(Protocol):
    """The station's view of a rig; implemented by :class:`station.rig.mapped.RegisterRig` on a transport
    (:class:`station.rig.modbus.ModbusRig`, the in-process fake of :mod:`station.sim.fakes`).

    Commands return once the rig acknowledged them; the ``wait_*`` calls confirm
    the motion from status bits *and* readbacks within tolerance, never from the
    setpoint. Timeouts are rig seconds of the injected clock.

    Attributes:
        reconnects: how often the link to the rig was lost and re-established since it was
            opened (the run treats any as a station fault: the rig went unsupervised).
        listeners: called with every state the rig reports while the station waits on it
            (the runner publishes them as live readings).
    """

    reconnects: int
    listeners: list[Callable[[RigState], None]]

    def identify(self) -> RigIdentity: ...

    def state(self) -> RigState: ...

    def move_to(self, orientation: Orientation) -> None: ...

    def wait_in_position(self, timeout_s: float) -> RigState: ...

    def spin(self, rate_dps: float) -> None: ...

    def wait_rate_settled(self, timeout_s: float) -> RigState: ...

    def stop(self) -> None: ...

    def wait_at_rest(self, timeout_s: float) -> RigState: ...

    def reset_fault(self) -> None: ...

    def close(self) -> None: ...
