"""Chamber URLs: the same Modbus URL forms as the rig's, in the chamber's role.

* ``modbus-tcp://HOST[:PORT]?unit=1`` (port 502 by default)
* ``modbus-rtu:///dev/ttyUSB0?baud=9600&parity=N&unit=1`` (also ``stopbits``, ``bytesize``)

Common query parameters: ``unit`` (Modbus unit id, 1 by default), ``timeout`` (per-request I/O
timeout, wall s, 1.0 by default), ``retries`` (extra attempts after no answer, 2 by default).
"""

from __future__ import annotations

from dataclasses import dataclass
from urllib.parse import parse_qs, urlsplit

from station.kernel.errors import StationError

SCHEMES = ("modbus-tcp", "modbus-rtu")
_KNOWN = {
    "modbus-tcp": {"unit", "timeout", "retries"},
    "modbus-rtu": {"unit", "timeout", "retries", "baud", "parity", "stopbits", "bytesize"},
}
_PARITIES = {"N": "N", "E": "E", "O": "O", "NONE": "N", "EVEN": "E", "ODD": "O"}


class ChamberUrlError(StationError, ValueError):
    """A chamber URL that cannot be used; the message says which part and why."""


@dataclass(frozen=True)
class ChamberUrl:
    scheme: str
    host: str = ""
    port: int = 502
    device: str = ""
    baud: int = 9600
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
        return f"modbus-rtu://{self.device}?baud={self.baud}&parity={self.parity}&unit={self.unit}"


def _int(url: str, params: dict[str, str], key: str, default: int, lo: int, hi: int) -> int:
    if key not in params:
        return default
    try:
        value = int(params[key])
    except ValueError:
        raise ChamberUrlError(f"chamber URL {url!r}: {key}={params[key]!r} is not an integer") from None
    if not lo <= value <= hi:
        raise ChamberUrlError(f"chamber URL {url!r}: {key}={value} outside [{lo}, {hi}]")
    return value


def parse_chamber_url(url: str) -> ChamberUrl:
    """Parse a chamber URL; raises :class:`ChamberUrlError` naming the offending part."""
    parts = urlsplit(url)
    scheme = parts.scheme.lower()
    if scheme not in SCHEMES:
        raise ChamberUrlError(f"chamber URL {url!r}: scheme must be one of {', '.join(SCHEMES)}")
    params: dict[str, str] = {}
    for key, values in parse_qs(parts.query, keep_blank_values=True).items():
        if key not in _KNOWN[scheme]:
            raise ChamberUrlError(f"chamber URL {url!r}: unknown parameter {key!r} for {scheme}")
        if len(values) != 1:
            raise ChamberUrlError(f"chamber URL {url!r}: parameter {key!r} given {len(values)} times")
        params[key] = values[0]
    unit = _int(url, params, "unit", 1, 0, 247)
    retries = _int(url, params, "retries", 2, 0, 10)
    timeout_s = 1.0
    if "timeout" in params:
        try:
            timeout_s = float(params["timeout"])
        except ValueError:
            raise ChamberUrlError(f"chamber URL {url!r}: timeout={params['timeout']!r} is not a number") from None
        if not 0.01 <= timeout_s <= 60.0:
            raise ChamberUrlError(f"chamber URL {url!r}: timeout={timeout_s} outside [0.01, 60] s")
    if scheme == "modbus-tcp":
        if not parts.hostname:
            raise ChamberUrlError(f"chamber URL {url!r}: no host")
        if parts.path not in ("", "/"):
            raise ChamberUrlError(f"chamber URL {url!r}: a TCP URL has no path")
        try:
            port = parts.port if parts.port is not None else 502
        except ValueError:
            raise ChamberUrlError(f"chamber URL {url!r}: bad port") from None
        if port == 0:
            raise ChamberUrlError(f"chamber URL {url!r}: port 0")
        return ChamberUrl(scheme, host=parts.hostname, port=port, unit=unit, timeout_s=timeout_s, retries=retries)
    device = f"{parts.netloc}{parts.path}" if parts.netloc else parts.path
    if not device or device == "/":
        raise ChamberUrlError(f"chamber URL {url!r}: no serial device")
    parity = _PARITIES.get(params.get("parity", "E").upper())
    if parity is None:
        raise ChamberUrlError(f"chamber URL {url!r}: parity must be N, E or O")
    return ChamberUrl(
        scheme, device=device, baud=_int(url, params, "baud", 9600, 50, 4_000_000), parity=parity,
        stopbits=_int(url, params, "stopbits", 1, 1, 2), bytesize=_int(url, params, "bytesize", 8, 7, 8),
        unit=unit, timeout_s=timeout_s, retries=retries,
    )
