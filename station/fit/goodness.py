"""Goodness of fit: does the fitted eq. (1) explain the recording within the noise the fit itself estimated?

Per triad and output axis, the fit residual (measurement minus the fitted mean model, outliers
left out) is averaged over each settled segment. Under the model the segment means have the
covariance ``C = diag(sigma^2 / n_s) + q K``: the white noise the fit measured (sample
differences) over each segment's ``n_s`` samples, plus the stochastic drift of eq. (3), a
Gauss-Markov process started at 0 at power-on (``K_ij = exp(-|t_i - t_j| / T_c) - exp(-(t_i + t_j) / T_c)``
at the segment centres; an unresolved T_c is taken as the recording's span).

The drift variance ``q`` is the fit's, bounded by what the recording shows *inside* its segments:
the ML fit alone would take a segment that contradicts its reference for drift noise (q grows
until the offset looks like drift). Differences of consecutive block means within one segment
are free of any segment's offset; their excess over white noise bounds the drift's diffusion
``q / T_c`` (upper end of its 98 % interval, chi-square), so ``q <= D_upper T_c``.

The linear part of eq. (1) (the row of M, b_stat, the optional g-sensitivity) is re-fitted to
the segment means by generalized least squares; with ``P = C^-1 - C^-1 X (X' C^-1 X)^+ X' C^-1``:

* per segment: the leave-one-segment-out prediction error in its own standard uncertainty,
  ``z_s = (P r)_s / sqrt(P_ss)``, which names the segment that contradicts the others (a pose
  whose reference is wrong, a rate step off its command). Segments the others cannot predict
  (``P_ss`` below 2 % of ``(C^-1)_ss``: e.g. the only pose with an axis down) are not tested alone;
* per segment kind K (rest, pose, rate): leaving all its segments out at once,
  ``chi2 = (P r)_K' (P_KK)^+ (P r)_K`` against the chi-square distribution with ``rank(P_KK)``
  degrees of freedom.

With known-angle rotations (``angle.N``) the angle residuals enter as their own kind (``move``),
when there are more than three rotations.

Every test runs at the same false-alarm rate, :data:`FALSE_ALARM` for the whole recording split
evenly over the tests (Bonferroni), so a good recording fails with probability below it. A fit
that fails is not a calibration: ``ParameterSet.quality.goodness_of_fit`` holds the verdict
(``passed``, ``failed``: which triad and segment kind, and every statistic), the ``station fit``
command exits with :data:`EXIT_GOODNESS` and the sequence counts it as a FAIL of the recording.
"""

from __future__ import annotations

import operator
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy import stats

from station.fit.blocks import Blocks
from station.kernel.parameters import GoodnessOfFit
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


class Rows:
    """Per-sample values (n, p) made for the rows asked only: ``rows[a:b]`` (b - a, p), ``rows[a:b, j]``,
    ``rows[i]`` (p,), ``rows.shape`` (n, p); ``make(lo, hi)`` gives rows ``lo:hi``. The test reads the design and
    the residual one segment at a time, so a long recording's (n, p) matrices are never held whole."""

    def __init__(self, n: int, make: Callable[[int, int], np.ndarray]) -> None:
        self._make = make
        self.shape = (n, int(make(0, min(n, 1)).shape[1]))

    def __len__(self) -> int:
        return self.shape[0]

    def __getitem__(self, key: int | slice | tuple[int | slice, int]) -> np.ndarray:
        column = None
        if isinstance(key, tuple):
            key, column = key
        if isinstance(key, slice):
            start, stop, step = key.indices(self.shape[0])
            if step != 1:
                raise IndexError("Rows takes contiguous rows")
            out = self._make(start, max(start, stop))
        else:
            i = operator.index(key)
            out = self._make(i, i + 1)[0]
        return out if column is None else out[..., column]


