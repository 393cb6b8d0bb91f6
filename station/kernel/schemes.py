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

from station.kernel.errors import StationError
from station.kernel.urls import split_url

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
        self._parsers: dict[str, Callable[[str], object]] = {}

    def register(self, scheme: str, opener: Callable[..., T], parse: Callable[[str], object] | None = None) -> None:
        """Make ``opener(url, *args, **kwargs)`` open URLs of ``scheme`` (lower case, no '://'); ``parse(url)``
        (optional) checks a URL of the scheme without opening anything (raises on a bad one)."""
        key = scheme.lower()
        if not key or "://" in key:
            raise ValueError(f"bad scheme {scheme!r}")
        self._openers[key] = opener
        if parse is not None:
            self._parsers[key] = parse

    def unregister(self, scheme: str) -> None:
        self._openers.pop(scheme.lower(), None)

    @property
    def schemes(self) -> tuple[str, ...]:
        return tuple(sorted(self._openers))

    def opener(self, url: str) -> Callable[..., T]:
        """The opener registered for ``url``'s scheme; raises ``error`` naming the known schemes."""
        scheme = split_url(url, self.what, self.error).scheme.lower()
        try:
            return self._openers[scheme]
        except KeyError:
            known = ", ".join(f"{s}://" for s in self.schemes)
            raise self.error(f"{self.what} URL {url!r}: scheme must be one of {known}") from None

    def check(self, url: str) -> None:
        """Check ``url`` before anything starts: it parses, its scheme is registered, and the scheme's own
        parser (if registered) takes it; raises ``error`` in one line."""
        self.opener(url)
        parse = self._parsers.get(split_url(url, self.what, self.error).scheme.lower())
        if parse is not None:
            parse(url)

    def open(self, url: str, *args: Any, **kwargs: Any) -> T:
        """Open the device at ``url`` with the opener of its scheme."""
        return self.opener(url)(url, *args, **kwargs)


__all__ = ["SchemeRegistry"]
