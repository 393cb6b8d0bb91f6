"""The rig-free fit: a hand-held multi-position recording to today's parameter set.

Chosen automatically (:func:`is_rig_free`) when the recording's poses carry no reference, or
asked for with ``station fit --rig-free``. Steps (numerics in :mod:`station.fit.multipos`):

1. Noise and outliers per triad from sample differences within the still segments (as the rig fit).
2. Accelerometer warm-up, eq. (3), a first look: ``b_drift exp(-t/T_c)`` per axis from the initial still
   (the ``rest`` segment: there the specific force is constant, so only the drift moves the output),
   with the rig fit's per-axis ML (:func:`station.fit.axis_ml.fit_axis`, design = a constant); it says
   which axes resolve T_c and gives the start values of step 3.
3. Accelerometer M, b_stat, b_drift (and T_c where step 2 resolved it; elsewhere held at the initial
   still's length) jointly over the block means of all still segments, gravity's norm the reference
   (:func:`station.fit.multipos.fit_accel_joint`, started from imu_tk's gravity-norm fit), in the stated
   convention (M upper-triangular: the accelerometer's own axes are the frame). ``accel_drift=False``:
   imu_tk's model, the gravity-norm fit alone.
4. Gyroscope bias b_stat, b_drift, T_c from all still segments (rest and poses; the rate there is
   zero up to Earth rate, which the model leaves in the bias), again with ``fit_axis``: the poses spread
   over the whole recording see the warm-up better than the initial still alone.
5. Gyroscope M from the rotations between consecutive still segments (RK4 of the calibrated rate
   over each move, matched to the accelerometer's gravity direction before and after). A logger that
   polls the gyro axis by axis on its own clock reads each axis's sample twice once per beat of the two
   clocks (:mod:`station.fit.readtiming`); when the record shows such a beat (its selection rule, on exact
   repeats, not on the fit), each move is integrated on the sensor's own samples: the stale reads
   dropped, the axes aligned by sample, the sensor's sample period (eq. 3 there).
6. Held-out validation (:func:`cross_validate`): k-fold leave-poses-out of the gravity norm and of
   the move rotations, reported in ``quality["rig_free"]["cross_validation"]``.

Observability and bad input are refused with one line (:class:`~station.kernel.errors.FitError`):
too few distinct poses, poses that do not span the sphere, a move during a "still" segment, moves
too fast for the sample rate, a gyro that clips, rates in the wrong unit.

What today's parameter set cannot hold: the frame convention (stated in ``quality["rig_free"]``),
and the local gravity the accelerometer scale refers to (``source["gravity_mps2"]``); the cross-axis
terms of M are those of the stated convention, not of a rig's frame.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from threadpoolctl import threadpool_limits

from station import __version__
from station.fit.axis_ml import AxisFit, fit_axis
from station.fit.blocks import make_blocks
from station.fit.boundary import numerics
from station.fit.calibrate import residual_allan, white_noise
from station.fit.checks import check_finite, check_time
from station.fit.determinability import assess
from station.fit.multipos import (
    UPPER_TRIANGLE,
    AccelJointFit,
    AccelNormFit,
    GyroRotationFit,
    accel_from_params,
    direction_errors_deg,
    fit_accel_joint,
    fit_accel_norm,
    fit_gyro_rotations,
    norm_residuals,
    rough_directions,
)
from station.fit.readtiming import ReadTiming, detect_stale_reads
from station.kernel.errors import FitError
from station.kernel.parameters import FitQuality, GoodnessOfFit, ParameterSet, ResidualFigures, TriadParams
from station.session.model import Kind, Segment, Session

__all__ = [
    "CONVENTION", "FORMAT", "Fold", "RigFreeData", "RigFreeOptions", "calibrated_accel", "cross_validate",
    "fit_rig_free", "folds", "is_rig_free", "prepare", "still_directions",
]

#: version of the ``quality["rig_free"]`` section
FORMAT = "station-rigfree/1"
CONVENTION = ("accelerometer frame: M_a upper-triangular (imu_tk T K = M_a^-1): the accelerometer's z sensing axis "
              "is the frame's z axis, its y sensing axis lies in the frame's y-z plane; the gyroscope is referred "
              "to that frame (M_w full)")


@dataclass(frozen=True)
class RigFreeOptions:
    """Knobs of the rig-free fit (angles in deg, times in s).

    Attributes:
        min_distinct_poses: still orientations at least ``distinct_deg`` apart that the fit needs.
        min_plane_spread: smallest eigenvalue of the mean ``u u'`` over the distinct gravity directions
            (1/3 for a uniform sphere, 0 when every pose is a turn about one axis).
        min_axis_reach: every axis must point within ``arccos(min_axis_reach)`` of up and of down in some pose.
        max_step_deg: largest rotation per sample the integration of a move accepts.
        still_rotation_deg: a still segment whose gyro turns (integrated, the segment's own mean rate
            removed, so that a constant offset such as a g-sensitivity does not count) or whose gravity
            direction moves by more than this is refused as a move.
        cv_folds: folds of the leave-poses-out cross-validation (0: none).
        accel_drift: fit the accelerometer's eq. (3) drift jointly (step 3); False: imu_tk's model, no drift.
        read_timing: look for stale per-axis gyro reads (:func:`station.fit.readtiming.detect_stale_reads`) and,
            when its selection rule accepts them, integrate the moves on the sensor's samples; False: the reads.
        min_segment_samples: still segments shorter than this are refused.
        outlier_sigma, drift_lr_threshold, max_blocks, tc_range_s: as in the rig fit
            (:class:`~station.fit.calibrate.FitOptions`): ``tc_range_s`` the sensor class's range of eq. 3's T_c
            per triad (``'accel'``, ``'gyro'``), a prior; without it T_c comes from the record alone.
    """

    min_distinct_poses: int = 12
    distinct_deg: float = 10.0
    min_plane_spread: float = 0.04
    min_axis_reach: float = 0.5
    max_step_deg: float = 20.0
    still_rotation_deg: float = 2.0
    cv_folds: int = 5
    min_segment_samples: int = 20
    outlier_sigma: float = 6.0
    drift_lr_threshold: float = 9.0
    max_blocks: int = 70
    moving_average_length: int = 40
    tc_range_s: Mapping[str, tuple[float, float]] = field(default_factory=dict)
    accel_drift: bool = True
    read_timing: bool = True


def _still(session: Session) -> list[Segment]:
    return [s for s in session.segments_of(Kind.REST, Kind.POSE)]


def is_rig_free(session: Session) -> bool:
    """True when the recording has still segments and none of its poses carries an accelerometer reference."""
    poses = session.segments_of(Kind.POSE)
    if not poses:
        return False
    return not any(np.isfinite(session.ref_accel_mps2[s.start:s.stop]).all() for s in poses)


def _runs(segments: Sequence[Segment]) -> list[tuple[int, int, int]]:
    return [(s.index, s.start, s.stop) for s in segments]


def _fit_drift(session: Session, data: np.ndarray, runs: list[tuple[int, int, int]], keep: np.ndarray,
               sigma: np.ndarray, options: RigFreeOptions, triad: str) -> list[AxisFit]:
    """Per-axis ``c + b_drift exp(-t/T_c)`` over ``runs`` (eq. 3), the rig fit's ML with a constant design."""
    zeros = np.zeros((len(session), 3))
    blocks = make_blocks(session.t_s, data, zeros, zeros, keep, runs, 1.0 / session.sample_rate_hz, options.max_blocks)
    design = np.ones((len(blocks), 1))
    tc_range = options.tc_range_s.get(triad)
    return [fit_axis(blocks, k, design, float(sigma[k]), lr_threshold=options.drift_lr_threshold, tc_range_s=tc_range)
            for k in range(3)]


