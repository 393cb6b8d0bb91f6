"""The found terms of a parameter set with their determinability, for people and the JSON API.

The time offset tau (``ParameterSet.time_offset_s``) and the scale polynomials of the gyro (IEEE 952) and the
accelerometer (``scale_quadratic`` k2, ``scale_cubic`` k3 per axis) are fitted where the recording determines them
and kept where significant (docs/found-terms.md). What the set holds for them is a number (0 when not kept); what
the fit could say about them is in its notes (``quality.time_offset``, ``quality.scale_nonlinearity`` for the gyro,
``quality.accel_scale_polynomial``). :func:`found_terms` reads both into one
typed summary, so that a term the recording could not determine is shown as such (no number), not as a 0:

* ``fitted``: kept, in the set, applied by Algorithm 1 (value and standard uncertainty);
* ``not_significant``: estimated, not kept (its Wald statistic below the threshold): the set holds 0;
* ``not_determined``: the recording cannot determine it (with the reason and the rig step that would);
* ``beyond_range``: (time offset) estimated, more than Algorithm 1 applies: not kept;
* ``not_fitted``: the fit did not try (switched off, or a set written before these terms).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from station.kernel.display import display_of_check
from station.kernel.parameters import ParameterSet

__all__ = ["FOUND_TERM_STATUSES", "FoundTerm", "FoundTerms", "found_terms"]

FOUND_TERM_STATUSES = ("fitted", "not_significant", "not_determined", "beyond_range", "not_fitted")
_AXES = ("x", "y", "z")


@dataclass(frozen=True)
class FoundTerm:
    """One found term: ``name`` (``time_offset``, ``gyro.k2.x``, ...), ``status`` (:data:`FOUND_TERM_STATUSES`),
    ``value`` and ``std`` in SI (``value`` NaN unless fitted; a not-significant estimate is in ``estimate``),
    ``unit`` (SI), ``z`` the Wald statistic's square root where the fit gave it, ``reason`` for people."""

    name: str
    status: str
    value: float = math.nan
    std: float = math.nan
    unit: str = ""
    estimate: float = math.nan
    z: float = math.nan
    reason: str = ""

    @property
    def applied(self) -> bool:
        """The set holds it and Algorithm 1 applies it."""
        return self.status == "fitted"

    def shown(self) -> str:
        """For people, in the display convention: ``value ± u unit`` when applied, else what the fit said."""
        d = display_of_check(self.name, self.unit)
        if self.status == "fitted":
            return d.format(self.value, self.std if math.isfinite(self.std) else None)
        if self.status == "not_significant":
            est = f"{d.format(self.estimate, self.std)}, " if math.isfinite(self.estimate) else ""
            return f"not kept ({est}|z| {abs(self.z):.2f})" if math.isfinite(self.z) else "not kept"
        return self.status.replace("_", " ")

    def to_dict(self) -> dict[str, Any]:
        def num(v: float) -> float | None:
            return v if math.isfinite(v) else None

        return {"name": self.name, "status": self.status, "value": num(self.value), "std": num(self.std),
                "unit": self.unit, "estimate": num(self.estimate), "z": num(self.z), "reason": self.reason}


@dataclass(frozen=True)
class FoundTerms:
    """The time offset and the twelve polynomial terms (gyro, then accelerometer: k2, k3 per axis) of one set."""

    time_offset: FoundTerm
    polynomial: tuple[FoundTerm, ...]

    @property
    def terms(self) -> tuple[FoundTerm, ...]:
        return (self.time_offset, *self.polynomial)

    def to_dict(self) -> dict[str, Any]:
        return {"time_offset": self.time_offset.to_dict(), "polynomial": [t.to_dict() for t in self.polynomial]}


def _not_fitted(params: ParameterSet, triad: str = "gyro") -> str:
    """Why the fit did not try: the term was switched off, or the set predates it (the line's joint fit estimated
    neither term before it took them, and does not estimate the accelerometer's polynomial)."""
    if "line" in params.source and triad == "accel":
        return "the line's joint fit does not estimate the accelerometer's scale polynomial"
    if "line" in params.source:
        return ("the line's joint fit did not estimate it (switched off, or a set written before the joint fit "
                "estimated these terms)")
    return "the fit did not estimate it (switched off, or a set written before these terms)"


def _time_offset(params: ParameterSet) -> FoundTerm:
    note = params.quality.time_offset
    if note is None:
        if params.time_offset_s:  # a set given its offset by hand (no fit note)
            return FoundTerm("time_offset", "fitted", float(params.time_offset_s),
                             float(params.time_offset_std_s) or math.nan, "s", reason="stored without a fit note")
        return FoundTerm("time_offset", "not_fitted", unit="s", reason=_not_fitted(params))
    if note.status == "fitted":
        return FoundTerm("time_offset", "fitted", float(params.time_offset_s), float(params.time_offset_std_s), "s",
                         estimate=note.estimate_s, z=note.estimate_s / note.std_s if note.std_s > 0 else math.nan,
                         reason=note.reason)
    z = note.estimate_s / note.std_s if math.isfinite(note.estimate_s) and note.std_s > 0 else math.nan
    return FoundTerm("time_offset", note.status, std=note.std_s, unit="s", estimate=note.estimate_s, z=z,
                     reason=note.reason)


#: The SI unit of the polynomial's k2 and k3 per triad.
_POLY_UNITS = {"gyro": ("1/(rad/s)", "1/(rad/s)^2"), "accel": ("1/(m/s^2)", "1/(m/s^2)^2")}


def _polynomial(params: ParameterSet, triad: str) -> tuple[FoundTerm, ...]:
    note = params.quality.scale_nonlinearity if triad == "gyro" else params.quality.accel_scale_polynomial
    detail = dict(note.detail) if note is not None else {}
    g = params.gyro if triad == "gyro" else params.accel
    out: list[FoundTerm] = []
    for term, field, unit in zip(("k2", "k3"), ("scale_quadratic", "scale_cubic"), _POLY_UNITS[triad], strict=True):
        values, stds = getattr(g, field), getattr(g, f"{field}_std")
        identifiable = (detail.get("identifiable") or {}).get(term)
        zs = (detail.get("z") or {}).get(term) or [math.nan] * 3
        missing = detail.get("not_identifiable") or []
        for k, a in enumerate(_AXES):
            name = f"{triad}.{term}.{a}"
            value, std = float(values[k]), float(stds[k])
            z = float(zs[k]) if isinstance(zs[k], int | float) else math.nan
            if value != 0.0:
                out.append(FoundTerm(name, "fitted", value, std, unit, value, z))
            elif note is None or identifiable is None:
                # no note, or the note of the older u|u| term: the polynomial was not fitted
                why = note.reason if note is not None and note.status == "not_identifiable" else ""
                status = "not_determined" if why else "not_fitted"
                out.append(FoundTerm(name, status, unit=unit, reason=why or _not_fitted(params, triad)))
            elif a not in identifiable:
                why = next((m for m in missing if isinstance(m, str) and m.startswith(f"{a}:")), note.reason)
                out.append(FoundTerm(name, "not_determined", unit=unit, reason=why))
            else:
                why = f"|z| = {abs(z):.2f}, below the Wald threshold: not kept (the set holds 0)"
                out.append(FoundTerm(name, "not_significant", unit=unit, z=z, reason=why))
    return tuple(out)


def found_terms(params: ParameterSet) -> FoundTerms:
    """The set's time offset and the polynomial terms of both triads, each with what the fit could say about it."""
    return FoundTerms(_time_offset(params), (*_polynomial(params, "gyro"), *_polynomial(params, "accel")))
