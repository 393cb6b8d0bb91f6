"""A simulated climate chamber behind a real pymodbus server.

:class:`ChamberModel` is the controller and the thermal plant without I/O, on the injected clock
(chamber seconds): the working setpoint ramps to the target at the commanded rate; the air follows
it as a first-order lag (``air_tau_s``) limited by the plant's heating and cooling capacity (K/min);
with conditioning off (STOP, or any alarm) the air relaxes to the room temperature; the *load* (the
fixture and the units on it) follows the air with its own lag (``load_tau_s``). The units' own
self-heating is added on top by their physics (:class:`station.sim.physics_source.PhysicsSource`),
which reads :meth:`ChamberModel.load_temperature` at any past clock time. The state is integrated
exactly per step of ``dt_s`` (exponential update, the slew limit applied per step) through the step that
contains the current clock time, lazily, whenever anything asks; a command takes effect from the next step.

:class:`SimulatedChamber` serves the map of :mod:`station.chamber.registers`
(``station/chamber/register-map.md``) over Modbus/TCP on a background thread. Faults are switched at
runtime through :attr:`SimulatedChamber.faults`: no answer, exception replies, a latched alarm, a
plant that cannot reach the setpoint (capacity limits), a stalled alive counter.
"""

from __future__ import annotations

import math
import threading
from dataclasses import dataclass
from types import ModuleType
from typing import ClassVar

import numpy as np
from pymodbus.constants import ExcCodes
from pymodbus.server import ModbusTcpServer

from station.chamber import registers as reg
from station.chamber.registers import HR, IR, AlarmCode, Mode, Status
from station.kernel.clock import Clock
from station.sim.device_heartbeat import DeviceHeartbeat
from station.sim.modbus_server import ThreadedModbusServer


@dataclass
class ChamberFaults:
    """Faults to inject; change the fields at any time while the chamber runs.

    Attributes:
        no_answer: the chamber stops replying (requests are received and ignored).
        exception_replies: answer every request with this Modbus exception code (0 = off).
        alarm_code: latch this alarm (0 = off); acknowledging fails while it is set.
        air_limits_degc: (low, high): the plant cannot condition the air beyond these (a weak
            compressor or heater): a setpoint outside is never reached.
        alive_stalled: the alive counter stops (hung controller, comms still up).
    """

    no_answer: bool = False
    exception_replies: int = 0
    alarm_code: int = 0
    air_limits_degc: tuple[float, float] | None = None
    alive_stalled: bool = False


