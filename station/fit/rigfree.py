"""The rig-free fit: a hand-held multi-position recording to today's parameter set.

Chosen automatically (:func:`is_rig_free`) when the recording's poses carry no reference, or
asked for with ``station fit --rig-free``. Steps (numerics in :mod:`station.fit.multipos`):

1. Noise and outliers per triad from sample differences within the still segments (as the rig fit).
2. Accelerometer warm-up, eq. (3): ``b_drift exp(-t/T_c)`` per axis from the initial still (the
   ``rest`` segment: there the specific force is constant, so only the drift moves the output),
   with the rig fit's per-axis ML (:func:`station.fit.axis_ml.fit_axis`, design = a constant);
   subtracted before the pose means are taken. Unresolved (Wald test) drift is 0, T_c NaN.
3. Accelerometer M and b_stat from the gravity norm over all still segments (rest and poses), in the
   stated convention (M upper-triangular: the accelerometer's own axes are the frame).
4. Gyroscope bias b_stat, b_drift, T_c from all still segments (rest and poses; the rate there is
   zero up to Earth rate, which the model leaves in the bias), again with ``fit_axis``.
5. Gyroscope M from the rotations between consecutive still segments (RK4 of the calibrated rate
   over each move, matched to the accelerometer's gravity direction before and after).
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

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from threadpoolctl import threadpool_limits

from station import __version__
from station.fit.axis_ml import AxisFit, fit_axis
from station.fit.blocks import make_blocks
from station.fit.boundary import numerics
from station.fit.calibrate import _allan, _noise
from station.fit.checks import check_finite, check_time
from station.fit.multipos import (
    AccelNormFit,
    GyroRotationFit,
    direction_errors_deg,
    fit_accel_norm,
    fit_gyro_rotations,
    norm_residuals,
    rough_directions,
)
from station.fit.params import ParameterSet, TriadParams
from station.kernel.errors import FitError
from station.session.model import Kind, Segment, Session

__all__ = [
    "CONVENTION", "FORMAT", "RigFreeData", "RigFreeOptions", "cross_validate", "fit_rig_free", "is_rig_free", "prepare",
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
        still_rotation_deg: a still segment whose gyro turns (integrated, bias removed) or whose gravity
            direction moves by more than this is refused as a move.
        cv_folds: folds of the leave-poses-out cross-validation (0: none).
        min_segment_samples: still segments shorter than this are refused.
        outlier_sigma, drift_lr_threshold, max_blocks: as in the rig fit (:class:`~station.fit.calibrate.FitOptions`).
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
               sigma: np.ndarray, options: RigFreeOptions) -> list[AxisFit]:
    """Per-axis ``c + b_drift exp(-t/T_c)`` over ``runs`` (eq. 3), the rig fit's ML with a constant design."""
    zeros = np.zeros((len(session), 3))
    blocks = make_blocks(session.t_s, data, zeros, zeros, keep, runs, 1.0 / session.sample_rate_hz, options.max_blocks)
    design = np.ones((len(blocks), 1))
    return [fit_axis(blocks, k, design, float(sigma[k]), lr_threshold=options.drift_lr_threshold) for k in range(3)]


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
        turn = float(np.degrees(np.linalg.norm(gyro_unbiased[s.start:s.stop].sum(axis=0) * ts)))
        q = max(2, len(s) // 5)
        a0, a1 = accel[s.start:s.start + q].mean(axis=0), accel[s.stop - q:s.stop].mean(axis=0)
        tilt = float(np.degrees(np.arccos(np.clip(_unit(a0) @ _unit(a1), -1.0, 1.0))))
        if max(turn, tilt) > options.still_rotation_deg:
            raise FitError(f"segment {s.index} is labelled {s.kind.label} but the unit moves in it (gyro turns "
                           f"{turn:.1f} deg, gravity direction {tilt:.1f} deg; at most {options.still_rotation_deg:g}); "
                           "relabel it or re-run the still detector")


def _check_moves(session: Session, moves: list[np.ndarray], raw_moves: list[np.ndarray], options: RigFreeOptions,
                 move_index: list[int]) -> None:
    ts = 1.0 / session.sample_rate_hz
    for j, (w, raw) in enumerate(zip(moves, raw_moves, strict=True)):
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
                raise FitError(f"the gyro rates look like {name} given as {given}: integrated as {given} the moves miss "
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
        a_noise = _noise(session, session.accel_mps2, runs, options.outlier_sigma)
        g_noise = _noise(session, session.gyro_radps, runs, options.outlier_sigma)
    rest = [s for s in still if s.kind == Kind.REST]
    with numerics("accelerometer warm-up (eq. 3) over the initial still"):
        a_drift = (_fit_drift(session, session.accel_mps2, _runs(rest[:1]), a_noise.keep, a_noise.sigma, options)
                   if rest and len(rest[0]) >= 10 * options.min_segment_samples else None)
    accel = session.accel_mps2 - (_drift_curve(a_drift, session.t_s) if a_drift else 0.0)
    with numerics("gyroscope bias and warm-up (eq. 3) over the still segments"):
        g_drift = _fit_drift(session, session.gyro_radps, runs, g_noise.keep, g_noise.sigma, options)
    g_bias = np.array([f.beta[0] for f in g_drift]) + _drift_curve(g_drift, session.t_s)
    gyro = session.gyro_radps - g_bias
    _check_still(session, still, gyro, accel, options)
    means = _means(accel, a_noise.keep, still)
    n_distinct = _check_poses(still, means, session.gravity_mps2, options)
    ts = 1.0 / session.sample_rate_hz
    moves, raw_moves, pairs = [], [], []
    for i in range(len(still) - 1):
        a, b = still[i].stop - 1, still[i + 1].start + 1
        moves.append(gyro[a:b])
        raw_moves.append(session.gyro_radps[a:b])
        pairs.append((i, i + 1))
    _check_moves(session, moves, raw_moves, options, [still[i].index + 1 for i, _ in pairs])
    extra = {"a_noise": a_noise, "g_noise": g_noise, "a_drift": a_drift, "g_drift": g_drift,
             "n_distinct": n_distinct, "accel": accel, "gyro": gyro}
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


def cross_validate(prep: RigFreeData, gravity_mps2: float, folds: int, full_gyro: np.ndarray) -> dict[str, Any]:
    """k-fold leave-poses-out: every k-th still segment held out; the accelerometer is fitted to the others
    and its gravity-norm error on the held-out ones recorded; the gyro is fitted to the moves between two
    kept segments and its direction error on the moves touching a held-out segment recorded."""
    n = len(prep.still)
    norm_err = np.full(n, np.nan)
    dir_err = np.full(len(prep.moves), np.nan)
    for f in range(folds):
        held = np.arange(n) % folds == f
        acc = fit_accel_norm(prep.accel_means[~held], gravity_mps2)
        norm_err[held] = norm_residuals(acc.a_matrix, acc.bias, prep.accel_means[held], gravity_mps2)
        train = [j for j, (i0, i1) in enumerate(prep.move_pairs) if not (held[i0] or held[i1])]
        test = [j for j, (i0, i1) in enumerate(prep.move_pairs) if held[i0] or held[i1]]
        gyr = _fit_gyro(prep, acc, train, initial=full_gyro)
        u = _directions(acc, prep.accel_means)
        ub = np.array([u[prep.move_pairs[j][0]] for j in test])
        ua = np.array([u[prep.move_pairs[j][1]] for j in test])
        dir_err[test] = direction_errors_deg(gyr.c_matrix, [prep.moves[j] for j in test], prep.ts, ub, ua)
    return {
        "folds": folds,
        "scheme": "every k-th still segment held out (k = folds); moves touching a held-out segment held out",
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


def _fit(session: Session, options: RigFreeOptions) -> ParameterSet:
    prep, extra = prepare(session, options)
    g = session.gravity_mps2
    with numerics("accelerometer gravity-norm fit"):
        acc = fit_accel_norm(prep.accel_means, g)
    diag = np.diag(acc.a_matrix)
    if np.any(diag < 0.5) or np.any(diag > 2.0):
        raise FitError(f"accelerometer scale {1 / diag.max():.3g}..{1 / diag.min():.3g} of nominal: not m/s^2 "
                       "(g, counts?); give the sensitivity when importing")
    u = _directions(acc, prep.accel_means)
    ub = np.array([u[i] for i, _ in prep.move_pairs])
    ua = np.array([u[j] for _, j in prep.move_pairs])
    _check_gyro_units(prep.moves, prep.ts, ub, ua)
    with numerics("gyroscope rotation fit"):
        gyr = fit_gyro_rotations(prep.moves, prep.ts, ub, ua)
    cv: dict[str, Any] = {}
    if options.cv_folds >= 2 and len(prep.still) >= 2 * options.cv_folds:
        with numerics("cross-validation"):
            cv = cross_validate(prep, g, options.cv_folds, gyr.c_matrix)

    a_noise, g_noise = extra["a_noise"], extra["g_noise"]
    m_a = np.linalg.inv(acc.a_matrix)
    m_a_std = _inverse_std(acc.a_matrix, acc.cov[:6, :6], ((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2)))
    m_w = np.linalg.inv(gyr.c_matrix)
    m_w_std = _inverse_std(gyr.c_matrix, gyr.cov, [(i, j) for i in range(3) for j in range(3)])
    g_drift = extra["g_drift"]

    def residual(data: np.ndarray) -> np.ndarray:
        res = np.zeros_like(data)
        for s in prep.still:
            res[s.start:s.stop] = data[s.start:s.stop] - data[s.start:s.stop].mean(axis=0)
        return res

    a_res, g_res = residual(extra["accel"]), residual(extra["gyro"])
    mask = np.zeros(len(session), dtype=bool)
    for s in prep.still:
        mask[s.start:s.stop] = True

    accel = TriadParams(
        misalignment=m_a, misalignment_std=m_a_std,
        bias_static=acc.bias, bias_static_std=np.sqrt(np.diag(acc.cov)[6:9]),
        **_drift_params(extra["a_drift"]),
        noise_std=a_noise.sigma, noise_std_std=a_noise.sigma_std,
        allan=_allan(session, a_res, a_noise.keep),
        residual_rms=np.sqrt(np.mean(a_res[mask & a_noise.keep] ** 2, axis=0)),
    )
    g_par = _drift_params(g_drift)
    gyro = TriadParams(
        misalignment=m_w, misalignment_std=m_w_std,
        bias_static=np.array([f.beta[0] for f in g_drift]),
        bias_static_std=np.array([np.sqrt(max(f.beta_cov[0, 0], 0.0)) for f in g_drift]),
        **g_par,
        noise_std=g_noise.sigma, noise_std_std=g_noise.sigma_std,
        allan=_allan(session, g_res, g_noise.keep),
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
        "gyro_param_cov": gyr.cov.tolist(),
        "cross_validation": cv,
    }
    verdict_ok = bool(cv) and cv["accel_norm_rms_mps2"] <= 3.0 * max(acc.rms_mps2, 1e-6) and \
        cv["gyro_direction_rms_deg"] <= 3.0 * max(gyr.rms_deg, 1e-6)
    quality: dict[str, Any] = {
        "rig_free": report,
        "gyro_scale_method": "rig-free",
        "goodness_of_fit": {
            "format": "station-goodness/1", "passed": verdict_ok, "failed": [] if verdict_ok else ["rig-free cv"],
            "tests": [],
            "note": "rig-free fit: judged by leave-poses-out cross-validation (held-out RMS within 3x the fitted "
                    "RMS for the gravity norm and the move rotations)",
        },
        "accel": {"rms": accel.residual_rms.round(9).tolist()},
        "gyro": {"rms": gyro.residual_rms.round(9).tolist()},
    }
    return ParameterSet(
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
