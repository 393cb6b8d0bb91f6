"""The time offset tau between the sensor's samples and the rig's reference, estimated on the transitions.

The sensor's sample stamped t holds the input at rig time t - tau (tau > 0: the sensor lags). In settled
segments the reference is constant and tau leaves no trace; in the transitions (``move`` segments: tumbles,
rate ramps) the reference changes and the sensor's output against the base model's prediction at the
reference of time t is, to first order, ``-tau d/dt model(ref(t))``. The estimator is Gauss-Newton on

    x~_k(t) = model_k(ref(t - tau)) + c_(segment, k) + noise,

over the gyro's ``move`` segments where the reference changes (:data:`MIN_CHANGING`), each with up to :data:`PAD`
samples of its still neighbours (a lagging sensor's response spills over the segment's edges; cut there, the
per-segment constant below would take part of it and pull tau towards 0), a constant per segment and axis
absorbing the slow drift and what the base model leaves out of the segment's mean, the reference interpolated
linearly at ``t - tau`` (a modified Akima interpolation did no better on the independent generator), the derivative
by a central difference of the model in tau, weights 1 / sigma_k^2 (the white noise). Only the gyroscope: in
the accelerometer's transitions the lever arm (``alpha x r``, ``w x (w x r)``), absent from the base model,
would pass for a time shift.

Uncertainty: the larger of the white-noise figure ``1 / sqrt(sum D^2 / sigma^2)`` and the delete-one-segment
jackknife over the transitions (what the noise figure misses: drift and model error within a segment).
Determined when at least :data:`MIN_TRANSITIONS` segments each determine tau to better than one sample period
on their own; kept (applied by Algorithm 1) when ``(tau / sigma_tau)^2`` passes the Wald threshold and tau is
within what Algorithm 1 applies.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from station.kernel.parameters import MAX_LAG_SAMPLES, MAX_LEAD_SAMPLES, TimeOffsetNote
from station.session.model import Kind, Session

#: Transitions that must each determine tau on their own (to one sample period) for it to be determined.
MIN_TRANSITIONS = 3
#: Gauss-Newton steps.
STEPS = 4
#: Samples of the neighbouring segments the reference is interpolated over at a segment's edge.
PAD = 64
#: A move segment is a transition when its reference changes on at least this many samples: a segment where the
#: rig holds still (a pause labelled ``move``) carries only the kink of the motion before it, where the sampled
#: reference cannot say when the motion stopped, and the linear interpolation's error there would pass for tau.
MIN_CHANGING = 10

Model = Callable[[np.ndarray, np.ndarray, np.ndarray, np.ndarray | None], np.ndarray]


def _window(session: Session, start: int, stop: int) -> tuple[int, int] | None:
    """The segment's rows with up to :data:`PAD` neighbours each side where the reference is finite."""
    ref = session.ref_gyro_radps
    if not np.all(np.isfinite(ref[start:stop])):
        return None
    lo, hi = start, stop
    while lo > max(0, start - PAD) and np.all(np.isfinite(ref[lo - 1])):
        lo -= 1
    while hi < min(len(session), stop + PAD) and np.all(np.isfinite(ref[hi])):
        hi += 1
    return lo, hi


