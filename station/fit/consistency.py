"""Physical consistency of a recording before it is fitted: what the rig says against what physics allows.

Each check refuses with a one-line :class:`~station.kernel.errors.FitError` that names the segment
(or sample) and the contradiction. They catch inputs that the fit would otherwise turn into a
silently wrong calibration:

* measurements beyond any MEMS sensor's range (a 1e30 cell, a temperature of 1e300 degC);
* a ``sample_rate_hz`` that the time column contradicts, and gaps in the time column inside a segment;
* pose references whose norm is not the recording's gravity (within ``reference_tolerance_mps2``,
  default :data:`REFERENCE_TOLERANCE` of g), or a measured specific force that points away from
  its reference (a flipped or mislabelled pose) or is far from its magnitude (wrong unit);
* rate steps whose measured rate contradicts the commanded one (sign, axis, size);
* ``angle.N`` for a segment that does not exist or is not a ``move``; known-angle moves whose
  integrated rate is not about one fixed axis or not about the stated one (swapped labels).

The thresholds are far outside what a working sensor produces (MEMS misalignment is a few
degrees, scale errors a few percent, biases a small fraction of g), so good recordings pass.
"""

from __future__ import annotations

import numpy as np

from station.kernel.errors import FitError, TimeBaseError
from station.session.model import Kind, Segment, Session

AXES = "xyz"

#: largest |specific force| (m/s^2) and |rate| (rad/s) any MEMS triad reports (~500 g, ~11 000 deg/s)
ACCEL_RANGE_MPS2 = 5000.0
GYRO_RANGE_RADPS = 200.0
#: plausible sensor temperature (degC)
TEMP_RANGE_DEGC = (-100.0, 250.0)
#: pose reference norm vs gravity: relative tolerance when the recording states none
REFERENCE_TOLERANCE = 0.005
#: largest angle (deg) between a pose's raw mean specific force and its reference
MAX_POSE_ANGLE_DEG = 30.0
#: raw |mean specific force| / g must lie within this range (else: wrong unit or wrong reference)
POSE_MAGNITUDE_RATIO = (0.5, 2.0)
#: a rate step's mean rate may miss its reference by this fraction of it plus the offset (rad/s)
RATE_RELATIVE = 0.3
RATE_OFFSET_RADPS = float(np.radians(5.0))
#: sample interval vs 1 / sample_rate_hz: relative tolerance of the median
RATE_MISMATCH = 0.02
#: a gap in t inside a segment longer than this many sample periods (and GAP_MIN_S) is refused
GAP_PERIODS = 1000.0
GAP_MIN_S = 10.0
#: known-angle moves: largest angle (deg) between the integrated rate and the stated rotation,
#: the integrated magnitude relative to the stated one, and the share of rotation off the mean axis
MAX_ROTATION_AXIS_DEG = 30.0
ROTATION_MAGNITUDE_RATIO = (0.7, 1.3)
MAX_OFF_AXIS_SHARE = 0.15


def check_ranges(session: Session) -> None:
    """Refuse samples beyond any MEMS sensor's range (the fit would take them for the signal)."""
    for name, data, limit, unit, scale in (
        ("accel", session.accel_mps2, ACCEL_RANGE_MPS2, "m/s^2", 1.0),
        ("gyro", session.gyro_radps, GYRO_RANGE_RADPS, "deg/s", float(np.degrees(1.0))),
    ):
        bad = np.abs(data) > limit
        if bad.any():
            i, j = (int(v) for v in np.argwhere(bad)[0])
            raise FitError(
                f"{name} {AXES[j]} is {data[i, j] * scale:.6g} {unit} at sample {i} (t={session.t_s[i]:.4f} s): "
                f"beyond any MEMS sensor's range (|value| <= {limit * scale:.6g} {unit})"
            )
    temp = session.temp_degc
    lo, hi = TEMP_RANGE_DEGC
    bad = np.isfinite(temp) & ((temp < lo) | (temp > hi))
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise FitError(f"temperature {temp[i]:.6g} degC at sample {i} is outside {lo:g}..{hi:g} degC")


