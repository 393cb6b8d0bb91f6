"""Is the white noise's variance the same in every settled segment? (eq. 1's noise term has one variance per axis.)

The base model (paper eq. 1 with eq. 3's drift) gives each axis white measurement noise of one constant variance;
the rest of the diagnosis tests block *means* and cannot see a noise whose size changes (a gyro whose drive loop
loses Q as the die warms, vibration in the rate holds). Here, per sensor and axis, from the raw samples alone:

1. **Segments.** The settled segments (rest, pose, rate holds; the accelerometer's rate holds are left out: gravity
   turns in the body frame there, the signal is not constant) with :data:`TRIM_S` cut at each end (the transition
   from the move); the moves are never used.
2. **Variance per chunk.** Half the mean square of the first differences, over chunks of :data:`CHUNK` differences:
   white noise of variance ``s^2`` gives ``s^2``; a segment's mean and the slow eq. 3 drift cancel; a stationary
   coloured noise (AR(1), pink, sigma-delta shaped) gives the same value in every segment. Its log is the statistic
   (the log of a variance estimate has a spread that does not depend on the level).
3. **Homogeneity.** A one-way analysis of variance of the chunks' log-variances between segments (the within-segment
   spread of the chunks gives the sampling error empirically, so the test holds for non-Gaussian tails and for the
   correlation of first differences, unlike Bartlett's test with its nominal degrees of freedom). Level: the
   locator's :data:`station.diagnose.locator.ALPHA_LOCATED` shared by the three axes (Bonferroni). An axis whose
   noise is below one converter step (:func:`quantum`) is not tested (the quantized differences' variance depends
   on where the segment's mean falls between steps), nor one with a chunk of differences all zero (an output standing
   still is no white noise); a segment with fewer than :data:`MIN_CHUNKS` chunks is left
   out.
4. **Covariate, or none.** The segments' mean log-variances (weighted by their chunk counts) are regressed on one
   covariate at a time (the die temperature, ``|rate|``, time since power-on); one whose F-test passes at the
   level shared by the covariates and that takes at least the locator's
   :data:`station.diagnose.locator.COVARIATE_SHARE` of the between-segment sum of squares is named (the largest F);
   otherwise "none".

Scipy's ``f_oneway`` and ``f`` distribution do the tests; the first-difference variance is three lines of numpy.
Cost: one pass over the samples (sub-0.1 s for a 15-minute recording at 100 Hz).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import stats

from station.diagnose.locator import ALPHA_LOCATED, COVARIATE_SHARE
from station.diagnose.results import Unexplained
from station.session.model import Kind, Session

#: Cut at each end of a settled segment (s): the end of the move before it, the start of the next.
TRIM_S = 0.25
#: First differences per chunk (about 21 effective degrees of freedom of white noise: 2/3 of them).
CHUNK = 32
#: A segment with fewer chunks than this is left out (no within-segment spread).
MIN_CHUNKS = 2
#: Segments needed for a test of an axis.
MIN_SEGMENTS = 3
#: The family level of one sensor's three axes: the locator's.
ALPHA_AXIS = ALPHA_LOCATED / 3.0
COVARIATES = ("temperature", "|rate|", "time since power-on")
AX = "xyz"
_SETTLED = {"accel": (Kind.REST, Kind.POSE), "gyro": (Kind.REST, Kind.POSE, Kind.RATE)}


@dataclass(frozen=True)
class AxisVariance:
    """One axis's test: ``tested`` False when its noise is below a converter step or too few segments hold data."""

    sensor: str
    axis: str
    tested: bool
    segments: int
    chunks: int
    f_stat: float
    p_value: float
    #: ratio of the largest to the smallest segment std (of those with the most chunks' weight: the 10 and 90 %)
    std_ratio: float
    #: the covariate the log-variance follows ("none" when none passes), its F-test p and the std ratio over its range
    covariate: str
    covariate_p: float
    covariate_std_ratio: float
    #: segment kinds holding a segment whose variance is significantly above the axis's median segment
    kinds_above: tuple[str, ...]
    #: kind -> variance relative to the axis's pooled (chunk-weighted geometric mean) variance
    ratio_by_kind: dict[str, float]

    @property
    def significant(self) -> bool:
        return self.tested and self.p_value < ALPHA_AXIS