@dataclass(frozen=True)
class TriadResidual:
    """What the test needs of one fitted triad.

    Attributes:
        name: ``accel`` or ``gyro``.
        residual: measurement minus fitted mean model per sample (sensor unit), (n, 3): an array or
            :class:`Rows` (read per segment).
        design: the linear regressors of eq. (1) per sample (reference, 1, force), (n, p): an array or a
            :class:`Rows` (read per segment).
        runs: settled ``(segment, start, stop)`` runs that entered the fit.
        keep: samples used (not outliers), (n,).
        sigma: white-noise std per sample and axis, (3,).
        drift_var: variance q of the stochastic drift per axis as fitted, (3,).
        drift_tc_s: its correlation time per axis (NaN: unresolved), (3,).
        blocks: the fit's block means (times, counts, segments), for the within-segment drift bound.
        block_residual: block mean residuals per axis, (m, 3).
        unit_scale, unit: multiply sensor units by this to report in ``unit``.
        reference_var: variance of a still segment's reference per axis (sensor unit^2): 0 for a rig whose
            reference is exact, ``(reference_tolerance_mps2 / 2)^2`` where the recording states a tolerance
            (a hand-held pose).
    """

    name: str
    residual: np.ndarray | Rows
    design: np.ndarray | Rows
    runs: list[tuple[int, int, int]]
    keep: np.ndarray
    sigma: np.ndarray
    drift_var: np.ndarray
    drift_tc_s: np.ndarray
    blocks: Blocks
    block_residual: np.ndarray
    unit_scale: float
    unit: str
    reference_var: float = 0.0


@dataclass(frozen=True)
class _Axis:
    kind: np.ndarray  # kind code per segment
    index: np.ndarray  # segment index
    offset: np.ndarray  # leave-one-out prediction error (sensor unit), NaN where not testable
    z: np.ndarray  # the same in its standard uncertainty, 0 where not testable
    pr: np.ndarray  # P r
    p: np.ndarray  # P
    drift_var: float  # q used


def diffusion_upper(blocks: Blocks, residual: np.ndarray, sigma: float, level: float = 0.01) -> float:
    """Upper end of the 98 % interval of the drift's diffusion q / T_c from within-segment block differences.

    ``d = r_(i+1) - r_i`` for consecutive blocks of one segment has variance
    ``sigma^2 (1/n_i + 1/n_(i+1)) + 2 D lag`` (the Gauss-Markov increment over ``lag`` << T_c);
    D_upper is where ``sum d^2 / var`` falls to the ``level`` quantile of chi-square. Inf without pairs.
    """
    same = blocks.segment[1:] == blocks.segment[:-1]
    if not same.any():
        return float("inf")
    d = np.diff(residual)[same]
    white = sigma**2 * (1.0 / blocks.count[1:] + 1.0 / blocks.count[:-1])[same]
    lag = np.diff(blocks.t_s)[same]
    low = float(stats.chi2.ppf(level, d.size))

    def statistic(diffusion: float) -> float:
        return float(np.sum(d**2 / (white + 2.0 * diffusion * lag)))

    if statistic(0.0) <= low:
        return 0.0
    hi = float(np.max(d**2 / lag)) + 1e-300
    while statistic(hi) > low:
        hi *= 4.0
    lo = 0.0
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if statistic(mid) > low else (lo, mid)
    return hi


