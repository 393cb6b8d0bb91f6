"""The :class:`~station.rig.protocol.Rig` protocol over the rig's register map, on any register transport.

The rig's interface is its register map (:mod:`station.rig.registers`, ``station/rig/register-map.md``).
:class:`RegisterRig` implements the station's side of it once: identification, state snapshots
with their sanity checks and the alive-counter supervision, commands (targets + command + a new
sequence number, then the rig's acknowledgement), motion confirmed by status bits *and*
readbacks within tolerance polled on the injected clock, and the heartbeat. A transport
supplies two hooks, reading input registers and writing holding registers:
:class:`station.rig.modbus.ModbusRig` over Modbus/TCP or RTU, and the in-process fake of
:mod:`station.sim.fakes`, which calls the simulated rig's model directly.
"""

from __future__ import annotations

import logging
import math
import threading
from collections.abc import Callable
from typing import TypeVar

from station.kernel.clock import Clock, WallClock
from station.kernel.geometry import POSE_ANGLES_DEG
from station.modbus.heartbeat import Heartbeat
from station.rig import registers as reg
from station.rig.protocol import (
    Orientation,
    RigCommandRejected,
    RigFault,
    RigIdentity,
    RigMotionTimeout,
    RigProtocolError,
    RigState,
    RigTimeout,
)
from station.rig.registers import HR, IR, AckResult, Command, Status

log = logging.getLogger(__name__)