def quantum(x: np.ndarray) -> float:
    """The converter step of a recorded axis: the smallest gap between distinct values (0 for unquantized data)."""
    u = np.unique(x[np.isfinite(x)])
    if len(u) < 2:
        return 0.0
    gaps = np.diff(u)
    gaps = gaps[gaps > 1e-9 * float(np.max(np.abs(u)))]
    return float(gaps.min()) if len(gaps) else 0.0


def _chunks(x: np.ndarray) -> np.ndarray:
    d = np.diff(x)
    m = len(d) // CHUNK
    return 0.5 * np.mean(d[: m * CHUNK].reshape(m, CHUNK) ** 2, axis=1)


def _untested(sensor: str, k: int, segments: int, chunks: int) -> AxisVariance:
    nan = math.nan
    return AxisVariance(sensor, AX[k], False, segments, chunks, nan, nan, nan, "none", nan, nan, (), {})


def test_axis(session: Session, sensor: str, k: int) -> AxisVariance:
    """The homogeneity of axis ``k``'s white-noise variance over the settled segments (module docstring)."""
    data = session.accel_mps2 if sensor == "accel" else session.gyro_radps
    x = data[:, k]
    fs = session.sample_rate_hz
    trim = max(2, round(TRIM_S * fs))
    logs: list[np.ndarray] = []
    kinds: list[str] = []
    cov: list[tuple[float, float, float]] = []
    for seg in session.segments_of(*_SETTLED[sensor]):
        a, b = seg.start + trim, seg.stop - trim
        if b - a < MIN_CHUNKS * CHUNK + 1:
            continue
        v = _chunks(x[a:b])
        if not np.all(np.isfinite(v)):
            continue
        if np.any(v <= 0.0):  # a quantized axis standing on one step: no noise to measure
            return _untested(sensor, k, len(logs), 0)
        logs.append(np.log(v))
        kinds.append(seg.kind.label)
        temp = session.temp_degc[a:b]
        cov.append((float(np.nanmean(temp)) if np.isfinite(temp).any() else math.nan,
                    float(np.linalg.norm(np.mean(session.gyro_radps[a:b], axis=0))),
                    float(np.mean(session.t_s[a:b]))))
    nchunks = sum(len(g) for g in logs)
    if len(logs) < MIN_SEGMENTS:
        return _untested(sensor, k, len(logs), nchunks)
    allv = np.exp(np.concatenate(logs))
    if math.sqrt(float(np.median(allv))) < quantum(x):  # below one converter step
        return _untested(sensor, k, len(logs), nchunks)
    f_stat, p = stats.f_oneway(*logs)
    w = np.array([len(g) for g in logs], float)
    mean = np.array([g.mean() for g in logs])
    pooled = float(np.sum(w * mean) / w.sum())
    within = float(sum(np.sum((g - g.mean()) ** 2) for g in logs) / (nchunks - len(logs)))
    lo, hi = np.percentile(mean, [10, 90])
    ratio = math.exp(0.5 * (hi - lo))
    med = float(np.median(mean))
    z = stats.norm.isf(ALPHA_AXIS)
    above = sorted({kd for kd, m, n in zip(kinds, mean, w, strict=True) if m - med > z * math.sqrt(within / n)})
    by_kind = {kd: round(math.exp(float(np.sum(w[sel] * mean[sel]) / w[sel].sum()) - pooled), 3)
               for kd in sorted(set(kinds)) for sel in [np.array([q == kd for q in kinds])]}
    name, cp, cratio = "none", math.nan, math.nan
    if p < ALPHA_AXIS:
        name, cp, cratio = _covariate(mean, w, np.array(cov))
        if not above:
            above = [kinds[int(np.argmax(mean))]]
    return AxisVariance(sensor, AX[k], True, len(logs), nchunks, float(f_stat), float(p), ratio, name, cp, cratio,
                        tuple(above), by_kind)


