"""The soak rack's relay board behind Modbus: one coil per slot switches the slot's supply.

:class:`RelayBoard` follows ``station/rack/register-map.md`` over :class:`station.modbus.client.ModbusTransport`
(retries, reconnects, Modbus exceptions as :class:`RelayBoardError`). URLs as the rig's and the
chamber's (:mod:`station.modbus.modbus_url`): ``modbus-tcp://HOST:PORT?unit=1``, ``modbus-rtu:///dev/ttyUSB0?...``.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass

from station.kernel.errors import HardwareError, StationError
from station.modbus.client import ModbusTransport
from station.modbus.modbus_url import ModbusUrl, UrlDialect, parse_modbus_url
from station.rack import registers as reg


class RelayBoardError(HardwareError):
    """The relay board faulted, refused a request or did not answer: a station fault."""

    def __init__(self, message: str, exception_code: int | None = None) -> None:
        super().__init__(message)
        self.exception_code = exception_code


class RelayBoardTimeout(RelayBoardError):
    """The relay board did not answer after the retries."""


class RelayBoardUrlError(StationError, ValueError):
    """A relay-board URL that cannot be used; the message says which part and why."""


@dataclass(frozen=True)
class RelayBoardUrl(ModbusUrl):
    """A parsed relay-board URL (fields: :class:`~station.modbus.modbus_url.ModbusUrl`; 9600 baud by default)."""

    baud: int = 9600


_DIALECT = UrlDialect("relay board", RelayBoardUrlError)


def parse_board_url(url: str) -> RelayBoardUrl:
    """Parse a relay-board URL; raises :class:`RelayBoardUrlError` naming the offending part."""
    return parse_modbus_url(url, RelayBoardUrl, _DIALECT)


@dataclass(frozen=True)
class BoardState:
    """What the board reports: its channel count, its own power-on counter and every relay."""

    channels: int
    power_on_count: int
    relays: tuple[bool, ...]


class RelayBoard(ModbusTransport):
    """A Modbus relay board (coils = slot supplies)."""

    _role = "relay board"
    _protocol_error = RelayBoardError
    _timeout_error = RelayBoardTimeout

    def __init__(self, url: str | RelayBoardUrl, *, retry_backoff_s: float = 0.05) -> None:
        self.url = parse_board_url(url) if isinstance(url, str) else url
        self.retry_backoff_s = float(retry_backoff_s)
        self.reconnects = 0
        self._lock = threading.RLock()
        self._open_transport()
        self._channels: int | None = None

    @property
    def channels(self) -> int:
        """Number of relays (read once from the board)."""
        if self._channels is None:
            n = self._read_input(reg.IR_CHANNELS, 1, "read channel count")[0]
            if not 1 <= n <= reg.MAX_CHANNELS:
                raise RelayBoardError(f"relay board reports {n} channels (1..{reg.MAX_CHANNELS} expected)")
            self._channels = int(n)
        return self._channels

    def _slot(self, slot: int) -> int:
        if not 0 <= slot < self.channels:
            raise RelayBoardError(f"slot {slot} does not exist (the board has {self.channels} relays)")
        return reg.RELAY_START + slot

    def power(self, slot: int, on: bool) -> None:
        """Switch slot ``slot``'s supply and confirm it from the coil's readback."""
        address, unit = self._slot(slot), self.url.unit
        self._transact(f"switch slot {slot} {'on' if on else 'off'}",
                       lambda: self._client.write_coil(address, bool(on), device_id=unit))
        if self.relays()[slot] != bool(on):
            raise RelayBoardError(f"slot {slot}: relay reads {'off' if on else 'on'} after switching it "
                                  f"{'on' if on else 'off'}")

    def power_all(self, on: bool) -> None:
        """Switch every relay at once (write multiple coils)."""
        n, unit = self.channels, self.url.unit
        self._transact(f"switch all slots {'on' if on else 'off'}",
                       lambda: self._client.write_coils(reg.RELAY_START, [bool(on)] * n, device_id=unit))

    def relays(self) -> tuple[bool, ...]:
        """Every relay's state, slot order."""
        n, unit = self.channels, self.url.unit
        response = self._transact("read relays",
                                  lambda: self._client.read_coils(reg.RELAY_START, count=n, device_id=unit))
        bits = list(response.bits)[:n]
        if len(bits) != n:
            raise RelayBoardError(f"relay board: asked for {n} coils, got {len(bits)}")
        return tuple(bool(b) for b in bits)

    def state(self) -> BoardState:
        ir = self._read_input(0, reg.IR_COUNT, "read state")
        return BoardState(int(ir[reg.IR_CHANNELS]),
                          int(ir[reg.IR_POWER_ON_COUNT_LO]) | (int(ir[reg.IR_POWER_ON_COUNT_HI]) << 16),
                          self.relays())

    def close(self) -> None:
        self._close_link()

    def __enter__(self) -> RelayBoard:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


__all__ = ["BoardState", "RelayBoard", "RelayBoardError", "RelayBoardTimeout", "RelayBoardUrl",
           "RelayBoardUrlError", "parse_board_url"]
