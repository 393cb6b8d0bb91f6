"""Saturated (clipped) axes in the diagnosis: censored from its data, located, never a finding.

``station fit`` refuses a recording with a saturated axis (:func:`station.fit.checks.check_session`): a clipped
unit must not get coefficients from clipped samples. The diagnosis's job is to say where the recording and the
model differ, so it censors instead, with the same detection (:func:`station.fit.checks.saturations`, not a copy):

1. **The rails.** Per saturated axis and side (maximum / minimum) the level it sits at (the value the check found).
   Every sample of the whole recording at or beyond one is *at the rail*, in any segment kind (also the ramps and
   tumbles), and so are its neighbours within :data:`NEIGHBOURS_S` either side (a sensor whose front end
   saturates before its digital filter gives a few distorted samples around the rail ones).
2. **Censored segments.** The fit and the diagnosis take a settled segment as one block of data (its mean), and a
   move as blocks of 0.5 s; a segment holding a sample at the rail (or a neighbour) is taken out of its triad's data
   by taking the triad's reference away there (NaN: the fit's ``settled_runs`` and the diagnosis's blocks then pass
   it over). The other triad keeps it. The three axes of the triad lose it, as a diagnosis outlier takes the
   sample of the triad: the triad's rows are fitted on one set of segments.
3. **The rest is diagnosed as usual** with :class:`~station.fit.calibrate.FitOptions`'s ``censored_saturation``
   (the fit's input check then passes over the censored segments; a saturation anywhere else is still refused).
4. **Located**: one :class:`~station.diagnose.results.Unexplained` entry per saturated axis (``censored``: the
   level in the display convention, the samples at it and excluded, the segments and their kinds, the statement
   that the plan exceeds the sensor's range or its output stage limits below the class's). Never a finding.
5. **Too little left**: where the censored recording no longer holds what the fit's design checks
   (:func:`station.fit.checks.check_accel_design`, :func:`~station.fit.checks.check_gyro_design`) need, the
   parameters that cannot be determined are named (``not_determined``) with the check's reason, and no number is
   given for them: the diagnosis then reports the censored entries only (``base_fit`` null).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from station.diagnose.outcome import ResidualCurve
from station.diagnose.residuals import Baseline
from station.diagnose.results import Censored, Unexplained
from station.fit.checks import AXES, check_accel_design, check_gyro_design, saturations
from station.kernel.display import display_for
from station.kernel.errors import FitError
from station.session.model import Session

#: Samples within this time (s) of a sample at the rail are excluded with it: a digital low-pass after a
#: saturated front end (bandwidth >= 20 Hz, a first-order time constant <= 8 ms) settles to 1e-3 in 7 of them.
NEIGHBOURS_S = 0.05
#: At most this many samples per curve in the figure of a recording that determines no base fit.
CURVE_POINTS = 5000
#: What the input each sensor's axis measures is called (the covariate the clip follows).
INPUT = {"gyro": "rate about", "accel": "specific force along"}
#: The display quantity of each sensor's input.
QUANTITY = {"gyro": "angular_rate", "accel": "acceleration"}
#: The plain statement of what a clip means.
STATEMENT = ("the output sits at a rail: the sensor's range is exceeded by the plan (or its output stage limits "
             "below the sensor class's range); the samples at the rail and their segments are censored from this "
             "sensor's data, not fitted")
#: What the design checks leave undetermined when a censored triad fails them, per sensor (axis name filled in).
UNDETERMINED = {"gyro": ("M_w column {a} (gyro scale factor {a} and the cross-axis terms about {a})",),
                "accel": ("M_a row {a} (accel scale factor and cross-axis terms of {a})", "b_a {a} (accel bias {a})")}


@dataclass(frozen=True, eq=False)
class Censoring:
    """What :func:`censor` did to a recording: ``session`` with the censored segments' references taken away per
    triad, ``entries`` one per saturated axis (empty: nothing saturated, ``session`` is the recording
    itself), ``determined`` False where the censored recording fails the fit's design checks."""

    session: Session
    entries: tuple[Censored, ...]
    kinds: tuple[tuple[str, ...], ...]
    determined: bool
    masks: tuple[tuple[str, np.ndarray], ...] = ()

    def apply(self, baseline: Baseline) -> Baseline:
        """``baseline`` with each censored triad's :attr:`SensorData.censored` mask (the sample-level tests pass
        over those segments); unchanged without censoring."""
        masks = dict(self.masks)
        accel, gyro = (baseline.sensor(s) if s not in masks else replace(baseline.sensor(s), censored=masks[s])
                       for s in ("accel", "gyro"))
        return replace(baseline, accel=accel, gyro=gyro)

    def curves(self) -> list[ResidualCurve]:
        """The figure's rows where the censored data determine no base fit (no residual to show): per censored
        sensor its recording over time since power-on and what censoring leaves of it (NaN where censored), every
        k-th sample so that at most :data:`CURVE_POINTS` are drawn (a rail is flat: a stride keeps it)."""
        out = []
        every = max(1, math.ceil(len(self.session) / CURVE_POINTS))
        for sensor, mask in self.masks:
            x = np.array(self.session.gyro_radps if sensor == "gyro" else self.session.accel_mps2, dtype=float)
            left = x.copy()
            left[mask] = np.nan
            out.append(ResidualCurve(f"{sensor} recording", np.asarray(self.session.t_s)[::every], x[::every],
                                     left[::every], ("as recorded", "left after censoring")))
        return out

    def unexplained(self) -> tuple[Unexplained, ...]:
        """The report's entries: one :class:`Unexplained` per saturated axis."""
        return tuple(Unexplained(c.sensor, (c.axis,), kinds, _covariate(c), {}, math.nan, censored=c)
                     for c, kinds in zip(self.entries, self.kinds, strict=True))


