"""The one error root of the station and its direct families.

A limit failure is a *result* (a FAIL verdict), never an exception. Exceptions are
for inputs we cannot use and for station faults.
"""

from __future__ import annotations

import errno
import os
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from station.kernel.measurement import Measurement


class StationError(Exception):
    """Root of every error the station raises on purpose."""


class FormatError(StationError):
    """A saved artifact (session file, parameter JSON, EEPROM image) is malformed."""


class UnsupportedVersionError(FormatError):
    """An artifact carries a format version this software does not read."""


class SessionFormatError(FormatError):
    """A session CSV violates the v1 spec; ``line`` is the 1-based line number."""

    def __init__(self, message: str, line: int | None = None, path: str | None = None) -> None:
        # a message that quotes its input whole (a line of megabytes) is cut: readers quote with quote_input
        message = shorten(message, MESSAGE_LIMIT)
        where = ""
        if path is not None:
            where = f"{path}:"
        if line is not None:
            where = f"{where}line {line}: " if where else f"line {line}: "
        elif where:
            where = f"{where} "
        super().__init__(f"{where}{message}")
        self.line = line
        self.path = path
        self.reason = message


class FitError(StationError):
    """A recording cannot be fitted; the message says which part and why, in one line."""


class TimeBaseError(FitError):
    """The recording's time column contradicts itself (a gap inside a segment, a stated rate it does not have).

    In a file someone hands to ``station fit`` it is a bad input; in a recording the station captured itself it
    is a capture fault of the station (the link or the station did not keep up): the unit ends ERROR, not FAIL.
    """


class RackOrientationError(FitError):
    """A line unit's rest in the soak rack was not in the orientation the line's plan holds its units in (it was
    put in its slot another way): a handling fault of the line, not a property of the unit, so it ends ERROR."""


class HardwareError(StationError):
    """A station fault (rig, serial link, EEPROM): the run's outcome is ERROR, not FAIL."""


class UnitRejected(StationError):
    """A unit failed a check after its calibration (e.g. verification of corrected output).

    The outcome is FAIL, not ERROR: the station worked, the unit did not. ``checks`` holds the
    :class:`~station.kernel.measurement.Measurement` values that were measured.
    """

    def __init__(self, message: str, checks: tuple[Measurement, ...] = ()) -> None:
        super().__init__(message)
        self.checks = checks


class StationBusy(StationError):
    """The station is already running a calibration; one run at a time."""


#: How much of a piece of input an error message quotes (characters).
QUOTE_LIMIT = 60
#: The longest reason a :class:`SessionFormatError` keeps (characters); longer ones are cut with their length.
MESSAGE_LIMIT = 300


def shorten(text: str, limit: int = QUOTE_LIMIT) -> str:
    """``text`` for a one-line message: at most ``limit`` characters, control characters escaped, and when cut
    the head, '...' and how many characters there were."""
    shown = text.encode("unicode_escape").decode("ascii") if not text.isprintable() else text
    if len(shown) <= limit:
        return shown
    keep = max(limit - 3, 1)
    return f"{shown[:keep]}... ({len(text)} characters)"


def quote_input(text: str | bytes, position: int | None = None, limit: int = QUOTE_LIMIT) -> str:
    """A piece of input quoted for an error message: cut to about ``limit`` characters around ``position``
    (0-based offset into ``text``; None: its start), with where it is and how long it is when cut.

    ``quote_input('x' * 10_000_000)`` is ``'xxxx...' (10000000 characters)``, never the whole input: the
    session reader and every argument check use it, so an error line stays readable whatever was given.
    """
    if isinstance(text, bytes):
        text = text.decode("utf-8", "backslashreplace")
    n = len(text)
    if n <= limit:
        return repr(text) if position is None else f"{text!r} at character {position + 1}"
    near = position is not None and position >= limit // 2
    start = min(max(position - limit // 2, 0), max(n - limit, 0)) if near and position is not None else 0
    piece = text[start:start + limit]
    head = "..." if start > 0 else ""
    tail = "..." if start + limit < n else ""
    where = f" at character {position + 1}" if position is not None else ""
    return f"{head}{piece!r}{tail}{where} ({n} characters)"


def path_problem(exc: BaseException, path: str) -> str:
    """What is wrong with a file path an OS call refused, in words: a name too long (with the system's limits),
    a file where a directory should be, a full disk, a read-only file system, ... (never the whole path)."""
    code = getattr(exc, "errno", None)
    if code == errno.ENAMETOOLONG or (isinstance(exc, OSError) and "too long" in str(exc)):
        longest = max((len(p) for p in path.split("/")), default=0)
        return (f"file name too long ({len(path)} characters, longest component {longest}; the system allows "
                f"{os.pathconf('/', 'PC_NAME_MAX')} per component and {os.pathconf('/', 'PC_PATH_MAX')} in all)")
    if code == errno.ENOTDIR:
        return "a part of the path is a file, not a directory"
    if code in (errno.ENOSPC, errno.EDQUOT):
        return "the disk is full (no space left on the device)"
    if code == errno.EROFS:
        return "the file system is read-only"
    if code in (errno.EACCES, errno.EPERM):
        return "permission denied"
    if code == errno.ENOENT:
        return "no such file or directory (nothing can be created there)"
    if isinstance(exc, ValueError):
        return f"not a usable file name ({exc})"
    return getattr(exc, "strerror", None) or str(exc)