def estimate_time_offset(
    session: Session, model: Model, sigma: np.ndarray, dt: np.ndarray | None, *, wald: float
) -> tuple[TimeOffsetNote, float, float]:
    """tau on the gyro's transitions: the note, and the value and standard uncertainty the set keeps (0, 0 when
    not kept). ``model(t, ref, force, dt)`` is the fitted gyro mean model; ``sigma`` its white noise per axis."""
    ts = 1.0 / session.sample_rate_hz
    rule = (f"Gauss-Newton on the gyro's move samples (a constant per segment and axis), uncertainty the larger of "
            f"the noise and the delete-one-segment jackknife; determined by >= {MIN_TRANSITIONS} transitions that "
            f"each give it to one sample period; kept where (tau/sigma)^2 >= {wald:g}")
    pieces = []
    for seg in session.segments_of(Kind.MOVE):
        ref = session.ref_gyro_radps[seg.start:seg.stop]
        if len(seg) < 5 or np.count_nonzero(np.any(np.abs(np.diff(ref, axis=0)) > 0.0, axis=1)) < MIN_CHANGING:
            continue
        win = _window(session, seg.start, seg.stop)
        if win is not None:
            pieces.append((seg.start, seg.stop, win))
    w = 1.0 / np.maximum(np.asarray(sigma, dtype=float), 1e-15) ** 2
    force = np.nan_to_num(session.ref_accel_mps2)

    def sums(tau: float) -> tuple[np.ndarray, np.ndarray]:
        """Per transition: sum of w D^2 and of w D r (both demeaned per segment and axis)."""
        h = 0.5 * ts
        dd, dr = np.zeros(len(pieces)), np.zeros(len(pieces))
        for i, (_, _, (lo, hi)) in enumerate(pieces):
            # the segment with its still neighbours: the sensor's response to the move spills over its edges by tau
            t = session.t_s[lo:hi]
            d_t = None if dt is None else dt[lo:hi]

            def at(shift: float, t: np.ndarray = t, lo: int = lo, hi: int = hi,
                   d_t: np.ndarray | None = d_t) -> np.ndarray:
                ref = np.column_stack([np.interp(t - shift, t, session.ref_gyro_radps[lo:hi, j]) for j in range(3)])
                f = np.column_stack([np.interp(t - shift, t, force[lo:hi, j]) for j in range(3)])
                return model(t, ref, f, d_t)

            r = session.gyro_radps[lo:hi] - at(tau)
            d = (at(tau + h) - at(tau - h)) / (2.0 * h)  # d model / d tau (= -d model / dt)
            r -= r.mean(axis=0)
            d -= d.mean(axis=0)
            dd[i] = float(np.sum(w * d * d))
            dr[i] = float(np.sum(w * d * r))
        return dd, dr

    if not pieces:
        return TimeOffsetNote("not_determined", transitions=0, rule=rule,
                              reason="the recording has no transitions (move segments with a reference): add "
                                     "rate ramps or moves between the still segments"), 0.0, 0.0
    tau = 0.0
    for _ in range(STEPS):
        dd, dr = sums(tau)
        if dd.sum() <= 0:
            break
        tau += float(dr.sum() / dd.sum())
    dd, dr = sums(tau)
    total = float(dd.sum())
    informative = int(np.sum(dd * ts**2 >= 1.0))  # the segment alone: sigma_tau <= one sample period
    if total <= 0 or informative < MIN_TRANSITIONS:
        return TimeOffsetNote("not_determined", transitions=informative, rule=rule,
                              reason=f"{informative} transition(s) determine it (need {MIN_TRANSITIONS}): the rig's "
                                     "rate changes too little or too briefly; add rate ramps or moves"), 0.0, 0.0
    noise_std = 1.0 / math.sqrt(total)
    g = len(pieces)
    keep = dd < total  # a segment that holds all the information leaves nothing to jackknife
    jack = np.array([tau + (dr.sum() - dr[i]) / (total - dd[i]) for i in range(g) if keep[i]])
    jack_std = math.sqrt((len(jack) - 1) / len(jack) * float(np.sum((jack - jack.mean()) ** 2))) if len(jack) > 1 \
        else math.inf
    std = max(noise_std, jack_std)
    note = TimeOffsetNote("fitted", estimate_s=tau, std_s=std, transitions=informative, rule=rule)
    s = tau / ts
    if (tau / std) ** 2 < wald:
        return TimeOffsetNote("not_significant", tau, std, informative, rule,
                              reason=f"(tau/sigma)^2 = {(tau / std) ** 2:.2f} < {wald:g}"), 0.0, 0.0
    if s > MAX_LAG_SAMPLES or s < -MAX_LEAD_SAMPLES:
        return TimeOffsetNote("beyond_range", tau, std, informative, rule,
                              reason=f"{s:.3g} samples: Algorithm 1 applies {MAX_LAG_SAMPLES:g} samples of lag and "
                                     f"{MAX_LEAD_SAMPLES:g} of lead at most"), 0.0, 0.0
    return note, tau, std


__all__ = ["MIN_TRANSITIONS", "estimate_time_offset"]
