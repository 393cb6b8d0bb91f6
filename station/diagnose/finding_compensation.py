"""Which of a diagnosis's findings the station's calibration compensates.

For each finding the report says whether the calibration the station would write for this recording removes
the effect from the corrected output: the effect has parameters in the parameter set that Algorithm 1 applies
(:data:`station.fit.compensation.APPLIED`), and the fit, run with those terms enabled on this recording,
actually fits them (:func:`station.fit.compensation.compensated_by`). Otherwise it says why not: no
parameter for the effect, or the recording does not let the fit identify it (the fit's own note). Each entry
also carries the corrected output's error on held-out segments with and without the compensation
(:mod:`station.diagnose.compensation_gain`).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import replace

import numpy as np

from station.diagnose.compensation_gain import gains
from station.diagnose.effect_registry import REGISTRY
from station.diagnose.results import Compensation
from station.fit.calibrate import FitOptions, fit_session
from station.fit.compensation import APPLIED, COMPENSATION, compensated_by, field_value
from station.kernel.errors import StationError
from station.kernel.parameters import ParameterSet
from station.session.model import Session

#: Why an effect without applied parameters stays in the output when the registry does not say.
NO_PARAMETER = "no parameter for it in the set"


def _physics(name: str) -> str:
    """The physics effect whose parameters compensate diagnosis effect ``name`` (the registry's
    ``compensation``; the name itself for one the registry maps to none or does not know)."""
    effect = REGISTRY.get(name)
    return name if effect is None or effect.compensation is None else effect.compensation


def _not_compensated(name: str) -> str:
    effect = REGISTRY.get(name)
    return effect.not_compensated if effect is not None and effect.not_compensated else NO_PARAMETER


def _fields(effect: str, sensor: str) -> tuple[str, ...]:
    """The effect's parameter-set fields for this sensor (all of them when none is the sensor's)."""
    own = tuple(f for f in COMPENSATION[effect] if f.startswith(f"{sensor}."))
    return own or COMPENSATION[effect]


def _why_not_fitted(params: ParameterSet, effect: str, sensor: str) -> str:
    if effect.startswith("temperature_"):
        return f"the fit has the terms but did not fit them here: {params.thermal.status}: {params.thermal.reason}"
    if effect == "scale_nonlinearity":
        note = params.quality.accel_scale_polynomial if sensor == "accel" else params.quality.scale_nonlinearity
        return (f"the fit has the term but did not fit it here: {note.status if note else None}: "
                f"{note.reason if note else None}")
    if effect == "time_offset":
        offset = params.quality.time_offset
        return (f"the fit has the term but did not keep it here: {offset.status if offset else None}: "
                f"{offset.reason if offset else None}")
    return "the fit has the term but it is not significant in this recording"


def compensation(
    session: Session, findings: list[tuple[str, str]], *,
    warmup_tc_s: Mapping[str, tuple[float, float]] | None = None, censored: bool = False,
) -> list[Compensation]:
    """One :class:`Compensation` per ``(effect, sensor)`` in ``findings`` (the diagnosis's findings, in order).
    ``censored``: ``session`` has its saturated segments censored (:mod:`station.diagnose.censoring`)."""
    effects = [e for e, _ in findings]
    physics = [_physics(e) for e in effects]
    params: ParameterSet | None = None
    error = ""
    options = FitOptions(tc_range_s=dict(warmup_tc_s or {}), thermal="auto", scale_nonlinearity="auto",
                         time_offset="auto" if "time_offset" in physics else "off",
                         g_sensitivity="g_sensitivity" in physics, censored_saturation=censored)
    if any(p in APPLIED for p in physics):
        try:
            params = fit_session(session, options)
        except StationError as exc:
            error = f"the fit with the terms refused the recording: {exc}"
    out = []
    for (name, sensor), eff in zip(findings, physics, strict=True):
        if eff not in APPLIED:
            out.append(Compensation(name, False, _not_compensated(name)))
        elif params is None:
            out.append(Compensation(name, False, error))
        elif compensated_by(params, eff) and any(
                np.any(np.asarray(field_value(params, f)) != 0) for f in _fields(eff, sensor)):
            fields = ", ".join(f for f in _fields(eff, sensor) if np.any(np.asarray(field_value(params, f)) != 0))
            out.append(Compensation(name, True, f"the calibration fits and applies it ({fields})"))
        else:
            out.append(Compensation(name, False, _why_not_fitted(params, eff, sensor)))
    if findings:  # each finding's corrected error on held-out segments, with and without its compensation
        out = [replace(c, gain=g) for c, g in zip(out, gains(session, findings, physics, options), strict=True)]
    return out


__all__ = ["NO_PARAMETER", "Compensation", "compensation"]
