"""Diagnosis of a rig-free (hand-held, multi-position) recording: what it can test and what it cannot.

A rig-free recording has no rig references: still poses at unknown orientations, hand moves
between them (Tedaldi et al. 2014; :mod:`station.fit.rigfree_fit`). The diagnosis here:

1. **Base model** from :func:`station.fit.rigfree_fit.fit_rig_free` (eq. 1 + eq. 3, in its stated frame
   convention). References derived from it, per still segment: the accelerometer's fitted gravity
   direction ``u_i = unit(M_a^-1 (mean_i - b_stat - b_drift g(t)))`` times the local gravity as the
   specific force, and a zero rate for the gyroscope. The moves have no sample-level reference (the
   hand's rate and linear acceleration are what the recording measures, not what it knows), so the
   blocks of the diagnosis are the still segments only; the moves' information (the rotation between
   two stills) is already spent on the gyroscope's M in the base fit.
2. **Candidates** restricted to those such a recording can test: the registry's identifiability rules
   (``Identifiability.rig_free``, :func:`station.diagnose.effect_registry.rig_free_testable`) and what the recording
   holds (``Identifiability.needs``: e.g. a temperature span); the others are listed as :class:`Untestable`
   with the reason. ``bias_random_walk`` and ``outliers`` are tested as on any recording.
3. **Earth rate**: a still gyro sees the Earth rate, whose vertical part ``Omega sin(lat)`` lies along
   gravity in every pose, i.e. it is a g-sensitivity ``Omega sin(lat) / g`` times the identity. With the
   latitude in the metadata (``latitude_deg``) that part is removed as known physics; without it a
   g-sensitivity finding that the vertical Earth rate explains (``G = c I``, ``|c| <= Omega / g``) is
   rejected (a G that it does not explain is named, its diagonal then holding the vertical Earth rate as
   well, at most 0.0042 deg/s per g). The horizontal part ``Omega cos(lat)`` needs the heading of every pose,
   which a hand does not keep: it enters the gyro's block covariance as a per-pose offset of random heading
   (``SensorData.extra_var``), so that neither a candidate nor a bias random walk takes it.

Units: SI inside; the report in the engineering units of :mod:`station.diagnose.candidates`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import replace
from typing import Any

import numpy as np
from scipy import stats
from threadpoolctl import threadpool_limits

from station.diagnose.effect_registry import REGISTRY, rig_free_testable
from station.diagnose.locator import TABLE1_DRIFT, DriftClass
from station.diagnose.outcome import Diagnosis, ResidualCurve
from station.diagnose.residuals import SENSORS, BaseFitNoise, Baseline, baseline_from_params, locate, warmup_ranges
from station.diagnose.results import (
    Compensation,
    DiagnosisReport,
    Finding,
    Rejection,
    RerunError,
    RigFreeSection,
    Untestable,
)
from station.diagnose.selection import select
from station.fit.rigfree_fit import RigFreeOptions, fit_rig_free
from station.kernel.constants import EARTH_RATE_RADPS
from station.session.model import Kind, Session

__all__ = ["EARTH_P", "EDGE_S", "Untestable", "diagnose_rig_free", "earth_horizontal_radps", "earth_vertical_radps",
           "horizontal_earth_var", "rig_free_baseline", "rig_free_candidates", "rig_free_references", "trimmed_kinds"]

#: Trimmed from both ends of every still pose before the diagnosis (s): the hand's release and pick-up.
EDGE_S = 0.5
#: A g-sensitivity consistent with the vertical Earth rate at this p-value (or more) is rejected as Earth rate.
EARTH_P = 1e-3


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _still(session: Session) -> list:
    return session.segments_of(Kind.REST, Kind.POSE)


def rig_free_references(session: Session, params: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(specific force reference (n, 3) m/s^2, rate reference (n, 3) rad/s, gravity direction per still (s, 3)):
    in each still segment ``g u_i`` and 0, elsewhere NaN (no reference). ``u_i`` is the fitted accelerometer's
    gravity direction of still i, in the rig-free fit's frame (eq. 1 inverted with eq. 3's drift removed)."""
    a = params.accel
    m = np.nan_to_num(np.asarray(a.misalignment, dtype=float))
    cal = np.linalg.solve(m, (session.accel_mps2 - a.bias_static - a.warmup_drift(session.t_s)).T).T
    ref_a = np.full((len(session), 3), np.nan)
    ref_w = np.full((len(session), 3), np.nan)
    dirs = []
    for s in _still(session):
        u = _unit(np.median(cal[s.start:s.stop], axis=0))
        dirs.append(u)
        ref_a[s.start:s.stop] = session.gravity_mps2 * u
        ref_w[s.start:s.stop] = 0.0
    return ref_a, ref_w, np.array(dirs)


