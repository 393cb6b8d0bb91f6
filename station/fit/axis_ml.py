"""Maximum-likelihood fit of one output axis of a triad: eq. (1) with the drift of eq. (3).

Model for axis k over block means (see :mod:`station.fit.blocks`):

    y_b = X_b beta + d * E_b(T_c) + s(t_b) + e_b

* ``X_b beta``: the linear part of eq. (1): row k of M times the reference, the static
  bias b_stat, and optional extra regressors (gyro g-sensitivity);
* ``d * E_b``: the deterministic part of the Gauss-Markov drift, g(0) = 1 decaying as
  exp(-t/T_c) (eq. 3 without its driving noise), averaged over the block;
* ``s(t)``: the stochastic part of eq. (3), a GM process started at 0 at power-on, with
  stationary variance ``q``: Cov(s_i, s_j) = q (exp(-|t_i-t_j|/T_c) - exp(-(t_i+t_j)/T_c));
* ``e_b``: white noise, variance sigma_w^2 / n_b (sigma_w known from sample differences).

The linear parameters are profiled out by generalized least squares; (T_c, q) are found
by maximizing the (restricted) Gaussian likelihood. When the drift is resolved, the
uncertainties of (beta, d) average the GLS covariance over the restricted likelihood of
(q, T_c), and the estimate and uncertainty of the drift noise sqrt(q) come from that
likelihood with T_c integrated out (:class:`_ProfileGrid`); without a resolved drift they
are evaluated at the upper end of q's 95 % profile interval and widened by what an
unresolved drift could hide. The std of T_c comes from its own profile likelihood. This is
the "better estimator" that replaces the paper's ACF reading of eq. (4) (see :mod:`station.fit.acf`), and it uses all
settled data of the session, not only the power-on rest.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy import linalg, optimize, special
from scipy.interpolate import PchipInterpolator
from scipy.linalg import lapack

from station.fit.blocks import Blocks, block_exp_mean, power_on_gm_correlation

_LOG_TC_MIN = np.log(2.0)
_LOG_Q_MIN, _LOG_Q_MAX = -25.0, 12.0  # q relative to the white variance of a block
#: log q grid of the profile likelihoods (relative to the white variance of a block); e^-12 is q = 0 in effect
_GRID_LOG_Q = np.arange(-12.0, _LOG_Q_MAX + 1e-9, 0.5)
#: rise of the negative log-likelihood that bounds a 95 % profile interval (chi^2_1 / 2)
_RISE_95 = 1.92


@dataclass(frozen=True, eq=False)
class AxisFit:
    """Result for one axis.

    Attributes:
        beta: linear parameters (columns of the design, then ``d`` last if resolved).
        beta_cov: their covariance (including the T_c uncertainty when resolved).
        tc_s, tc_std_s: correlation time and its standard uncertainty (NaN if unresolved).
        drift_noise, drift_noise_std: stationary std of the stochastic drift sqrt(q).
        drift_resolved: whether the exponential drift is significant (Wald test).
        nll: negative log-likelihood at the optimum; lr: Wald statistic of the drift.
        residual: block residuals y - mean model, (m,).
    """

    beta: np.ndarray
    beta_cov: np.ndarray
    tc_s: float
    tc_std_s: float
    drift_noise: float
    drift_noise_std: float
    drift_resolved: bool
    nll: float
    lr: float
    residual: np.ndarray


class AxisProblem:
    """Concentrated likelihood of one axis for given (T_c, q)."""

    def __init__(self, blocks: Blocks, y: np.ndarray, design: np.ndarray, sigma_w: float, with_drift: bool) -> None:
        self.t = blocks.t_s
        self.h = blocks.width_s
        self.y = y
        self.design = design
        self.white = sigma_w**2 / blocks.count
        self.with_drift = with_drift
        self.dist = np.abs(self.t[:, None] - self.t[None, :])
        # scale of q: the white variance of a typical block
        self.q0 = float(np.median(self.white))
        self._kernels: dict[float, np.ndarray] = {}
        self._columns: dict[float, np.ndarray] = {}
        self._nll_memo: dict[tuple[float, float], float] = {}

    def kernel(self, tc: float) -> np.ndarray:
        """GM correlation started at power-on, exp(-|ti-tj|/T_c) - exp(-(ti+tj)/T_c), cached per T_c."""
        k = self._kernels.get(tc)
        if k is None:
            if len(self._kernels) > 64:
                self._kernels.clear()
            k = power_on_gm_correlation(self.t, self.dist, tc)
            self._kernels[tc] = k
        return k

    def covariance(self, tc: float, q: float) -> np.ndarray:
        cov = q * self.kernel(tc)
        cov.flat[:: cov.shape[0] + 1] += self.white
        return cov

    def columns(self, tc: float) -> np.ndarray:
        """Design with the drift column exp(-t/T_c) averaged over each block (eq. 3), cached per T_c."""
        if not self.with_drift:
            return self.design
        x = self._columns.get(tc)
        if x is None:
            if len(self._columns) > 64:
                self._columns.clear()
            x = np.column_stack([self.design, block_exp_mean(self.t, self.h, tc)])
            self._columns[tc] = x
        return x

    def solve(self, tc: float, q: float) -> tuple[float, np.ndarray, np.ndarray, np.ndarray]:
        """(nll, beta, whitened design, lower cholesky factor) at (tc, q).

        Hot path of the fit (about a thousand calls per session): LAPACK directly, one
        triangular solve for design and data together, normal equations for the few betas.
        """
        chol, info = lapack.dpotrf(self.covariance(tc, q), lower=1, clean=0, overwrite_a=1)
        if info != 0:
            raise linalg.LinAlgError("covariance is not positive definite")
        x = self.columns(tc)
        rhs = np.asfortranarray(np.column_stack([x, self.y]))
        sol, info = lapack.dtrtrs(chol, rhs, lower=1, overwrite_b=1)
        if info != 0:
            raise linalg.LinAlgError("singular cholesky factor")
        xw, yw = sol[:, :-1], sol[:, -1]
        normal = xw.T @ xw
        try:
            beta = np.linalg.solve(normal, xw.T @ yw)
        except np.linalg.LinAlgError:
            beta = np.linalg.lstsq(xw, yw, rcond=None)[0]
        r = yw - xw @ beta
        nll = 0.5 * float(r @ r) + float(np.log(np.diagonal(chol)).sum())
        # REML: the linear parameters absorb part of the slow stochastic drift; without
        # this term its variance q is biased towards zero (and with it every uncertainty).
        # Only the fixed design enters: the drift column depends on T_c, and its collinearity
        # with the static bias at long T_c would otherwise be rewarded.
        p0 = self.design.shape[1]
        sign, logdet = np.linalg.slogdet(normal[:p0, :p0])
        nll += 0.5 * float(logdet) if sign > 0 else np.inf
        return nll, beta, xw, chol  # lower triangle holds the factor (upper is not cleared)

    def nll(self, theta: np.ndarray) -> float:
        key = (float(theta[0]), float(theta[1]))
        value = self._nll_memo.get(key)
        if value is None:
            tc, q = float(np.exp(key[0])), self.q0 * float(np.exp(key[1]))
            try:
                value = self.solve(tc, q)[0]
            except (linalg.LinAlgError, ValueError):
                value = np.inf
            self._nll_memo[key] = value
        return value


class _ProfileGrid:
    """Restricted likelihood of one axis over a grid of (log T_c, log q), with the GLS fit at every node.

    For each T_c the white-scaled GM kernel is diagonalized once, so the whole q axis costs
    a few small matrix products: with K = U diag(lam) U^T, the covariance (eq. 3's drift plus
    white noise) is W^1/2 U diag(1 + q lam) U^T W^1/2.

    The REML term counts every mean column, the drift column ``exp(-t/T_c)`` included, at the
    fitted ``tc_ref_s``: the drift amplitude uses up one of the few degrees of freedom that
    carry information on q, and leaving it out biases q (and every uncertainty) low. Fixing
    its T_c keeps the term from rewarding the collinearity of drift and static bias at long T_c.

    Between the T_c nodes the likelihood is interpolated (monotone cubic) on a fine grid.
    """

    def __init__(
        self,
        problem: AxisProblem,
        log_tc_nodes: np.ndarray,
        tc_ref_s: float,
        tc_column: np.ndarray | None = None,
        n_fine: int = 120,
    ) -> None:
        sw = np.sqrt(problem.white)
        q = problem.q0 * np.exp(_GRID_LOG_Q)
        x_ref = np.column_stack([problem.design, block_exp_mean(problem.t, problem.h, tc_ref_s)]) / sw[:, None]
        p = x_ref.shape[1]
        n_tc = len(log_tc_nodes)
        nll = np.empty((n_tc, len(q)))
        usable = np.empty((n_tc, len(q)), dtype=bool)
        self.node_beta = np.empty((n_tc, len(q), p))
        self.node_cov = np.empty((n_tc, len(q), p, p))
        i_ref = int(np.argmin(np.abs(log_tc_nodes - np.log(tc_ref_s))))
        self.ref_cov: np.ndarray | None = None
        scale = np.outer(sw, sw)
        for i, lt in enumerate(log_tc_nodes):
            tc = float(np.exp(lt))
            lam, u = linalg.eigh(problem.kernel(tc) / scale, check_finite=False, driver="evr")
            lam = np.clip(lam, 0.0, None)
            rotated = u.T @ np.column_stack([problem.columns(tc) / sw[:, None], x_ref, problem.y / sw])
            xr, xf, yr = rotated[:, :p], rotated[:, p:2 * p], rotated[:, -1]
            ql = q[:, None] * lam[None, :]
            wt = 1.0 / (1.0 + ql)  # (n_q, m): the inverse covariance in the eigenbasis
            # normal equations for all q at once: sum over m of wt[q, m] (outer products of rows)
            normal = (wt @ _outer_rows(xr)).reshape(-1, p, p)
            rhs = wt @ (xr * yr[:, None])
            cov = np.linalg.inv(normal)
            b = (cov @ rhs[:, :, None])[:, :, 0]
            quad = wt @ yr**2 - np.sum(rhs * b, axis=1)
            logdet = np.log1p(ql).sum(axis=1)
            reml = np.linalg.slogdet((wt @ _outer_rows(xf)).reshape(-1, p, p))[1]
            nll[i] = 0.5 * (quad + logdet + reml)
            self.node_beta[i], self.node_cov[i] = b, cov
            if i == i_ref and tc_column is not None:
                # Fisher information of (beta, d, T_c) at the reference T_c: the drift's T_c
                # derivative enters as one more column (linearized, eq. 3's exp(-t/T_c))
                ext = np.column_stack([xr, u.T @ (tc_column / sw)])
                info = (wt @ _outer_rows(ext)).reshape(-1, p + 1, p + 1)
                self.ref_cov = np.array([information_inverse(m)[:p, :p] for m in info])
            usable[i] = np.all(np.isfinite(b), axis=1) & np.all(np.diagonal(cov, axis1=1, axis2=2) > 0, axis=1)
        # nodes where the normal equations are singular (drift and static bias collinear) drop out
        bad = ~(np.isfinite(nll) & usable)
        if bad.all():
            raise linalg.LinAlgError("no usable node in the profile grid")
        nll[bad] = nll[~bad].max() + 1e3
        self.node_nll, self.node_usable, self.i_ref = nll, ~bad, i_ref
        self.log_tc_nodes = log_tc_nodes
        fine = np.linspace(log_tc_nodes[0], log_tc_nodes[-1], n_fine)
        self.nll = PchipInterpolator(log_tc_nodes, nll, axis=0)(fine)  # monotone: no spurious minima
        self.nll_min = float(self.nll.min())
        self.s = np.sqrt(q)

    def drift_noise(self, rise: float = _RISE_95, z: float = 1.96) -> tuple[float, float]:
        """Estimate of sqrt(q) with T_c integrated out, and its std: 95 % interval half-width / 1.96.

        The restricted likelihood is averaged over log T_c (flat on the grid's range) rather than
        maximized: where the Gauss-Markov process is slower than the record, q and T_c trade off
        and the profile's interval is too short (90.7 % of gyro axes within 3 sigma, against
        96.7 % marginalized; tests/test_fit_recovery.py). At the bound q = 0 the interval is
        one-sided; its full width then enters the half-width.
        """
        n_tc = self.nll.shape[0]
        marginal = -(special.logsumexp(-(self.nll - self.nll_min), axis=0) - np.log(n_tc))
        prof = marginal - marginal.min()
        i = int(np.argmin(prof))
        est = float(self.s[i])
        if 0 < i < len(prof) - 1:
            # parabola through the minimum and its neighbours, in log q
            a, b, c = prof[i - 1], prof[i], prof[i + 1]
            den = a - 2 * b + c
            if den > 0:
                est = float(self.s[i] * np.exp(0.5 * 0.5 * (_GRID_LOG_Q[1] - _GRID_LOG_Q[0]) * (a - c) / den))
        lo, hi = _edges(self.s, prof, i, rise)
        return est, (hi - lo) / (2.0 * z)

    def beta_covariance(self, beta: np.ndarray, over_tc: bool) -> np.ndarray:
        """Covariance of the estimate ``beta`` (linear parameters, then ``d``), averaged over the likelihood.

        The covariance of the GLS estimate at each grid node, weighted by the restricted likelihood
        (flat in log q and log T_c), plus the spread of the node estimates about ``beta``: the
        uncertainty of the drift variance q (and of T_c) is integrated out instead of taking one
        q. ``over_tc`` False: over q only, at the reference T_c, with T_c's own uncertainty from
        the linearized Fisher information (when ``tc_column`` was given); True: over both.
        """
        nll, usable = self.node_nll, self.node_usable
        if over_tc:
            lt = self.log_tc_nodes
            edges = np.concatenate([[lt[0]], 0.5 * (lt[1:] + lt[:-1]), [lt[-1]]])
            width = np.diff(edges) if len(lt) > 1 else np.ones(1)
            w = np.exp(-(nll - nll[usable].min())) * width[:, None] * usable
            b, c = self.node_beta[usable], self.node_cov[usable]
            w = w[usable]
        else:
            i = self.i_ref
            ok = usable[i]
            w = np.exp(-(nll[i] - nll[i][ok].min()))[ok]
            b = self.node_beta[i][ok]
            c = (self.ref_cov if self.ref_cov is not None else self.node_cov[i])[ok]
        w = w / w.sum()
        dev = b - beta
        return np.einsum("n,nij->ij", w, c) + (dev.T * w) @ dev


def _outer_rows(x: np.ndarray) -> np.ndarray:
    """Outer product of each row of ``x`` (m, p) with itself, flattened to (m, p * p)."""
    return (x[:, :, None] * x[:, None, :]).reshape(x.shape[0], -1)


def _edges(x: np.ndarray, f: np.ndarray, i0: int, rise: float) -> tuple[float, float]:
    """Where ``f`` (excess of a negative log-likelihood over its minimum at ``x[i0]``) first exceeds ``rise``.

    Linear interpolation between grid points; a side that never rises that much ends at the grid's end.
    """
    out = []
    for step in (-1, 1):
        i = i0
        while 0 <= i + step < len(x) and f[i + step] <= rise:
            i += step
        j = i + step
        if 0 <= j < len(x):
            out.append(float(x[i] + (x[j] - x[i]) * (rise - f[i]) / (f[j] - f[i])))
        else:
            out.append(float(x[i]))
    return out[0], out[1]


def _optimize(problem: AxisProblem, grid: tuple[float, float], bounds: tuple[float, float]) -> np.ndarray:
    """Coarse grid over (log T_c, log q), log T_c from ``grid``, then Nelder-Mead within ``bounds`` of log T_c."""
    grid_tc = np.linspace(grid[0], grid[1], 10)
    grid_q = np.array([-10.0, -2.0, 2.0])
    best = min(((problem.nll(np.array([a, b])), a, b) for a in grid_tc for b in grid_q), key=lambda z: z[0])
    lo = np.array([bounds[0], _LOG_Q_MIN])
    hi = np.array([bounds[1], _LOG_Q_MAX])

    def bounded(theta: np.ndarray) -> float:
        if np.any(theta < lo) or np.any(theta > hi):
            return np.inf
        return problem.nll(theta)

    x0 = np.array([best[1], best[2]])
    # start from a simplex the size of the grid cell around the best grid point
    step_tc = 0.5 * (grid_tc[1] - grid_tc[0])
    simplex = np.array([x0, x0 + np.array([step_tc, 0.0]), x0 + np.array([0.0, 2.0])])
    res = optimize.minimize(
        bounded,
        x0,
        method="Nelder-Mead",
        options={"xatol": 0.02, "fatol": 0.01, "maxiter": 120, "initial_simplex": simplex},
    )
    return np.asarray(res.x)


def fit_axis(
    blocks: Blocks,
    axis: int,
    design: np.ndarray,
    sigma_w: float,
    *,
    lr_threshold: float = 9.0,
    tc_range_s: tuple[float, float] | None = None,
) -> AxisFit:
    """Fit axis ``axis`` of ``blocks.y`` with linear ``design`` (m, p) plus GM drift.

    ``sigma_w`` is the white-noise std per sample (sensor unit). The exponential drift
    is kept when its Wald statistic ``d^2 / var(d)`` at the fitted T_c exceeds
    ``lr_threshold`` (9: 3 sigma) at the fitted T_c or at any T_c up to the record's span;
    otherwise ``d`` is reported as 0 and T_c as NaN.

    ``tc_range_s``: the sensor class's range of eq. 3's T_c (s), a prior flat in log T_c on it. T_c is
    then searched, profiled, averaged over and worst-cased within that range only, so a recording too
    short to identify T_c no longer makes b_stat an extrapolation along exp(-t/T_c) to any T_c up to
    50 record spans (whose uncertainty grew with how long the moves took). None: the record alone.
    """
    y = blocks.y[:, axis]
    span = float(blocks.t_s.max() + 0.5 * blocks.width_s.max())
    log_tc_max = np.log(max(50.0 * span, 100.0))
    if tc_range_s is not None:
        lo_s, hi_s = float(tc_range_s[0]), float(tc_range_s[1])
        if not (0.0 < lo_s <= hi_s and np.isfinite(hi_s)):
            raise ValueError(f"T_c range must be 0 < low <= high, got {tc_range_s}")
        lt_lo, lt_hi = float(np.log(lo_s)), float(np.log(hi_s))
        if lt_hi - lt_lo < 0.1:  # a range too narrow to search: widen it symmetrically to +-5 %
            mid = 0.5 * (lt_lo + lt_hi)
            lt_lo, lt_hi = mid - 0.05, mid + 0.05
        grid_lt, wald_lt = (lt_lo, lt_hi), np.linspace(lt_lo, lt_hi, 8)
    else:
        lt_lo, lt_hi = float(_LOG_TC_MIN), float(log_tc_max + 1.0)
        grid_lt = (float(np.log(5.0)), float(log_tc_max))
        wald_lt = np.linspace(np.log(5.0), np.log(max(span, 10.0)), 8)

    full = AxisProblem(blocks, y, design, sigma_w, with_drift=True)
    theta = _optimize(full, grid_lt, (lt_lo, lt_hi))
    tc, q = float(np.exp(theta[0])), full.q0 * float(np.exp(theta[1]))
    nll, beta, xw, chol = full.solve(tc, q)
    p = xw.shape[1]
    # Wald statistic of d, z^2 = d^2 / var(d | T_c), at the fitted T_c and, since d and b_stat
    # trade off at long T_c, its largest value over T_c from 5 s to the record's span.
    lr = 0.0
    for tc_g in (tc, *np.exp(wald_lt)):
        _, beta_g, xw_g, _ = full.solve(float(tc_g), q)
        lr = max(lr, float(beta_g[-1] ** 2 / information_inverse(xw_g.T @ xw_g)[-1, -1]))
    resolved = bool(lr > lr_threshold)
    problem = full if resolved else AxisProblem(blocks, y, design, sigma_w, with_drift=False)
    theta_q = theta if resolved else np.array([theta[0], _optimize_q(problem, theta)])
    q = problem.q0 * float(np.exp(theta_q[1]))
    # The stochastic drift q is often poorly determined (a Gauss-Markov process slower than
    # the record looks like a random offset and trend) and ML underestimates it. With a resolved
    # drift, the stds of the linear parameters and sqrt(q) come from profile likelihoods over
    # (T_c, q) (:class:`_ProfileGrid`), the std of T_c from its profile at the upper end of q's
    # 95 % interval (at the fitted T_c). Without, everything is evaluated at that upper end, and the
    # std of sqrt(q) is the interval's half-width / 1.96 (the 1-sigma half-width for a Gaussian
    # likelihood, wider when it is skewed by the q = 0 bound).
    def profile_q(u: float) -> float:
        return problem.nll(np.array([theta_q[0], u]))

    q_lo95, q_hi95 = _profile_interval(profile_q, theta_q[1], _LOG_Q_MIN, _LOG_Q_MAX, 1.92)
    sq = np.sqrt(problem.q0 * np.exp(np.array([q_lo95, q_hi95])))
    sq_std = float((sq[1] - sq[0]) / (2 * 1.96))
    q_unc = problem.q0 * float(np.exp(q_hi95))
    drift_noise = float(np.sqrt(q))
    if resolved:
        nll, beta, _, _ = full.solve(tc, q)
        step = 1e-4 * tc
        de_dtc = (block_exp_mean(blocks.t_s, blocks.width_s, tc + step)
                  - block_exp_mean(blocks.t_s, blocks.width_s, tc - step)) / (2 * step)
        _, _, xw, chol = full.solve(tc, q_unc)
        # Fisher information of the mean parameters (beta, d, T_c), at the upper end of q's interval.
        jw = np.column_stack([xw, linalg.solve_triangular(chol, beta[-1] * de_dtc, lower=True, check_finite=False)])
        beta_cov = information_inverse(jw.T @ jw)[:p, :p]
        # T_c is non-linear: its uncertainty from the profile likelihood (beta re-fitted)
        lo, hi = _profile_interval(lambda u: full.solve(float(np.exp(u)), q_unc)[0], float(np.log(tc)),
                                   lt_lo, lt_hi)
        tc_std = 0.5 * float(np.exp(hi) - np.exp(lo))
        residual = y - full.columns(tc) @ beta
        # The restricted likelihood on a (T_c, q) grid: nodes over 2.5 times T_c's asymmetric
        # 1-sigma profile interval, 4 when T_c is longer than half the record (see below).
        # sqrt(q) and its std come from it with T_c integrated out; the covariance of (beta, d) averages
        # over it. Where the record spans two fitted correlation times the warm-up is seen to
        # settle: average over q at the fitted T_c (T_c linearized). Where it does not, b_stat is
        # an extrapolation along exp(-t/T_c) and the average runs over T_c too. Averaging over T_c
        # everywhere (or wherever T_c's upper 1-sigma edge exceeds half the record) made stds 100x
        # the actual error where the drift is tiny and a long T_c trades b_stat against b_drift,
        # and failed good demo units on the fit-quality limit; one q at its 95 % upper edge
        # everywhere made the accelerometer's stds twice its errors (tests/test_fit_recovery.py).
        lt0 = float(np.log(tc))
        over_tc = span < 2.0 * tc
        below, above = max(lt0 - lo, 0.03), max(hi - lt0, 0.03)
        steps = np.linspace(0.0, 4.0, 6) if over_tc else np.linspace(0.0, 2.5, 4)
        nodes = np.concatenate([lt0 - below * steps[:0:-1], lt0 + above * steps])
        try:
            grid = _ProfileGrid(
                full, np.unique(np.clip(nodes, lt_lo, lt_hi)), tc, tc_column=beta[-1] * de_dtc
            )
            profile_sq = grid.drift_noise()
            averaged = grid.beta_covariance(beta, over_tc)
        except (linalg.LinAlgError, ValueError):  # keep the fixed-T_c values
            profile_sq = (drift_noise, sq_std)
            averaged = beta_cov
        if np.all(np.isfinite(profile_sq)) and profile_sq[1] > 0:
            drift_noise, sq_std = profile_sq
        if np.all(np.isfinite(averaged)) and np.all(np.diag(averaged) > 0):
            beta_cov = averaged
        if not lt_lo + 0.05 < theta[0] < lt_hi - 0.05:
            # T_c at a bound of the search is a bound, not an estimate (the exponential is then
            # indistinguishable from a trend or from the noise): any T_c of the searched range is
            # possible, and its std is that of a uniform distribution over the range
            tc_std = max(tc_std, float(np.exp(lt_hi) - np.exp(lt_lo)) / np.sqrt(12.0))
    else:
        # No significant drift: report d = 0 and the level from the model without drift,
        # widening the uncertainties by what an unresolved drift could hide. T_c is not
        # known then, so take the worst case over T_c from 5 s to the record's span (a
        # drift much slower than the record is indistinguishable from the static bias
        # and cannot be bounded by any recording of this length).
        nll, beta, _, _ = problem.solve(tc, q)
        _, _, xw, _ = problem.solve(tc, q_unc)
        cov0 = information_inverse(xw.T @ xw)
        inflation = np.zeros(p - 1)
        hidden_d = 0.0
        for tc_g in np.exp(wald_lt):
            _, beta_g, xw_g, _ = full.solve(tc_g, q_unc)
            var_g = information_inverse(xw_g.T @ xw_g)
            hidden = float(beta_g[-1] ** 2 + var_g[-1, -1])
            # GLS regression of the drift column on the design: how much of it each beta absorbs
            absorbed = cov0 @ (xw.T @ xw_g[:, -1])
            inflation = np.maximum(inflation, hidden * absorbed**2)
            hidden_d = max(hidden_d, hidden)
        beta_cov = np.zeros((p, p))
        beta_cov[:-1, :-1] = cov0 + np.diag(inflation)
        beta_cov[-1, -1] = hidden_d
        beta = np.append(beta, 0.0)
        residual = y - design @ beta[:-1]
        tc, tc_std = float("nan"), float("nan")
    return AxisFit(
        beta=beta,
        beta_cov=beta_cov,
        tc_s=tc,
        tc_std_s=tc_std,
        drift_noise=drift_noise,
        drift_noise_std=sq_std,
        drift_resolved=resolved,
        nll=nll,
        lr=lr,
        residual=residual,
    )


def _optimize_q(problem: AxisProblem, theta: np.ndarray) -> float:
    """log q (relative to q0) maximizing the likelihood at fixed T_c."""
    res = optimize.minimize_scalar(
        lambda u: problem.nll(np.array([theta[0], u])), bounds=(_LOG_Q_MIN, _LOG_Q_MAX), method="bounded",
        options={"xatol": 1e-2},
    )
    return float(res.x)


def _profile_interval(
    f: Callable[[float], float], x0: float, lo: float, hi: float, rise: float = 0.5
) -> tuple[float, float]:
    """Where ``f`` (a negative log-likelihood) rises by ``rise`` from ``f(x0)`` on each side.

    ``rise`` = 1/2 gives the 1-sigma interval, 1.92 the 95 % interval.

    A side on which it never rises that much within [lo, hi] extends to the bound.
    """
    f0 = f(x0)
    edges = []
    for bound in (lo, hi):
        inside, edge = x0, bound
        for x in np.linspace(x0, bound, 9)[1:]:
            if f(x) - f0 > rise:
                edge = x
                break
            inside = x
        if edge != bound or f(bound) - f0 > rise:
            for _ in range(6):  # bisect between the last point inside and the first outside
                mid = 0.5 * (inside + edge)
                if f(mid) - f0 > rise:
                    edge = mid
                else:
                    inside = mid
        edges.append(edge)
    return edges[0], edges[1]


def information_inverse(info: np.ndarray) -> np.ndarray:
    """Inverse of an information matrix, with Jacobi scaling (columns differ by many decades)."""
    d = np.sqrt(np.clip(np.diag(info), 1e-300, None))
    scaled = info / np.outer(d, d)
    try:
        with warnings.catch_warnings():  # nearly collinear columns (a slow drift and a temperature course): expected
            warnings.simplefilter("ignore", linalg.LinAlgWarning)
            inv = linalg.inv(scaled, check_finite=False)
    except linalg.LinAlgError:
        inv = linalg.pinv(scaled)
    return inv / np.outer(d, d)
