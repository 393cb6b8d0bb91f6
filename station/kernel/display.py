"""The one display convention: which engineering unit people see for each quantity, and how it is written.

The station computes and stores in SI (m/s^2, rad/s, s, dimensionless); the JSON API stays in SI with the
unit in every field's name or schema. Everything a person reads — the terminal, the pages, the CSV
downloads and the calibration certificate — goes through this module, so a quantity has one unit
everywhere (see ``docs/display-units.md`` for the table per output):

==========================================  ==============  =========================================
quantity                                    shown in        from SI
==========================================  ==============  =========================================
accelerometer bias, noise, residual, error  mg              m/s^2 / 9.80665e-3 (1 mg = 9.80665e-3 m/s^2)
gyroscope rate, bias, noise, residual       deg/s           rad/s * 180/pi
scale-factor error (diagonal of M, -1)      ppm             (M_ii - 1) * 1e6
cross-axis term (off-diagonal of M)         ppm             M_ij * 1e6
uncertainty of an element of M              ppm             * 1e6
drift correlation time T_c                  s               1
time offset of the unit's samples           ms              * 1e3
temperature coefficient of a bias           mg/K, deg/s/K   as the bias, per K
temperature coefficient of a scale factor   ppm/K           * 1e6
fractions (samples received, dropped)       %               * 100
gravity ratio (|f| / g)                     %               * 100
gyro g-sensitivity                          (deg/s)/g       rad/s per m/s^2 * 180/pi * 9.80665
gyro scale nonlinearity k of u + k u|u|     ppm/(deg/s)     1/(rad/s) * pi/180 * 1e6
gyro IEEE 952 polynomial k2 (u^2)           ppm/(deg/s)     1/(rad/s) * pi/180 * 1e6
gyro IEEE 952 polynomial k3 (u^3)           ppm/(deg/s)^2   1/(rad/s)^2 * (pi/180)^2 * 1e6
temperature                                 degC            1
==========================================  ==============  =========================================

A value with an uncertainty is written ``value ± U unit`` with one "±" (U+00B1), U to two significant
digits and the value to the same decimal place (GUM 7.2.6); a value without one to four significant
digits in fixed notation. A value that is not finite is "—" (not determined), never a number. Times shown
to people are local time with the zone (:func:`local_time`).

Plain functions of floats and strings; nothing here imports numpy or the station's types.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from datetime import UTC, datetime

__all__ = [
    "G0_MPS2",
    "NOT_DETERMINED",
    "PM",
    "Display",
    "display_for",
    "display_of_check",
    "format_number",
    "format_value",
    "limits_identity",
    "local_time",
]

#: Standard gravity (m/s^2) that defines the milli-g.
G0_MPS2 = 9.80665
#: The one plus-minus sign every output uses.
PM = "±"
#: What a value the data did not determine shows as.
NOT_DETERMINED = "—"

_DEG_PER_RAD = 180.0 / math.pi


@dataclass(frozen=True)
class Display:
    """How one quantity is shown: ``shown = (si + offset) * scale`` in ``unit``.

    ``offset`` applies to values only (a scale factor M_ii is shown as its error M_ii - 1);
    uncertainties and spreads are scaled without it (:meth:`spread`). ``label`` names the quantity for
    people (e.g. "scale-factor error"), ``si_unit`` the stored unit.
    """

    quantity: str
    unit: str
    scale: float
    si_unit: str
    offset: float = 0.0
    label: str = ""

    def value(self, si: float | None) -> float | None:
        """The SI value in the display unit (None stays None)."""
        return None if si is None else self.convert(si)

    def convert(self, si: float) -> float:
        """The SI value in the display unit."""
        return (float(si) + self.offset) * self.scale

    def spread(self, si: float | None) -> float | None:
        """An uncertainty, a standard deviation or a difference in the display unit (no offset)."""
        return None if si is None else float(si) * self.scale

    def format(self, si: float | None, u_si: float | None = None, *, k: float = 1.0, unit: bool = True) -> str:
        """``value ± k*u unit`` (see the module docstring); ``unit=False`` leaves the unit off."""
        return format_value(self.value(si), self.spread(u_si * k) if u_si is not None else None,
                            self.unit if unit else "")


#: quantity -> how it is shown. The keys are the quantity names :func:`display_of_check` returns.
DISPLAYS: dict[str, Display] = {d.quantity: d for d in (
    Display("acceleration", "mg", 1.0 / (G0_MPS2 * 1e-3), "m/s^2", label="acceleration"),
    Display("angular_rate", "deg/s", _DEG_PER_RAD, "rad/s", label="angular rate"),
    Display("scale_error", "ppm", 1e6, "1", offset=-1.0, label="scale-factor error"),
    Display("cross_axis", "ppm", 1e6, "1", label="cross-axis term"),
    Display("matrix_uncertainty", "ppm", 1e6, "1", label="uncertainty of an element of M"),
    Display("time_constant", "s", 1.0, "s", label="time"),
    Display("time_offset", "ms", 1e3, "s", label="time offset"),
    Display("accel_tempco", "mg/K", 1.0 / (G0_MPS2 * 1e-3), "m/s^2/K", label="bias temperature coefficient"),
    Display("gyro_tempco", "deg/s/K", _DEG_PER_RAD, "rad/s/K", label="bias temperature coefficient"),
    Display("scale_tempco", "ppm/K", 1e6, "1/K", label="scale temperature coefficient"),
    Display("fraction", "%", 100.0, "1", label="fraction"),
    Display("g_sensitivity", "(deg/s)/g", _DEG_PER_RAD * G0_MPS2, "rad/s/(m/s^2)", label="g-sensitivity"),
    Display("nonlinearity", "ppm/(deg/s)", 1e6 / _DEG_PER_RAD, "1/(rad/s)", label="scale nonlinearity"),
    Display("nonlinearity_cubic", "ppm/(deg/s)^2", 1e6 / _DEG_PER_RAD**2, "1/(rad/s)^2",
            label="cubic scale nonlinearity"),
    Display("accel_nonlinearity", "ppm/g", 1e6 * G0_MPS2, "1/(m/s^2)", label="accelerometer scale nonlinearity"),
    Display("accel_nonlinearity_cubic", "ppm/g^2", 1e6 * G0_MPS2**2, "1/(m/s^2)^2",
            label="accelerometer cubic scale nonlinearity"),
    Display("temperature", "degC", 1.0, "degC", label="temperature"),
    Display("count", "", 1.0, "1", label="count"),
    Display("ratio", "", 1.0, "1", label="ratio"),
)}

#: SI unit -> the quantity of a value in it, where the unit alone decides.
_BY_SI_UNIT = {"m/s^2": "acceleration", "rad/s": "angular_rate", "s": "time_constant", "m/s^2/K": "accel_tempco",
               "rad/s/K": "gyro_tempco", "1/K": "scale_tempco", "degC": "temperature", "1/(rad/s)": "nonlinearity",
               "1/(rad/s)^2": "nonlinearity_cubic", "1/(m/s^2)": "accel_nonlinearity",
               "1/(m/s^2)^2": "accel_nonlinearity_cubic"}


def display_for(quantity: str) -> Display:
    """The display of ``quantity`` (a key of :data:`DISPLAYS`); KeyError for an unknown one."""
    return DISPLAYS[quantity]


def display_of_check(name: str, si_unit: str) -> Display:
    """The display of a recorded check or parameter by its stored name and SI unit.

    ``accel.M.xx`` (a scale factor) -> scale error in ppm; ``gyro.M.zx`` -> cross-axis ppm;
    ``fit.accel.M_std.xy`` -> ppm; ``*time_offset*`` in s -> ms; ``*fraction``, ``gravity_ratio`` -> %;
    ``*failed_tests`` -> a count; otherwise by the SI unit (m/s^2 -> mg, rad/s -> deg/s, ...). A name and
    unit it does not know come back as a plain ratio in their own unit.
    """
    parts = name.split(".")
    family = parts[-2] if len(parts) >= 2 else ""
    last = parts[-1]
    if si_unit == "1":
        if family == "M" and len(last) == 2:
            return DISPLAYS["scale_error" if last[0] == last[1] else "cross_axis"]
        if family == "M_std":
            return DISPLAYS["matrix_uncertainty"]
        if last.endswith("fraction") or last == "gravity_ratio":
            return DISPLAYS["fraction"]
        if last.endswith("failed_tests") or last.endswith("_count"):
            return DISPLAYS["count"]
        return DISPLAYS["ratio"]
    if si_unit == "s" and "time_offset" in name:
        return DISPLAYS["time_offset"]
    quantity = _BY_SI_UNIT.get(si_unit)
    if quantity is not None:
        return DISPLAYS[quantity]
    return Display("other", si_unit, 1.0, si_unit, label=si_unit)


def format_number(x: float | None, decimals: int | None = None, *, sign: bool = False) -> str:
    """``x`` in fixed notation: with ``decimals`` places, else four significant digits; "—" if not finite."""
    if x is None or not math.isfinite(x):
        return NOT_DETERMINED
    if x == 0 and decimals is None:
        return "+0" if sign else "0"
    if decimals is None:
        decimals = _decimals_for(x, 4)
    text = f"{x:+.{decimals}f}" if sign else f"{x:.{decimals}f}"
    return "0" if text in ("-0", "+0") and not sign else text


def _decimals_for(x: float, significant: int) -> int:
    """Decimal places that keep ``significant`` digits of ``x`` (never negative)."""
    if x == 0:
        return significant - 1 if significant > 1 else 0
    return max(0, significant - 1 - math.floor(math.log10(abs(x))))


def format_value(value: float | None, uncertainty: float | None = None, unit: str = "") -> str:
    """``value ± uncertainty unit``: the uncertainty to two significant digits, the value to its decimal
    place; without an (finite, positive) uncertainty the value to four significant digits. A value that is
    not finite is "—" (with no unit: nothing to qualify)."""
    if value is None or not math.isfinite(value):
        return NOT_DETERMINED
    suffix = f" {unit}" if unit else ""
    if uncertainty is not None and math.isfinite(uncertainty) and uncertainty > 0:
        d = _decimals_for(uncertainty, 2)
        return f"{format_number(value, d)} {PM} {format_number(uncertainty, d)}{suffix}"
    return f"{format_number(value)}{suffix}"


def local_time(when: datetime | str | None, *, seconds: bool = True) -> str:
    """A time for people: the station's local time with its zone, e.g. "2026-11-27 07:06:15 CET (UTC+01:00)".

    Accepts a datetime (naive = UTC, as SQLite hands it back) or an ISO 8601 string; None or "" -> "—".
    """
    if when is None or when == "":
        return NOT_DETERMINED
    if isinstance(when, str):
        try:
            parsed = datetime.fromisoformat(when)
        except ValueError:
            return when
        when = parsed
    if when.tzinfo is None:
        when = when.replace(tzinfo=UTC)
    local = when.astimezone()
    offset = local.strftime("%z")
    offset = f"UTC{offset[:3]}:{offset[3:]}" if offset else "UTC"
    zone = local.tzname() or ""
    text = local.strftime("%Y-%m-%d %H:%M:%S" if seconds else "%Y-%m-%d %H:%M")
    if zone and zone != "UTC" and not zone.startswith(("+", "-")):
        return f"{text} {zone} ({offset})"
    return f"{text} {offset}"


def limits_identity(version: str, sha256: str, *, short: bool = True) -> str:
    """The limits file as people see it everywhere: name, version and content hash.

    ``version`` is the recorded "name version" (e.g. "table1-default 2.0.0"); ``sha256`` the hex SHA-256 of
    the file's bytes (an edited file with the same name and version differs here). ``short``: the hash's
    first 12 hex digits.
    """
    if not version and not sha256:
        return NOT_DETERMINED
    digest = (sha256[:12] if short else sha256) if sha256 else "unknown"
    return f"{version or '(unnamed)'}, sha256 {digest}"
