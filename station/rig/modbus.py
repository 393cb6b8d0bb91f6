"""The station's Modbus client for the rig (map in :mod:`station.rig.registers`).

``open_rig(url, clock)`` connects over Modbus/TCP or Modbus RTU (pymodbus sync
clients), checks the map version and starts the heartbeat thread. Every Modbus
transaction goes through one lock and a bounded retry loop: a request that gets
no answer (or whose connection dropped) is retried ``retries`` times after
closing and reopening the link, then :class:`RigTimeout` is raised. Command writes
are idempotent because the rig executes a command only when COMMAND_SEQ changes,
so a retried write whose reply was lost does not run the command twice.

What the registers mean to the station (motion confirmed by the status bits *and* the
readbacks within tolerance, polled on the injected clock: ``WallClock`` for hardware,
``SimClock`` in simulation, so timeouts are in rig seconds) is
:class:`~station.rig.mapped.RegisterRig`'s; this module is its Modbus transport. I/O timeouts
are wall seconds.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

from pymodbus import FramerType
from pymodbus.client import ModbusSerialClient, ModbusTcpClient
from pymodbus.constants import ExcCodes
from pymodbus.exceptions import ConnectionException, ModbusException, ModbusIOException

from station.kernel.clock import Clock
from station.rig.mapped import RegisterRig, start_rig
from station.rig.protocol import RigProtocolError, RigTimeout
from station.rig.url import RigUrl, parse_rig_url


def _exception_name(code: int) -> str:
    try:
        return ExcCodes(code).name
    except ValueError:
        return f"code {code}"


class ModbusRig(RegisterRig):
    """A rig behind Modbus; implements :class:`station.rig.protocol.Rig` (see :class:`RegisterRig`).

    Args:
        url: rig URL (see :mod:`station.rig.url`) or a parsed :class:`RigUrl`.
        clock: time base for waits, polling and the heartbeat (rig seconds).
        retry_backoff_s: pause before a retry (wall s).
        options: the motion and supervision settings of :class:`RegisterRig`.
    """

    def __init__(
        self,
        url: RigUrl | str,
        clock: Clock | None = None,
        *,
        retry_backoff_s: float = 0.05,
        **options: Any,
    ) -> None:
        super().__init__(clock, **options)
        self.url = url if isinstance(url, RigUrl) else parse_rig_url(url)
        self.retry_backoff_s = retry_backoff_s
        self._client = self._make_client()

    # ------------------------------------------------------------------ transport

    def _make_client(self) -> ModbusTcpClient | ModbusSerialClient:
        u = self.url
        if u.is_tcp:
            return ModbusTcpClient(u.host, port=u.port, timeout=u.timeout_s, retries=0)
        return ModbusSerialClient(
            u.device,
            framer=FramerType.RTU,
            baudrate=u.baud,
            bytesize=u.bytesize,
            parity=u.parity,
            stopbits=u.stopbits,
            timeout=u.timeout_s,
            retries=0,
        )

    def _transact(self, what: str, request: Callable[[], Any], retries: int | None = None) -> Any:
        """Run one Modbus request with bounded retries; returns the (non-error) response."""
        attempts = 1 + (self.url.retries if retries is None else retries)
        last: Exception | None = None
        for attempt in range(attempts):
            if attempt:
                time.sleep(self.retry_backoff_s)
            with self._lock:
                try:
                    if not self._client.connected and not self._client.connect():
                        raise ConnectionException(f"cannot connect to {self.url}")
                    response = request()
                except (ConnectionException, ModbusIOException, OSError) as exc:
                    # no answer, refused or dropped link: start over on a fresh connection
                    last = exc
                    self._client.close()
                    self.reconnects += 1
                    continue
                except ModbusException as exc:
                    raise RigProtocolError(f"rig {what}: {exc}") from exc
            if response.isError():
                code = int(getattr(response, "exception_code", 0))
                raise RigProtocolError(
                    f"rig {what}: Modbus exception {code} ({_exception_name(code)})", exception_code=code
                )
            return response
        raise RigTimeout(f"rig {what}: no answer from {self.url} after {attempts} attempts ({last})")

    def _read_input(self, address: int, count: int, what: str) -> list[int]:
        unit = self.url.unit
        response = self._transact(what, lambda: self._client.read_input_registers(address, count=count, device_id=unit))
        registers = list(response.registers)
        if len(registers) != count:
            raise RigProtocolError(f"rig {what}: asked for {count} registers, got {len(registers)}")
        return registers

    def _write(self, address: int, values: list[int], what: str, retries: int | None = None) -> None:
        unit = self.url.unit
        self._transact(what, lambda: self._client.write_registers(address, values, device_id=unit), retries=retries)

    def _close_link(self) -> None:
        with self._lock:
            self._client.close()

    def __enter__(self) -> ModbusRig:
        return self


def rig_client_options(scale: float = 1.0) -> dict[str, Any]:
    """Keyword arguments for :func:`open_rig` on a clock running ``scale`` times real time.

    At scale 1 these are the client defaults (poll 0.1 s, heartbeat 0.5 s, watchdog 2 s).
    On a fast simulated clock the rig seconds between polls and heartbeats grow so the
    wall-clock rates stay modest (~50 polls and ~25 heartbeats per wall second), and
    the watchdog and acknowledgement timeouts keep a margin of several wall periods.
    """
    s = float(scale)
    return {
        "poll_s": max(0.1, 0.02 * s),
        "heartbeat_period_s": max(0.5, 0.04 * s),
        "ack_timeout_s": max(2.0, 0.5 * s),
        "alive_timeout_s": max(2.0, 0.5 * s),
        "watchdog_s": min(60.0, max(2.0, 1.0 * s)),
    }


def open_rig(
    url: str | RigUrl,
    clock: Clock | None = None,
    *,
    heartbeat: bool = True,
    watchdog_s: float | None = None,
    **options: Any,
) -> ModbusRig:
    """Connect to the rig at ``url``, identify it, and start the heartbeat.

    ``watchdog_s`` (rig s) is written to the rig's WATCHDOG_MS if given; ``options``
    are the keyword arguments of :class:`ModbusRig`. Raises :class:`RigTimeout`
    when the rig does not answer and :class:`RigProtocolError` on a map mismatch.
    """
    return start_rig(ModbusRig(url, clock, **options), heartbeat=heartbeat, watchdog_s=watchdog_s)
