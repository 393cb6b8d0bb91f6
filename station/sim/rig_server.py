"""A simulated tumble + rate-table rig behind a real pymodbus server.

:class:`RigModel` is the rig's controller and mechanics without I/O: three
:class:`~station.physics.motion.AxisTrajectory` (roll, pitch, yaw; rad) extended by
trapezoidal moves and rate ramps when commands arrive, evaluated lazily at
``clock.now()`` (rig seconds). Status bits and readbacks come from the
trajectories, so a simulated sensor mounted on the rig can render exactly what it
feels via :meth:`RigModel.kinematics`.

:class:`SimulatedRig` serves that model over Modbus/TCP (or Modbus RTU over a
bridged pty pair) with pymodbus' ``SimDevice``/``SimData`` datastore (the
non-deprecated API of pymodbus >= 3.13) in an asyncio loop on a background thread,
following the register map of :mod:`station.rig.registers` / ``station/rig/register-map.md``.
Faults can be injected at runtime through :attr:`SimulatedRig.faults`.
"""

from __future__ import annotations

import asyncio
import contextlib
import math
import os
import threading
import tty
from dataclasses import dataclass
from types import ModuleType
from typing import ClassVar

import numpy as np
from pymodbus.constants import ExcCodes
from pymodbus.server import ModbusSerialServer, ModbusTcpServer

from station.kernel.clock import Clock
from station.kernel.geometry import Kinematics, kinematics_from_angles
from station.physics.motion import AxisTrajectory
from station.rig import registers as reg
from station.rig.registers import HR, IR, AckResult, Command, FaultCode, Status
from station.sim.device_heartbeat import DeviceHeartbeat
from station.sim.modbus_server import ThreadedModbusServer

_EPS_RATE = 1e-9  # rad/s: below this an axis is still
_EPS_ANGLE = 1e-7  # rad: position match for IN_POSITION


@dataclass
class RigFaults:
    """Faults to inject; change the fields at any time while the rig runs.

    Attributes:
        no_answer: the rig stops replying (requests are received and ignored).
        exception_replies: answer every request with this Modbus exception code (0 = off),
            e.g. 4 = SLAVE_DEVICE_FAILURE.
        stuck_in_position: the IN_POSITION bit is never set.
        fault_code: latch this fault code (0 = off); RESET_FAULT fails while it is set.
        drop_connection_mid_motion: one shot: close every TCP connection halfway through the
            next move or ramp (on RTU: swallow one reply instead); cleared when it fires.
        estop: the emergency stop button is pressed (latches FaultCode.ESTOP).
        nan_angle: the roll readback is NaN.
        local_mode: the local/remote switch is in local: motion commands are refused.
        alive_stalled: the alive counter stops counting (hung firmware, comms still up).
    """

    no_answer: bool = False
    exception_replies: int = 0
    stuck_in_position: bool = False
    fault_code: int = 0
    drop_connection_mid_motion: bool = False
    estop: bool = False
    nan_angle: bool = False
    local_mode: bool = False
    alive_stalled: bool = False


def _cut(traj: AxisTrajectory, t: float) -> None:
    """Make ``t`` the end of ``traj``: drop planned phases after ``t``, or hold until ``t``."""
    if traj.end_time <= t:
        traj.hold_until(t)
        return
    keep = [ph for ph in traj.phases if ph[0] <= t] or traj.phases[:1]
    traj.phases[:] = keep
    traj.end_time = t


def _pin_rest(traj: AxisTrajectory) -> None:
    """Remove rounding from a ramp to rest: the final phase has exactly zero rate."""
    t, p, _, _ = traj.phases[-1]
    traj.phases[-1] = (t, p, 0.0, 0.0)


