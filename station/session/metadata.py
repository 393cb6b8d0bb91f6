"""Values of the optional numeric metadata keys a recording may carry, checked against physics.

The spec keeps unknown keys as text; the keys below are read as numbers by the fit and the
diagnosis, so a reader refuses a value that is not a finite number in its physical range
(``latitude_deg: abc`` or ``500`` is an error of the file, not a site).
"""

from __future__ import annotations

import math
import re

#: key -> (lowest, highest, unit): the physically meaningful range of an optional numeric key
NUMERIC_RANGES: dict[str, tuple[float, float, str]] = {
    "latitude_deg": (-90.0, 90.0, "deg"),
    "heading_deg": (-360.0, 360.0, "deg"),
    "angle_std_deg": (0.0, 90.0, "deg"),
    "reference_tolerance_mps2": (0.0, 1.0, "m/s^2"),
}

_NUMBER = re.compile(r"[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?", re.ASCII)


def number_problem(text: str) -> str | None:
    """Why ``text`` is not a finite decimal number, or None."""
    if not _NUMBER.fullmatch(text):
        return f"{text!r} is not a number"
    if not math.isfinite(float(text)):
        return f"{text!r} is not finite"
    return None


def metadata_problem(key: str, value: str) -> str | None:
    """Why the value of a known numeric key is unusable (not a number, or outside its range), or None."""
    bounds = NUMERIC_RANGES.get(key)
    if bounds is None or value == "":
        return None
    problem = number_problem(value.strip())
    if problem:
        return problem
    lo, hi, unit = bounds
    number = float(value)
    if not lo <= number <= hi:
        return f"{value!r} is outside {lo:g}..{hi:g} {unit}"
    return None
