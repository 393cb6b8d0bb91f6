"""A small URL-scheme registry: how the station picks the implementation of a device from its URL.

As python-can selects a bus interface by name, the station selects a rig or sensor
implementation by the scheme of its URL (``modbus-tcp://``, ``modbus-rtu://``, ``serial://``).
Each device package owns one :class:`SchemeRegistry` and registers its built-in transports;
anything else (the in-process fakes of :mod:`station.sim.fakes`, a vendor's own rig) registers
its scheme the same way, without the station importing it. There is no ``simulate`` flag
anywhere: a simulated device is just another URL.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, Generic, TypeVar
from urllib.parse import urlsplit

from station.kernel.errors import StationError

T = TypeVar("T")


class SchemeRegistry(Generic[T]):
    """Openers of one kind of device, keyed by URL scheme.

    Args:
        what: the device kind for messages ('rig', 'sensor').
        error: the :class:`StationError` subclass raised for a URL no opener takes.
    """

    def __init__(self, what: str, error: type[StationError] = StationError) -> None:
        self.what = what
        self.error = error
        self._openers: dict[str, Callable[..., T]] = {}

    def register(self, scheme: str, opener: Callable[..., T]) -> None:
        """Make ``opener(url, *args, **kwargs)`` open URLs of ``scheme`` (lower case, no '://')."""
        key = scheme.lower()
        if not key or "://" in key:
            raise ValueError(f"bad scheme {scheme!r}")
        self._openers[key] = opener

    def unregister(self, scheme: str) -> None:
        self._openers.pop(scheme.lower(), None)

    @property
    def schemes(self) -> tuple[str, ...]:
        return tuple(sorted(self._openers))

    def opener(self, url: str) -> Callable[..., T]:
        """The opener registered for ``url``'s scheme; raises ``error`` naming the known schemes."""
        scheme = urlsplit(url).scheme.lower() if isinstance(url, str) else ""
        try:
            return self._openers[scheme]
        except KeyError:
            known = ", ".join(f"{s}://" for s in self.schemes)
            raise self.error(f"{self.what} URL {url!r}: scheme must be one of {known}") from None

    def open(self, url: str, *args: Any, **kwargs: Any) -> T:
        """Open the device at ``url`` with the opener of its scheme."""
        return self.opener(url)(url, *args, **kwargs)


__all__ = ["SchemeRegistry"]
