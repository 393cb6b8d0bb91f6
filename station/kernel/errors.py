"""The one error root of the station and its direct families.

A limit failure is a *result* (a FAIL verdict), never an exception. Exceptions are
for inputs we cannot use and for station faults.
"""

from __future__ import annotations

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
