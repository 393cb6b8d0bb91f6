"""Modbus device URLs: which transport, where, and with which serial settings.

* ``modbus-tcp://HOST[:PORT]?unit=1`` (port 502 by default)
* ``modbus-rtu:///dev/ttyUSB0?baud=19200&parity=N&unit=1`` (also ``stopbits``, ``bytesize``)

Common query parameters: ``unit`` (Modbus unit/device id, 1 by default), ``timeout`` (per-request
I/O timeout in wall seconds, 1.0 by default), ``retries`` (extra attempts after a request got no
answer, 2 by default). Each device kind (rig, chamber) subclasses :class:`ModbusUrl` for its own
serial defaults and describes its errors with a :class:`UrlDialect`.
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import TypeVar
from urllib.parse import parse_qs

from station.kernel.errors import StationError, quote_input
from station.kernel.urls import split_url

SCHEMES = ("modbus-tcp", "modbus-rtu")
_PARITIES = {"N": "N", "E": "E", "O": "O", "NONE": "N", "EVEN": "E", "ODD": "O"}
_KNOWN = {
    "modbus-tcp": {"unit", "timeout", "retries"},
    "modbus-rtu": {"unit", "timeout", "retries", "baud", "parity", "stopbits", "bytesize"},
}


@dataclass(frozen=True)
class ModbusUrl:
    """A parsed Modbus URL.

    Attributes:
        scheme: 'modbus-tcp' or 'modbus-rtu'.
        host, port: TCP peer (TCP only).
        device: serial device path (RTU only).
        baud, parity, stopbits, bytesize: serial settings (RTU only).
        unit: Modbus unit (device) id, 0..247.
        timeout_s: per-request I/O timeout (wall seconds).
        retries: extra attempts after a request got no answer.
    """

    scheme: str
    host: str = ""
    port: int = 502
    device: str = ""
    baud: int = 19200
    parity: str = "E"
    stopbits: int = 1
    bytesize: int = 8
    unit: int = 1
    timeout_s: float = 1.0
    retries: int = 2

    @property
    def is_tcp(self) -> bool:
        return self.scheme == "modbus-tcp"


U = TypeVar("U", bound=ModbusUrl)


@dataclass(frozen=True)
class UrlDialect:
    """How one device kind names its URL errors.

    Attributes:
        role: the device named in messages ('rig', 'chamber').
        error: the error type raised (one message argument).
        quote_url_in_values: messages about a bad option value name the URL too (else only the role).
        device_hint: appended to the 'no serial device' message.
        parity_names_value: the bad-parity message repeats the value given.
    """

    role: str
    error: type[StationError]
    quote_url_in_values: bool = True
    device_hint: str = ""
    parity_names_value: bool = False


def _int(where: str, dialect: UrlDialect, params: dict[str, str], key: str, default: int, lo: int, hi: int) -> int:
    if key not in params:
        return default
    try:
        value = int(params[key])
    except ValueError:
        raise dialect.error(f"{where}: {key}={params[key]!r} is not an integer") from None
    if not lo <= value <= hi:
        raise dialect.error(f"{where}: {key}={value} outside [{lo}, {hi}]")
    return value


def parse_modbus_url(url: str, kind: type[U], dialect: UrlDialect) -> U:
    """Parse ``url`` into a ``kind`` (its field defaults are the device's); raises ``dialect.error``
    naming the offending part."""
    error = dialect.error
    where = f"{dialect.role} URL {url!r}"
    value_where = where if dialect.quote_url_in_values else f"{dialect.role} URL"
    parts = split_url(url, dialect.role, error)
    where = f"{dialect.role} URL {quote_input(url)}"
    value_where = where if dialect.quote_url_in_values else f"{dialect.role} URL"
    scheme = parts.scheme.lower()
    if scheme not in SCHEMES:
        raise error(f"{where}: scheme must be one of {', '.join(SCHEMES)}")
    params: dict[str, str] = {}
    for key, values in parse_qs(parts.query, keep_blank_values=True).items():
        if key not in _KNOWN[scheme]:
            raise error(f"{where}: unknown parameter {key!r} for {scheme}")
        if len(values) != 1:
            raise error(f"{where}: parameter {key!r} given {len(values)} times")
        params[key] = values[0]
    unit = _int(value_where, dialect, params, "unit", 1, 0, 247)
    retries = _int(value_where, dialect, params, "retries", 2, 0, 10)
    timeout_s = 1.0
    if "timeout" in params:
        try:
            timeout_s = float(params["timeout"])
        except ValueError:
            raise error(f"{value_where}: timeout={params['timeout']!r} is not a number") from None
        if not 0.01 <= timeout_s <= 60.0:
            raise error(f"{value_where}: timeout={timeout_s} outside [0.01, 60] s")
    if scheme == "modbus-tcp":
        if not parts.hostname:
            raise error(f"{where}: no host")
        if parts.path not in ("", "/"):
            raise error(f"{where}: a TCP URL has no path")
        try:
            port = parts.port if parts.port is not None else 502
        except ValueError:
            raise error(f"{where}: bad port") from None
        if port == 0:
            raise error(f"{where}: port 0")
        return kind(scheme, host=parts.hostname, port=port, unit=unit, timeout_s=timeout_s, retries=retries)
    device = f"{parts.netloc}{parts.path}" if parts.netloc else parts.path
    if not device or device == "/":
        raise error(f"{where}: no serial device{dialect.device_hint}")
    parity = _PARITIES.get(params.get("parity", "E").upper())
    if parity is None:
        given = f"={params['parity']!r}" if dialect.parity_names_value else ""
        raise error(f"{value_where}: parity{given} must be N, E or O")
    default_baud = next(f.default for f in fields(kind) if f.name == "baud")
    assert isinstance(default_baud, int)
    return kind(
        scheme,
        device=device,
        baud=_int(value_where, dialect, params, "baud", default_baud, 50, 4_000_000),
        parity=parity,
        stopbits=_int(value_where, dialect, params, "stopbits", 1, 1, 2),
        bytesize=_int(value_where, dialect, params, "bytesize", 8, 7, 8),
        unit=unit,
        timeout_s=timeout_s,
        retries=retries,
    )


__all__ = ["SCHEMES", "ModbusUrl", "UrlDialect", "parse_modbus_url"]