class RigModel:
    """The rig's controller and mechanics (thread-safe, no I/O).

    Args:
        clock: rig time base (s).
        tumble_rate_dps, tumble_accel_dps2: roll/pitch trapezoid limits (deg/s, deg/s^2).
        table_accel_dps2: table rate ramp acceleration (deg/s^2).
        settle_s: settling time after a move or ramp before IN_POSITION / RATE_SETTLED (s).
        max_rate_dps: largest table rate accepted (deg/s).
        watchdog_s: initial watchdog timeout (s), the WATCHDOG_MS register.
        firmware_id: up to 16 ASCII characters.
        faults: the fault injection switches.
    """

    def __init__(
        self,
        clock: Clock,
        *,
        tumble_rate_dps: float = 30.0,
        tumble_accel_dps2: float = 60.0,
        table_accel_dps2: float = 50.0,
        settle_s: float = 0.5,
        max_rate_dps: float = 500.0,
        watchdog_s: float = 2.0,
        firmware_id: str = "STATION-SIMRIG",
        firmware_version: int = 0x0100,
        faults: RigFaults | None = None,
    ) -> None:
        self.clock = clock
        self.faults = faults if faults is not None else RigFaults()
        self.tumble_rate = math.radians(tumble_rate_dps)
        self.tumble_accel = math.radians(tumble_accel_dps2)
        self.table_accel = math.radians(table_accel_dps2)
        self.settle_s = settle_s
        self.max_rate_dps = max_rate_dps
        self.firmware_id = firmware_id
        self.firmware_version = firmware_version
        self._lock = threading.RLock()
        t0 = clock.now()
        self.t_boot = t0
        self.axes = [AxisTrajectory(t0=t0), AxisTrajectory(t0=t0), AxisTrajectory(t0=t0)]
        self.holding = [0] * reg.HOLDING_COUNT
        lo, hi = reg.WATCHDOG_MS_RANGE
        self.holding[HR.WATCHDOG_MS] = min(max(round(watchdog_s * 1000.0), lo), hi)
        self.target_roll_deg = 0.0
        self.target_pitch_deg = 0.0
        self.target_rate_dps = 0.0
        self.fault_code = 0
        self.fault_time: float | None = None
        self.ack_seq = 0
        self.ack_result = int(AckResult.OK)
        self.heartbeat = DeviceHeartbeat(t0, reg.ALIVE_PERIOD_S)
        self.commands: list[tuple[float, int, int]] = []  # (time, command, ack result) log
        self._drop_at: float | None = None
        self._drop_pending = False

    # ------------------------------------------------------------------ time evolution

    @property
    def watchdog_s(self) -> float:
        return self.holding[HR.WATCHDOG_MS] / 1000.0

    def _tumble_end(self) -> float:
        return max(self.axes[0].end_time, self.axes[1].end_time)

    def _trip(self, code: int, t: float) -> None:
        """Latch fault ``code`` at time ``t`` and bring every axis to rest from there."""
        if self.fault_code:
            return
        self.fault_code = int(code)
        self.fault_time = t
        self._stop_all(t)

    def update(self) -> float:
        """Apply everything that happened up to now (watchdog, injected faults); returns now."""
        with self._lock:
            now = self.clock.now()
            deadline = self.heartbeat.deadline(self.watchdog_s)
            if deadline is not None and not self.fault_code and now > deadline:
                self._trip(FaultCode.WATCHDOG, deadline)
            if self.faults.estop:
                self._trip(FaultCode.ESTOP, now)
            if self.faults.fault_code:
                self._trip(self.faults.fault_code, now)
            if self._drop_at is not None and now >= self._drop_at:
                self._drop_at = None
                self._drop_pending = True
                self.faults.drop_connection_mid_motion = False
            return now

    def take_drop_request(self) -> bool:
        """True once when an armed connection drop is due."""
        with self._lock:
            pending, self._drop_pending = self._drop_pending, False
            return pending

    def _arm_drop(self, now: float, end: float) -> None:
        if self.faults.drop_connection_mid_motion:
            self._drop_at = now + 0.5 * max(end - now, 0.0)

    # ------------------------------------------------------------------ motion planning

    def _stop_all(self, t: float) -> None:
        """Decelerate every moving axis to rest starting at ``t``."""
        for axis, accel in ((0, self.tumble_accel), (1, self.tumble_accel), (2, self.table_accel)):
            traj = self.axes[axis]
            _, v, _ = traj.state_at(t)
            if traj.end_time > t or abs(v) > _EPS_RATE:
                _cut(traj, t)
                traj.ramp_rate(0.0, accel)
                _pin_rest(traj)
        self.target_rate_dps = 0.0

    def _table_still(self, now: float) -> bool:
        _, v, _ = self.axes[2].state_at(now)
        return self.axes[2].end_time <= now and abs(v) <= _EPS_RATE

    def _move_tumble(self, now: float, roll_deg: float, pitch_deg: float) -> float:
        """Plan roll/pitch trapezoids from now; returns the end time."""
        for axis, target in ((0, roll_deg), (1, pitch_deg)):
            traj = self.axes[axis]
            traj.hold_until(now)
            traj.move_to(math.radians(target), self.tumble_rate, self.tumble_accel)
        self.target_roll_deg, self.target_pitch_deg = roll_deg, pitch_deg
        return self._tumble_end()

    def _execute(self, command: int, now: float) -> AckResult:
        """Run one command at ``now`` (targets taken from the holding registers)."""
        try:
            cmd = Command(command)
        except ValueError:
            return AckResult.UNKNOWN_COMMAND
        if cmd == Command.NOP:
            return AckResult.OK
        if cmd == Command.STOP:
            self._stop_all(now)
            return AckResult.OK
        if cmd == Command.RESET_FAULT:
            if not self.fault_code:
                return AckResult.OK
            if self.faults.estop or self.faults.fault_code:
                return AckResult.FAULTED
            self.fault_code = 0
            self.fault_time = None
            self.heartbeat.refreshed(now)
            return AckResult.OK
        if self.faults.local_mode:
            return AckResult.NOT_REMOTE
        if self.fault_code:
            return AckResult.FAULTED
        tumble_moving = self._tumble_end() > now
        if cmd in (Command.MOVE_TO_ORIENTATION, Command.HOME):
            if cmd == Command.HOME:
                roll, pitch = 0.0, 0.0
            else:
                roll = reg.regs_to_float32(self.holding[HR.TARGET_ROLL : HR.TARGET_ROLL + 2])
                pitch = reg.regs_to_float32(self.holding[HR.TARGET_PITCH : HR.TARGET_PITCH + 2])
            if not (abs(roll) <= reg.ROLL_LIMIT_DEG and abs(pitch) <= reg.PITCH_LIMIT_DEG):
                return AckResult.OUT_OF_RANGE
            if not self._table_still(now):
                return AckResult.NOT_AT_REST
            if tumble_moving:
                return AckResult.BUSY
            end = self._move_tumble(now, roll, pitch)
            if cmd == Command.HOME:
                yaw = self.axes[2]
                yaw.hold_until(now)
                p, _, _ = yaw.state_at(now)
                yaw.move_to(2 * math.pi * round(p / (2 * math.pi)), self.tumble_rate, self.tumble_accel)
                end = max(end, yaw.end_time)
            self._arm_drop(now, end)
            return AckResult.OK
        # Command.SPIN
        rate = reg.regs_to_float32(self.holding[HR.TARGET_RATE : HR.TARGET_RATE + 2])
        if not abs(rate) <= self.max_rate_dps:
            return AckResult.OUT_OF_RANGE
        if tumble_moving:
            return AckResult.BUSY
        yaw = self.axes[2]
        _cut(yaw, now)
        yaw.ramp_rate(math.radians(rate), self.table_accel)
        if rate == 0.0:
            _pin_rest(yaw)
        self.target_rate_dps = rate
        self._arm_drop(now, yaw.end_time)
        return AckResult.OK

    # ------------------------------------------------------------------ Modbus face

    def write_holding(self, address: int, values: list[int]) -> ExcCodes | None:
        """Apply a holding-register write; returns a Modbus exception code to answer with, or None."""
        with self._lock:
            now = self.update()
            image = list(self.holding)
            image[address : address + len(values)] = values
            written = range(address, address + len(values))
            lo, hi = reg.WATCHDOG_MS_RANGE
            if HR.WATCHDOG_MS in written and not lo <= image[HR.WATCHDOG_MS] <= hi:
                return ExcCodes.ILLEGAL_VALUE
            self.holding = image
            if HR.HEARTBEAT in written:
                self.heartbeat.written(image[HR.HEARTBEAT], now)
            if HR.COMMAND_SEQ in written and image[HR.COMMAND_SEQ] != self.ack_seq:
                result = self._execute(image[HR.COMMAND], now)
                self.ack_seq = image[HR.COMMAND_SEQ]
                self.ack_result = int(result)
                self.commands.append((now, image[HR.COMMAND], int(result)))
            return None

    def _status(self, now: float, v: list[float]) -> Status:
        tumble_end = self._tumble_end()
        tumble_moving = tumble_end > now or abs(v[0]) > _EPS_RATE or abs(v[1]) > _EPS_RATE
        table_moving = self.axes[2].end_time > now or abs(v[2]) > _EPS_RATE
        status = Status(0)
        if tumble_moving or table_moving:
            status |= Status.MOVING
        else:
            status |= Status.AT_REST
        roll, pitch = self.axes[0].state_at(now)[0], self.axes[1].state_at(now)[0]
        if (
            not tumble_moving
            and now >= tumble_end + self.settle_s
            and abs(roll - math.radians(self.target_roll_deg)) <= _EPS_ANGLE
            and abs(pitch - math.radians(self.target_pitch_deg)) <= _EPS_ANGLE
            and not self.faults.stuck_in_position
        ):
            status |= Status.IN_POSITION
        if now >= self.axes[2].end_time + self.settle_s and abs(v[2] - math.radians(self.target_rate_dps)) <= 1e-6:
            status |= Status.RATE_SETTLED
        if self.fault_code:
            status |= Status.FAULT
        if self.faults.estop:
            status |= Status.ESTOP
        if not self.faults.local_mode:
            status |= Status.REMOTE
        if not (self.fault_code or self.faults.estop or self.faults.local_mode):
            status |= Status.READY
        if self.heartbeat.armed:
            status |= Status.WATCHDOG_ARMED
        return status

    def readback(self) -> tuple[float, float, float, float, Status]:
        """(roll_deg, pitch_deg, yaw_deg wrapped to [-180, 180), table rate deg/s, status) now."""
        with self._lock:
            now = self.update()
            p = [ax.state_at(now)[0] for ax in self.axes]
            v = [ax.state_at(now)[1] for ax in self.axes]
            return (
                math.degrees(p[0]),
                math.degrees(p[1]),
                reg.wrap_deg(math.degrees(p[2])),
                math.degrees(v[2]),
                self._status(now, v),
            )

    def input_registers(self) -> dict[int, int]:
        """Every defined input register (address -> value) as of now."""
        with self._lock:
            now = self.update()
            roll, pitch, yaw, rate, status = self.readback()
            if self.faults.nan_angle:
                roll = math.nan
            out: dict[int, int] = {
                IR.STATUS: int(status),
                IR.FAULT_CODE: self.fault_code,
                IR.ACK_SEQ: self.ack_seq,
                IR.ACK_RESULT: self.ack_result,
                IR.ALIVE: self.heartbeat.alive(now, self.faults.alive_stalled),
                IR.HEARTBEAT_ECHO: self.heartbeat.echo,
                IR.MAP_VERSION: reg.MAP_VERSION,
                IR.FIRMWARE_VERSION: self.firmware_version,
            }
            blocks = (
                (IR.RIG_TIME_MS, reg.uint32_to_regs(int((now - self.t_boot) * 1000.0))),
                (IR.ACTUAL_ROLL, reg.float32_to_regs(roll)),
                (IR.ACTUAL_PITCH, reg.float32_to_regs(pitch)),
                (IR.ACTUAL_YAW, reg.float32_to_regs(yaw)),
                (IR.ACTUAL_RATE, reg.float32_to_regs(rate)),
                (IR.FIRMWARE_ID, reg.ascii_to_regs(self.firmware_id, reg.FIRMWARE_ID_REGS)),
                (IR.MAX_RATE, reg.float32_to_regs(self.max_rate_dps)),
            )
            for start, words in blocks:
                for i, word in enumerate(words):
                    out[start + i] = word
            return out

    # ------------------------------------------------------------------ what a sensor feels

    def axis_states(self, t_s: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(angle rad, rate rad/s, accel rad/s^2), each shape (n, 3), columns (roll, pitch, yaw).

        Exact for ``t_s <= now``; later times assume no further command.
        """
        t = np.atleast_1d(np.asarray(t_s, dtype=float))
        with self._lock:
            self.update()
            states = [ax.state(t) for ax in self.axes]
        angle = np.column_stack([s[0] for s in states])
        rate = np.column_stack([s[1] for s in states])
        accel = np.column_stack([s[2] for s in states])
        return angle, rate, accel

    def kinematics(self, t_s: np.ndarray) -> Kinematics:
        """What a sensor mounted at the rotation centre does at times ``t_s`` (s)."""
        t = np.atleast_1d(np.asarray(t_s, dtype=float))
        angle, rate, accel = self.axis_states(t)
        return kinematics_from_angles(t, angle, rate, accel)


class RigModelView:
    """What simulated sensors and tests see of a simulated rig: its model's fault switches, readbacks
    and kinematics (the Modbus server and the in-process fake rig both offer it)."""

    model: RigModel

    @property
    def faults(self) -> RigFaults:
        return self.model.faults

    def readback(self) -> tuple[float, float, float, float, Status]:
        """(roll_deg, pitch_deg, yaw_deg, table rate deg/s, status) now."""
        return self.model.readback()

    def axis_states(self, t_s: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """See :meth:`RigModel.axis_states`."""
        return self.model.axis_states(t_s)

    def kinematics(self, t_s: np.ndarray) -> Kinematics:
        """See :meth:`RigModel.kinematics`."""
        return self.model.kinematics(t_s)


class _PtyBridge:
    """Two pty pairs joined master-to-master (like ``socat pty pty``) on an asyncio loop.

    The server opens ``server_path``, the client ``client_path``. The slave ends
    stay open here so a closed client does not make the masters report EIO.
    """

    def __init__(self) -> None:
        self._m1, self._s1 = os.openpty()
        self._m2, self._s2 = os.openpty()
        for fd in (self._s1, self._s2):
            tty.setraw(fd)
        for fd in (self._m1, self._m2):
            os.set_blocking(fd, False)
        self.server_path = os.ttyname(self._s1)
        self.client_path = os.ttyname(self._s2)
        self._loop: asyncio.AbstractEventLoop | None = None
        self.swallow = 0  # replies (server -> client chunks) to drop

    @staticmethod
    def _pump(src: int, dst: int) -> bytes:
        try:
            data = os.read(src, 4096)
        except (BlockingIOError, OSError):
            return b""
        return data

    def _to_client(self) -> None:
        data = self._pump(self._m1, self._m2)
        if data:
            os.write(self._m2, data)

    def _to_server(self) -> None:
        data = self._pump(self._m2, self._m1)
        if data:
            os.write(self._m1, data)

    def attach(self, loop: asyncio.AbstractEventLoop) -> None:
        self._loop = loop
        loop.add_reader(self._m1, self._to_client)
        loop.add_reader(self._m2, self._to_server)

    def close(self) -> None:
        if self._loop is not None and not self._loop.is_closed():
            self._loop.remove_reader(self._m1)
            self._loop.remove_reader(self._m2)
        for fd in (self._m1, self._s1, self._m2, self._s2):
            with contextlib.suppress(OSError):
                os.close(fd)


class SimulatedRig(RigModelView, ThreadedModbusServer[RigModel]):
    """The rig model served over Modbus in a background thread.

    ``transport="tcp"`` listens on ``host:port`` (port 0 picks a free port);
    ``transport="rtu"`` serves Modbus RTU on a pty pair and :attr:`url` names the
    client end (``modbus-rtu:///dev/pts/N?...``). Use as a context manager or call
    :meth:`start` / :meth:`stop`. Motion parameters are those of :class:`RigModel`. The thread,
    the lifetime and the datastore hook are :class:`~station.sim.modbus_server.ThreadedModbusServer`'s.
    """

    _role = "rig"
    _map: ClassVar[ModuleType] = reg

    def __init__(
        self,
        clock: Clock,
        host: str = "127.0.0.1",
        port: int = 0,
        *,
        transport: str = "tcp",
        unit: int = 1,
        baud: int = 115200,
        tumble_rate_dps: float = 30.0,
        tumble_accel_dps2: float = 60.0,
        table_accel_dps2: float = 50.0,
        settle_s: float = 0.5,
        max_rate_dps: float = 500.0,
        watchdog_s: float = 2.0,
        firmware_id: str = "STATION-SIMRIG",
        faults: RigFaults | None = None,
    ) -> None:
        if transport not in ("tcp", "rtu"):
            raise ValueError(f"transport must be 'tcp' or 'rtu', not {transport!r}")
        self.clock = clock
        self.host = host
        self.port = port
        self.transport = transport
        self.unit = unit
        self.baud = baud
        self.model = RigModel(
            clock,
            tumble_rate_dps=tumble_rate_dps,
            tumble_accel_dps2=tumble_accel_dps2,
            table_accel_dps2=table_accel_dps2,
            settle_s=settle_s,
            max_rate_dps=max_rate_dps,
            watchdog_s=watchdog_s,
            firmware_id=firmware_id,
            faults=faults,
        )
        self._init_server()
        self.connections_dropped = 0
        self._bridge: _PtyBridge | None = None
        self._swallow = 0

    @property
    def url(self) -> str:
        if self.transport == "tcp":
            if self.port == 0:
                raise RuntimeError("the TCP rig is not started (no port yet)")
            return f"modbus-tcp://{self.host}:{self.port}?unit={self.unit}"
        if self._bridge is None:
            raise RuntimeError("the RTU rig is not started")
        return f"modbus-rtu://{self._bridge.client_path}?baud={self.baud}&parity=N&unit={self.unit}"

    @property
    def device_path(self) -> str:
        """Client end of the pty pair (RTU only)."""
        if self._bridge is None:
            raise RuntimeError("no pty: the rig is not started or uses TCP")
        return self._bridge.client_path

    # ------------------------------------------------------------------ pymodbus glue

    def _after_access(self) -> None:
        if self.model.take_drop_request():
            asyncio.get_running_loop().call_soon(self._drop_connections)

    def _trace_packet(self, sending: bool, data: bytes) -> bytes:
        if sending and (self.model.faults.no_answer or self._swallow > 0):
            self._swallow = max(self._swallow - 1, 0)
            return b""
        return data

    def _drop_connections(self) -> None:
        server = self._server
        if server is None:
            return
        if self.transport == "rtu":
            self._swallow += 1
            return
        for conn in list(server.active_connections.values()):
            conn.close()
            self.connections_dropped += 1

    async def _open_server(self) -> ModbusTcpServer | ModbusSerialServer:
        server: ModbusTcpServer | ModbusSerialServer
        if self.transport == "tcp":
            server = ModbusTcpServer(self._device(), address=(self.host, self.port), trace_packet=self._trace_packet)
            await server.serve_forever(background=True)
            self.port = int(server.transport.sockets[0].getsockname()[1])  # type: ignore[attr-defined]  # pymodbus
            # types the listener's transport as asyncio.BaseTransport; for a server it is the asyncio.Server (.sockets)
        else:
            self._bridge = _PtyBridge()
            self._bridge.attach(asyncio.get_running_loop())
            server = ModbusSerialServer(
                self._device(),
                port=self._bridge.server_path,
                baudrate=self.baud,
                parity="N",
                timeout=0.1,
                trace_packet=self._trace_packet,
            )
            await server.serve_forever(background=True)
        return server

    async def _closed(self) -> None:
        if self._bridge is not None:
            self._bridge.close()

    def _thread_name(self) -> str:
        return f"sim-rig-{self.transport}"