def check_sample_rate(session: Session) -> None:
    """The stated sample rate must be what the time column shows, and the time column may not jump."""
    rate = session.sample_rate_hz
    dt = np.diff(session.t_s)
    median = float(np.median(dt))
    if abs(median * rate - 1.0) > RATE_MISMATCH:
        raise TimeBaseError(
            f"metadata sample_rate_hz {rate:g} Hz contradicts the time column: its median sample interval "
            f"is {median:.6g} s ({1.0 / median:.6g} Hz)"
        )
    limit = max(GAP_PERIODS / rate, GAP_MIN_S)
    same = (np.diff(session.segment) == 0) & (np.diff(session.kind) == 0)
    gaps = np.flatnonzero((dt > limit) & same)
    if gaps.size:
        i = int(gaps[0]) + 1
        raise TimeBaseError(
            f"time jumps by {dt[i - 1]:.6g} s at sample {i} (t={session.t_s[i]:.6g} s) inside segment "
            f"{int(session.segment[i])}; a segment's samples may not have gaps longer than {limit:g} s"
        )


def _still_segments(session: Session) -> list[tuple[Segment, np.ndarray, np.ndarray]]:
    out = []
    for seg in session.segments_of(Kind.REST, Kind.POSE):
        ref = session.ref_accel_mps2[seg.slice]
        if np.all(np.isfinite(ref)):
            out.append((seg, ref.mean(axis=0), session.accel_mps2[seg.slice].mean(axis=0)))
    return out


def _vector(v: np.ndarray, scale: float = 1.0) -> str:
    return "(" + ", ".join(f"{x * scale:.4g}" for x in v) + ")"


def _angle_deg(a: np.ndarray, b: np.ndarray) -> float:
    na, nb = float(np.linalg.norm(a)), float(np.linalg.norm(b))
    if na == 0.0 or nb == 0.0:
        return 180.0
    return float(np.degrees(np.arccos(np.clip(float(a @ b) / (na * nb), -1.0, 1.0))))


def check_pose_references(session: Session) -> None:
    """Rest and pose references: norm = gravity, and the measured specific force points along them."""
    g = session.gravity_mps2
    tolerance = session.meta_float("reference_tolerance_mps2")
    tol = REFERENCE_TOLERANCE * g if tolerance is None else tolerance
    for seg, ref, measured in _still_segments(session):
        where = f"{seg.kind.label} segment {seg.index}"
        norm = float(np.linalg.norm(ref))
        if abs(norm - g) > tol:
            raise FitError(
                f"{where}: reference {_vector(ref)} m/s^2 has norm {norm:.6g}, not the recording's gravity "
                f"{g:.6g} m/s^2 (tolerance {tol:.3g})"
            )
        angle = _angle_deg(measured, ref)
        if angle > MAX_POSE_ANGLE_DEG:
            raise FitError(
                f"{where}: the accelerometer measures {_vector(measured)} m/s^2, {angle:.0f} deg away from the "
                f"reference {_vector(ref)} (at most {MAX_POSE_ANGLE_DEG:g}): wrong or mislabelled reference"
            )
        ratio = float(np.linalg.norm(measured)) / g
        lo, hi = POSE_MAGNITUDE_RATIO
        if not lo <= ratio <= hi:
            raise FitError(
                f"{where}: the accelerometer measures |a| = {ratio * g:.6g} m/s^2, {ratio:.3g} g: "
                "not a specific force in m/s^2 at rest"
            )


def check_rate_references(session: Session) -> None:
    """Rate steps: the measured mean rate agrees with the commanded one in axis, sign and size."""
    for seg in session.segments_of(Kind.RATE):
        ref = session.ref_gyro_radps[seg.slice]
        if not np.all(np.isfinite(ref)):
            continue
        r = ref.mean(axis=0)
        measured = session.gyro_radps[seg.slice].mean(axis=0)
        miss = float(np.linalg.norm(measured - r))
        allowed = RATE_RELATIVE * float(np.linalg.norm(r)) + RATE_OFFSET_RADPS
        if miss > allowed:
            deg = float(np.degrees(1.0))
            raise FitError(
                f"rate segment {seg.index}: the gyroscope measures {_vector(measured, deg)} deg/s, the reference "
                f"says {_vector(r, deg)} deg/s ({miss * deg:.3g} deg/s apart, at most {allowed * deg:.3g})"
            )


