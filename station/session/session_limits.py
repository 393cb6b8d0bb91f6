"""How much a session reader accepts: a size and a row limit, from the environment or given.

A recording larger than either limit is refused before (size) or while (rows) it is read, in one line
that names the limit and how to raise it, so that no input makes a reader take the machine's memory.
The defaults hold a 1 kHz recording of two hours (7.2 M rows, about 1 GB of text as the station writes it);
8 M rows are about 1 GB of arrays in memory. A station that records more sets the environment variables.
"""

from __future__ import annotations

import os
import re
from collections.abc import Mapping
from dataclasses import dataclass

from station.kernel.errors import SessionFormatError, StationError

__all__ = ["DEFAULT_MAX_BYTES", "DEFAULT_MAX_ROWS", "MAX_BYTES_ENV", "MAX_ROWS_ENV", "SessionLimitError",
           "SessionLimits", "size_text"]

MAX_BYTES_ENV = "STATION_SESSION_MAX_BYTES"
MAX_ROWS_ENV = "STATION_SESSION_MAX_ROWS"
#: Default largest session file (bytes): 1 GiB.
DEFAULT_MAX_BYTES = 2**30
#: Default most data rows: 8 M (about 1 GB of arrays in a :class:`~station.session.model.Session`).
DEFAULT_MAX_ROWS = 8_000_000

_SUFFIX = {"": 1, "k": 2**10, "m": 2**20, "g": 2**30, "t": 2**40}
_SIZE = re.compile(r"(\d[\d_]*)\s*([kmgt]?)(?:i?b)?", re.IGNORECASE)


class SessionLimitError(SessionFormatError):
    """A session file is larger than the reader's size or row limit (:class:`SessionLimits`)."""


@dataclass(frozen=True)
class SessionLimits:
    """The largest session a reader takes: ``max_bytes`` of file, ``max_rows`` data rows."""

    max_bytes: int = DEFAULT_MAX_BYTES
    max_rows: int = DEFAULT_MAX_ROWS

    def __post_init__(self) -> None:
        if self.max_bytes < 1 or self.max_rows < 1:
            raise ValueError(f"session limits must be positive: {self}")

    @classmethod
    def from_env(cls, environ: Mapping[str, str] | None = None) -> SessionLimits:
        """Limits from ``STATION_SESSION_MAX_BYTES`` (bytes, or with a K/M/G/T suffix in powers of 1024) and
        ``STATION_SESSION_MAX_ROWS``; the defaults where unset. An unreadable value is a :class:`StationError`."""
        env = os.environ if environ is None else environ
        max_bytes, max_rows = DEFAULT_MAX_BYTES, DEFAULT_MAX_ROWS
        if (text := env.get(MAX_BYTES_ENV, "").strip()) != "":
            m = _SIZE.fullmatch(text)
            if m is None or int(m.group(1)) == 0:
                raise StationError(f"{MAX_BYTES_ENV}={text[:40]!r}: expected a positive size in bytes, e.g. 2G")
            max_bytes = int(m.group(1)) * _SUFFIX[m.group(2).lower()]
        if (text := env.get(MAX_ROWS_ENV, "").strip()) != "":
            if not re.fullmatch(r"\d[\d_]*", text) or int(text) == 0:
                raise StationError(f"{MAX_ROWS_ENV}={text[:40]!r}: expected a positive number of rows")
            max_rows = int(text)
        return cls(max_bytes=max_bytes, max_rows=max_rows)


def size_text(n: int) -> str:
    """A byte count for people: ``2.0 GiB``, ``684.4 MiB``, ``512 bytes``."""
    for unit, factor in (("TiB", 2**40), ("GiB", 2**30), ("MiB", 2**20), ("KiB", 2**10)):
        if n >= factor:
            return f"{n / factor:.1f} {unit}"
    return f"{n} bytes"