def trimmed_kinds(session: Session, edge_s: float | None = None) -> np.ndarray:
    """The session's segment kinds with ``EDGE_S`` at both ends of every pose (and the end of the rest) relabelled
    as move: a hand lets the unit go and takes it up there, and that motion is no sensor outlier and no
    offset of the still's mean."""
    edge = round((EDGE_S if edge_s is None else edge_s) * session.sample_rate_hz)
    kind = np.array(session.kind, dtype=np.int8)
    for s in _still(session):
        lo = s.start + (edge if s.kind == Kind.POSE else 0)
        hi = s.stop - edge
        if hi - lo < max(20, edge):  # too short to trim: the whole still goes with the moves
            kind[s.start:s.stop] = int(Kind.MOVE)
            continue
        kind[s.start:lo] = int(Kind.MOVE)
        kind[hi:s.stop] = int(Kind.MOVE)
    return kind


def earth_vertical_radps(session: Session) -> float | None:
    """``Omega sin(latitude)`` (rad/s), the Earth rate's vertical part, or None without ``latitude_deg``."""
    lat = session.meta_float("latitude_deg")
    return None if lat is None else EARTH_RATE_RADPS * math.sin(math.radians(lat))


def rig_free_baseline(
    session: Session, *, warmup_tc_s: Mapping[str, tuple[float, float]] | None = None, max_settled_blocks: int = 150
) -> Baseline:
    """The base fit (:func:`fit_rig_free`) and both triads' residuals against it, on the still segments.

    Earth rate: with ``latitude_deg`` in the metadata, the vertical Earth rate along each still's gravity
    direction (through the fitted gyro M) is taken out of the gyro's residual as known physics. Its horizontal
    part ``Omega cos(lat)`` points north, and every hand-held pose has its own unknown heading: it enters the
    gyro's block covariance as a per-pose offset of random heading (:func:`horizontal_earth_var`), not as a
    signal a candidate (or a bias random walk) may take.
    Raises :class:`~station.kernel.errors.FitError` when the rig-free fit refuses the recording.
    """
    params = fit_rig_free(session, RigFreeOptions(cv_folds=0, tc_range_s=dict(warmup_tc_s or {})))
    ref_a, ref_w, _ = rig_free_references(session, params)
    kind = trimmed_kinds(session)
    ref_a[kind == int(Kind.MOVE)] = np.nan
    ref_w[kind == int(Kind.MOVE)] = np.nan
    ref_session = session.replace(ref_accel_mps2=ref_a, ref_gyro_radps=ref_w, kind=kind)
    gyro = session.gyro_radps
    vertical = earth_vertical_radps(session)
    m_w = np.asarray(params.gyro.misalignment, dtype=float)
    if vertical is not None:
        up = np.nan_to_num(ref_a) / session.gravity_mps2  # zero outside the stills
        gyro = gyro - vertical * up @ m_w.T
    baseline = baseline_from_params(ref_session, params, gyro_radps=gyro, warmup_tc_s=warmup_tc_s,
                                    max_settled_blocks=max_settled_blocks)
    extra = horizontal_earth_var(baseline, m_w, earth_horizontal_radps(session))
    return replace(baseline, gyro=replace(baseline.gyro, extra_var=extra))