def _axis_statistics(session: Session, tri: TriadResidual, k: int) -> _Axis:
    runs = tri.runs
    n_seg = len(runs)
    r = np.empty(n_seg)
    white = np.empty(n_seg)
    t = np.empty(n_seg)
    x = np.empty((n_seg, tri.design.shape[1]))
    kind = np.empty(n_seg, dtype=int)
    index = np.empty(n_seg, dtype=int)
    for i, (seg, a, b) in enumerate(runs):
        keep = tri.keep[a:b]
        n = max(int(keep.sum()), 1)
        r[i] = float(tri.residual[a:b, k][keep].mean()) if keep.any() else 0.0
        x[i] = tri.design[a:b][keep].mean(axis=0) if keep.any() else tri.design[a]
        t[i] = float(session.t_s[a:b].mean())
        kind[i] = int(session.kind[a])
        white[i] = tri.sigma[k] ** 2 / n + (tri.reference_var if kind[i] in (Kind.REST, Kind.POSE) else 0.0)
        index[i] = seg
    tc = float(tri.drift_tc_s[k])
    if not (np.isfinite(tc) and tc > 0):
        tc = max(float(session.t_s[-1]), 1.0)
    q = min(float(tri.drift_var[k]), diffusion_upper(tri.blocks, tri.block_residual[:, k], float(tri.sigma[k])) * tc)
    dist = np.abs(t[:, None] - t[None, :])
    e = np.exp(-t / tc)
    cov = q * (np.exp(-dist / tc) - np.outer(e, e))
    cov[np.diag_indices(n_seg)] += np.maximum(white, np.finfo(float).tiny)
    ci = np.linalg.pinv(cov, hermitian=True)
    cix = ci @ x
    p = ci - cix @ np.linalg.pinv(x.T @ cix, hermitian=True) @ cix.T
    pr = p @ r
    pss = np.clip(np.diag(p), 0.0, None)
    testable = pss > (1.0 - MAX_LEVERAGE) * np.diag(ci)
    z = np.where(testable, pr / np.sqrt(np.where(testable, pss, 1.0)), 0.0)
    offset = np.where(testable, pr / np.where(testable, pss, 1.0), np.nan)
    return _Axis(kind=kind, index=index, offset=offset, z=z, pr=pr, p=p, drift_var=q)


def _kind_test(ax: _Axis, sel: np.ndarray) -> tuple[float, int]:
    """chi2 and degrees of freedom of leaving every segment in ``sel`` out at once."""
    m = ax.p[np.ix_(sel, sel)]
    w, v = np.linalg.eigh(0.5 * (m + m.T))
    keep = w > 1e-9 * max(float(w.max()), 0.0) if w.size and w.max() > 0 else np.zeros(w.size, dtype=bool)
    u = v[:, keep].T @ ax.pr[sel]
    return float(np.sum(u**2 / w[keep])), int(keep.sum())


def _count_tests(axes: list[tuple[TriadResidual, int, _Axis]], angle_dof: int) -> int:
    count = 1 if angle_dof > 0 else 0
    for _, _, ax in axes:
        for code in np.unique(ax.kind):
            count += int(_kind_test(ax, ax.kind == code)[1] > 0)
        count += int(np.count_nonzero(ax.z != 0.0))
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
            chi2, dof = _kind_test(ax, sel)
            z = ax.z[sel]
            worst = int(np.argmax(np.abs(z)))
            limit = float(stats.chi2.isf(alpha, dof)) if dof > 0 else None
            passed = (limit is None or chi2 <= limit) and bool(np.all(np.abs(z) <= z_limit))
            offset = float(ax.offset[sel][worst])
            tests.append({
                "triad": tri.name,
                "kind": Kind(int(code)).label,
                "axis": AXES[k],
                "segments": int(sel.sum()),
                "chi2": round(chi2, 3),
                "dof": dof,
                "chi2_limit": None if limit is None else round(limit, 3),
                "worst_segment": int(ax.index[sel][worst]),
                "worst_z": round(float(z[worst]), 3),
                "worst_offset": None if not np.isfinite(offset) else offset * tri.unit_scale,
                "drift_noise": float(np.sqrt(ax.drift_var)) * tri.unit_scale,
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


def summary(verdict: GoodnessOfFit) -> str:
    """One line naming what failed (the worst test of each failed triad and kind)."""
    parts = []
    for name in verdict.failed:
        tri, kind = name.split(" ")
        bad = [t for t in verdict.report.get("tests", [])
               if t["triad"] == tri and t["kind"] == kind and not t["passed"]]
        t = max(bad, key=lambda t: abs(t["worst_z"]) + t["chi2"] / max(t["chi2_limit"] or 1.0, 1e-9))
        offset = "" if t["worst_offset"] is None else f", offset {t['worst_offset']:.3g} {t['unit']}"
        limit = "" if t["chi2_limit"] is None else f" (limit {t['chi2_limit']:g})"
        parts.append(f"{name} segments: chi2 {t['chi2']:g} for {t['dof']:g} dof{limit} on axis {t['axis']}, "
                     f"segment {t['worst_segment']} at {t['worst_z']:+.1f} sigma{offset}")
    return "; ".join(parts)
