"""Rig URLs: which transport, where, and with which serial settings.

* ``modbus-tcp://HOST[:PORT]?unit=1`` (port 502 by default)
* ``modbus-rtu:///dev/ttyUSB0?baud=115200&parity=N&unit=1`` (also ``stopbits``, ``bytesize``)

Common query parameters: ``unit`` (Modbus unit/device id, 1 by default),
``timeout`` (per-request I/O timeout in wall seconds, 1.0 by default),
``retries`` (extra attempts after a request got no answer, 2 by default).
RTU defaults follow the Modbus serial line spec: 19200 baud, 8 data bits, even
parity, 1 stop bit.
"""

from __future__ import annotations

from dataclasses import dataclass
from urllib.parse import parse_qs, urlsplit

from station.kernel.errors import StationError

SCHEMES = ("modbus-tcp", "modbus-rtu")
_PARITIES = {"N": "N", "E": "E", "O": "O", "NONE": "N", "EVEN": "E", "ODD": "O"}
_KNOWN = {
    "modbus-tcp": {"unit", "timeout", "retries"},
    "modbus-rtu": {"unit", "timeout", "retries", "baud", "parity", "stopbits", "bytesize"},
}


class RigUrlError(StationError, ValueError):
    """A rig URL that cannot be used; the message says which part and why."""


@dataclass(frozen=True)
class RigUrl:
    """A parsed rig URL.

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

    def __str__(self) -> str:
        if self.is_tcp:
            return f"modbus-tcp://{self.host}:{self.port}?unit={self.unit}"
        return (
            f"modbus-rtu://{self.device}?baud={self.baud}&parity={self.parity}"
            f"&stopbits={self.stopbits}&bytesize={self.bytesize}&unit={self.unit}"
        )


def _int(params: dict[str, str], key: str, default: int, lo: int, hi: int) -> int:
    if key not in params:
        return default
    try:
        value = int(params[key])
    except ValueError:
        raise RigUrlError(f"rig URL: {key}={params[key]!r} is not an integer") from None
    if not lo <= value <= hi:
        raise RigUrlError(f"rig URL: {key}={value} outside [{lo}, {hi}]")
    return value


def parse_rig_url(url: str) -> RigUrl:
    """Parse a rig URL; raises :class:`RigUrlError` naming the offending part."""
    parts = urlsplit(url)
    scheme = parts.scheme.lower()
    if scheme not in SCHEMES:
        raise RigUrlError(f"rig URL {url!r}: scheme must be one of {', '.join(SCHEMES)}")
    query = parse_qs(parts.query, keep_blank_values=True, strict_parsing=False)
    params: dict[str, str] = {}
    for key, values in query.items():
        if key not in _KNOWN[scheme]:
            raise RigUrlError(f"rig URL {url!r}: unknown parameter {key!r} for {scheme}")
        if len(values) != 1:
            raise RigUrlError(f"rig URL {url!r}: parameter {key!r} given {len(values)} times")
        params[key] = values[0]
    unit = _int(params, "unit", 1, 0, 247)
    retries = _int(params, "retries", 2, 0, 10)
    timeout_s = 1.0
    if "timeout" in params:
        try:
            timeout_s = float(params["timeout"])
        except ValueError:
            raise RigUrlError(f"rig URL: timeout={params['timeout']!r} is not a number") from None
        if not 0.01 <= timeout_s <= 60.0:
            raise RigUrlError(f"rig URL: timeout={timeout_s} outside [0.01, 60] s")
    if scheme == "modbus-tcp":
        if not parts.hostname:
            raise RigUrlError(f"rig URL {url!r}: no host")
        if parts.path not in ("", "/"):
            raise RigUrlError(f"rig URL {url!r}: a TCP URL has no path")
        try:
            port = parts.port if parts.port is not None else 502
        except ValueError:
            raise RigUrlError(f"rig URL {url!r}: bad port") from None
        if port == 0:
            raise RigUrlError(f"rig URL {url!r}: port 0")
        return RigUrl(scheme, host=parts.hostname, port=port, unit=unit, timeout_s=timeout_s, retries=retries)
    device = f"{parts.netloc}{parts.path}" if parts.netloc else parts.path
    if not device or device == "/":
        raise RigUrlError(f"rig URL {url!r}: no serial device (use modbus-rtu:///dev/ttyUSB0)")
    parity = _PARITIES.get(params.get("parity", "E").upper())
    if parity is None:
        raise RigUrlError(f"rig URL: parity={params['parity']!r} must be N, E or O")
    return RigUrl(
        scheme,
        device=device,
        baud=_int(params, "baud", 19200, 50, 4_000_000),
        parity=parity,
        stopbits=_int(params, "stopbits", 1, 1, 2),
        bytesize=_int(params, "bytesize", 8, 7, 8),
        unit=unit,
        timeout_s=timeout_s,
        retries=retries,
    )