def _drift_curve(fits: list[AxisFit], t_s: np.ndarray) -> np.ndarray:
    out = np.zeros((len(t_s), 3))
    for k, f in enumerate(fits):
        if np.isfinite(f.tc_s) and f.beta[-1] != 0.0:
            out[:, k] = f.beta[-1] * np.exp(-t_s / f.tc_s)
    return out


def _means(data: np.ndarray, keep: np.ndarray, segments: Sequence[Segment]) -> np.ndarray:
    return np.array([data[s.start:s.stop][keep[s.start:s.stop]].mean(axis=0) for s in segments])


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


# --------------------------------------------------------------------------- checks


def _check_poses(segments: Sequence[Segment], means: np.ndarray, gravity_mps2: float, options: RigFreeOptions) -> int:
    u = rough_directions(means, gravity_mps2)
    distinct: list[np.ndarray] = []
    cos_min = np.cos(np.radians(options.distinct_deg))
    for v in u:
        if all(float(v @ d) < cos_min for d in distinct):
            distinct.append(v)
    if len(distinct) < options.min_distinct_poses:
        raise FitError(f"too few distinct poses: {len(distinct)} orientations at least {options.distinct_deg:g} deg "
                       f"apart among {len(segments)} still segments; the rig-free fit needs at least "
                       f"{options.min_distinct_poses} (36 or more recommended)")
    d = np.array(distinct)
    eig = np.linalg.eigvalsh(d.T @ d / len(d))
    if eig[0] < options.min_plane_spread:
        tilt = float(np.degrees(np.arcsin(np.sqrt(max(eig[0], 0.0)))))
        raise FitError(f"the poses do not span the sphere: every gravity direction lies within about {tilt:.1f} deg "
                       "of one plane (all poses turned about one axis?); place the unit in orientations all round")
    for k, axis in enumerate("xyz"):
        if d[:, k].max() < options.min_axis_reach or d[:, k].min() > -options.min_axis_reach:
            side = "+" if d[:, k].max() < options.min_axis_reach else "-"
            raise FitError(f"the poses do not span the sphere: no pose has the {side}{axis} axis within "
                           f"{np.degrees(np.arccos(options.min_axis_reach)):.0f} deg of up, so the {axis} offset and "
                           "scale cannot be separated")
    return len(distinct)


