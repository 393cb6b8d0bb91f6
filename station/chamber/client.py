"""The station's Modbus client for the climate chamber (map in :mod:`station.chamber.registers`).

``open_chamber(url, clock)`` connects over Modbus/TCP or RTU (pymodbus sync clients), checks the
map version, writes the watchdog timeout and starts the heartbeat thread. Every transaction goes
through one lock and a bounded retry loop (reconnecting after a request that got no answer), then
:class:`ChamberTimeout`. Waits and polling use the injected clock (chamber seconds); I/O timeouts
are wall seconds.
"""

from __future__ import annotations

import logging
import math
import threading
from collections.abc import Callable
from typing import Any

from station.chamber import registers as reg
from station.chamber.chamber_url import ChamberUrl, parse_chamber_url
from station.chamber.protocol import (
    ChamberAlarm,
    ChamberIdentity,
    ChamberProtocolError,
    ChamberSetpointTimeout,
    ChamberState,
    ChamberTimeout,
)
from station.chamber.registers import HR, IR, Mode, Status
from station.kernel.clock import Clock, WallClock
from station.modbus.client import ModbusTransport
from station.modbus.heartbeat import Heartbeat

log = logging.getLogger(__name__)


class ModbusChamber(ModbusTransport, Heartbeat):
    """A climate chamber behind Modbus; implements :class:`station.chamber.protocol.Chamber`.

    The transport (retries, reconnects) is :class:`station.modbus.client.ModbusTransport`'s, the
    heartbeat thread :class:`station.modbus.heartbeat.Heartbeat`'s.

    Args:
        url: chamber URL (:mod:`station.chamber.chamber_url`) or a parsed :class:`ChamberUrl`.
        clock: time base for waits, polling and the heartbeat (chamber s).
        poll_s: status polling period while waiting (chamber s).
        heartbeat_period_s: heartbeat write period (chamber s), well inside the watchdog.
        alive_timeout_s: the alive counter must change within this (chamber s).
        setpoint_tol_k: the air readback must be within this of the setpoint to confirm it (K).
        retry_backoff_s: pause before a retry (wall s).
    """

    _role = "chamber"
    _protocol_error = ChamberProtocolError
    _timeout_error = ChamberTimeout
    _name_exceptions = False
    _heartbeat_register = HR.HEARTBEAT
    _log = log

    url: ChamberUrl

    def __init__(
        self,
        url: ChamberUrl | str,
        clock: Clock | None = None,
        *,
        poll_s: float = 1.0,
        heartbeat_period_s: float = 2.0,
        alive_timeout_s: float = 5.0,
        setpoint_tol_k: float = 0.5,
        retry_backoff_s: float = 0.05,
    ) -> None:
        self.url = url if isinstance(url, ChamberUrl) else parse_chamber_url(url)
        self.clock: Clock = clock if clock is not None else WallClock()
        self.poll_s = poll_s
        self.heartbeat_period_s = heartbeat_period_s
        self.alive_timeout_s = alive_timeout_s
        self.setpoint_tol_k = setpoint_tol_k
        self.retry_backoff_s = retry_backoff_s
        self.reconnects = 0
        self._init_heartbeat()
        self.listeners: list[Callable[[ChamberState], None]] = []
        self._lock = threading.RLock()
        self._identity: ChamberIdentity | None = None
        self._alive_seen: tuple[int, float] | None = None
        self._open_transport()

    # ------------------------------------------------------------------ reading

    def identify(self) -> ChamberIdentity:
        """Read the identification block; :class:`ChamberProtocolError` on an unknown map major version."""
        regs = self._read_input(reg.IDENT_START, reg.IDENT_COUNT, "identify")
        base = reg.IDENT_START

        def f32(address: int) -> float:
            return reg.regs_to_float32(regs[address - base : address - base + 2])

        word = regs[IR.MAP_VERSION - base]
        if word >> 8 != reg.MAP_VERSION_MAJOR:
            raise ChamberProtocolError(
                f"chamber register map version {reg.version_string(word)} is not supported "
                f"(station speaks {reg.version_string(reg.MAP_VERSION)})"
            )
        lo, hi, ramp = f32(IR.MIN_TEMP), f32(IR.MAX_TEMP), f32(IR.MAX_RAMP)
        if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi and math.isfinite(ramp) and ramp > 0):
            raise ChamberProtocolError(f"chamber reports a nonsense range [{lo}, {hi}] degC, ramp {ramp} K/min")
        at = IR.FIRMWARE_ID - base
        self._identity = ChamberIdentity(
            firmware_id=reg.regs_to_ascii(regs[at : at + reg.FIRMWARE_ID_REGS]),
            firmware_version=reg.version_string(regs[IR.FIRMWARE_VERSION - base]),
            map_version=reg.version_string(word),
            min_temp_degc=lo,
            max_temp_degc=hi,
            max_ramp_k_per_min=ramp,
        )
        return self._identity

    def state(self) -> ChamberState:
        """One snapshot; nonsense values raise :class:`ChamberProtocolError`, a stuck alive counter
        :class:`ChamberTimeout` (hung controller)."""
        regs = self._read_input(reg.STATE_START, reg.STATE_COUNT, "state")
        now = self.clock.now()

        def f32(address: int) -> float:
            return reg.regs_to_float32(regs[address : address + 2])

        st = ChamberState(
            t_s=now,
            uptime_s=reg.regs_to_uint32(regs[IR.UPTIME_MS : IR.UPTIME_MS + 2]) / 1000.0,
            air_degc=f32(IR.AIR_PV),
            working_setpoint_degc=f32(IR.WORKING_SETPOINT),
            product_degc=f32(IR.PRODUCT_PV),
            setpoint_degc=f32(IR.SETPOINT_ECHO),
            status=Status(regs[IR.STATUS] & reg.STATUS_DEFINED),
            alarm_code=regs[IR.ALARM_CODE],
            alive=regs[IR.ALIVE],
            heartbeat_echo=regs[IR.HEARTBEAT_ECHO],
        )
        lo, hi = reg.SANE_TEMP_DEGC
        for name, value in (("air", st.air_degc), ("product", st.product_degc),
                            ("working setpoint", st.working_setpoint_degc), ("setpoint", st.setpoint_degc)):
            if not (math.isfinite(value) and lo <= value <= hi):
                raise ChamberProtocolError(f"chamber reports a nonsense {name} temperature {value!r}")
        if st.alarm != (st.alarm_code != 0):
            raise ChamberProtocolError(f"chamber ALARM bit {st.alarm} disagrees with alarm code {st.alarm_code}")
        if self._alive_seen is None or self._alive_seen[0] != st.alive:
            self._alive_seen = (st.alive, now)
        elif now - self._alive_seen[1] > self.alive_timeout_s:
            raise ChamberTimeout(f"chamber alive counter stuck at {st.alive} for {now - self._alive_seen[1]:.1f} s")
        for listener in tuple(self.listeners):
            listener(st)
        return st

    def check(self) -> ChamberState:
        """A snapshot; raises :class:`ChamberAlarm` when an alarm is latched."""
        st = self.state()
        if st.alarm:
            raise ChamberAlarm(st.alarm_code, f"chamber alarm {st.alarm_code} ({reg.alarm_name(st.alarm_code)}): "
                                              f"{st.describe()}")
        return st

    # ------------------------------------------------------------------ commands

    def set_setpoint(self, degc: float, ramp_k_per_min: float = 0.0) -> ChamberState:
        """Write the target and ramp rate (K/min, 0 = as fast as the plant can) in one request; returns
        the state that confirms the chamber took it (SETPOINT_ECHO)."""
        degc, ramp = float(degc), float(ramp_k_per_min)
        ident = self._identity or self.identify()
        if not ident.min_temp_degc <= degc <= ident.max_temp_degc:
            raise ValueError(f"setpoint {degc} degC outside the chamber's [{ident.min_temp_degc}, "
                             f"{ident.max_temp_degc}] degC")
        if not (math.isfinite(ramp) and ramp >= 0):
            raise ValueError(f"ramp rate {ramp} K/min must be >= 0")
        self._write(HR.SETPOINT, [*reg.float32_to_regs(degc), *reg.float32_to_regs(ramp)], "setpoint")
        st = self.check()
        if abs(st.setpoint_degc - degc) > 1e-3:
            raise ChamberProtocolError(f"chamber did not take setpoint {degc} degC: {st.describe()}")
        return st

    def run(self) -> None:
        """MODE = RUN: condition the air to the (ramped) setpoint; raises if an alarm is latched."""
        self._write(HR.MODE, [int(Mode.RUN)], "mode RUN")
        st = self.check()
        if not st.running:
            raise ChamberProtocolError(f"chamber does not run after MODE=RUN: {st.describe()}")

    def stop(self) -> None:
        """MODE = STOP: conditioning off (accepted while an alarm is latched)."""
        self._write(HR.MODE, [int(Mode.STOP)], "mode STOP")

    def acknowledge_alarm(self) -> None:
        """Clear a latched alarm; :class:`ChamberAlarm` if its cause persists."""
        self._write(HR.ALARM_ACK, [1], "alarm acknowledge")
        self.check()

    def wait_at_setpoint(self, timeout_s: float) -> ChamberState:
        """Wait for AT_SETPOINT with the air readback within ``setpoint_tol_k`` of the setpoint.

        Raises :class:`ChamberAlarm` on an alarm and :class:`ChamberSetpointTimeout` after ``timeout_s``.
        """
        deadline = self.clock.now() + timeout_s
        while True:
            st = self.check()
            if st.at_setpoint and st.running and abs(st.air_degc - st.setpoint_degc) <= self.setpoint_tol_k:
                return st
            if self.clock.now() > deadline:
                raise ChamberSetpointTimeout(
                    f"chamber did not reach {st.setpoint_degc:g} degC within {timeout_s:g} s: {st.describe()}", st
                )
            self.clock.sleep(self.poll_s)

    def go_ambient(self, ambient_degc: float, ramp_k_per_min: float = 0.0) -> None:
        """Teardown: target the room temperature and keep conditioning towards it; with an alarm latched
        the chamber only gets STOP (it then drifts to the room by itself)."""
        st = self.state()
        if st.alarm:
            self.stop()
            return
        self.set_setpoint(ambient_degc, ramp_k_per_min)
        self._write(HR.MODE, [int(Mode.RUN)], "mode RUN")

    # ------------------------------------------------------------------ heartbeat

    def write_watchdog(self, timeout_s: float) -> None:
        """Set the chamber's watchdog timeout (chamber s, 1..3600)."""
        s = round(timeout_s)
        lo, hi = reg.WATCHDOG_S_RANGE
        if not lo <= s <= hi:
            raise ValueError(f"chamber watchdog timeout {timeout_s} s outside [{lo}, {hi}] s")
        self._write(HR.WATCHDOG_S, [s], "watchdog timeout")

    # ------------------------------------------------------------------ lifetime

    def close(self) -> None:
        """Stop the heartbeat and close the link (the chamber keeps its mode; its watchdog guards it)."""
        self.stop_heartbeat()
        self._close_link()

    def __enter__(self) -> ModbusChamber:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def chamber_client_options(scale: float = 1.0) -> dict[str, Any]:
    """Keyword arguments for :func:`open_chamber` on a clock running ``scale`` times real time
    (polls and heartbeats keep a modest wall rate; the watchdog keeps several wall periods)."""
    s = float(scale)
    return {
        "poll_s": max(1.0, 0.05 * s),
        "heartbeat_period_s": max(2.0, 0.1 * s),
        "alive_timeout_s": max(5.0, 1.0 * s),
        "watchdog_s": min(3600.0, max(30.0, 2.0 * s)),
    }


def open_chamber(
    url: str | ChamberUrl,
    clock: Clock | None = None,
    *,
    heartbeat: bool = True,
    watchdog_s: float | None = None,
    **options: Any,
) -> ModbusChamber:
    """Connect to the chamber at ``url``, identify it, write its watchdog timeout (if given), start the
    heartbeat. Raises :class:`ChamberTimeout` when it does not answer, :class:`ChamberProtocolError` on a
    map mismatch; closes what it opened on failure."""
    chamber = ModbusChamber(url, clock, **options)
    try:
        chamber.identify()
        if watchdog_s is not None:
            chamber.write_watchdog(watchdog_s)
        if heartbeat:
            chamber.start_heartbeat()
    except BaseException:
        chamber.close()
        raise
    return chamber


__all__ = ["ModbusChamber", "chamber_client_options", "open_chamber"]