class ChamberModel:
    """The chamber's controller and thermal plant (thread-safe, no I/O).

    Args:
        clock: chamber time base (s).
        ambient_degc: the room temperature (and the power-up temperature of air and load).
        air_tau_s: time constant of the air following the working setpoint (s).
        heat_k_per_min, cool_k_per_min: the plant's largest air heating and cooling rates (K/min).
        off_tau_s: time constant of the air relaxing to the room with conditioning off (s).
        load_tau_s: time constant of the load (fixture and units) following the air (s).
        band_k, hold_s: AT_SETPOINT once the ramp ended and the air stayed within ``band_k`` of the
            setpoint for ``hold_s`` (K, s).
        min_temp_degc, max_temp_degc: accepted setpoints (degC).
        watchdog_s: initial watchdog timeout (s).
        dt_s: integration step (s).
        faults: the fault switches.
    """

    def __init__(
        self,
        clock: Clock,
        *,
        ambient_degc: float = 23.0,
        air_tau_s: float = 60.0,
        heat_k_per_min: float = 5.0,
        cool_k_per_min: float = 3.5,
        off_tau_s: float = 900.0,
        load_tau_s: float = 240.0,
        band_k: float = 0.5,
        hold_s: float = 30.0,
        min_temp_degc: float = -40.0,
        max_temp_degc: float = 120.0,
        watchdog_s: float = reg.WATCHDOG_S_DEFAULT,
        dt_s: float = 1.0,
        firmware_id: str = "STATION-SIMCHAMB",
        firmware_version: int = 0x0100,
        faults: ChamberFaults | None = None,
    ) -> None:
        self.clock = clock
        self.faults = faults if faults is not None else ChamberFaults()
        self.ambient_degc = float(ambient_degc)
        self.air_tau_s = float(air_tau_s)
        self.heat_k_per_s = heat_k_per_min / 60.0
        self.cool_k_per_s = cool_k_per_min / 60.0
        self.off_tau_s = float(off_tau_s)
        self.load_tau_s = float(load_tau_s)
        self.band_k = float(band_k)
        self.hold_s = float(hold_s)
        self.min_temp_degc = float(min_temp_degc)
        self.max_temp_degc = float(max_temp_degc)
        self.dt_s = float(dt_s)
        self.firmware_id = firmware_id
        self.firmware_version = firmware_version
        self._lock = threading.RLock()
        t0 = clock.now()
        self.t_boot = t0
        self.holding = [0] * reg.HOLDING_COUNT
        self.holding[HR.SETPOINT : HR.SETPOINT + 2] = reg.float32_to_regs(self.ambient_degc)
        lo, hi = reg.WATCHDOG_S_RANGE
        self.holding[HR.WATCHDOG_S] = min(max(round(watchdog_s), lo), hi)
        self.setpoint_degc = self.ambient_degc
        self.ramp_k_per_min = 0.0
        self.mode = Mode.STOP
        self.alarm_code = 0
        self.heartbeat = DeviceHeartbeat(t0, reg.ALIVE_PERIOD_S)
        self._wsp = self.ambient_degc
        self._in_band_s = 0.0
        # integrated history: times, air, load (grown per step)
        self._t = [t0]
        self._air = [self.ambient_degc]
        self._load = [self.ambient_degc]
        self.log: list[tuple[float, str]] = []  # (time, event) for tests and reports

    # ------------------------------------------------------------------ the plant

    @property
    def running(self) -> bool:
        return self.mode == Mode.RUN and not self.alarm_code

    def _step(self) -> None:
        """Advance the state by one ``dt_s``."""
        dt = self.dt_s
        air, load = self._air[-1], self._load[-1]
        if self.running:
            sp = self.setpoint_degc
            if self.ramp_k_per_min > 0:
                room = self.ramp_k_per_min / 60.0 * dt
                self._wsp += max(-room, min(room, sp - self._wsp))
            else:
                self._wsp = sp
            d = (self._wsp - air) * -math.expm1(-dt / self.air_tau_s)
            d = max(-self.cool_k_per_s * dt, min(self.heat_k_per_s * dt, d))
            new_air = air + d
            limits = self.faults.air_limits_degc
            if limits is not None:
                new_air = min(max(new_air, min(air, limits[0])), max(air, limits[1]))
            if self._wsp == sp and abs(new_air - sp) <= self.band_k:
                self._in_band_s += dt
            else:
                self._in_band_s = 0.0
        else:
            new_air = air + (self.ambient_degc - air) * -math.expm1(-dt / self.off_tau_s)
            self._wsp = new_air
            self._in_band_s = 0.0
        new_load = load + (new_air - load) * -math.expm1(-dt / self.load_tau_s)
        self._t.append(self._t[-1] + dt)
        self._air.append(new_air)
        self._load.append(new_load)

    def _advance(self, t: float) -> None:
        # Integrate every step that has begun by ``t`` (the grid covers ``t``): a step's value then depends only
        # on the state and the setpoint at its start, never on when someone asked (a sample rendered early or
        # late, on a virtual clock the same run): a command takes effect from the next step.
        while self._t[-1] < t - 1e-9:
            self._step()

    def _trip(self, code: int, why: str) -> None:
        if self.alarm_code:
            return
        self.alarm_code = int(code)
        self.log.append((self._t[-1], f"alarm {code} ({reg.alarm_name(code)}): {why}"))

    def update(self) -> float:
        """Integrate up to now, applying the watchdog and injected alarms on the way; returns now."""
        with self._lock:
            now = self.clock.now()
            deadline = self.heartbeat.deadline(self.holding[HR.WATCHDOG_S])
            if deadline is not None and not self.alarm_code and now > deadline:
                self._advance(deadline)
                self._trip(AlarmCode.WATCHDOG, "heartbeat not refreshed")
            if self.faults.alarm_code:
                self._advance(now)
                self._trip(self.faults.alarm_code, "injected")
            self._advance(now)
            return now

    def load_temperature(self, t_s: np.ndarray) -> np.ndarray:
        """Load (fixture and unit case) temperature (degC) at clock times ``t_s``; exact for past times,
        the latest value for times not integrated yet."""
        t = np.asarray(t_s, dtype=float)
        with self._lock:
            self.update()
            return np.interp(t, np.asarray(self._t), np.asarray(self._load))

    def air_temperature(self, t_s: np.ndarray) -> np.ndarray:
        """Air temperature (degC) at clock times ``t_s`` (as :meth:`load_temperature`)."""
        t = np.asarray(t_s, dtype=float)
        with self._lock:
            self.update()
            return np.interp(t, np.asarray(self._t), np.asarray(self._air))

    # ------------------------------------------------------------------ Modbus face

    def write_holding(self, address: int, values: list[int]) -> ExcCodes | None:
        """Apply a holding-register write; returns a Modbus exception code to answer with, or None."""
        with self._lock:
            now = self.update()
            image = list(self.holding)
            image[address : address + len(values)] = values
            written = range(address, address + len(values))
            lo, hi = reg.WATCHDOG_S_RANGE
            if HR.WATCHDOG_S in written and not lo <= image[HR.WATCHDOG_S] <= hi:
                return ExcCodes.ILLEGAL_VALUE
            if HR.MODE in written and image[HR.MODE] not in (Mode.STOP, Mode.RUN):
                return ExcCodes.ILLEGAL_VALUE
            sp = reg.regs_to_float32(image[HR.SETPOINT : HR.SETPOINT + 2])
            ramp = reg.regs_to_float32(image[HR.RAMP_RATE : HR.RAMP_RATE + 2])
            sp_written = HR.SETPOINT in written or HR.SETPOINT + 1 in written
            if sp_written and not (math.isfinite(sp) and self.min_temp_degc <= sp <= self.max_temp_degc):
                return ExcCodes.ILLEGAL_VALUE
            ramp_written = HR.RAMP_RATE in written or HR.RAMP_RATE + 1 in written
            if ramp_written and not (math.isfinite(ramp) and ramp >= 0):
                return ExcCodes.ILLEGAL_VALUE
            self.holding = image
            if sp != self.setpoint_degc or ramp != self.ramp_k_per_min:
                if self.ramp_k_per_min == 0 and ramp > 0:
                    self._wsp = self._air[-1]  # a ramp starts from where the air is
                self.setpoint_degc, self.ramp_k_per_min = sp, ramp
                self._in_band_s = 0.0
                self.log.append((now, f"setpoint {sp:g} degC ramp {ramp:g} K/min"))
            if HR.MODE in written and Mode(image[HR.MODE]) != self.mode:
                self.mode = Mode(image[HR.MODE])
                if self.mode == Mode.RUN:
                    self._wsp = self._air[-1] if self.ramp_k_per_min > 0 else self.setpoint_degc
                self.log.append((now, f"mode {self.mode.name}"))
            if HR.HEARTBEAT in written:
                self.heartbeat.written(image[HR.HEARTBEAT], now)
            if HR.ALARM_ACK in written and image[HR.ALARM_ACK] == 1:
                self.holding[HR.ALARM_ACK] = 0
                if self.alarm_code and not self.faults.alarm_code:
                    self.log.append((now, f"alarm {self.alarm_code} acknowledged"))
                    self.alarm_code = 0
                    self.heartbeat.refreshed(now)
                    self.mode = Mode.STOP  # after an alarm the operator (or station) restarts explicitly
                    self.holding[HR.MODE] = int(Mode.STOP)
            return None

    def _status(self) -> Status:
        status = Status.REMOTE
        if self.running:
            status |= Status.RUNNING
            if self._wsp != self.setpoint_degc:
                status |= Status.RAMPING
            if self._in_band_s >= self.hold_s:
                status |= Status.AT_SETPOINT
        if self.alarm_code:
            status |= Status.ALARM
        if self.heartbeat.armed:
            status |= Status.WATCHDOG_ARMED
        return status

    def input_registers(self) -> dict[int, int]:
        """Every defined input register (address -> value) as of now."""
        with self._lock:
            now = self.update()
            out: dict[int, int] = {
                IR.STATUS: int(self._status()),
                IR.ALARM_CODE: self.alarm_code,
                IR.ALIVE: self.heartbeat.alive(now, self.faults.alive_stalled),
                IR.HEARTBEAT_ECHO: self.heartbeat.echo,
                IR.MAP_VERSION: reg.MAP_VERSION,
                IR.FIRMWARE_VERSION: self.firmware_version,
            }
            blocks = (
                (IR.UPTIME_MS, reg.uint32_to_regs(int((now - self.t_boot) * 1000.0))),
                (IR.AIR_PV, reg.float32_to_regs(self._air[-1])),
                (IR.WORKING_SETPOINT, reg.float32_to_regs(self._wsp)),
                (IR.PRODUCT_PV, reg.float32_to_regs(self._load[-1])),
                (IR.SETPOINT_ECHO, reg.float32_to_regs(self.setpoint_degc)),
                (IR.FIRMWARE_ID, reg.ascii_to_regs(self.firmware_id, reg.FIRMWARE_ID_REGS)),
                (IR.MIN_TEMP, reg.float32_to_regs(self.min_temp_degc)),
                (IR.MAX_TEMP, reg.float32_to_regs(self.max_temp_degc)),
                (IR.MAX_RAMP, reg.float32_to_regs(60.0 * min(self.heat_k_per_s, self.cool_k_per_s))),
            )
            for start, words in blocks:
                for i, word in enumerate(words):
                    out[start + i] = word
            return out