def _check_still(session: Session, segments: Sequence[Segment], gyro_unbiased: np.ndarray, accel: np.ndarray,
                 options: RigFreeOptions) -> None:
    ts = 1.0 / session.sample_rate_hz
    for s in segments:
        if len(s) < options.min_segment_samples:
            raise FitError(f"segment {s.index} ({s.kind.label}) has {len(s)} samples; a still segment needs at least "
                           f"{options.min_segment_samples}")
        # the largest rotation away from the segment's start, its own mean rate removed: a hand move (a burst)
        # shows at least half its angle wherever it falls, a constant rate offset that the all-stills bias does
        # not hold (a g-sensitivity in this pose, a random-walk excursion) does not add up over a long still
        w = gyro_unbiased[s.start:s.stop]
        swing = np.cumsum(w - w.mean(axis=0), axis=0) * ts
        turn = float(np.degrees(np.linalg.norm(swing, axis=1).max(initial=0.0)))
        q = max(2, len(s) // 5)
        a0, a1 = accel[s.start:s.start + q].mean(axis=0), accel[s.stop - q:s.stop].mean(axis=0)
        tilt = float(np.degrees(np.arccos(np.clip(_unit(a0) @ _unit(a1), -1.0, 1.0))))
        if max(turn, tilt) > options.still_rotation_deg:
            raise FitError(f"segment {s.index} is labelled {s.kind.label} but the unit moves in it (gyro turns "
                           f"{turn:.1f} deg, gravity direction {tilt:.1f} deg; "
                           f"at most {options.still_rotation_deg:g}); "
                           "relabel it or re-run the still detector")


def _check_moves(session: Session, moves: list[np.ndarray], raw_moves: list[np.ndarray], options: RigFreeOptions,
                 move_index: list[int]) -> None:
    ts = 1.0 / session.sample_rate_hz
    for j, w in enumerate(moves):
        step = float(np.degrees(np.linalg.norm(w, axis=1).max() * ts))
        if step > options.max_step_deg:
            raise FitError(f"move {move_index[j]} turns {step:.1f} deg in one sample at {session.sample_rate_hz:g} Hz: "
                           f"too fast for the sample rate (at most {options.max_step_deg:g} deg per sample); "
                           "move more slowly or sample faster")
    peak = np.abs(session.gyro_radps).max(axis=0)
    for j, raw in enumerate(raw_moves):
        for k in range(3):
            at_peak = np.abs(raw[:, k]) >= peak[k] * (1 - 1e-9)
            if np.convolve(at_peak, np.ones(3), "valid").max(initial=0) >= 3 and peak[k] > 0:
                raise FitError(f"move {move_index[j]}: the gyro's {'xyz'[k]} axis stays at its largest value "
                               f"{peak[k]:.4g} rad/s for 3+ samples: it clips; move more slowly")


def _check_gyro_units(moves: list[np.ndarray], ts: float, ub: np.ndarray, ua: np.ndarray) -> None:
    deg = np.pi / 180.0
    err = {k: float(np.sqrt(np.mean(direction_errors_deg(np.eye(3) * k, moves, ts, ub, ua) ** 2)))
           for k in (1.0, deg, 1.0 / deg)}
    if err[1.0] > 10.0:
        for k, name, given in ((deg, "deg/s", "rad/s"), (1.0 / deg, "rad/s", "deg/s")):
            if err[k] < err[1.0] / 3.0:
                raise FitError(f"the gyro rates look like {name} given as {given}: integrated as {given} "
                               "the moves miss "
                               f"the gravity direction by {err[1.0]:.0f} deg RMS, as {name} by {err[k]:.1f} deg; "
                               "fix the unit (or the sensitivity) of the import")


# --------------------------------------------------------------------------- the fit


@dataclass(frozen=True, eq=False)
class RigFreeData:
    """What the fit works on: the still segments, their drift-corrected accelerometer means, the bias-free
    gyro over each move between consecutive still segments, and the sample period (s)."""

    still: list[Segment]
    accel_means: np.ndarray  # drift-corrected
    moves: list[np.ndarray]  # bias-free gyro over each move
    move_pairs: list[tuple[int, int]]  # (still i, still i+1) indices into ``still``
    ts: float


def prepare(session: Session, options: RigFreeOptions | None = None) -> tuple[RigFreeData, dict[str, Any]]:
    """Checks and data preparation of the rig-free fit (steps 1, 2 and 4 of the module docstring)."""
    options = options or RigFreeOptions()
    check_time(session)
    check_finite(session)
    still = _still(session)
    if len(still) < 2:
        raise FitError(f"{len(still)} still segments (rest or pose): a rig-free fit needs many still poses; "
                       "label them (station import ... runs the still detector)")
    runs = _runs(still)
    with numerics("noise of the still segments"):
        a_noise = white_noise(session, session.accel_mps2, runs, options.outlier_sigma)
        g_noise = white_noise(session, session.gyro_radps, runs, options.outlier_sigma)
    rest = [s for s in still if s.kind == Kind.REST]
    with numerics("accelerometer warm-up (eq. 3) over the initial still"):
        a_drift = (_fit_drift(session, session.accel_mps2, _runs(rest[:1]), a_noise.keep, a_noise.sigma, options,
                              "accel")
                   if rest and len(rest[0]) >= 10 * options.min_segment_samples else None)
    accel = session.accel_mps2 - (_drift_curve(a_drift, session.t_s) if a_drift else 0.0)
    with numerics("gyroscope bias and warm-up (eq. 3) over the still segments"):
        g_drift = _fit_drift(session, session.gyro_radps, runs, g_noise.keep, g_noise.sigma, options, "gyro")
    g_bias = np.array([f.beta[0] for f in g_drift]) + _drift_curve(g_drift, session.t_s)
    gyro = session.gyro_radps - g_bias
    means = _means(accel, a_noise.keep, still)
    n_distinct = _check_poses(still, means, session.gravity_mps2, options)
    ts = 1.0 / session.sample_rate_hz
    with numerics("stale gyro reads (read timing)"):
        timing = (detect_stale_reads(session.gyro_radps, g_noise.sigma) if options.read_timing
                  else ReadTiming.off(len(session), "not looked for (read_timing=False)"))
    moves, raw_moves, pairs = [], [], []
    for i in range(len(still) - 1):
        a, b = still[i].stop - 1, still[i + 1].start + 1
        moves.append(timing.move_rates(gyro, a, b))  # with stale reads: the sensor's samples (readtiming)
        raw_moves.append(session.gyro_radps[a:b])
        pairs.append((i, i + 1))
    extra = {"a_noise": a_noise, "g_noise": g_noise, "a_drift": a_drift, "g_drift": g_drift,
             "n_distinct": n_distinct, "accel": accel, "gyro": gyro, "raw_moves": raw_moves, "read_timing": timing}
    return RigFreeData(still, means, moves, pairs, ts), extra


def _directions(fit: AccelNormFit, means: np.ndarray) -> np.ndarray:
    return _unit(fit.calibrate(means))


def _fit_gyro(prep: RigFreeData, accel: AccelNormFit, pairs: Sequence[int] | None = None,
              initial: np.ndarray | None = None) -> GyroRotationFit:
    u = _directions(accel, prep.accel_means)
    sel = range(len(prep.moves)) if pairs is None else pairs
    ub = np.array([u[prep.move_pairs[j][0]] for j in sel])
    ua = np.array([u[prep.move_pairs[j][1]] for j in sel])
    return fit_gyro_rotations([prep.moves[j] for j in sel], prep.ts, ub, ua, initial=initial)


@dataclass(frozen=True, eq=False)
class Fold:
    """One fold of the leave-poses-out cross-validation: ``held`` (still segments held out, bool (m,)), the
    gravity direction of every still segment from the accelerometer fitted without them (unit vectors (m, 3)),
    the gravity-norm error of the held-out ones (m/s^2), and the moves to fit on (``train``) and to test."""

    held: np.ndarray
    u: np.ndarray
    norm_error_mps2: np.ndarray
    train: list[int]
    test: list[int]


def folds(session: Session, prep: RigFreeData, extra: dict[str, Any], options: RigFreeOptions) -> list[Fold]:
    """The accelerometer side of :func:`cross_validate`: every k-th pose held out (k = ``options.cv_folds``, the
    rest never), the accelerometer fitted to the other still segments as in the full fit (drift of eq. 3
    included); the moves touching a held-out pose are the fold's test moves, the others its training moves."""
    k = options.cv_folds
    g = session.gravity_mps2
    keep = extra["a_noise"].keep
    order = np.cumsum([s.kind == Kind.POSE for s in prep.still]) - 1
    is_pose = np.array([s.kind == Kind.POSE for s in prep.still])
    out = []
    for f in range(k):
        held = is_pose & (order % k == f)
        fold = _fit_accel(session, [s for s, h in zip(prep.still, held, strict=True) if not h], extra, options)
        means = _means(session.accel_mps2 - fold.drift, keep, prep.still)
        out.append(Fold(
            held=held, u=_unit(fold.norm.calibrate(means)),
            norm_error_mps2=norm_residuals(fold.norm.a_matrix, fold.norm.bias, means[held], g),
            train=[j for j, (i0, i1) in enumerate(prep.move_pairs) if not (held[i0] or held[i1])],
            test=[j for j, (i0, i1) in enumerate(prep.move_pairs) if held[i0] or held[i1]]))
    return out


def calibrated_accel(session: Session, prep: RigFreeData, extra: dict[str, Any],
                     options: RigFreeOptions) -> np.ndarray:
    """The specific force (m/s^2, (n, 3)) of every sample through the accelerometer fitted to all still segments
    (step 3, its drift of eq. 3 removed)."""
    fit = _fit_accel(session, prep.still, extra, options)
    return fit.norm.calibrate(session.accel_mps2 - fit.drift)


def still_directions(session: Session, prep: RigFreeData, extra: dict[str, Any],
                     options: RigFreeOptions) -> np.ndarray:
    """The gravity direction of every still segment (unit vectors (m, 3)) from the accelerometer fitted to all of
    them (step 3), as the full fit matches the moves to."""
    return _unit(_means(calibrated_accel(session, prep, extra, options), extra["a_noise"].keep, prep.still))


def cross_validate(session: Session, prep: RigFreeData, extra: dict[str, Any], options: RigFreeOptions,
                   full_gyro: np.ndarray) -> dict[str, Any]:
    """k-fold leave-poses-out (:func:`folds`): the accelerometer's gravity-norm error on the held-out poses; the
    gyro fitted to the moves between two kept segments, with that fold's gravity directions, and its direction
    error on the moves touching a held-out pose (a move touching two folds keeps the later fold's). (The still
    labels, the gyro bias model and the read timing come from the whole recording.)"""
    is_pose = np.array([s.kind == Kind.POSE for s in prep.still])
    norm_err = np.full(len(prep.still), np.nan)
    dir_err = np.full(len(prep.moves), np.nan)
    pairs = np.array(prep.move_pairs)
    for fold in folds(session, prep, extra, options):
        norm_err[fold.held] = fold.norm_error_mps2
        train, test = fold.train, fold.test
        gyr = fit_gyro_rotations([prep.moves[j] for j in train], prep.ts, fold.u[pairs[train, 0]],
                                 fold.u[pairs[train, 1]], initial=full_gyro)
        dir_err[test] = direction_errors_deg(gyr.c_matrix, [prep.moves[j] for j in test], prep.ts,
                                             fold.u[pairs[test, 0]], fold.u[pairs[test, 1]])
    norm_err, dir_err = norm_err[is_pose], dir_err[np.isfinite(dir_err)]
    return {
        "folds": options.cv_folds,
        "scheme": "every k-th pose held out (k = folds), the rest never; moves touching a held-out pose held out",
        "accel_norm_rms_mps2": float(np.sqrt(np.mean(norm_err**2))),
        "gyro_direction_rms_deg": float(np.sqrt(np.mean(dir_err**2))),
        "accel_norm_error_mps2": [round(float(v), 7) for v in norm_err],
        "gyro_direction_error_deg": [round(float(v), 5) for v in dir_err],
    }


def _inverse_std(matrix: np.ndarray, cov: np.ndarray, index: Sequence[tuple[int, int]]) -> np.ndarray:
    """Standard uncertainty of the elements of ``inv(matrix)`` by linear propagation (d inv = -inv dX inv)."""
    inv = np.linalg.inv(matrix)
    jac = np.zeros((9, len(index)))
    for k, (i, j) in enumerate(index):
        e = np.zeros((3, 3))
        e[i, j] = 1.0
        jac[:, k] = (-inv @ e @ inv).ravel()
    return np.sqrt(np.clip(np.diag(jac @ cov @ jac.T), 0.0, None)).reshape(3, 3)


def _drift_params(fits: list[AxisFit] | None) -> dict[str, np.ndarray]:
    if fits is None:
        nan = np.full(3, np.nan)
        z = np.zeros(3)
        return {"bias_drift": z, "bias_drift_std": z, "correlation_time_s": nan, "correlation_time_s_std": nan,
                "drift_noise": z, "drift_noise_std": z}
    return {
        "bias_drift": np.array([f.beta[-1] for f in fits]),
        "bias_drift_std": np.array([np.sqrt(max(f.beta_cov[-1, -1], 0.0)) for f in fits]),
        "correlation_time_s": np.array([f.tc_s for f in fits]),
        "correlation_time_s_std": np.array([f.tc_std_s for f in fits]),
        "drift_noise": np.array([f.drift_noise for f in fits]),
        "drift_noise_std": np.array([f.drift_noise_std for f in fits]),
    }


def fit_rig_free(session: Session, options: RigFreeOptions | None = None) -> ParameterSet:
    """Fit today's parameter set to a hand-held multi-position recording (see the module docstring)."""
    with threadpool_limits(limits=1, user_api="blas"), numerics(f"rig-free fit of {session.serial!r}"):
        return _fit(session, options or RigFreeOptions())


def _a_param_cov(m: np.ndarray, b: np.ndarray, cov9: np.ndarray) -> np.ndarray:
    """Covariance of (A00, A01, A02, A11, A12, A22, b) with A = M^-1 from that of (M00, ..., M22, b): linear."""
    def f(x: np.ndarray) -> np.ndarray:
        mm = np.zeros((3, 3))
        for k, (i, j) in enumerate(UPPER_TRIANGLE):
            mm[i, j] = x[k]
        a = np.linalg.inv(mm)
        return np.array([a[i, j] for i, j in UPPER_TRIANGLE] + list(x[6:9]))

    x0 = np.array([m[i, j] for i, j in UPPER_TRIANGLE] + list(b))
    jac = np.empty((9, 9))
    for k in range(9):
        h = 1e-7 * max(1.0, abs(x0[k]))
        e = np.zeros(9)
        e[k] = h
        jac[:, k] = (f(x0 + e) - f(x0 - e)) / (2 * h)
    return jac @ cov9 @ jac.T


def _joint_accel(session: Session, still: list[Segment], extra: dict[str, Any], initial: AccelNormFit,
                 options: RigFreeOptions) -> AccelJointFit:
    """Step 3 with the drift of eq. (3) fitted jointly over every still block (rest and poses)."""
    a_noise, a_drift = extra["a_noise"], extra["a_drift"]
    zeros = np.zeros((len(session), 3))
    ts = 1.0 / session.sample_rate_hz
    blocks = make_blocks(session.t_s, session.accel_mps2, zeros, zeros, a_noise.keep, _runs(still), ts,
                         options.max_blocks)
    rest = [s for s in still if s.kind == Kind.REST]
    t_fix = float(session.t_s[rest[0].stop - 1] - session.t_s[rest[0].start]) if rest else session.duration_s / 3
    tc, free, d0 = np.full(3, max(t_fix, 2.0)), np.zeros(3, dtype=bool), np.zeros(3)
    for k in range(3):
        f = a_drift[k] if a_drift else None
        if f is not None and f.drift_resolved and np.isfinite(f.tc_s):
            tc[k], free[k], d0[k] = f.tc_s, True, f.beta[-1]
    span = float(session.t_s[-1]) + ts
    bounds = options.tc_range_s.get("accel", (2.0, 50.0 * span))
    tc = np.clip(tc, bounds[0] * 1.0001, bounds[1] * 0.9999)
    return fit_accel_joint(blocks.t_s, blocks.width_s, blocks.y, blocks.count, blocks.segment, a_noise.sigma,
                           session.gravity_mps2, initial=initial, tc_s=tc, tc_free=free, drift0=d0,
                           tc_bounds_s=(float(bounds[0]), float(bounds[1])))


@dataclass(frozen=True, eq=False)
class _AccelResult:
    norm: AccelNormFit  # A, b and their covariance; residuals over the segments fitted
    joint: AccelJointFit | None  # with the drift of eq. (3), None for imu_tk's model
    drift: np.ndarray  # (n, 3) the drift subtracted from the accelerometer (m/s^2)


def _fit_accel(session: Session, still: list[Segment], extra: dict[str, Any], options: RigFreeOptions) -> _AccelResult:
    """Step 3 on the still segments ``still``: the gravity-norm fit, then (``accel_drift``) the joint fit with eq. 3."""
    keep, g = extra["a_noise"].keep, session.gravity_mps2
    rest_drift = extra["a_drift"] if options.accel_drift else None
    pre = _drift_curve(rest_drift, session.t_s) if rest_drift else np.zeros((len(session), 3))
    with numerics("accelerometer gravity-norm fit"):
        acc0 = fit_accel_norm(_means(session.accel_mps2 - pre, keep, still), g)
    diag = np.diag(acc0.a_matrix)
    if np.any(diag < 0.5) or np.any(diag > 2.0):
        raise FitError(f"accelerometer scale {1 / diag.max():.3g}..{1 / diag.min():.3g} of nominal: not m/s^2 "
                       "(g, counts?); give the sensitivity when importing")
    if not options.accel_drift:
        return _AccelResult(acc0, None, pre)
    with numerics("accelerometer fit with the drift of eq. (3)"):
        joint = _joint_accel(session, still, extra, acc0, options)
    drift = joint.drift_at(session.t_s)
    means = _means(session.accel_mps2 - drift, keep, still)
    a_matrix = np.linalg.inv(joint.misalignment)
    resid = norm_residuals(a_matrix, joint.bias, means, g)
    norm = AccelNormFit(a_matrix=a_matrix, bias=joint.bias,
                        params=np.array([a_matrix[i, j] for i, j in UPPER_TRIANGLE] + list(joint.bias)),
                        cov=_a_param_cov(joint.misalignment, joint.bias, joint.cov[:9, :9]), residual_mps2=resid,
                        scale_mps2=float(np.sqrt(np.sum(resid**2) / max(len(resid) - 9, 1))), gravity_mps2=g)
    return _AccelResult(norm, joint, drift)


def _gyro_cov_with_frame(gyr: GyroRotationFit, prep: RigFreeData, accel_fit: _AccelResult, session: Session,
                         keep: np.ndarray) -> np.ndarray:
    """C's covariance plus that of the accelerometer's frame: the gravity directions the rotations are matched to
    come from the fitted accelerometer, whose errors turn every direction alike (linear propagation through the
    implicit function of the gyro fit). With the drift of eq. (3) the directions depend on (M, b, b_drift, T_c)
    jointly, and their joint covariance is used (b and b_drift are strongly correlated)."""
    i0 = np.array([i for i, _ in prep.move_pairs])
    i1 = np.array([j for _, j in prep.move_pairs])
    joint = accel_fit.joint
    raw_means = _means(session.accel_mps2, keep, prep.still)
    if joint is not None:
        free = np.flatnonzero(joint.tc_free)
        t_seg = [session.t_s[s.start:s.stop][keep[s.start:s.stop]] for s in prep.still]
        x0 = np.concatenate([[joint.misalignment[i, j] for i, j in UPPER_TRIANGLE], joint.bias, joint.drift,
                             np.log(joint.tc_s[free])])
        cov = joint.cov

        def directions(x: np.ndarray) -> np.ndarray:
            m = np.zeros((3, 3))
            for k, (i, j) in enumerate(UPPER_TRIANGLE):
                m[i, j] = x[k]
            tc = joint.tc_s.copy()
            tc[free] = np.exp(x[12:])
            e = np.array([np.exp(-t[:, None] / tc).mean(axis=0) for t in t_seg])
            return _unit((raw_means - x[9:12] * e - x[6:9]) @ np.linalg.inv(m).T)
    else:
        x0, cov = accel_fit.norm.params, accel_fit.norm.cov

        def directions(x: np.ndarray) -> np.ndarray:
            a, b = accel_from_params(x)
            return _unit((prep.accel_means - b) @ a.T)

    def residual(x: np.ndarray) -> np.ndarray:
        u = directions(x)
        return (u[i1] - np.einsum("nji,nj->ni", gyr.rotations, u[i0])).ravel()

    d = np.empty((3 * len(i0), len(x0)))
    for k in range(len(x0)):
        h = 1e-7 * max(1.0, abs(x0[k]))
        e = np.zeros(len(x0))
        e[k] = h
        d[:, k] = (residual(x0 + e) - residual(x0 - e)) / (2 * h)
    sens = -np.linalg.solve(gyr.jac.T @ gyr.jac, gyr.jac.T @ d)
    return gyr.cov + sens @ cov @ sens.T


def _timing_report(t: ReadTiming) -> dict[str, Any]:
    def num(v: float) -> float | None:
        return round(float(v), 6) if np.isfinite(v) else None

    return {
        "selected": t.selected, "reason": t.reason,
        "period_reads": num(t.period_reads), "period_reads_std": num(t.period_std),
        "drift_reads_per_cycle2": num(t.drift_reads), "drift_std": num(t.drift_std),
        "offsets_reads": [num(v) for v in t.offsets], "candidates": t.candidates, "on_grid": t.on_grid,
        "rayleigh": num(t.rayleigh), "p_value": float(t.p_value), "residual_reads": num(t.residual_reads),
        "stale_reads": [int(v) for v in t.stale.sum(axis=0)],
        "model": "stale read of axis i in beat cycle j at read c_i + P j + Q j^2; sensor period = read period "
                 "* P_j / (P_j - 1), P_j = P + 2 Q j (station.fit.readtiming)",
    }


def _fit(session: Session, options: RigFreeOptions) -> ParameterSet:
    prep, extra = prepare(session, options)
    g = session.gravity_mps2
    accel_fit = _fit_accel(session, prep.still, extra, options)
    acc, joint = accel_fit.norm, accel_fit.joint
    a_noise, g_noise = extra["a_noise"], extra["g_noise"]
    accel_data = session.accel_mps2 - accel_fit.drift
    prep = replace(prep, accel_means=_means(accel_data, a_noise.keep, prep.still))
    u = _directions(acc, prep.accel_means)
    ub = np.array([u[i] for i, _ in prep.move_pairs])
    ua = np.array([u[j] for _, j in prep.move_pairs])
    _check_gyro_units(prep.moves, prep.ts, ub, ua)
    _check_still(session, prep.still, extra["gyro"], extra["accel"], options)
    _check_moves(session, prep.moves, extra["raw_moves"], options,
                 [prep.still[i].index + 1 for i, _ in prep.move_pairs])
    with numerics("gyroscope rotation fit"):
        gyr = fit_gyro_rotations(prep.moves, prep.ts, ub, ua)
    cv: dict[str, Any] = {}
    if options.cv_folds >= 2 and len(prep.still) >= 2 * options.cv_folds:
        with numerics("cross-validation"):
            cv = cross_validate(session, prep, extra, options, gyr.c_matrix)

    gyro_cov = _gyro_cov_with_frame(gyr, prep, accel_fit, session, a_noise.keep)
    m_w = np.linalg.inv(gyr.c_matrix)
    m_w_std = _inverse_std(gyr.c_matrix, gyro_cov, [(i, j) for i in range(3) for j in range(3)])
    g_drift = extra["g_drift"]

    def residual(data: np.ndarray) -> np.ndarray:
        res = np.zeros_like(data)
        for s in prep.still:
            res[s.start:s.stop] = data[s.start:s.stop] - data[s.start:s.stop].mean(axis=0)
        return res

    a_res, g_res = residual(accel_data), residual(extra["gyro"])
    mask = np.zeros(len(session), dtype=bool)
    for s in prep.still:
        mask[s.start:s.stop] = True

    rest_fit = extra["a_drift"]
    if joint is not None:
        a_std = joint.std()
        accel_terms = {
            "misalignment": joint.misalignment, "misalignment_std": a_std["misalignment"],
            "bias_static": joint.bias, "bias_static_std": a_std["bias"],
            "bias_drift": joint.drift, "bias_drift_std": a_std["drift"],
            "correlation_time_s": joint.tc_s, "correlation_time_s_std": a_std["tc_s"],
            "drift_noise": np.array([f.drift_noise for f in rest_fit]) if rest_fit else np.zeros(3),
            "drift_noise_std": np.array([f.drift_noise_std for f in rest_fit]) if rest_fit else np.zeros(3),
        }
    else:
        accel_terms = {
            "misalignment": np.linalg.inv(acc.a_matrix),
            "misalignment_std": _inverse_std(acc.a_matrix, acc.cov[:6, :6], UPPER_TRIANGLE),
            "bias_static": acc.bias, "bias_static_std": np.sqrt(np.diag(acc.cov)[6:9]),
            **_drift_params(None),
        }
    accel = TriadParams(
        **accel_terms,
        noise_std=a_noise.sigma, noise_std_std=a_noise.sigma_std,
        allan=residual_allan(session, a_res, a_noise.keep),
        residual_rms=np.sqrt(np.mean(a_res[mask & a_noise.keep] ** 2, axis=0)),
    )
    g_par = _drift_params(g_drift)
    gyro = TriadParams(
        misalignment=m_w, misalignment_std=m_w_std,
        bias_static=np.array([f.beta[0] for f in g_drift]),
        bias_static_std=np.array([np.sqrt(max(f.beta_cov[0, 0], 0.0)) for f in g_drift]),
        **g_par,
        noise_std=g_noise.sigma, noise_std_std=g_noise.sigma_std,
        allan=residual_allan(session, g_res, g_noise.keep),
        residual_rms=np.sqrt(np.mean(g_res[mask & g_noise.keep] ** 2, axis=0)),
    )
    report = {
        "format": FORMAT,
        "convention": CONVENTION,
        "gravity_mps2": g,
        "still_segments": len(prep.still),
        "distinct_poses": extra["n_distinct"],
        "moves": len(prep.moves),
        "accel_norm_rms_mps2": acc.rms_mps2,
        "accel_norm_error_mps2": [round(float(v), 7) for v in acc.residual_mps2],
        "gyro_direction_rms_deg": gyr.rms_deg,
        "gyro_direction_error_deg": [round(float(v), 5) for v in gyr.error_deg],
        "accel_tk": {"matrix": acc.a_matrix.tolist(), "bias_after_matrix": (acc.a_matrix @ acc.bias).tolist()},
        "accel_param_cov": acc.cov.tolist(),
        "accel_param_order": "A00 A01 A02 A11 A12 A22 b0 b1 b2 (A = M^-1, calibrated = A (y - b))",
        "accel_model": "eq. (1) with the drift of eq. (3)" if joint is not None else "imu_tk (no drift)",
        "accel_tc_fitted": joint.tc_free.tolist() if joint is not None else [],
        "accel_block_scale": joint.scale if joint is not None else None,
        "gyro_param_cov": gyro_cov.tolist(),
        "cross_validation": cv,
        "read_timing": _timing_report(extra["read_timing"]),
    }
    verdict_ok = bool(cv) and cv["accel_norm_rms_mps2"] <= 3.0 * max(acc.rms_mps2, 1e-6) and \
        cv["gyro_direction_rms_deg"] <= 3.0 * max(gyr.rms_deg, 1e-6)
    quality = FitQuality(
        rig_free=report,
        gyro_scale_method="rig-free",
        goodness_of_fit=GoodnessOfFit(passed=verdict_ok, failed=() if verdict_ok else ("rig-free cv",), report={
            "format": "station-goodness/1", "tests": [],
            "note": "rig-free fit: judged by leave-poses-out cross-validation (held-out RMS within 3x the fitted "
                    "RMS for the gravity norm and the move rotations)",
        }),
        accel=ResidualFigures(rms=tuple(accel.residual_rms.round(9).tolist())),
        gyro=ResidualFigures(rms=tuple(gyro.residual_rms.round(9).tolist())),
    )
    params = ParameterSet(
        serial=session.serial,
        sample_period_s=1.0 / session.sample_rate_hz,
        moving_average_length=options.moving_average_length,
        accel=accel,
        gyro=gyro,
        quality=quality,
        source={
            "software": f"station {__version__}",
            "method": "rig-free multi-position (gravity norm + move rotations)",
            "samples": len(session),
            "duration_s": round(session.duration_s, 6),
            "sample_rate_hz": session.sample_rate_hz,
            "gravity_mps2": g,
        },
    )
    return assess(params, float(session.t_s[-1]))