def earth_horizontal_radps(session: Session) -> float:
    """``Omega cos(latitude)`` (rad/s), the Earth rate's horizontal part; without ``latitude_deg`` its largest
    value ``Omega`` (the equator)."""
    lat = session.meta_float("latitude_deg")
    return EARTH_RATE_RADPS * (1.0 if lat is None else abs(math.cos(math.radians(lat))))


def horizontal_earth_var(baseline: Baseline, m_w: np.ndarray, horizontal_radps: float) -> np.ndarray:
    """Per gyro block, the variance (rad/s)^2 per axis of the horizontal Earth rate in a pose of unknown
    heading: ``h (cos psi e1 + sin psi e2)`` with ``e1, e2`` perpendicular to the pose's gravity direction
    ``u`` and psi uniform has the covariance ``h^2/2 (I - u u')``, through the gyro's M. One heading per pose:
    a pose cut into b blocks gets b times it on each block (the pose mean then has the variance once). The rest
    (one heading for the whole initial still) gets none: its offset is the bias the base fit takes."""
    sd = baseline.gyro
    up = sd.block_mean(np.nan_to_num(baseline.session.ref_accel_mps2))
    norm = np.linalg.norm(up, axis=1, keepdims=True)
    up = np.divide(up, norm, out=np.zeros_like(up), where=norm > 0)
    proj = np.eye(3)[None] - up[:, :, None] * up[:, None, :]  # (m, 3, 3)
    cov = 0.5 * horizontal_radps**2 * np.einsum("ij,mjk,lk->mil", m_w, proj, m_w)
    var = np.diagonal(cov, axis1=1, axis2=2).copy()
    pose = sd.kind == int(Kind.POSE)
    blocks = np.bincount(sd.segment[pose].astype(int), minlength=int(sd.segment.max()) + 1) if np.any(pose) else None
    var[~pose] = 0.0
    if blocks is not None:
        var[pose] *= blocks[sd.segment[pose].astype(int)][:, None]
    return var


def rig_free_candidates(baseline: Baseline) -> tuple[dict[str, tuple[str, ...]], list[Untestable]]:
    """Per sensor, the mean candidates the rig-free recording of ``baseline`` can test, and the candidates it
    cannot, with the reason: the registry's rule for rig-free recordings, else what the candidate ``needs``
    when this recording does not excite it (its regressors None or zero, e.g. no temperature span)."""
    rule, not_testable = rig_free_testable()
    out = [Untestable(e, s, r) for e, s, r in not_testable]
    keep: dict[str, tuple[str, ...]] = {}
    for sensor in SENSORS:
        sd = baseline.sensor(sensor)
        here = []
        for name in rule[sensor]:
            effect = REGISTRY[name]
            z = effect.build(baseline, sd) if effect.build is not None else None
            if z is not None and np.any(z):
                here.append(name)
            else:
                out.append(Untestable(name, sensor, f"needs {effect.identifiability.needs}"))
        keep[sensor] = tuple(here)
    return keep, sorted(out, key=lambda u: (u.sensor, u.effect))


def _earth_check(parameters: Mapping[str, Any]) -> tuple[float, float] | None:
    """(c in deg/s per g, p-value) of ``G = c I`` with ``|c| <= Omega / g`` against the fitted g-sensitivity
    (engineering units, per-element std); None when the finding carries no 3x3 matrix."""
    g = np.asarray(parameters.get("value", []), dtype=float)
    s = np.asarray(parameters.get("std", []), dtype=float)
    if g.shape != (3, 3) or s.shape != (3, 3) or not np.all(s > 0):
        return None
    w = 1.0 / s**2
    cmax = math.degrees(EARTH_RATE_RADPS)  # deg/s per g: the whole Earth rate along a 1 g specific force
    c = float(np.clip(np.sum(np.diag(w) * np.diag(g)) / np.sum(np.diag(w)), -cmax, cmax))
    chi2 = float(np.sum(w * (g - c * np.eye(3)) ** 2))
    return c, float(stats.chi2.sf(chi2, 8))