class SimulatedChamber(ThreadedModbusServer[ChamberModel]):
    """The chamber model served over Modbus/TCP in a background thread (port 0: a free port).

    Use as a context manager or call :meth:`start` / :meth:`stop`; ``model_options`` are those of
    :class:`ChamberModel`. :attr:`url` is what :func:`station.chamber.open_chamber` takes. The thread,
    the lifetime and the datastore hook are :class:`~station.sim.modbus_server.ThreadedModbusServer`'s.
    """

    _role = "chamber"
    _map: ClassVar[ModuleType] = reg
    model: ChamberModel

    def __init__(self, clock: Clock, host: str = "127.0.0.1", port: int = 0, *, unit: int = 1,
                 faults: ChamberFaults | None = None, **model_options: float) -> None:
        self.clock = clock
        self.host = host
        self.port = port
        self.unit = unit
        # mypy cannot tell that **model_options (floats by name) never holds 'faults'
        self.model = ChamberModel(clock, faults=faults, **model_options)  # type: ignore[arg-type]
        self._init_server()

    @property
    def faults(self) -> ChamberFaults:
        return self.model.faults

    @property
    def url(self) -> str:
        if self.port == 0:
            raise RuntimeError("the simulated chamber is not started (no port yet)")
        return f"modbus-tcp://{self.host}:{self.port}?unit={self.unit}"

    def load_temperature(self, t_s: np.ndarray) -> np.ndarray:
        """See :meth:`ChamberModel.load_temperature`."""
        return self.model.load_temperature(t_s)

    # ------------------------------------------------------------------ pymodbus glue

    async def _open_server(self) -> ModbusTcpServer:
        server = ModbusTcpServer(self._device(), address=(self.host, self.port), trace_packet=self._trace_packet)
        await server.serve_forever(background=True)
        self.port = int(server.transport.sockets[0].getsockname()[1])  # type: ignore[attr-defined]  # pymodbus
            # types the listener's transport as asyncio.BaseTransport; for a server it is the asyncio.Server (.sockets)
        return server


__all__ = ["ChamberFaults", "ChamberModel", "SimulatedChamber"]
