"""Rig URLs: which transport, where, and with which serial settings.

* ``modbus-tcp://HOST[:PORT]?unit=1`` (port 502 by default)
* ``modbus-rtu:///dev/ttyUSB0?baud=115200&parity=N&unit=1`` (also ``stopbits``, ``bytesize``)

Common query parameters: ``unit`` (Modbus unit/device id, 1 by default),
``timeout`` (per-request I/O timeout in wall seconds, 1.0 by default),
``retries`` (extra attempts after a request got no answer, 2 by default).
RTU defaults follow the Modbus serial line spec: 19200 baud, 8 data bits, even
parity, 1 stop bit. The parsing is :mod:`station.modbus.modbus_url`'s.
"""

from __future__ import annotations

from dataclasses import dataclass

from station.kernel.errors import StationError
from station.modbus.modbus_url import SCHEMES, ModbusUrl, UrlDialect, parse_modbus_url


class RigUrlError(StationError, ValueError):
    """A rig URL that cannot be used; the message says which part and why."""


@dataclass(frozen=True)
class RigUrl(ModbusUrl):
    """A parsed rig URL (fields: :class:`~station.modbus.modbus_url.ModbusUrl`; 19200 baud by default)."""

    def __str__(self) -> str:
        if self.is_tcp:
            return f"modbus-tcp://{self.host}:{self.port}?unit={self.unit}"
        return (
            f"modbus-rtu://{self.device}?baud={self.baud}&parity={self.parity}"
            f"&stopbits={self.stopbits}&bytesize={self.bytesize}&unit={self.unit}"
        )


_DIALECT = UrlDialect(
    "rig", RigUrlError, quote_url_in_values=False,
    device_hint=" (use modbus-rtu:///dev/ttyUSB0)", parity_names_value=True,
)


def parse_rig_url(url: str) -> RigUrl:
    """Parse a rig URL; raises :class:`RigUrlError` naming the offending part."""
    return parse_modbus_url(url, RigUrl, _DIALECT)


__all__ = ["SCHEMES", "RigUrl", "RigUrlError", "parse_rig_url"]