def _covariate(c: Censored) -> str:
    levels = " and ".join(f"{v:+.4g}" for v in c.levels)
    return (f"{INPUT[c.sensor]} {c.axis}: clips at {levels} {c.unit} (saturated output: {c.samples_at_level} "
            f"samples at the rail{'s' if len(c.levels) > 1 else ''})")


def _dilate(mask: np.ndarray, n: int) -> np.ndarray:
    """``mask`` widened by ``n`` samples either side."""
    if n <= 0 or not mask.any():
        return mask
    c = np.concatenate([[0], np.cumsum(mask, dtype=np.int64)])
    i = np.arange(len(mask))
    return (c[np.minimum(i + n + 1, len(mask))] - c[np.maximum(i - n, 0)]) > 0


def censor(session: Session) -> Censoring:
    """Find the saturated axes (the fit's own check) and censor them (see the module docstring)."""
    found = saturations(session)
    if not found:
        return Censoring(session, (), (), True)
    refs = {"accel": np.array(session.ref_accel_mps2, dtype=float),
            "gyro": np.array(session.ref_gyro_radps, dtype=float)}
    data = {"accel": session.accel_mps2, "gyro": session.gyro_radps}
    reach = max(1, math.ceil(NEIGHBOURS_S * session.sample_rate_hz))
    segments = session.segments()
    rails: dict[tuple[str, int], dict[str, float]] = {}
    for s in found:  # the level the check found per axis and side
        rails.setdefault((s.sensor, s.axis), {}).setdefault(s.side, s.level)
    made: list[tuple[Censored, tuple[str, ...]]] = []
    masks: dict[str, np.ndarray] = {}
    for (sensor, axis), sides in rails.items():
        x = data[sensor][:, axis]
        at = np.zeros(len(x), dtype=bool)
        for side, level in sides.items():
            at |= x >= level if side == "maximum" else x <= level
        near = _dilate(at, reach)
        touched = [g for g in segments if near[g.start:g.stop].any()]
        for g in touched:
            refs[sensor][g.start:g.stop] = np.nan
            masks.setdefault(sensor, np.zeros(len(session), dtype=bool))[g.start:g.stop] = True
        shown = display_for(QUANTITY[sensor])
        levels = sorted(sides.values())
        entry = Censored(sensor, AXES[axis], tuple(levels), tuple(round(shown.convert(v), 3) for v in levels),
                         shown.unit, int(np.count_nonzero(at)), int(sum(len(g) for g in touched)),
                         tuple(sorted({g.index for g in touched})), STATEMENT)
        made.append((entry, tuple(sorted({g.kind.label for g in touched}))))
    out = session.replace(ref_accel_mps2=refs["accel"], ref_gyro_radps=refs["gyro"])
    reasons: dict[str, str] = {}
    for sensor, check in (("accel", check_accel_design), ("gyro", check_gyro_design)):
        try:
            check(out)
        except FitError as exc:
            reasons[sensor] = str(exc)
    entries = []
    for entry, kinds in made:
        if entry.sensor in reasons:
            names = tuple(n.format(a=entry.axis) for n in UNDETERMINED[entry.sensor])
            entry = replace(entry, not_determined=names,
                            reason=f"with the saturated segments censored: {reasons[entry.sensor]}")
        entries.append((entry, kinds))
    return Censoring(out, tuple(e for e, _ in entries), tuple(k for _, k in entries), not reasons,
                     tuple(masks.items()))


__all__ = ["CURVE_POINTS", "NEIGHBOURS_S", "Censoring", "censor"]
