"""The station's pymodbus client transport, shared by the rig and the chamber clients.

:class:`ModbusTransport` opens a pymodbus sync client for a :class:`~station.modbus.modbus_url.ModbusUrl`
(Modbus/TCP or RTU) and runs every transaction under the device's lock in a bounded retry loop: a
request that gets no answer (or whose connection dropped) is retried ``url.retries`` times after
closing and reopening the link, then the device's timeout error is raised; a Modbus exception reply
raises its protocol error. I/O timeouts are wall seconds.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from typing import Any, ClassVar, Protocol

from pymodbus import FramerType
from pymodbus.client import ModbusSerialClient, ModbusTcpClient
from pymodbus.constants import ExcCodes
from pymodbus.exceptions import ConnectionException, ModbusException, ModbusIOException

from station.kernel.errors import StationError
from station.modbus.modbus_url import ModbusUrl


class ProtocolErrorType(Protocol):
    def __call__(self, message: str, exception_code: int | None = None) -> StationError: ...


def exception_name(code: int) -> str:
    """The name of a Modbus exception code ('code N' for one pymodbus does not know)."""
    try:
        return ExcCodes(code).name
    except ValueError:
        return f"code {code}"


def make_client(url: ModbusUrl) -> ModbusTcpClient | ModbusSerialClient:
    """A pymodbus sync client for ``url`` (its own retries off: :class:`ModbusTransport` retries)."""
    if url.is_tcp:
        return ModbusTcpClient(url.host, port=url.port, timeout=url.timeout_s, retries=0)
    return ModbusSerialClient(
        url.device,
        framer=FramerType.RTU,
        baudrate=url.baud,
        bytesize=url.bytesize,
        parity=url.parity,
        stopbits=url.stopbits,
        timeout=url.timeout_s,
        retries=0,
    )


class ModbusTransport:
    """Register reads and writes over pymodbus with bounded retries (a mixin for device clients).

    The device class sets the class attributes (its role in messages, its error types) and, before
    use, :attr:`url`, :attr:`retry_backoff_s`, :attr:`reconnects` and :attr:`_lock`; then calls
    :meth:`_open_transport`.
    """

    #: the device named in error messages ('rig', 'chamber')
    _role: ClassVar[str]
    #: raised on a Modbus exception reply or a short read: ``(message, exception_code=None)``
    _protocol_error: ClassVar[ProtocolErrorType]
    #: raised when a request got no answer after the retries
    _timeout_error: ClassVar[type[StationError]]
    #: Modbus exception messages carry the exception's name too
    _name_exceptions: ClassVar[bool] = True

    url: ModbusUrl
    retry_backoff_s: float
    reconnects: int
    _lock: threading.RLock
    _client: ModbusTcpClient | ModbusSerialClient

    def _open_transport(self) -> None:
        self._client = make_client(self.url)

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
                    raise self._protocol_error(f"{self._role} {what}: {exc}") from exc
            if response.isError():
                code = int(getattr(response, "exception_code", 0))
                name = f" ({exception_name(code)})" if self._name_exceptions else ""
                raise self._protocol_error(f"{self._role} {what}: Modbus exception {code}{name}", exception_code=code)
            return response
        raise self._timeout_error(f"{self._role} {what}: no answer from {self.url} after {attempts} attempts ({last})")

    def _read_input(self, address: int, count: int, what: str) -> list[int]:
        unit = self.url.unit
        response = self._transact(what, lambda: self._client.read_input_registers(address, count=count, device_id=unit))
        registers = list(response.registers)
        if len(registers) != count:
            raise self._protocol_error(f"{self._role} {what}: asked for {count} registers, got {len(registers)}")
        return registers

    def _write(self, address: int, values: list[int], what: str, retries: int | None = None) -> None:
        unit = self.url.unit
        self._transact(what, lambda: self._client.write_registers(address, values, device_id=unit), retries=retries)

    def _close_link(self) -> None:
        with self._lock:
            self._client.close()


__all__ = ["ModbusTransport", "exception_name", "make_client"]
