"""Goodness of fit: does the fitted eq. (1) explain the recording within the noise the fit itself estimated?

Per triad and output axis, the fit residual (measurement minus the fitted mean model, outliers
left out) is averaged over each settled segment. Under the model a segment mean residual has
variance ``v_s = sigma^2 / n_s + q (1 - exp(-2 t_s / T_c))``: the white noise the fit measured
(sample differences) over the segment's ``n_s`` samples, plus the stochastic drift of eq. (3)
(started at 0 at power-on, stationary variance ``q`` = the fitted drift noise squared; without a
resolved T_c its stationary variance). The linear part of eq. (1) (the row of M, b_stat, the
optional g-sensitivity) is re-fitted to the segment means by weighted least squares, giving for
each segment its residual ``e_s`` and leverage ``h_s``. Two statistics:

* per segment kind (rest, pose, rate): ``chi2 = sum e_s^2 / v_s`` against the chi-square
  distribution with ``sum (1 - h_s)`` degrees of freedom;
* per segment: the leave-one-segment-out prediction error in its own standard uncertainty,
  ``z_s = e_s / sqrt(v_s (1 - h_s))``, which names the segment that contradicts the others
  (a pose whose reference is wrong, a rate step off its command). Segments the others cannot
  predict (``h_s`` near 1: e.g. the only pose with an axis down) are not tested.

With known-angle rotations (``angle.N``) the angle residuals enter as their own kind (``move``),
when there are more than three rotations.

Every test runs at the same false-alarm rate, :data:`FALSE_ALARM` for the whole recording split
evenly over the tests (Bonferroni), so a good recording fails with probability below it. A fit
that fails is not a calibration: ``ParameterSet.quality["goodness_of_fit"]`` holds the verdict
(``passed``, ``failed``: which triad and segment kind, and every statistic), the ``station fit``
command exits with :data:`EXIT_GOODNESS` and the sequence counts it as a FAIL of the recording.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy import stats

from station.session.model import Kind, Session

#: probability that a recording that follows the model fails the verdict (all tests together)
FALSE_ALARM = 1e-3
#: segments whose leverage exceeds this are predicted by nothing else and are not tested alone
MAX_LEVERAGE = 0.98
#: exit code of ``station fit`` when the fit fails this test
EXIT_GOODNESS = 3
#: version of the ``goodness_of_fit`` section
FORMAT = "station-goodness/1"

AXES = "xyz"


@dataclass(frozen=True)
class TriadResidual:
    """What the test needs of one fitted triad.

    Attributes:
        name: ``accel`` or ``gyro``.
        residual: measurement minus fitted mean model per sample (sensor unit), (n, 3).
        design: the linear regressors of eq. (1) per sample (reference, 1, force), (n, p).
        runs: settled ``(segment, start, stop)`` runs that entered the fit.
        keep: samples used (not outliers), (n,).
        sigma: white-noise std per sample and axis, (3,).
        drift_var: stationary variance q of the stochastic drift per axis, (3,).
        drift_tc_s: its correlation time per axis (NaN: unresolved), (3,).
        unit_scale, unit: multiply sensor units by this to report in ``unit``.
    """

    name: str
    residual: np.ndarray
    design: np.ndarray
    runs: list[tuple[int, int, int]]
    keep: np.ndarray
    sigma: np.ndarray
    drift_var: np.ndarray
    drift_tc_s: np.ndarray
    unit_scale: float
    unit: str


@dataclass(frozen=True)
class _Axis:
    kind: np.ndarray  # kind code per segment
    index: np.ndarray  # segment index
    e: np.ndarray  # WLS residual
    v: np.ndarray  # variance of a segment mean under the model
    h: np.ndarray  # leverage


def _axis_statistics(session: Session, tri: TriadResidual, k: int) -> _Axis:
    runs = tri.runs
    n_seg = len(runs)
    r = np.empty(n_seg)
    v = np.empty(n_seg)
    x = np.empty((n_seg, tri.design.shape[1]))
    kind = np.empty(n_seg, dtype=int)
    index = np.empty(n_seg, dtype=int)
    tc, q = float(tri.drift_tc_s[k]), float(tri.drift_var[k])
    for i, (seg, a, b) in enumerate(runs):
        keep = tri.keep[a:b]
        n = max(int(keep.sum()), 1)
        r[i] = float(tri.residual[a:b, k][keep].mean()) if keep.any() else 0.0
        x[i] = tri.design[a:b][keep].mean(axis=0) if keep.any() else tri.design[a]
        t = float(session.t_s[a:b].mean())
        share = 1.0 - np.exp(-2.0 * t / tc) if np.isfinite(tc) and tc > 0 else 1.0
        v[i] = tri.sigma[k] ** 2 / n + q * share
        kind[i] = int(session.kind[a])
        index[i] = seg
    v = np.maximum(v, np.finfo(float).tiny)
    w = 1.0 / v
    xw = x * np.sqrt(w)[:, None]
    gram = xw.T @ xw
    inv = np.linalg.pinv(gram, rcond=1e-12)
    e = r - x @ (inv @ (x.T @ (w * r)))
    h = np.clip(np.einsum("ij,jk,ik->i", xw, inv, xw), 0.0, 1.0)
    return _Axis(kind=kind, index=index, e=e, v=v, h=h)


def _count_tests(axes: list[tuple[TriadResidual, int, _Axis]], angle_dof: int) -> int:
    count = 1 if angle_dof > 0 else 0
    for _, _, ax in axes:
        for code in np.unique(ax.kind):
            sel = ax.kind == code
            if float(np.sum(1.0 - ax.h[sel])) >= 0.5:
                count += 1
        count += int(np.count_nonzero(ax.h < MAX_LEVERAGE))
    return max(count, 1)


def goodness_of_fit(
    session: Session, triads: list[TriadResidual], angle: dict[str, Any] | None = None
) -> dict[str, Any]:
    """The verdict and its statistics, JSON-ready (see the module docstring).

    ``angle``: the known-angle fit's ``chi2`` and ``dof`` (angle residuals in their uncertainty), if any.
    """
    axes = [(tri, k, _axis_statistics(session, tri, k)) for tri in triads for k in range(3)]
    angle_dof = int(angle.get("dof", 0)) if angle else 0
    n_tests = _count_tests(axes, angle_dof)
    alpha = FALSE_ALARM / n_tests
    z_limit = float(stats.norm.isf(alpha / 2.0))
    tests: list[dict[str, Any]] = []
    for tri, k, ax in axes:
        for code in np.unique(ax.kind):
            sel = ax.kind == code
            dof = float(np.sum(1.0 - ax.h[sel]))
            chi2 = float(np.sum(ax.e[sel] ** 2 / ax.v[sel]))
            testable = ax.h[sel] < MAX_LEVERAGE
            z = np.zeros(sel.sum())
            z[testable] = ax.e[sel][testable] / np.sqrt(ax.v[sel][testable] * (1.0 - ax.h[sel][testable]))
            worst = int(np.argmax(np.abs(z))) if z.size else 0
            limit = float(stats.chi2.isf(alpha, dof)) if dof >= 0.5 else None
            passed = (limit is None or chi2 <= limit) and bool(np.all(np.abs(z) <= z_limit))
            tests.append({
                "triad": tri.name,
                "kind": Kind(int(code)).label,
                "axis": AXES[k],
                "segments": int(sel.sum()),
                "chi2": round(chi2, 3),
                "dof": round(dof, 3),
                "chi2_limit": None if limit is None else round(limit, 3),
                "worst_segment": int(ax.index[sel][worst]),
                "worst_z": round(float(z[worst]), 3) if z.size else 0.0,
                "worst_offset": float(ax.e[sel][worst] * tri.unit_scale),
                "unit": tri.unit,
                "passed": passed,
            })
    if angle_dof > 0 and angle is not None:
        chi2 = float(angle["chi2"])
        limit = float(stats.chi2.isf(alpha, angle_dof))
        tests.append({"triad": "gyro", "kind": "move", "axis": "xyz", "segments": int(angle.get("rotations", 0)),
                      "chi2": round(chi2, 3), "dof": angle_dof, "chi2_limit": round(limit, 3),
                      "worst_segment": int(angle.get("worst_segment", -1)),
                      "worst_z": round(float(angle.get("worst_z", 0.0)), 3), "worst_offset": None,
                      "unit": "deg", "passed": chi2 <= limit})
    failed = sorted({f"{t['triad']} {t['kind']}" for t in tests if not t["passed"]})
    return {
        "format": FORMAT,
        "passed": not failed,
        "failed": failed,
        "false_alarm": FALSE_ALARM,
        "tests_run": n_tests,
        "z_limit": round(z_limit, 3),
        "tests": tests,
    }


def summary(verdict: dict[str, Any]) -> str:
    """One line naming what failed (the worst test of each failed triad and kind)."""
    parts = []
    for name in verdict["failed"]:
        tri, kind = name.split(" ")
        bad = [t for t in verdict["tests"] if t["triad"] == tri and t["kind"] == kind and not t["passed"]]
        t = max(bad, key=lambda t: abs(t["worst_z"]) + t["chi2"] / max(t["chi2_limit"] or 1.0, 1e-9))
        offset = "" if t["worst_offset"] is None else f", offset {t['worst_offset']:.3g} {t['unit']}"
        limit = "" if t["chi2_limit"] is None else f" (limit {t['chi2_limit']:g})"
        parts.append(f"{name} segments: chi2 {t['chi2']:g} for {t['dof']:g} dof{limit} on axis {t['axis']}, "
                     f"segment {t['worst_segment']} at {t['worst_z']:+.1f} sigma{offset}")
    return "; ".join(parts)
