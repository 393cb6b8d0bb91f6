"""What each finding's compensation does to the corrected output, on segments the calibration did not see.

For every finding of a diagnosis: the calibration the station would write (the fit with its compensable terms
on) is fitted with some segments held out: every third ``rate`` segment and every second ``move`` segment have
their references removed (so neither the fit of eq. 1 nor the time offset's estimate sees them). Algorithm 1
(:func:`station.correct.correct_session`, one-sided) then corrects the whole recording twice: with that
calibration, and with the same calibration less the finding's fields (:data:`station.fit.compensation.COMPENSATION`
set to zero). The error of each is the RMS, over the held-out samples of the finding's sensor, of the corrected
output minus the rig's reference passed through the same one-sided moving average (eq. 6): what a user of the
unit would see on motion the calibration was not fitted to. A finding without parameters in the set has the
same error both ways (it says so).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from scipy.ndimage import uniform_filter1d

from station.correct.session_correct import correct_session
from station.fit.calibrate import FitOptions, fit_session
from station.fit.compensation import APPLIED, COMPENSATION
from station.kernel.errors import StationError
from station.kernel.parameters import ParameterSet
from station.session.model import Kind, Session

#: How the segments are held out (stated in each result).
HELD_OUT_RULE = "every third rate segment and every second move segment, references removed from the fit"
#: Display factor and unit per sensor.
UNITS = {"gyro": (math.degrees(1.0), "deg/s"), "accel": (1.0, "m/s^2")}


@dataclass(frozen=True)
class CompensationGain:
    """One finding's corrected-output error on the held-out segments, with and without its compensation.

    Attributes:
        error_with, error_without: RMS error of the finding's sensor over the held-out samples (``unit``);
            NaN when not computed (``note`` says why).
        unit: ``'deg/s'`` or ``'m/s^2'``.
        held_out: held-out segments (rate, move).
        applied: the calibration holds and applies parameters for the finding (else the two errors are equal).
        note: one line for people.
    """

    error_with: float
    error_without: float
    unit: str
    held_out: tuple[int, int]
    applied: bool
    note: str = ""

    def to_json(self) -> dict[str, Any]:
        def num(x: float) -> float | None:
            return float(x) if math.isfinite(x) else None

        return {"error_with": num(self.error_with), "error_without": num(self.error_without), "unit": self.unit,
                "held_out": {"rate": self.held_out[0], "move": self.held_out[1]}, "applied": self.applied,
                "rule": HELD_OUT_RULE, "note": self.note}

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> CompensationGain:
        def num(x: Any) -> float:
            return math.nan if x is None else float(x)

        held = d["held_out"]
        return cls(num(d["error_with"]), num(d["error_without"]), str(d["unit"]),
                   (int(held["rate"]), int(held["move"])), bool(d["applied"]), str(d.get("note", "")))

    def describe(self) -> str:
        if not (math.isfinite(self.error_with) and math.isfinite(self.error_without)):
            return f"held-out error not computed: {self.note}"
        tail = "" if self.applied else " (no parameter applies it)"
        return (f"held-out corrected error {self.error_with:.4g} {self.unit} with the compensation, "
                f"{self.error_without:.4g} without{tail} ({self.held_out[0]} rate, {self.held_out[1]} move segments)")


def held_out_session(session: Session) -> tuple[Session, np.ndarray, tuple[int, int]]:
    """The session with the held-out segments' references removed, the held-out sample mask, and the count of
    held-out (rate, move) segments."""
    mask = np.zeros(len(session), dtype=bool)
    counts = []
    for kind, every in ((Kind.RATE, 3), (Kind.MOVE, 2)):
        segs = session.segments_of(kind)[1::every]
        for seg in segs:
            mask[seg.start:seg.stop] = True
        counts.append(len(segs))
    refs = []
    for ref in (session.ref_accel_mps2, session.ref_gyro_radps):
        held = ref.copy()
        held[mask] = np.nan
        held.flags.writeable = False  # a read-only array of its own: the Session takes it without a copy
        refs.append(held)
    return session.replace(ref_accel_mps2=refs[0], ref_gyro_radps=refs[1]), mask, (counts[0], counts[1])


def without(params: ParameterSet, effect: str) -> ParameterSet:
    """``params`` less the fields that compensate ``effect`` (set to zero)."""
    out = params
    for path in COMPENSATION.get(effect, ()):
        if "." in path:
            triad_name, name = path.split(".")
            triad = getattr(out, triad_name)
            out = replace(out, **{triad_name: replace(triad, **{name: np.zeros_like(getattr(triad, name))})})
        elif path == "time_offset_s":
            out = replace(out, time_offset_s=0.0, time_offset_std_s=0.0)
    return out


def held_out_error(session: Session, params: ParameterSet, mask: np.ndarray, sensor: str) -> float:
    """RMS over the samples in ``mask`` of the corrected ``sensor`` output minus its reference through eq. 6's
    one-sided moving average (SI units)."""
    out = correct_session(session, params)
    ref = session.ref_gyro_radps if sensor == "gyro" else session.ref_accel_mps2
    n = params.moving_average_length
    rows = mask & np.all(np.isfinite(ref), axis=1)
    err = (out.gyro_radps if sensor == "gyro" else out.accel_mps2)[rows]  # only the held-out rows
    del out
    for k in range(3):
        # eq. 6's one-sided average of the reference: the window of n samples ending at each sample; one axis at a
        # time (the filter runs along each axis on its own: the same numbers as the (n, 3) call, a third of its
        # memory)
        ma = uniform_filter1d(np.nan_to_num(ref[:, k]), size=n, origin=(n - 1) // 2, mode="nearest")
        err[:, k] -= ma[rows]
    return float(np.sqrt(np.mean(np.sum(err**2, axis=1)))) if len(err) else math.nan


def _held_out_fit(session: Session, options: FitOptions
                  ) -> tuple[np.ndarray, tuple[int, int], ParameterSet | StationError | None]:
    """The held-out mask and counts, and the calibration fitted without the held-out references (the fit's
    refusal; None when nothing is held out). The held-out session's references are dropped on return, before
    the corrections run."""
    held, mask, counts = held_out_session(session)
    if not mask.any():
        return mask, counts, None
    try:
        return mask, counts, fit_session(held, options)
    except StationError as exc:
        return mask, counts, exc


def gains(
    session: Session, findings: list[tuple[str, str]], physics: list[str], options: FitOptions
) -> list[CompensationGain]:
    """One :class:`CompensationGain` per ``(effect, sensor)`` finding; ``physics`` names each finding's physics
    effect (the registry's compensation mapping), ``options`` the calibration's fit options."""
    mask, counts, fitted = _held_out_fit(session, options)
    if fitted is None:  # nothing held out
        return [CompensationGain(math.nan, math.nan, UNITS[s][1], counts, e in APPLIED,
                                 "no rate or move segments to hold out") for (_, s), e in zip(findings, physics,
                                                                                               strict=True)]
    if isinstance(fitted, StationError):
        return [CompensationGain(math.nan, math.nan, UNITS[s][1], counts, e in APPLIED,
                                 f"the fit without the held-out segments refused: {fitted}")
                for (_, s), e in zip(findings, physics, strict=True)]
    params = fitted
    out = []
    for (_, sensor), effect in zip(findings, physics, strict=True):
        scale, unit = UNITS.get(sensor, UNITS["gyro"])
        try:
            e_with = scale * held_out_error(session, params, mask, sensor)
            applied = effect in APPLIED
            e_without = scale * held_out_error(session, without(params, effect), mask, sensor) if applied else e_with
        except StationError as exc:
            out.append(CompensationGain(math.nan, math.nan, unit, counts, effect in APPLIED, str(exc)))
            continue
        out.append(CompensationGain(e_with, e_without, unit, counts, applied))
    return out


__all__ = ["HELD_OUT_RULE", "CompensationGain", "gains", "held_out_error", "held_out_session", "without"]