def _covariate(mean: np.ndarray, w: np.ndarray, cov: np.ndarray) -> tuple[str, float, float]:
    """The covariate the segments' log-variances follow: a weighted line per covariate, its slope's F-test at the
    level shared by the covariates and at least :data:`COVARIATE_SHARE` of the between-segment sum of squares."""
    m = len(mean)
    ybar = float(np.sum(w * mean) / w.sum())
    ss0 = float(np.sum(w * (mean - ybar) ** 2))
    best: tuple[str, float, float] = ("none", math.nan, math.nan)
    best_f = -math.inf
    for j, name in enumerate(COVARIATES):
        c = cov[:, j]
        if not np.all(np.isfinite(c)) or np.ptp(c) <= 0.0:
            continue
        basis = np.column_stack([np.ones(m), c]) * np.sqrt(w)[:, None]
        coef, *_ = np.linalg.lstsq(basis, mean * np.sqrt(w), rcond=None)
        ss1 = float(np.sum(w * (mean - coef[0] - coef[1] * c) ** 2))
        if ss1 <= 0.0 or ss0 <= 0.0:
            continue
        f = (ss0 - ss1) / (ss1 / (m - 2))
        p = float(stats.f.sf(f, 1, m - 2))
        if p < ALPHA_AXIS / len(COVARIATES) and (ss0 - ss1) >= COVARIATE_SHARE * ss0 and f > best_f:
            best_f = f
            best = (name, p, math.exp(0.5 * abs(coef[1]) * float(np.ptp(c))))
    return best


def test_sensor(session: Session, sensor: str) -> tuple[AxisVariance, ...]:
    return tuple(test_axis(session, sensor, k) for k in range(3))


def _covariate_text(axes: list[AxisVariance]) -> str:
    named = {a.covariate for a in axes}
    if named == {"none"}:
        return ("noise variance changes between segments, no simple covariate (temperature, |rate|, time since "
                "power-on tested)")
    parts = []
    for a in axes:
        if a.covariate == "none":
            parts.append(f"{a.axis}: none")
        else:
            parts.append(f"{a.axis}: std x{a.covariate_std_ratio:.2f} over its range")
    cov = "/".join(sorted(named - {"none"}))
    return f"noise variance follows {cov} ({', '.join(parts)})"


def unexplained(session: Session) -> tuple[Unexplained, ...]:
    """One :class:`Unexplained` entry per sensor with an axis whose white-noise variance is not the same in every
    settled segment: ``dispersion`` holds per segment kind the variance relative to the axis's pooled one, per axis
    of the entry's ``axes`` (the significant ones, all tested); ``excess_chi2`` the between-segment excess."""
    out = []
    for sensor in ("accel", "gyro"):
        tests = test_sensor(session, sensor)
        sig = [a for a in tests if a.significant]
        if not sig:
            continue
        kinds = sorted({kd for a in sig for kd in a.kinds_above})
        all_kinds = sorted({kd for a in sig for kd in a.ratio_by_kind})
        dispersion = {kd: [a.ratio_by_kind.get(kd, 1.0) for a in sig] for kd in all_kinds}
        excess = float(sum((a.f_stat - 1.0) * (a.segments - 1) for a in sig))
        out.append(Unexplained(sensor, tuple(a.axis for a in sig), tuple(kinds), _covariate_text(sig),
                               dispersion, excess))
    return tuple(out)


__all__ = ["ALPHA_AXIS", "CHUNK", "AxisVariance", "quantum", "test_axis", "test_sensor", "unexplained"]
