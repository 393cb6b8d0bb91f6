"""Chamber URLs: the same Modbus URL forms as the rig's, in the chamber's role.

* ``modbus-tcp://HOST[:PORT]?unit=1`` (port 502 by default)
* ``modbus-rtu:///dev/ttyUSB0?baud=9600&parity=N&unit=1`` (also ``stopbits``, ``bytesize``)

Common query parameters: ``unit`` (Modbus unit id, 1 by default), ``timeout`` (per-request I/O
timeout, wall s, 1.0 by default), ``retries`` (extra attempts after no answer, 2 by default).
The parsing is :mod:`station.modbus.modbus_url`'s.
"""

from __future__ import annotations

from dataclasses import dataclass

from station.kernel.errors import StationError
from station.modbus.modbus_url import SCHEMES, ModbusUrl, UrlDialect, parse_modbus_url


class ChamberUrlError(StationError, ValueError):
    """A chamber URL that cannot be used; the message says which part and why."""


@dataclass(frozen=True)
class ChamberUrl(ModbusUrl):
    """A parsed chamber URL (fields: :class:`~station.modbus.modbus_url.ModbusUrl`; 9600 baud by default)."""

    baud: int = 9600

    def __str__(self) -> str:
        if self.is_tcp:
            return f"modbus-tcp://{self.host}:{self.port}?unit={self.unit}"
        return f"modbus-rtu://{self.device}?baud={self.baud}&parity={self.parity}&unit={self.unit}"


_DIALECT = UrlDialect("chamber", ChamberUrlError)


def parse_chamber_url(url: str) -> ChamberUrl:
    """Parse a chamber URL; raises :class:`ChamberUrlError` naming the offending part."""
    return parse_modbus_url(url, ChamberUrl, _DIALECT)


__all__ = ["SCHEMES", "ChamberUrl", "ChamberUrlError", "parse_chamber_url"]
