"""One measurement type for every check the station makes (as OpenHTF's measurements).

A :class:`Measurement` is a measured value with its unit, the limits it was judged against,
its standard uncertainty where one is known, and the verdict. Capture gates, product-limit
checks, fit-quality checks and the on-rig verification of the corrected output are all
measurements; the sequence's records carry them unchanged to the store, the web page and the
terminal. A failed measurement is a result (a FAIL, or for a ``link`` gate a station ERROR),
never an exception.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import Enum


class Verdict(Enum):
    """A measurement's verdict.

    MARGINAL is a PASS close to a limit (the limits file's band). INCONCLUSIVE is a value inside
    the specification whose uncertainty interval ``value +- k u`` reaches outside it (ISO 14253-1):
    neither conformance nor non-conformance is proven; the limits file maps it to FAIL or a retest.
    """

    PASS = "PASS"
    MARGINAL = "MARGINAL"
    INCONCLUSIVE = "INCONCLUSIVE"
    FAIL = "FAIL"


@dataclass(frozen=True)
class Measurement:
    """One measured value against its limits.

    Attributes:
        name: what was measured, e.g. ``'gravity_ratio'``, ``'accel.bias_static.x'``.
        value: the measured value (``unit``).
        unit: SI unit, or ``'1'`` for a ratio.
        low, high: the limits (``unit``); ``-inf`` / ``inf`` where one side is open.
        passed: the verdict of the rule that judged it (see the constructors and
            :func:`station.sequence.limits.check_limits`).
        std: standard uncertainty of ``value`` (``unit``), NaN if none.
        link: a link gate: its failure is a station fault (ERROR), not the unit's (FAIL).
        marginal: a pass close enough to a limit to be flagged.
        inconclusive: not passed, but not proven outside the limits either (see :class:`Verdict`).
        k: the coverage factor of the uncertainty interval the verdict used (0: none).
    """

    name: str
    value: float
    unit: str
    low: float = -math.inf
    high: float = math.inf
    passed: bool = True
    std: float = math.nan
    link: bool = False
    marginal: bool = False
    inconclusive: bool = False
    k: float = 0.0

    @classmethod
    def in_range(
        cls, name: str, value: float, low: float, high: float, unit: str, *, std: float = math.nan, link: bool = False
    ) -> Measurement:
        """Passed when ``value`` is finite and ``low <= value <= high``."""
        v = float(value)
        ok = bool(math.isfinite(v) and low <= v <= high)
        return cls(name, v, unit, float(low), float(high), ok, float(std), link)

    @classmethod
    def at_most_abs(cls, name: str, value: float, limit: float, unit: str) -> Measurement:
        """Passed when ``|value| <= limit`` (limits ``-limit`` and ``limit``)."""
        return cls.in_range(name, value, -float(limit), float(limit), unit)

    @property
    def verdict(self) -> Verdict:
        if not self.passed:
            return Verdict.INCONCLUSIVE if self.inconclusive else Verdict.FAIL
        return Verdict.MARGINAL if self.marginal else Verdict.PASS

    @property
    def expanded_uncertainty(self) -> float:
        """``k u`` (``unit``): the half-width of the interval the verdict used (0 without one)."""
        return self.k * self.std if self.k > 0 and math.isfinite(self.std) else 0.0

    def describe(self) -> str:
        """One line for people, in the display convention (:mod:`station.kernel.display`): the quantity, its
        value ± k u in its engineering unit and the limits it missed or met, e.g. "accel.M.xx (scale-factor
        error) = 10820 ± 100 ppm outside [-2000, 5000] ppm"."""
        from station.kernel.display import display_of_check, format_number

        d = display_of_check(self.name, self.unit)
        ku = self.expanded_uncertainty
        value = d.format(self.value, ku if ku > 0 else None)
        where = {Verdict.FAIL: "outside", Verdict.INCONCLUSIVE: "straddles"}.get(self.verdict, "within")
        lo = d.value(self.low) if math.isfinite(self.low) else None
        hi = d.value(self.high) if math.isfinite(self.high) else None
        low = format_number(lo) if lo is not None else "-inf"
        bounds = f"[{low}, {format_number(hi) if hi is not None else 'inf'}]"
        what = f" ({d.label})" if d.quantity in ("scale_error", "cross_axis") else ""
        return f"{self.name}{what} = {value} {where} {bounds}{' ' + d.unit if d.unit else ''}"


__all__ = ["Measurement", "Verdict"]
