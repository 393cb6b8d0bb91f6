"""Input checks before a fit: a recording that cannot give a trustworthy parameter set is
refused with a one-line reason (which sensor, axis or segment, and why).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from station.fit.consistency import check_recording, check_references
from station.kernel.errors import FitError
from station.session.model import Kind, Session

AXES = "xyz"


def check_time(session: Session) -> None:
    """Refuse empty sessions, non-finite, negative or non-increasing time."""
    if len(session) < 2:
        raise FitError("session has fewer than 2 samples")
    t = session.t_s
    if not np.all(np.isfinite(t)):
        i = int(np.flatnonzero(~np.isfinite(t))[0])
        raise FitError(f"time is not finite at sample {i}")
    if t[0] < 0:
        raise FitError(f"time starts at {t[0]:.6g} s: t is seconds since power-on, from 0 (the model's warm-up "
                       f"term b_drift exp(-t/T_c) starts there); shift the time stamps so the first is >= 0")
    bad = np.flatnonzero(np.diff(t) <= 0)
    if bad.size:
        i = int(bad[0]) + 1
        raise FitError(f"time does not increase at sample {i} (t={t[i]:.6f} s after {t[i - 1]:.6f} s)")


def check_finite(session: Session) -> None:
    """Refuse NaN or infinite measurements."""
    for name, data in (("accel", session.accel_mps2), ("gyro", session.gyro_radps)):
        bad = ~np.isfinite(data)
        if bad.any():
            i, j = np.argwhere(bad)[0]
            raise FitError(f"{name} {AXES[j]} is NaN or infinite at sample {i} (t={session.t_s[i]:.4f} s)")


@dataclass(frozen=True)
class Saturation:
    """An axis sitting at its session-wide maximum or minimum in a settled segment (:func:`axis_saturations`).

    Attributes:
        sensor: ``accel`` or ``gyro``; axis: 0, 1, 2 (x, y, z).
        side: ``maximum`` or ``minimum``; level: the value it sits at (the sensor's SI unit).
        segment, kind: the settled segment and its kind; at, samples: samples at the level and in the segment.
    """

    sensor: str
    axis: int
    side: str
    level: float
    segment: int
    kind: Kind
    at: int
    samples: int

    @property
    def reason(self) -> str:
        """The input check's one-line refusal."""
        return (f"{self.sensor} {AXES[self.axis]} is saturated: {self.at} of {self.samples} samples of "
                f"{self.kind.label} segment {self.segment} sit at its {self.side} {self.level:.6g}")


def axis_saturations(session: Session, name: str, data: np.ndarray, mask: np.ndarray, j: int, *,
                     ref: np.ndarray | None = None) -> tuple[Saturation, ...]:
    """Every settled segment (in order; per segment the maximum before the minimum) where axis ``j`` sits at its
    maximum or minimum over the ``mask``ed samples for at least half of the segment's samples.

    Saturated: in some settled segment the axis sits at its session-wide maximum or minimum
    for most samples, while it is not stuck in most other settled segments (a quantized
    axis quieter than one LSB is constant everywhere and is not saturated).

    ``ref``: the sensor's reference; when given, a settled segment without a finite reference is passed over (a
    caller that censored the saturated segments by taking their reference away: the fit does not use them).
    """
    x = data[np.flatnonzero(mask), j]
    hi, lo = x.max(), x.min()
    segments = [s for s in session.segments_of(Kind.REST, Kind.POSE, Kind.RATE) if len(s) >= 20]
    stuck = [np.ptp(data[s.start:s.stop, j]) == 0.0 for s in segments]
    if sum(stuck) > len(segments) // 2:
        return ()
    hits = []
    for seg in segments:
        if ref is not None and not np.all(np.isfinite(ref[seg.start:seg.stop])):
            continue
        v = data[seg.start:seg.stop, j]
        for label, value in (("maximum", hi), ("minimum", lo)):
            at = int(np.count_nonzero(v == value))
            if at >= 0.5 * len(v):
                hits.append(Saturation(name, j, label, float(value), seg.index, seg.kind, at, len(v)))
    return tuple(hits)


def check_axes_alive(session: Session, name: str, data: np.ndarray, mask: np.ndarray, *,
                     ref: np.ndarray | None = None) -> None:
    """Refuse a dead (constant) axis and a saturated (clipped) axis among the ``mask``ed samples
    (:func:`axis_saturations`; ``ref`` as there)."""
    index = np.flatnonzero(mask)
    for j in range(3):
        x = data[index, j]
        if np.ptp(x) == 0.0:
            raise FitError(f"{name} {AXES[j]} is constant at {x[0]:.6g} over the whole session (dead axis)")
        hits = axis_saturations(session, name, data, mask, j, ref=ref)
        if hits:
            raise FitError(hits[0].reason)


def saturations(session: Session) -> tuple[Saturation, ...]:
    """Every saturated settled segment of both sensors' live axes (:func:`axis_saturations` over the settled
    samples): what :func:`check_session` refuses, for a caller that censors it instead (the diagnosis)."""
    settled = np.isin(session.kind, (Kind.REST, Kind.POSE, Kind.RATE))
    if not settled.any():
        return ()
    out: list[Saturation] = []
    for name, data in (("accel", session.accel_mps2), ("gyro", session.gyro_radps)):
        for j in range(3):
            if np.ptp(data[settled, j]) > 0.0:
                out += axis_saturations(session, name, data, settled, j)
    return tuple(out)


def check_pose_lengths(session: Session, min_samples: int) -> None:
    """Refuse settled segments too short to give a mean."""
    for seg in session.segments_of(Kind.POSE, Kind.RATE, Kind.REST):
        if len(seg) < min_samples:
            raise FitError(
                f"{seg.kind.label} segment {seg.index} has {len(seg)} samples; at least {min_samples} are needed"
            )


#: Samples per pass in :func:`check_accel_design`.
_ROWS = 1 << 18


def check_accel_design(session: Session) -> None:
    """The static references must point both ways along every axis, or M_a and b_a mix.

    Read a piece of the recording at a time: the rank of the (n, 4) design ``[ref, 1]`` is counted from the
    singular values of its 4 x 4 Gram matrix (the design's singular values squared), summed over the pieces.
    """
    mask = np.isin(session.kind, (Kind.REST, Kind.POSE)) & np.all(np.isfinite(session.ref_accel_mps2), axis=1)
    if not mask.any():
        raise FitError("no rest or pose segment with an accelerometer reference: M_a cannot be fitted")
    g = session.gravity_mps2
    up = np.zeros(3, dtype=bool)
    down = np.zeros(3, dtype=bool)
    gram = np.zeros((4, 4))
    count = 0
    for lo in range(0, len(mask), _ROWS):
        ref = session.ref_accel_mps2[lo:lo + _ROWS][mask[lo:lo + _ROWS]]
        up |= np.any(ref > 0.5 * g, axis=0)
        down |= np.any(-ref > 0.5 * g, axis=0)
        design = np.column_stack([ref, np.ones(len(ref))])
        gram += design.T @ design
        count += len(ref)
    for j in range(3):
        for seen, sign, word in ((up, 1, "up"), (down, -1, "down")):
            if not seen[j]:
                raise FitError(
                    f"missing pose: no settled pose with {AXES[j]} pointing {word} "
                    f"(ref_a{AXES[j]} {'>' if sign > 0 else '<'} {'+' if sign > 0 else '-'}g/2), "
                    "so M_a and the bias along it cannot be separated"
                )
    singular = np.sqrt(np.clip(np.linalg.eigvalsh(gram), 0.0, None))
    if np.count_nonzero(singular > 1e-6 * g * np.sqrt(count)) < 4:
        raise FitError("the pose references do not span three dimensions: M_a cannot be fitted")


def check_gyro_design(session: Session) -> str:
    """Which gyro scale fit the recording supports: 'rate' (rate steps) or 'angle' (angle.N)."""
    rate_mask = (session.kind == Kind.RATE) & np.all(np.isfinite(session.ref_gyro_radps), axis=1)
    if rate_mask.any():
        ref = session.ref_gyro_radps[rate_mask]
        missing = [AXES[j] for j in range(3) if not np.any(np.abs(ref[:, j]) > np.radians(1.0))]
        if missing:
            raise FitError(f"no rate step about {', '.join(missing)}: M_w cannot be fitted")
        return "rate"
    if session.angles_deg:
        angles = np.array(list(session.angles_deg.values()))
        if np.linalg.matrix_rank(angles, tol=1.0) < 3:
            raise FitError("the known-angle rotations (angle.N) do not span three axes: M_w cannot be fitted")
        return "angle"
    raise FitError("no rate step and no known-angle rotation (angle.N): M_w cannot be fitted")


def check_session(session: Session, *, min_pose_samples: int, censored: bool = False) -> str:
    """Run every check; returns the gyro scale method ('rate' or 'angle').

    ``censored``: the caller took the reference away (NaN) from every settled segment where a triad saturates
    (the diagnosis, :mod:`station.diagnose.censoring`): the saturation check passes over segments without the
    triad's reference, which the fit does not use; a saturation anywhere else is still refused."""
    check_time(session)
    check_finite(session)
    check_recording(session)
    check_pose_lengths(session, min_pose_samples)
    settled = np.isin(session.kind, (Kind.REST, Kind.POSE, Kind.RATE))
    if not settled.any():
        raise FitError("no settled segment (rest, pose or rate) in the session")
    check_axes_alive(session, "accel", session.accel_mps2, settled, ref=session.ref_accel_mps2 if censored else None)
    check_axes_alive(session, "gyro", session.gyro_radps, settled, ref=session.ref_gyro_radps if censored else None)
    check_references(session)
    check_accel_design(session)
    return check_gyro_design(session)