def check_angle_segments(session: Session) -> None:
    """Every ``angle.N`` names an existing ``move`` segment."""
    kinds: dict[int, set[int]] = {}
    for seg in session.segments():
        kinds.setdefault(seg.index, set()).add(int(seg.kind))
    for index in sorted(session.angles_deg):
        if index not in kinds:
            raise FitError(f"angle.{index}: the recording has no segment {index}")
        if kinds[index] != {int(Kind.MOVE)}:
            labels = ", ".join(Kind(k).label for k in sorted(kinds[index]))
            raise FitError(f"angle.{index}: segment {index} is {labels}, not a move; a known angle belongs to a move")


def check_rotations(session: Session, bias_radps: np.ndarray, sigma_radps: np.ndarray) -> None:
    """Known-angle moves must be rotations about one fixed axis, about the stated one.

    With ``w`` the bias-corrected gyro output, a rotation about a fixed axis keeps ``w`` along that
    axis (in the sensor frame, whatever M is): the rotation off the mean axis, the integral of
    ``|w - (w.u) u|``, is only noise. The integral of ``w`` must also point along the stated angle
    (within :data:`MAX_ROTATION_AXIS_DEG`; M misaligns by a few degrees) and be about as large.
    """
    ts = 1.0 / session.sample_rate_hz
    for index, angle in sorted(session.angles_deg.items()):
        sel = np.flatnonzero(session.segment == index)
        w = session.gyro_radps[sel] - bias_radps[sel]
        total = w.sum(axis=0) * ts
        stated = np.radians(np.asarray(angle, dtype=float))
        size = float(np.linalg.norm(total))
        deg = f"{np.degrees(size):.4g}"
        axis_angle = _angle_deg(total, stated)
        if axis_angle > MAX_ROTATION_AXIS_DEG:
            raise FitError(
                f"angle.{index}: the gyroscope integrates to {_vector(np.degrees(total))} deg over move segment "
                f"{index}, {axis_angle:.0f} deg from the stated rotation {_vector(np.asarray(angle))} deg "
                "(swapped or wrong angle label)"
            )
        ratio = size / float(np.linalg.norm(stated))
        lo, hi = ROTATION_MAGNITUDE_RATIO
        if not lo <= ratio <= hi:
            raise FitError(
                f"angle.{index}: the gyroscope integrates to {deg} deg over move segment {index}, the stated "
                f"rotation is {np.degrees(np.linalg.norm(stated)):.4g} deg"
            )
        u = total / size
        off = w - np.outer(w @ u, u)
        off_axis = float(np.linalg.norm(off, axis=1).sum() * ts)
        noise = float(1.3 * np.linalg.norm(sigma_radps) * ts * len(sel))  # mean |noise| off the axis, summed
        if off_axis > MAX_OFF_AXIS_SHARE * size + 3.0 * noise:
            raise FitError(
                f"angle.{index}: move segment {index} is not a rotation about one fixed axis: "
                f"{np.degrees(off_axis):.4g} deg of its {deg} deg turn are about other axes "
                f"(at most {100 * MAX_OFF_AXIS_SHARE:g} %); the known-angle fit needs fixed-axis turns"
            )


def check_recording(session: Session) -> None:
    """Ranges, sample rate and angle labels: the checks on the recording itself."""
    check_ranges(session)
    check_sample_rate(session)
    check_angle_segments(session)


def check_references(session: Session) -> None:
    """The rig's references against physics and against what the sensor measured."""
    check_pose_references(session)
    check_rate_references(session)


def check_consistency(session: Session) -> None:
    """Every check that needs no fitted parameter (see the module docstring)."""
    check_recording(session)
    check_references(session)


def check_import(session: Session) -> None:
    """The checks an imported recording can take before any fit: :func:`check_consistency`, and the
    known-angle moves against the gyro integrated with its mean still output as bias."""
    check_consistency(session)
    still = np.isin(session.kind, (Kind.REST, Kind.POSE))
    if session.angles_deg and np.count_nonzero(still) > 2:
        check_angle_segments(session)
        gyro = session.gyro_radps[still]
        sigma = np.std(np.diff(gyro, axis=0), axis=0) / np.sqrt(2.0)
        check_rotations(session, np.broadcast_to(gyro.mean(axis=0), session.gyro_radps.shape), sigma)
