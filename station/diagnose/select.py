"""Which candidate effects the recording supports: nested model comparison on block means.

Data: per sensor, the block-mean residuals of :mod:`station.diagnose.residuals`, three axes
stacked. Noise model per axis (block covariance, eq. 3's drift included):

    C = diag(sigma_w^2 / n_b) + q GM(T_c) + K^2 min(t_i, t_j)

with ``GM(T_c)_ij = exp(-|t_i - t_j|/T_c) - exp(-(t_i + t_j)/T_c)`` (the Gauss-Markov drift
started at power-on, eq. 3; ``T_c`` from the base fit, or the record's span when the base
fit left it unresolved) and ``q`` re-estimated per axis by maximum likelihood; ``K`` is the
``bias_random_walk`` candidate (0 in the base model).

Mean model per axis: the base model's linear terms are re-fitted together with the
candidate (corrections to the row of M, b_stat and b_drift), so a candidate only counts
with what the base model cannot absorb. Decision (forward selection, one effect at a
time): twice the log-likelihood gain must exceed the BIC penalty ``p ln N`` and the
chi^2 critical value at ``ALPHA``, and the error on held-out segments (4-fold by segment)
must fall. Where the best candidate's fitted signal and a competitor's are nearly
collinear with this recording, both are reported as inseparable.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy import linalg, optimize, stats

from station.diagnose.candidates import LIBRARY, RIG_STEPS, engineering
from station.diagnose.residuals import SENSORS, Baseline, SensorData
from station.fit.blocks import block_exp_mean

#: Significance of a single candidate test (chi^2 tail), on top of the BIC.
ALPHA = 1e-5
#: Two candidates are inseparable when each one's fitted signal is explained this well (R^2) by the other.
COLLINEAR_R2 = 0.9
#: Outlier rate per sample and axis that the base fit already tolerates (it rejects them):
#: the paper reports outliers on the accelerometer; none are expected on the gyroscope.
OUTLIER_ALLOWANCE = {"accel": 2e-4, "gyro": 1e-5}
FOLDS = 4
#: A temperature course and a warm-up drift are taken as indistinguishable above this mutual R^2.
WARMUP_R2 = 0.75
#: Candidates that look like the warm-up drift: tested with the drift's T_c re-fitted.
PROFILE_TC = ("temperature_bias", "temperature_scale", "bias_random_walk")


@dataclass
class Test:
    """Outcome of testing one candidate on one sensor at one selection step."""

    effect: str
    sensor: str
    gain: float  # 2 x log-likelihood gain (chi^2 units)
    params: int  # identifiable parameters added
    bic_gain: float  # gain - params ln N
    critical: float
    heldout_before: float = math.nan
    heldout_after: float = math.nan
    theta: np.ndarray = field(default_factory=lambda: np.zeros(0))
    cov: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    signal: np.ndarray = field(default_factory=lambda: np.zeros(0))  # whitened fitted signal of the effect
    span: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))  # whitened effect columns

    @property
    def passes(self) -> bool:
        return self.params > 0 and self.bic_gain > 0 and self.gain > self.critical


class SensorProblem:
    """The stacked block problem of one sensor; see the module docstring."""

    def __init__(self, baseline: Baseline, sd: SensorData) -> None:
        self.sd = sd
        self.m = len(sd.t_s)
        t = sd.t_s
        self.white = (sd.sigma[None, :] ** 2) / sd.count[:, None]  # (m, 3)
        span = float(t.max() + 0.5 * sd.width_s.max())
        self.dist = np.abs(t[:, None] - t[None, :])
        self.tsum = t[:, None] + t[None, :]
        self.tmin = np.minimum(t[:, None], t[None, :])
        self.tc = np.array([tc if np.isfinite(tc) and tc > 0 else span for tc in sd.params.correlation_time_s])
        self.gm = [np.exp(-self.dist / tc) - np.exp(-self.tsum / tc) for tc in self.tc]
        ref_b = sd.block_mean(sd.ref)
        self.base: list[np.ndarray] = []
        self._ref_cols = [ref_b[:, j] for j in range(3) if np.ptp(ref_b[:, j]) > 1e-9 * max(1.0, np.abs(ref_b).max())]
        for k in range(3):
            self.base.append(self._base_design(float(self.tc[k])))
        self.n_rows = 3 * self.m
        self.q = np.zeros(3)
        self.k2 = 0.0
        self.accepted: list[np.ndarray] = []  # block regressors (m, 3, p) of accepted mean effects
        self._fit_q()
        self.refit_drift()

    def _base_design(self, tc: float) -> np.ndarray:
        """Base linear terms of one axis: corrections to the row of M, b_stat and b_drift exp(-t/T_c) (eq. 3)."""
        return np.column_stack([*self._ref_cols, np.ones(self.m), block_exp_mean(self.sd.t_s, self.sd.width_s, tc)])

    def refit_drift(self) -> None:
        """Re-fit each axis's T_c (and q) with the accepted effects: the base fit's T_c may have absorbed them."""
        for k in range(3):
            extra = self._accepted_axis(k)
            best = (self._axis_nll(k, float(self.q[k]), self.k2, extra), float(self.tc[k]))
            for f in (0.25, 0.5, 0.7, 1.4, 2.0, 4.0):
                tc = float(self.tc[k]) * f
                self.base[k] = self._base_design(tc)
                self.gm[k] = np.exp(-self.dist / tc) - np.exp(-self.tsum / tc)
                val = self._axis_nll(k, float(self.q[k]), self.k2, extra)
                if val < best[0]:
                    best = (val, tc)
            self.tc[k] = best[1]
            self.base[k] = self._base_design(best[1])
            self.gm[k] = np.exp(-self.dist / best[1]) - np.exp(-self.tsum / best[1])
        self._fit_q()

    # --- covariance ----------------------------------------------------------
    def chol(self, k: int, q: float, k2: float) -> np.ndarray:
        c = q * self.gm[k] + k2 * self.tmin
        c[np.diag_indices_from(c)] += self.white[:, k]
        return linalg.cholesky(c, lower=True, check_finite=False)

    def _axis_nll(self, k: int, q: float, k2: float, extra: np.ndarray | None) -> float:
        try:
            ch = self.chol(k, q, k2)
        except linalg.LinAlgError:
            return np.inf
        x = self.base[k] if extra is None else np.column_stack([self.base[k], extra])
        xw = linalg.solve_triangular(ch, x, lower=True, check_finite=False)
        yw = linalg.solve_triangular(ch, self.sd.y[:, k], lower=True, check_finite=False)
        beta, *_ = linalg.lstsq(xw, yw, check_finite=False)
        r = yw - xw @ beta
        return 0.5 * float(r @ r) + float(np.log(np.diag(ch)).sum())

    def _profile_q(self, k: int, k2: float, extra: np.ndarray | None) -> tuple[float, float]:
        """(q, nll) maximizing the likelihood of axis k over q >= 0 at fixed K^2."""
        q0 = float(np.median(self.white[:, k]))
        res = optimize.minimize_scalar(lambda u: self._axis_nll(k, q0 * math.exp(u), k2, extra),
                                       bounds=(-12.0, 10.0), method="bounded", options={"xatol": 0.25})
        q = q0 * math.exp(float(res.x))
        nll0 = self._axis_nll(k, 0.0, k2, extra)
        return (0.0, nll0) if nll0 <= res.fun else (q, float(res.fun))

    def _accepted_axis(self, k: int) -> np.ndarray | None:
        if not self.accepted:
            return None
        z = np.concatenate([a[:, k, :] for a in self.accepted], axis=1)
        keep = np.any(z != 0, axis=0)
        return z[:, keep] if keep.any() else None

    def _fit_q(self) -> None:
        for k in range(3):
            self.q[k] = self._profile_q(k, self.k2, self._accepted_axis(k))[0]

    # --- mean fit ----------------------------------------------------------------
    def whitened(self) -> tuple[list[np.ndarray], np.ndarray]:
        chols = [self.chol(k, float(self.q[k]), self.k2) for k in range(3)]
        yw = np.concatenate([linalg.solve_triangular(chols[k], self.sd.y[:, k], lower=True, check_finite=False)
                             for k in range(3)])
        return chols, yw

    def design(self, chols: list[np.ndarray], blocks: list[np.ndarray]) -> tuple[np.ndarray, int]:
        """Whitened stacked design: per-axis base columns (block diagonal), then ``blocks`` (m, 3, p) shared."""
        nb = [b.shape[1] for b in self.base]
        total_base = sum(nb)
        p = sum(b.shape[2] for b in blocks)
        x = np.zeros((self.n_rows, total_base + p))
        col = 0
        for k in range(3):
            rows = slice(k * self.m, (k + 1) * self.m)
            x[rows, col:col + nb[k]] = linalg.solve_triangular(chols[k], self.base[k], lower=True, check_finite=False)
            col += nb[k]
            if p:
                zk = np.concatenate([b[:, k, :] for b in blocks], axis=1)
                x[rows, total_base:] = linalg.solve_triangular(chols[k], zk, lower=True, check_finite=False)
        return x, total_base

    @staticmethod
    def _rank(x: np.ndarray) -> int:
        if x.shape[1] == 0:
            return 0
        norms = np.linalg.norm(x, axis=0)
        xs = x[:, norms > 0] / norms[norms > 0]
        s = np.linalg.svd(xs, compute_uv=False)
        return int(np.sum(s > 1e-7 * s[0])) if len(s) else 0

    def total_nll(self) -> float:
        return sum(self._axis_nll(k, float(self.q[k]), self.k2, self._accepted_axis(k)) for k in range(3))

    def test_mean(self, name: str, zb: np.ndarray) -> Test:
        """Nested test of a mean candidate with block regressors ``zb`` (m, 3, p) against the current model.

        Candidates that compete with the drift (``PROFILE_TC``) get the drift's T_c re-fitted with them.
        """
        chols, yw = self.whitened()
        x0, _ = self.design(chols, self.accepted)
        b0, *_ = linalg.lstsq(x0, yw, check_finite=False)
        chi0 = float(np.sum((yw - x0 @ b0) ** 2))
        r0 = self._rank(x0)
        saved = None
        if name in PROFILE_TC:
            saved = (self.tc.copy(), list(self.base), list(self.gm), self.q.copy())
            # the null gets the same T_c refinement as the alternative: only the candidate may make the gain
            self.refit_drift()
            nll0 = self.total_nll()
            chols, yw = self.whitened()
            x0, _ = self.design(chols, self.accepted)
            r0 = self._rank(x0)
            self.accepted.append(zb)
            self.refit_drift()
            self.accepted.pop()
            chols, yw = self.whitened()
        x1, _ = self.design(chols, [*self.accepted, zb])
        gain_rank = self._rank(x1) - r0
        b1, *_ = linalg.lstsq(x1, yw, check_finite=False)
        chi1 = float(np.sum((yw - x1 @ b1) ** 2))
        gain = chi0 - chi1
        if saved is not None:
            self.accepted.append(zb)
            gain = 2.0 * (nll0 - self.total_nll())
            self.accepted.pop()
            self.tc, self.base, self.gm, self.q = saved
        p = zb.shape[2]
        nfix = x1.shape[1] - p
        zcols = x1[:, nfix:]
        theta = b1[nfix:]
        cov = linalg.pinv(x1.T @ x1)[nfix:, nfix:]
        test = Test(
            effect=name, sensor=self.sd.sensor, gain=gain, params=gain_rank,
            bic_gain=gain - gain_rank * math.log(self.n_rows),
            critical=float(stats.chi2.isf(ALPHA, max(gain_rank, 1))),
            theta=theta, cov=cov, signal=zcols @ theta, span=np.column_stack([x1[:, :nfix], zcols]),
        )
        if test.passes:
            test.heldout_before, test.heldout_after = self.heldout(zb)
        return test

    def heldout(self, zb: np.ndarray) -> tuple[float, float]:
        """Predictive error on held-out segments without/with ``zb``: mean squared Mahalanobis residual
        per held-out block (1 = as expected), under the block covariance, the linear parameters fitted
        by GLS on the other segments (4 folds by segment; the power-on rest always stays in training).
        """
        folds = self.sd.segment % FOLDS
        folds[self.sd.segment == self.sd.segment.min()] = -1
        covs = []
        for k in range(3):
            c = float(self.q[k]) * self.gm[k] + self.k2 * self.tmin
            c[np.diag_indices_from(c)] += self.white[:, k]
            covs.append(c)
        errs = []
        for blocks in (self.accepted, [*self.accepted, zb]):
            total, count = 0.0, 0
            for f in range(FOLDS):
                te = folds == f
                tr = ~te
                if not te.any() or te.sum() < 2:
                    continue
                nb = [b.shape[1] for b in self.base]
                p = sum(b.shape[2] for b in blocks)
                ntr = int(tr.sum())
                x = np.zeros((3 * ntr, sum(nb) + p))
                y = np.zeros(3 * ntr)
                xte, chols = [], []
                col = 0
                for k in range(3):
                    ch = linalg.cholesky(covs[k][np.ix_(tr, tr)], lower=True, check_finite=False)
                    chols.append(ch)
                    xk = np.zeros((self.m, sum(nb) + p))
                    xk[:, col:col + nb[k]] = self.base[k]
                    col += nb[k]
                    if p:
                        xk[:, sum(nb):] = np.concatenate([b[:, k, :] for b in blocks], axis=1)
                    xte.append(xk)
                    rows = slice(k * ntr, (k + 1) * ntr)
                    x[rows] = linalg.solve_triangular(ch, xk[tr], lower=True, check_finite=False)
                    y[rows] = linalg.solve_triangular(ch, self.sd.y[tr, k], lower=True, check_finite=False)
                beta, *_ = linalg.lstsq(x, y, check_finite=False)
                for k in range(3):
                    r = self.sd.y[:, k] - xte[k] @ beta
                    ch = chols[k]
                    a = linalg.cho_solve((ch, True), covs[k][np.ix_(tr, te)], check_finite=False)
                    mu = a.T @ r[tr]
                    cond = covs[k][np.ix_(te, te)] - covs[k][np.ix_(te, tr)] @ a
                    e = r[te] - mu
                    try:
                        cc = linalg.cholesky(cond, lower=True, check_finite=False)
                        ew = linalg.solve_triangular(cc, e, lower=True, check_finite=False)
                    except linalg.LinAlgError:
                        ew = e / np.sqrt(self.white[te, k])
                    total += float(ew @ ew)
                    count += len(e)
            errs.append(total / max(count, 1))
        return errs[0], errs[1]

    # --- random walk -------------------------------------------------------------
    def test_random_walk(self) -> Test:
        """Likelihood gain of a bias random walk K^2 min(t_i, t_j) shared by the three axes (q re-profiled)."""
        def total(k2: float) -> float:
            return sum(self._profile_q(k, k2, self._accepted_axis(k))[1] for k in range(3))

        base_nll = total(self.k2)
        span = float(self.sd.t_s.max())
        k2_0 = float(np.median(self.white)) / max(span, 1.0)
        grid = [k2_0 * 10.0 ** e for e in np.arange(-2.0, 2.01, 1.0)]
        vals = [total(g) for g in grid]
        i = int(np.argmin(vals))
        lo, hi = math.log(grid[max(i - 1, 0)]), math.log(grid[min(i + 1, len(grid) - 1)])
        res = optimize.minimize_scalar(lambda u: total(math.exp(u)), bounds=(lo, hi), method="bounded",
                                       options={"xatol": 0.3, "maxiter": 8})
        k2 = math.exp(float(res.x)) if res.fun < vals[i] else grid[i]
        best = min(float(res.fun), vals[i])
        gain = max(0.0, 2.0 * (base_nll - best))
        # K^2 >= 0 sits on the boundary: the null distribution is half chi^2_1
        crit = float(stats.chi2.isf(2.0 * ALPHA, 1))
        k = math.sqrt(k2)
        # uncertainty of K from the curvature of the profile in log K^2
        h = 0.3
        curv = (total(k2 * math.exp(h)) - 2.0 * best + total(k2 * math.exp(-h))) / h**2
        k_std = k * 0.5 / math.sqrt(curv) if curv > 0 else math.nan
        return Test(effect="bias_random_walk", sensor=self.sd.sensor, gain=gain, params=1,
                    bic_gain=gain - math.log(self.n_rows), critical=crit, theta=np.array([k]),
                    cov=np.array([[k_std**2]]))

    def random_drift(self) -> Test | None:
        """Bias wander the base model can only take as Gauss-Markov drift noise slower than the record.

        On an axis where the fitted drift noise ``sqrt(q)`` exceeds both the deterministic warm-up
        ``|b_drift|`` and 5 block-noise sigmas while ``T_c`` is at least a third of the record, the
        bias wanders like a random walk of density ``K = sqrt(2 q / T_c)`` (the GM covariance for
        ``T_c`` >> t is ``2 q min(t_i, t_j) / T_c``, the random walk's is ``K^2 min(t_i, t_j)``).
        Returns a passing test when two or more axes show it, else None.
        """
        span = float(self.sd.t_s.max())
        drift = np.abs(np.asarray(self.sd.params.bias_drift, dtype=float))
        ks = []
        for k in range(3):
            block_sigma = float(np.sqrt(np.median(self.white[:, k])))
            q = float(self.q[k])
            if self.tc[k] >= span / 3.0 and math.sqrt(q) > max(drift[k], 5.0 * block_sigma):
                ks.append(math.sqrt(2.0 * q / self.tc[k]))
        if len(ks) < 2:
            return None
        k_mean = float(np.mean(ks))
        k_std = float(np.std(ks) / math.sqrt(len(ks))) if len(ks) > 1 else math.nan
        return Test(effect="bias_random_walk", sensor=self.sd.sensor, gain=math.nan, params=1, bic_gain=math.nan,
                    critical=math.nan, theta=np.array([k_mean]), cov=np.array([[k_std**2]]))

    def drift_vs_temperature(self, d_temp_blocks: np.ndarray) -> tuple[float, float]:
        """(chi^2 cost of explaining the warm-up by temperature instead of the exp drift of eq. 3,
        chi^2 cost of no warm-up term at all), summed over axes; both relative to the base model."""
        def nll_with(last: np.ndarray | None) -> float:
            total = 0.0
            for k in range(3):
                saved = self.base[k]
                self.base[k] = saved[:, :-1] if last is None else np.column_stack([saved[:, :-1], last])
                total += self._profile_q(k, self.k2, self._accepted_axis(k))[1]
                self.base[k] = saved
            return total

        base = sum(self._profile_q(k, self.k2, self._accepted_axis(k))[1] for k in range(3))
        return 2.0 * (nll_with(d_temp_blocks) - base), 2.0 * (nll_with(None) - base)

    # --- fit quality ---------------------------------------------------------------
    def quality(self) -> dict[str, Any]:
        """Negative log-likelihood, BIC, block chi^2 per axis (white-noise units) of the current model."""
        chols, yw = self.whitened()
        x, _ = self.design(chols, self.accepted)
        beta, *_ = linalg.lstsq(x, yw, check_finite=False)
        rw = yw - x @ beta
        logdet = sum(float(np.log(np.diag(c)).sum()) for c in chols)
        nll = 0.5 * float(rw @ rw) + logdet
        npar = self._rank(x) + int(np.count_nonzero(self.q)) + (1 if self.k2 > 0 else 0)
        # raw block residual (not whitened) per axis, for the engineer
        raw = np.zeros((self.m, 3))
        nb = [b.shape[1] for b in self.base]
        col = 0
        total_base = sum(nb)
        for k in range(3):
            fit = self.base[k] @ beta[col:col + nb[k]]
            if self.accepted:
                fit = fit + np.concatenate([a[:, k, :] for a in self.accepted], axis=1) @ beta[total_base:]
            col += nb[k]
            raw[:, k] = self.sd.y[:, k] - fit
        chi = np.mean(raw**2 / self.white, axis=0)
        return {"nll": nll, "bic": 2.0 * nll + npar * math.log(self.n_rows), "block_chi2": chi,
                "block_rms": np.sqrt(np.average(raw**2, axis=0, weights=self.sd.count)), "block_residual": raw}


@dataclass
class Decision:
    """All findings, rejected tests and inseparable pairs of one diagnosis (numbers in SI)."""

    findings: list[dict[str, Any]]
    rejected: list[dict[str, Any]]
    inseparable: list[dict[str, Any]]


def _r2(signal: np.ndarray, span: np.ndarray) -> float:
    if not np.any(signal):
        return 0.0
    coef, *_ = linalg.lstsq(span, signal, check_finite=False)
    res = signal - span @ coef
    return 1.0 - float(res @ res) / float(signal @ signal)


def _warmup_shape(prob: SensorProblem, best: Test) -> Test | None:
    """A second exponential warm-up per axis (eq. 3's shape, T_c from 20 s to 5x the record) that explains
    the temperature candidate's signal, and vice versa (R^2 > WARMUP_R2); None when none does."""
    sd = prob.sd
    span = float(sd.t_s.max())
    for tc in np.geomspace(20.0, 5.0 * span, 16):
        col = block_exp_mean(sd.t_s, sd.width_s, float(tc))
        zb = np.zeros((prob.m, 3, 3))
        for k in range(3):
            zb[:, k, k] = col
        t = prob.test_mean("bias_drift (eq. 3 warm-up)", zb)
        if _r2(best.signal, t.span) > WARMUP_R2 and _r2(t.signal, best.span) > WARMUP_R2:
            return t
    return None


def _outlier_test(sd: SensorData) -> dict[str, Any]:
    n = max(sd.settled_samples, 1)
    count = int(sd.outlier_count.sum())
    lam = OUTLIER_ALLOWANCE[sd.sensor] * 3 * n
    p_value = float(stats.poisson.sf(count - 1, lam)) if count > 0 else 1.0
    rate = count / (3 * n)
    return {
        "effect": "outliers", "sensor": sd.sensor, "count": count, "samples": 3 * n,
        "rate": rate, "rate_std": math.sqrt(max(count, 1)) / (3 * n), "allowance": OUTLIER_ALLOWANCE[sd.sensor],
        "p_value": p_value, "accepted": p_value < ALPHA,
        "axes": [k for k in range(3) if sd.outlier_count[k] > OUTLIER_ALLOWANCE[sd.sensor] * n + 3 * math.sqrt(
            OUTLIER_ALLOWANCE[sd.sensor] * n + 1)],
    }


def _affected_axes(name: str, theta: np.ndarray, cov: np.ndarray) -> list[int]:
    std = np.sqrt(np.clip(np.diag(cov), 1e-300, None))
    z = np.abs(theta) / std
    if len(theta) == 3 and name not in ("lever_arm",):
        return [k for k in range(3) if z[k] > 3.0] or [int(np.argmax(z))]
    if len(theta) == 9:
        zz = z.reshape(3, 3)
        return [k for k in range(3) if zz[k].max() > 3.0] or [int(np.argmax(zz.max(axis=1)))]
    return [0, 1, 2]


def select(baseline: Baseline, *, max_effects: int = 4) -> Decision:
    """Forward selection of candidate effects per sensor (see the module docstring)."""
    findings: list[dict[str, Any]] = []
    rejected: list[dict[str, Any]] = []
    inseparable: list[dict[str, Any]] = []
    for sensor in SENSORS:
        sd = baseline.sensor(sensor)
        prob = SensorProblem(baseline, sd)
        regs: dict[str, np.ndarray] = {}
        for name, cand in LIBRARY.items():
            if sensor in cand.sensors:
                z = cand.build(baseline, sd)
                if z is not None and np.any(z):
                    regs[name] = sd.block_mean(z)
                elif z is None:
                    rejected.append({"effect": name, "sensor": sensor, "reason": "not testable: no data for it"})
        pool = set(regs) | {"bias_random_walk"}
        last: dict[str, Test] = {}
        for step in range(max_effects):
            before = prob.quality()
            tests = {name: prob.test_mean(name, regs[name]) for name in sorted(pool - {"bias_random_walk"})}
            if "bias_random_walk" in pool and step == 0:  # more mean terms only lower the residual wander
                tests["bias_random_walk"] = prob.test_random_walk()
            last.update(tests)
            ok = [t for t in tests.values() if t.passes and (
                t.effect == "bias_random_walk" or t.heldout_after < t.heldout_before)]
            if not ok:
                break
            best = max(ok, key=lambda t: t.bic_gain)
            # identifiability: a competitor that explains the same signal about as well
            twins = []
            if best.effect != "bias_random_walk":
                for t in ok:
                    if t is best or t.effect == "bias_random_walk":
                        continue
                    if _r2(best.signal, t.span) > COLLINEAR_R2 and _r2(t.signal, best.span) > COLLINEAR_R2:
                        twins.append(t)
            if best.effect == "temperature_bias":
                # a temperature course looks like the warm-up: does a second drift shape explain it as well?
                shape = _warmup_shape(prob, best)
                if shape is not None:
                    twins.append(shape)
            if twins:
                for t in (best, *twins):
                    pool.discard(t.effect)
                    last.pop(t.effect, None)
                inseparable.append({
                    "effects": [best.effect, *[t.effect for t in twins]], "sensor": sensor,
                    "evidence": {t.effect: {"gain": round(t.gain, 2), "bic_gain": round(t.bic_gain, 2)}
                                 for t in (best, *twins)},
                    "rig_step": "; ".join(RIG_STEPS.get(t.effect, "") for t in (best, *twins) if t.effect in RIG_STEPS),
                })
                continue
            if best.effect == "bias_random_walk":
                prob.k2 = float(best.theta[0] ** 2)
                prob._fit_q()
            else:
                prob.accepted.append(regs[best.effect])
                prob.refit_drift()
            after = prob.quality()
            pool.discard(best.effect)
            last.pop(best.effect, None)
            findings.append(_finding(sd, best, before, after))
        for t in last.values():
            entry: dict[str, Any] = {"effect": t.effect, "sensor": sensor, "gain": round(t.gain, 3),
                                     "bic_gain": round(t.bic_gain, 3), "params": t.params}
            if t.params == 0:
                entry["reason"] = "not identifiable with this recording (absorbed by the base model)"
                entry["rig_step"] = RIG_STEPS[t.effect]
            elif not t.passes:
                entry["reason"] = "no significant improvement"
            else:
                entry["reason"] = "does not improve held-out segments"
            rejected.append(entry)
        if "bias_random_walk" in pool:
            rd = prob.random_drift()
            if rd is not None:
                f = _finding(sd, rd, prob.quality(), prob.quality())
                f["evidence"] = {"note": "drift noise slower than the record and larger than the warm-up drift; "
                                 "a random walk and eq. 3's Gauss-Markov noise with T_c >> record are the same here",
                                 "correlation_time_s": np.round(prob.tc, 1).tolist(),
                                 "rig_step": RIG_STEPS["bias_random_walk"]}
                f["fit"] = {}
                findings.append(f)
                pool.discard("bias_random_walk")
                last.pop("bias_random_walk", None)
        if "temperature_bias" in pool and np.any(baseline.d_temp):
            cost_temp, cost_none = prob.drift_vs_temperature(sd.block_mean(baseline.d_temp))
            lr = baseline.params.quality.get("drift_likelihood_ratio", {}).get(sensor, [0.0])
            # the base fit resolved a warm-up drift, and the temperature course explains it as well
            if max(lr) > 9.0 and cost_temp < 3.0 * math.log(prob.n_rows):
                inseparable.append({
                    "effects": ["temperature_bias", "bias_drift (eq. 3 warm-up)"], "sensor": sensor,
                    "evidence": {"chi2_cost_temperature_instead_of_drift": round(cost_temp, 2),
                                 "chi2_cost_without_warmup": round(cost_none, 2)},
                    "rig_step": RIG_STEPS["temperature_bias"],
                })
        out = _outlier_test(sd)
        if out.pop("accepted"):
            findings.append({
                "effect": "outliers", "sensor": sensor, "axes": [AX[k] for k in out.pop("axes")] or list(AX),
                "parameters": {"rate_per_sample": {"value": out["rate"], "std": out["rate_std"], "unit": "1"}},
                "evidence": {k: out[k] for k in ("count", "samples", "allowance", "p_value")},
                "fit": {},
            })
        else:
            rejected.append({"effect": "outliers", "sensor": sensor, "reason": "no more outliers than allowed",
                             "count": out["count"], "p_value": out["p_value"]})
    return Decision(findings, rejected, inseparable)


AX = "xyz"


def _finding(sd: SensorData, t: Test, before: dict[str, Any], after: dict[str, Any]) -> dict[str, Any]:
    if t.effect == "bias_random_walk":
        k, k_std = float(t.theta[0]), float(math.sqrt(t.cov[0, 0]))
        factor, unit = (180.0 / math.pi, "deg/s/sqrt(s)") if sd.sensor == "gyro" else (1.0, "m/s^2/sqrt(s)")
        params: dict[str, Any] = {"density": {"value": k * factor, "std": k_std * factor, "unit": unit}}
        axes = [0, 1, 2]
    else:
        params = engineering(t.effect, sd.sensor, t.theta, t.cov)
        axes = _affected_axes(t.effect, t.theta, t.cov)
    unit_factor = 180.0 / math.pi if sd.sensor == "gyro" else 1.0
    unit = "deg/s" if sd.sensor == "gyro" else "m/s^2"
    return {
        "effect": t.effect,
        "sensor": sd.sensor,
        "axes": [AX[k] for k in axes],
        "parameters": params,
        "evidence": {
            "likelihood_gain_chi2": round(t.gain, 3), "params": t.params, "bic_gain": round(t.bic_gain, 3),
            "critical_chi2": round(t.critical, 3), "heldout_before": round(t.heldout_before, 4),
            "heldout_after": round(t.heldout_after, 4),
        },
        "fit": {
            "before": {"bic": round(before["bic"], 3), "block_chi2": np.round(before["block_chi2"], 4).tolist(),
                       "block_rms": np.round(before["block_rms"] * unit_factor, 9).tolist(), "unit": unit},
            "after": {"bic": round(after["bic"], 3), "block_chi2": np.round(after["block_chi2"], 4).tolist(),
                      "block_rms": np.round(after["block_rms"] * unit_factor, 9).tolist(), "unit": unit},
        },
        "_block_residual": (before["block_residual"], after["block_residual"]),
        "_theta": np.array(t.theta, dtype=float),  # fitted SI parameters, for the simulator re-run (rerun.py)
    }


__all__ = ["ALPHA", "COLLINEAR_R2", "OUTLIER_ALLOWANCE", "Decision", "SensorProblem", "Test", "select"]