def _earth_rate_rejection(f: Finding, vertical: float | None) -> Rejection | None:
    """A g-sensitivity finding that the vertical Earth rate explains while the latitude is unknown, rejected."""
    if f.effect != "g_sensitivity" or vertical is not None:
        return None
    check = _earth_check(f.parameters)
    if check is None or check[1] < EARTH_P:
        return None
    return Rejection(f.effect, f.sensor, "consistent with the vertical Earth rate (c I, |c| <= 15.04 deg/h per g) "
                     "and the latitude is unknown: give --latitude to the import (latitude_deg in the metadata) to "
                     "test it", {"earth_rate_c_dps_per_g": round(check[0], 6), "p_value": round(check[1], 4),
                                 "parameters": dict(f.parameters)})


def diagnose_rig_free(session: Session, *,
                      warmup_tc_s: Mapping[str, tuple[float, float]] | None = None,
                      resamples: int | None = None, seed: int | None = None,
                      drift_class: DriftClass = TABLE1_DRIFT) -> Diagnosis:
    """Diagnose a rig-free recording (see the module docstring): a :class:`~station.diagnose.outcome.Diagnosis`
    whose report has the keys of ``station-diagnosis/1`` plus ``untestable`` and ``rig_free``.
    ``resamples``, ``seed``: the bootstrap's, as in :func:`station.diagnose.report.diagnose` (None: its defaults).

    Raises :class:`~station.kernel.errors.FitError` when the rig-free fit refuses the recording.
    """
    with threadpool_limits(limits=1, user_api="blas"):
        baseline = rig_free_baseline(session, warmup_tc_s=warmup_tc_s)
        candidates, untestable = rig_free_candidates(baseline)
        boot = {k: v for k, v in (("resamples", resamples), ("seed", seed)) if v is not None}
        # the locator bounds the drift noise by the class of the recording's sensor (``drift_class``: a hand-held
        # recording is usually of another class than the station's Table 1; give its limits file)
        decision = select(baseline, candidates=candidates, locate=True, drift_class=drift_class, rig_moves=False,
                          **boot)
    findings, curves = [], []
    rejected = list(decision.rejected)
    vertical = earth_vertical_radps(session)
    for f in decision.findings:
        earth = _earth_rate_rejection(f, vertical)
        if earth is not None:
            rejected.append(earth)
            continue
        if f.block_residual is not None:
            curves.append(ResidualCurve(f"{f.sensor} {f.effect}", baseline.sensor(f.sensor).t_s, *f.block_residual))
        findings.append(replace(f, calibration=Compensation(f.effect, False, "not assessed on a rig-free recording")))
    rf = baseline.params.quality.rig_free or {}
    report = DiagnosisReport(
        serial=session.serial, method="rig-free", findings=tuple(findings), rejected=tuple(rejected),
        untestable=tuple(untestable), inseparable=decision.inseparable, unexplained=decision.unexplained,
        location=locate(baseline), warmup_tc_range_s=warmup_ranges(baseline), base_fit=BaseFitNoise.of(baseline),
        rig_free=RigFreeSection(
            still_segments=rf.get("still_segments"), moves=rf.get("moves"),
            accel_norm_rms_mps2=rf.get("accel_norm_rms_mps2"), gyro_direction_rms_deg=rf.get("gyro_direction_rms_deg"),
            earth_vertical_removed_dps=None if vertical is None else round(math.degrees(vertical), 6),
            read_timing=rf.get("read_timing"),
            blocks="still segments only (the moves carry no sample-level reference)"),
        rerun=RerunError("the simulator re-run needs the rig's motion; a hand-held recording's is unknown"))
    return Diagnosis(report=report, baseline=baseline, curves=curves, rerun=None)
