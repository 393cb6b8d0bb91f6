"""Sensor URLs: ``serial:///dev/ttyUSB0?baud=921600`` or ``serial:///dev/pts/7``."""

from __future__ import annotations

from dataclasses import dataclass
from urllib.parse import parse_qs

from station.kernel.errors import StationError, quote_input
from station.kernel.urls import split_url

DEFAULT_BAUD = 921600


class SensorUrlError(StationError):
    """A sensor URL the station cannot use."""


@dataclass(frozen=True)
class SerialUrl:
    """Where a sensor is: a serial device path and its baud rate (bit/s)."""

    path: str
    baudrate: int = DEFAULT_BAUD

    def __str__(self) -> str:
        return f"serial://{self.path}?baud={self.baudrate}"


def parse_sensor_url(url: str) -> SerialUrl:
    """Parse ``serial://<absolute device path>[?baud=N]``.

    Raises:
        SensorUrlError: wrong scheme, a host part, a relative or empty path, a bad or
            unknown query parameter.
    """
    parts = split_url(url, "sensor", SensorUrlError)
    shown = quote_input(url)
    if parts.scheme != "serial":
        raise SensorUrlError(f"sensor URL {shown}: scheme must be 'serial', e.g. serial:///dev/ttyUSB0?baud=921600")
    if parts.netloc:
        raise SensorUrlError(f"sensor URL {shown}: use three slashes, serial:///dev/..., no host part")
    if not parts.path.startswith("/") or parts.path == "/":
        raise SensorUrlError(f"sensor URL {shown}: needs an absolute device path")
    if parts.fragment:
        raise SensorUrlError(f"sensor URL {shown}: fragments are not allowed")
    try:
        query = parse_qs(parts.query, keep_blank_values=True, strict_parsing=bool(parts.query))
    except ValueError as exc:
        raise SensorUrlError(f"sensor URL {shown}: bad query: {exc}") from exc
    unknown = set(query) - {"baud"}
    if unknown:
        raise SensorUrlError(f"sensor URL {shown}: unknown parameter(s) {sorted(unknown)}; only 'baud' is known")
    baud = DEFAULT_BAUD
    if "baud" in query:
        values = query["baud"]
        if len(values) != 1 or not values[0].isdigit() or int(values[0]) <= 0:
            raise SensorUrlError(f"sensor URL {shown}: baud must be one positive integer")
        baud = int(values[0])
    return SerialUrl(parts.path, baud)