class RegisterRig(Heartbeat):
    """A rig behind its register map; implements :class:`station.rig.protocol.Rig` given a transport.

    Args:
        clock: time base for waits, polling and the heartbeat (rig seconds).
        poll_s: status polling period while waiting (rig s).
        heartbeat_period_s: heartbeat write period (rig s); keep well below the rig's watchdog.
        angle_tol_deg: readback tolerance confirming an orientation (deg).
        rate_tol_dps: readback tolerance confirming a table rate (deg/s).
        ack_timeout_s: how long a command may stay unacknowledged (rig s).
        alive_timeout_s: the rig's alive counter must change within this (rig s).

    Transports implement :meth:`_read_input`, :meth:`_write` and :meth:`_close_link`, and count
    re-established links in :attr:`reconnects`. The heartbeat thread is
    :class:`station.modbus.heartbeat.Heartbeat`'s.
    """

    _role = "rig"
    _heartbeat_register = HR.HEARTBEAT
    _log = log

    def __init__(
        self,
        clock: Clock | None = None,
        *,
        poll_s: float = 0.1,
        heartbeat_period_s: float = 0.5,
        angle_tol_deg: float = 0.05,
        rate_tol_dps: float = 0.05,
        ack_timeout_s: float = 2.0,
        alive_timeout_s: float = 2.0,
    ) -> None:
        #: called with every valid :class:`RigState` read (in the reading thread)
        self.listeners: list[Callable[[RigState], None]] = []
        self.clock: Clock = clock if clock is not None else WallClock()
        self.poll_s = poll_s
        self.heartbeat_period_s = heartbeat_period_s
        self.angle_tol_deg = angle_tol_deg
        self.rate_tol_dps = rate_tol_dps
        self.ack_timeout_s = ack_timeout_s
        self.alive_timeout_s = alive_timeout_s
        self.reconnects = 0
        self._init_heartbeat()
        self._lock = threading.RLock()
        self._seq = 0
        self._target_roll_deg = 0.0
        self._target_pitch_deg = 0.0
        self._target_rate_dps = 0.0
        self._alive_seen: tuple[int, float] | None = None
        self._identity: RigIdentity | None = None

    # ------------------------------------------------------------------ transport hooks

    def _read_input(self, address: int, count: int, what: str) -> list[int]:
        """``count`` input registers from ``address``; raises :class:`RigError` subclasses."""
        raise NotImplementedError

    def _write(self, address: int, values: list[int], what: str, retries: int | None = None) -> None:
        """Write holding registers from ``address`` (``retries``: extra attempts, None: the transport's)."""
        raise NotImplementedError

    def _close_link(self) -> None:
        raise NotImplementedError

    # ------------------------------------------------------------------ reading

    def identify(self) -> RigIdentity:
        """Read the identification block; raises :class:`RigProtocolError` on an unknown map major version."""
        regs = self._read_input(reg.IDENT_START, reg.IDENT_COUNT, "identify")
        base = reg.IDENT_START
        map_word = regs[IR.MAP_VERSION - base]
        if map_word >> 8 != reg.MAP_VERSION_MAJOR:
            raise RigProtocolError(
                f"rig register map version {reg.version_string(map_word)} is not supported "
                f"(station speaks {reg.version_string(reg.MAP_VERSION)})"
            )
        fw_at = IR.FIRMWARE_ID - base
        max_rate = reg.regs_to_float32(regs[IR.MAX_RATE - base : IR.MAX_RATE - base + 2])
        if not (math.isfinite(max_rate) and 0.0 < max_rate <= reg.SANE_RATE_DPS):
            raise RigProtocolError(f"rig reports a nonsense maximum rate {max_rate!r} deg/s")
        self._identity = RigIdentity(
            firmware_id=reg.regs_to_ascii(regs[fw_at : fw_at + reg.FIRMWARE_ID_REGS]),
            firmware_version=reg.version_string(regs[IR.FIRMWARE_VERSION - base]),
            map_version=reg.version_string(map_word),
            max_rate_dps=max_rate,
        )
        return self._identity

    def state(self) -> RigState:
        """One snapshot of status and readbacks; nonsense values raise :class:`RigProtocolError`.

        Also supervises the rig's alive counter: if it has not changed for
        ``alive_timeout_s`` the rig firmware is considered hung (:class:`RigTimeout`).
        """
        regs = self._read_input(reg.STATE_START, reg.STATE_COUNT, "state")
        now = self.clock.now()

        def f32(address: int) -> float:
            return reg.regs_to_float32(regs[address : address + 2])

        st = RigState(
            t_s=now,
            rig_time_s=reg.regs_to_uint32(regs[IR.RIG_TIME_MS : IR.RIG_TIME_MS + 2]) / 1000.0,
            roll_deg=f32(IR.ACTUAL_ROLL),
            pitch_deg=f32(IR.ACTUAL_PITCH),
            yaw_deg=f32(IR.ACTUAL_YAW),
            rate_dps=f32(IR.ACTUAL_RATE),
            status=Status(regs[IR.STATUS] & reg.STATUS_DEFINED),
            fault_code=regs[IR.FAULT_CODE],
            ack_seq=regs[IR.ACK_SEQ],
            ack_result=regs[IR.ACK_RESULT],
            alive=regs[IR.ALIVE],
            heartbeat_echo=regs[IR.HEARTBEAT_ECHO],
        )
        for name, value, limit in (
            ("roll", st.roll_deg, reg.SANE_ANGLE_DEG),
            ("pitch", st.pitch_deg, reg.SANE_ANGLE_DEG),
            ("yaw", st.yaw_deg, reg.SANE_ANGLE_DEG),
            ("table rate", st.rate_dps, reg.SANE_RATE_DPS),
        ):
            if not (math.isfinite(value) and abs(value) <= limit):
                raise RigProtocolError(f"rig reports a nonsense {name} readback {value!r}")
        if st.fault != (st.fault_code != 0):
            raise RigProtocolError(f"rig FAULT bit {st.fault} disagrees with fault code {st.fault_code}")
        if self._alive_seen is None or self._alive_seen[0] != st.alive:
            self._alive_seen = (st.alive, now)
        elif now - self._alive_seen[1] > self.alive_timeout_s:
            raise RigTimeout(f"rig alive counter stuck at {st.alive} for {now - self._alive_seen[1]:.1f} s")
        for listener in tuple(self.listeners):
            listener(st)
        return st

    # ------------------------------------------------------------------ commands

    def _next_seq(self) -> int:
        self._seq = self._seq % 0xFFFF + 1  # 1..65535, never 0
        return self._seq

    def _command(self, command: Command) -> RigState:
        """Write targets + command + a new sequence number, wait for the rig's acknowledgement."""
        with self._lock:
            seq = self._next_seq()
            values = [
                int(command),
                seq,
                *reg.float32_to_regs(self._target_roll_deg),
                *reg.float32_to_regs(self._target_pitch_deg),
                *reg.float32_to_regs(self._target_rate_dps),
            ]
            self._write(HR.COMMAND, values, f"command {command.name}")
        deadline = self.clock.now() + self.ack_timeout_s
        while True:
            st = self.state()
            if st.ack_seq == seq:
                break
            if self.clock.now() > deadline:
                raise RigTimeout(f"rig did not acknowledge {command.name} (seq {seq}) within {self.ack_timeout_s} s")
            self.clock.sleep(self.poll_s)
        if st.ack_result == AckResult.OK:
            return st
        if st.ack_result == AckResult.FAULTED and st.fault_code:
            raise RigFault(
                st.fault_code, f"rig refused {command.name}: fault {st.fault_code} ({reg.fault_name(st.fault_code)})"
            )
        raise RigCommandRejected(
            f"rig rejected {command.name}: {st.ack.name if isinstance(st.ack, AckResult) else st.ack_result}; "
            f"{st.describe()}",
            st.ack_result,
        )

    @staticmethod
    def _raise_if_faulted(st: RigState) -> None:
        if st.fault:
            raise RigFault(st.fault_code)

    def move_to(self, orientation: Orientation) -> None:
        """Command the tumble axes to (roll_deg, pitch_deg) or a pose name; returns once acknowledged."""
        roll, pitch = POSE_ANGLES_DEG[orientation] if isinstance(orientation, str) else orientation
        roll, pitch = float(roll), float(pitch)
        if not (abs(roll) <= reg.ROLL_LIMIT_DEG and abs(pitch) <= reg.PITCH_LIMIT_DEG):
            raise ValueError(f"orientation ({roll}, {pitch}) deg outside the gimbal limits")
        self._raise_if_faulted(self.state())
        self._target_roll_deg, self._target_pitch_deg = roll, pitch
        self._command(Command.MOVE_TO_ORIENTATION)

    def spin(self, rate_dps: float) -> None:
        """Command the table to ``rate_dps`` (deg/s, positive = counter-clockwise seen from above)."""
        rate = float(rate_dps)
        limit = self._identity.max_rate_dps if self._identity else reg.SANE_RATE_DPS
        if not abs(rate) <= limit:
            raise ValueError(f"table rate {rate} deg/s beyond the rig's maximum {limit}")
        self._raise_if_faulted(self.state())
        self._target_rate_dps = rate
        self._command(Command.SPIN)

    def stop(self) -> None:
        """Bring every axis to rest; accepted by the rig also while a fault is latched."""
        self._target_rate_dps = 0.0
        self._command(Command.STOP)

    def home(self) -> None:
        """Roll = pitch = 0 and yaw to its zero mark."""
        self._raise_if_faulted(self.state())
        self._target_roll_deg = self._target_pitch_deg = 0.0
        self._command(Command.HOME)

    def reset_fault(self) -> None:
        """Clear a latched fault; :class:`RigFault` if its cause persists (e.g. e-stop still pressed)."""
        self._command(Command.RESET_FAULT)

    # ------------------------------------------------------------------ waits

    def _wait(self, what: str, timeout_s: float, done: Callable[[RigState], bool], faults: bool = True) -> RigState:
        deadline = self.clock.now() + timeout_s
        st: RigState | None = None
        while True:
            st = self.state()
            if faults:
                self._raise_if_faulted(st)
            if done(st):
                return st
            if self.clock.now() > deadline:
                raise RigMotionTimeout(f"rig not {what} within {timeout_s} s: {st.describe()}", st)
            self.clock.sleep(self.poll_s)

    def wait_in_position(self, timeout_s: float) -> RigState:
        """Wait for IN_POSITION with roll/pitch readbacks within ``angle_tol_deg`` of the target."""
        tol, roll, pitch = self.angle_tol_deg, self._target_roll_deg, self._target_pitch_deg

        def done(st: RigState) -> bool:
            return (
                st.in_position
                and not st.moving
                and abs(reg.angle_error_deg(st.roll_deg, roll)) <= tol
                and abs(reg.angle_error_deg(st.pitch_deg, pitch)) <= tol
            )

        return self._wait(f"in position at roll={roll} pitch={pitch} deg", timeout_s, done)

    def wait_rate_settled(self, timeout_s: float) -> RigState:
        """Wait for RATE_SETTLED with the table rate readback within ``rate_tol_dps`` of the target."""
        tol, rate = self.rate_tol_dps, self._target_rate_dps
        return self._wait(
            f"settled at {rate} deg/s", timeout_s, lambda st: st.rate_settled and abs(st.rate_dps - rate) <= tol
        )

    def wait_at_rest(self, timeout_s: float) -> RigState:
        """Wait for AT_REST with a zero rate readback; does not raise on a latched fault."""
        tol = self.rate_tol_dps
        return self._wait(
            "at rest",
            timeout_s,
            lambda st: st.at_rest and not st.moving and abs(st.rate_dps) <= tol,
            faults=False,
        )

    # ------------------------------------------------------------------ heartbeat

    def write_watchdog(self, timeout_s: float) -> None:
        """Set the rig's watchdog timeout (rig s, 0.1..60)."""
        ms = round(timeout_s * 1000.0)
        lo, hi = reg.WATCHDOG_MS_RANGE
        if not lo <= ms <= hi:
            raise ValueError(f"watchdog timeout {timeout_s} s outside [{lo / 1000}, {hi / 1000}] s")
        self._write(HR.WATCHDOG_MS, [ms], "watchdog timeout")

    # ------------------------------------------------------------------ lifetime

    def connect(self) -> RigIdentity:
        """Identify the rig and continue its command sequence numbering."""
        identity = self.identify()
        self._seq = self.state().ack_seq
        return identity

    def close(self) -> None:
        """Stop the heartbeat and close the link (does not move the rig)."""
        self.stop_heartbeat()
        self._close_link()

    def __enter__(self: R) -> R:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


R = TypeVar("R", bound=RegisterRig)


def start_rig(rig: R, *, heartbeat: bool = True, watchdog_s: float | None = None) -> R:
    """Connect ``rig`` (identify it), write its watchdog timeout if given (rig s), start the heartbeat
    if asked; closes it and re-raises when any of that fails."""
    try:
        rig.connect()
        if watchdog_s is not None:
            rig.write_watchdog(watchdog_s)
        if heartbeat:
            rig.start_heartbeat()
    except BaseException:
        rig.close()
        raise
    return rig


__all__ = ["RegisterRig", "start_rig"]
