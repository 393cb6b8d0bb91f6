"""Power of the diagnosis's bias random walk test on the gyroscope against an oracle, by walk size.

Per recording (the independent generator ``tests/indepgen.py``, and the station simulator ``station.sim``), the
gyroscope's residual with every deterministic parameter at its true value (M, b_stat, the warm-up b_drift
exp(-t/T_c) of eq. 3) is, exactly, eq. 3's drift noise (a Gauss-Markov process started at 0 at power-on, variance
q, correlation time T_c) + the walk (K^2 t) + white noise. Three tests of "walk" against "no walk", each on that
residual's 4 s block means (the walk's information lies far below their 0.125 Hz at these sizes):

* ``oracle``: the likelihood-ratio test with q, T_c and the white variance at their true values, K^2 >= 0 profiled;
* ``class``: the same with q per axis unknown in ``[0, q_class]`` (the sensor class's bound the locator uses,
  :func:`station.diagnose.locator.class_drift_noise`: 3 x 1 % of |b_drift|), profiled in both hypotheses: the best a
  test can do that knows the class but not the unit's own drift noise;
* ``station``: the diagnosis itself, ``bias_random_walk`` named on the gyroscope (``diagnose()``; with
  ``--class-bound`` its walk test's null bounded by the class, ``likelihood.WALK_NULL_CLASS_BOUND``), and the raw gain
  of its walk test at the first step (:meth:`SensorProblem.test_random_walk`), with and without that bound.

Where the station loses against the class test, one thing at a time (the summary's columns, :data:`COLUMNS`): the
reference that also estimates b_stat and the warm-up's amplitude (``class+mean``: the restricted likelihood, at the
true T_c), and T_c too over the class's range (``class+mean+T_c``); with the class's bound at the station's estimate of
|b_drift| (``class(b est)``); with q free (``free q``: the shape alone); and the station's class-bounded test with q
re-fitted in its alternative, without the temperature nuisance term, at the true T_c, with the class's bound at the
true |b_drift|, and as the full profile likelihood ratio (``likelihood.WALK_PROFILE_TC``: T_c and q re-fitted in
both hypotheses; ``profile`` with the default bound). ``--openaxes LOG``: the same walk test's gains on the real
OpenAXES BMI160 gyroscope by bound and class.

All at the station's level: the critical value of half chi^2_1 at ``ALPHA`` (1e-5; 18.2), the asymptotic null
distribution of the oracle tests (nothing estimated but K^2, and q in the class test; the nulls print the share of
gains above 2.71, the 5 % point, as a coarse check: the 1e-5 tail is beyond a few nulls). ``lambda`` is the
oracle's noncentrality at the true K (2 KL divergence of the two block distributions, the expected gain): power
~ P(Z > sqrt(18.2) - sqrt(lambda)), 90 % at lambda ~ 31.

Sizes are the gyroscope's K in deg/s/sqrt(s); ``--mults`` times the independent generator's (0.1 x 3e-4 = 3e-5).
The station simulator's walk is given per accelerometer (``Effects.bias_random_walk``, the gyro 5 deg/s per m/s^2 of
it): set so that its gyro has the same K. Seeds: development 340000-344999 and 520000-520999, report
345000-349999 and 850105-850134.

Run: ``python benchmarks/bench_gyro_walk_power.py [--base 340000] [--per 4] [--nulls 4] [--mults 0.1,0.3,1,3,10]
[--generators indep,sim] [--class-bound] [--no-diagnose] [--plan] [--openaxes LOG]``
"""

# ruff: noqa: E402  (BLAS threads set before numpy is imported)
from __future__ import annotations

import argparse
import math
import os
import sys

# one BLAS thread: many small (m, m) factorizations, which threads on a shared machine only slow down
for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")
import time
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
from scipy import linalg, optimize, stats

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
sys.path.insert(0, str(Path(__file__).resolve().parent))

import indepgen
from bench_diagnose_indep import warmup_tc

from station.diagnose import diagnose, likelihood
from station.diagnose.likelihood import ALPHA, SensorProblem, Test
from station.diagnose.locator import class_drift_noise
from station.diagnose.residuals import fit_baseline
from station.fit.blocks import power_on_gm_correlation
from station.kernel.plan import random_plan
from station.physics.effects import GYRO_PER_ACCEL, Effects
from station.session.model import Session
from station.sim.session_sim import simulate_session

DEG = math.pi / 180.0
#: The independent generator's gyro walk (deg/s/sqrt(s)): 0.1 x its 3e-4.
K_GEN_DPS = 3e-5
#: Critical value of every test here: half chi^2_1 (K^2 >= 0 on the boundary) at the diagnosis's ALPHA.
CRIT = float(stats.chi2.isf(2.0 * ALPHA, 1))
BLOCK_S = 4.0


@dataclass(frozen=True)
class Truth:
    """What the oracle knows of one gyroscope: its residual (output - deterministic part) and stochastic model."""

    t_s: np.ndarray
    residual: np.ndarray  # (n, 3) rad/s
    q: np.ndarray  # (3,) drift-noise stationary variance
    tc: np.ndarray  # (3,) s
    white: np.ndarray  # (3,) per-sample white variance (noise and ADC)
    b_drift: np.ndarray  # (3,) rad/s


class Oracle:
    """The block-mean likelihood of the residual, one generalized eigen-decomposition per axis and q: with
    ``A = diag(white / n_b) + q GM`` and the walk's block covariance ``W``, ``A^-1/2 W A^-T/2 = V diag(l) V^T``, so
    ``-2 log L(K^2) = sum(z^2 / (1 + K^2 l) + log(1 + K^2 l)) + const`` with ``z = V^T A^-1/2 r``."""

    def __init__(self, tr: Truth, *, mean_fitted: bool = False, tc: np.ndarray | None = None) -> None:
        n = len(tr.t_s)
        fs = (n - 1) / (tr.t_s[-1] - tr.t_s[0])
        nb = round(BLOCK_S * fs)
        m = n // nb
        self.t = tr.t_s[: m * nb].reshape(m, nb).mean(axis=1)
        self.r = tr.residual[: m * nb].reshape(m, nb, 3).mean(axis=1)
        self.nb, self.tr = nb, tr
        #: eq. 3's T_c per axis of the drift noise and the warm-up (default: the truth)
        self.tc = tr.tc if tc is None else tc
        width = nb / fs
        self.dist = np.abs(self.t[:, None] - self.t[None, :])
        self.walk = np.minimum(self.t[:, None], self.t[None, :])
        self.walk[np.diag_indices(m)] -= width / 6.0
        #: ``mean_fitted``: per axis, the likelihood of the contrasts orthogonal to b_stat and the warm-up
        #: exp(-t/T_c) (eq. 3, at the true T_c): the restricted likelihood of those two mean terms estimated
        self.contrast: list[np.ndarray | None] = [None] * 3
        if mean_fitted:
            for k in range(3):
                x = np.column_stack([np.ones(m), np.exp(-self.t / float(self.tc[k]))])
                self.contrast[k] = linalg.null_space(x.T)

    def parts(self, k: int, q: float) -> tuple[np.ndarray, np.ndarray, float]:
        """(z^2, l, log det A) of axis k at drift-noise variance q."""
        a = q * power_on_gm_correlation(self.t, self.dist, float(self.tc[k]))
        a[np.diag_indices_from(a)] += self.tr.white[k] / self.nb
        walk, r = self.walk, self.r[:, k]
        nsp = self.contrast[k]
        if nsp is not None:
            a, walk, r = nsp.T @ a @ nsp, nsp.T @ walk @ nsp, nsp.T @ r
        ch = linalg.cholesky(a, lower=True)
        x = linalg.solve_triangular(ch, walk, lower=True)
        w = linalg.solve_triangular(ch, x.T, lower=True)
        lam, vec = linalg.eigh(0.5 * (w + w.T))
        z = vec.T @ linalg.solve_triangular(ch, r, lower=True)
        return z * z, np.clip(lam, 0.0, None), 2.0 * float(np.log(np.diag(ch)).sum())


def _m2ll(parts: list[tuple[np.ndarray, np.ndarray, float]], k2: float) -> float:
    return sum(float(np.sum(z2 / (1.0 + k2 * lam) + np.log1p(k2 * lam))) + ld for z2, lam, ld in parts)


def _best_k2(parts: list[tuple[np.ndarray, np.ndarray, float]], k2_ref: float) -> tuple[float, float]:
    """(-2 log L, K^2) at the best K^2 >= 0."""
    grid = k2_ref * 10.0 ** np.arange(-4.0, 4.01, 0.5)
    vals = [_m2ll(parts, g) for g in grid]
    i = int(np.argmin(vals))
    lo, hi = math.log(grid[max(i - 1, 0)]), math.log(grid[min(i + 1, len(grid) - 1)])
    res = optimize.minimize_scalar(lambda u: _m2ll(parts, math.exp(u)), bounds=(lo, hi), method="bounded")
    best = (float(res.fun), math.exp(float(res.x)))
    zero = _m2ll(parts, 0.0)
    return best if best[0] < zero else (zero, 0.0)


def oracle_tests(tr: Truth, k_true: float) -> dict[str, float]:
    """Gains of the oracle (q known) and the class test (q in [0, q_class] per axis), and the oracle's noncentrality
    at ``k_true`` (rad/s/sqrt(s))."""
    o = Oracle(tr)
    k2_ref = float(np.median(tr.white)) / o.nb / float(o.t[-1])
    known = [o.parts(k, float(tr.q[k])) for k in range(3)]
    nll1, k2_hat = _best_k2(known, k2_ref)
    gain = max(0.0, _m2ll(known, 0.0) - nll1)
    k2t = k_true**2
    lam = sum(float(np.sum(k2t * lam - np.log1p(k2t * lam))) for _, lam, _ in known)
    q_cls = class_drift_noise("gyro", tr.b_drift)
    out = {"oracle": gain, "oracle_k": math.sqrt(k2_hat) / DEG, "lambda": lam,
           "class": _class_gain(o, q_cls, k2_ref, range(-4, 1)),
           # q free (up to 3^8 x the class's bound): the walk told from eq. 3's drift noise by its shape alone
           "free": _class_gain(o, q_cls, k2_ref, range(-4, 9))}
    # the class test with b_stat and the warm-up estimated (restricted likelihood): what the mean terms cost
    out["class_mean"] = _class_gain(Oracle(tr, mean_fitted=True), q_cls, k2_ref, range(-4, 1))
    # ... and T_c not known either: per axis anywhere on a grid over the class's range (the station's limits,
    # TC_GRID), in both hypotheses
    oracles = [Oracle(tr, mean_fitted=True, tc=np.full(3, tc)) for tc in TC_GRID]
    out["class_mean_tc"] = _class_gain(oracles, q_cls, k2_ref, range(-4, 1))
    return out


#: T_c (s) over the station's gyroscope class range (1030-3760 s), for the reference test that does not know T_c.
TC_GRID = (1030.0, 1300.0, 1650.0, 2100.0, 2700.0, 3760.0)


def _class_gain(o: Oracle | list[Oracle], q_cls: np.ndarray, k2_ref: float, exps: range) -> float:
    """The class test's gain: q per axis on the grid ``0, q_class 3^e`` (e in ``exps``), and over the oracles
    ``o`` (e.g. one per T_c), both hypotheses profiled (the walk shared by the axes)."""
    grids = [[0.0, *(float(q_cls[k]) * 3.0 ** e for e in exps)] for k in range(3)]
    per_axis = [[oi.parts(k, q) for oi in (o if isinstance(o, list) else [o]) for q in grids[k]] for k in range(3)]
    null = sum(min(_m2ll([p], 0.0) for p in per_axis[k]) for k in range(3))
    # the alternative: K^2 on a grid, each axis's q at its best for that K^2, then refined around the best K^2
    def alt(k2: float) -> float:
        return sum(min(_m2ll([p], k2) for p in per_axis[k]) for k in range(3))
    grid = k2_ref * 10.0 ** np.arange(-4.0, 4.01, 0.25)
    vals = [alt(g) for g in grid]
    i = int(np.argmin(vals))
    res = optimize.minimize_scalar(lambda u: alt(math.exp(u)), bounds=(math.log(grid[max(i - 1, 0)]),
                                   math.log(grid[min(i + 1, len(grid) - 1)])), method="bounded")
    return max(0.0, null - min(float(res.fun), vals[i], null))


def station_test(session: Session, tc: dict[str, tuple[float, float]] | None, truth: Truth) -> dict[str, float]:
    """The gyroscope's walk test at the first step of the selection (:meth:`SensorProblem.test_random_walk`) with
    eq. 3's drift noise in its null bounded by the class too (``walk_null_class_bound``): its gain and decision; and
    three variants of it on the same block problem, to tell where the power goes:

    * ``gain_share``: the drift noise in the null bounded by the warm-up's share alone (``drift_noise_max``), not
      also by the class's (``q_class``): the station's default test (``WALK_NULL_CLASS_BOUND`` off);
    * ``gain_prof``: the drift noise re-fitted in the alternative too (0 <= q <= the warm-up's share,
      ``drift_noise_max``, per axis, at every K^2), where the test keeps the null's q;
    * ``gain_qtrue``: q and T_c at their true values in both hypotheses (the mean terms still estimated)."""
    baseline = fit_baseline(session, warmup_tc_s=tc)
    sd = baseline.sensor("gyro")

    def problem() -> SensorProblem:
        p = SensorProblem(baseline, sd)
        p.q_class = class_drift_noise("gyro", sd.params.bias_drift)
        return p

    prob = problem()
    prob.walk_null_class_bound = True
    t = prob.test_random_walk(size=False)
    q_cls = prob.q_class
    assert q_cls is not None
    ratio = float(np.median([prob.drift_noise_max(k) / q_cls[k] for k in range(3)]))
    prob.walk_null_class_bound = False  # the null's q bounded by the warm-up's share alone (the station's default)
    t_share = prob.test_random_walk(size=False)

    def refitted_q(prob: SensorProblem, *, cls: bool) -> Test:
        """The test with q re-fitted in the alternative too (at most the warm-up's share, and the class's where
        ``cls``)."""
        def profiled_k2(qs: list[float], extra: list[np.ndarray | None], *, reml: bool = False
                        ) -> tuple[float, float, float]:
            q_max = [prob.drift_noise_max(k) for k in range(3)]
            if cls:
                q_max = [min(a, float(b)) for a, b in zip(q_max, q_cls, strict=True)]

            def total(u: float) -> float:
                return sum(prob._profile_q(k, math.exp(u), extra[k], q_max=q_max[k])[1] for k in range(3))

            u0 = math.log(float(np.median(prob.white)) / max(float(prob.sd.t_s.max()), 1.0))
            grid = [u0 + math.log(10.0) * e for e in np.arange(-2.0, 3.01, 1.0)]
            vals = [total(u) for u in grid]
            i = int(np.argmin(vals))
            res = optimize.minimize_scalar(total, bounds=(grid[max(i - 1, 0)], grid[min(i + 1, len(grid) - 1)]),
                                           method="bounded", options={"xatol": 0.2, "maxiter": 10})
            return min(float(res.fun), vals[i]), math.exp(float(res.x)), math.nan

        prob._profile_k2 = profiled_k2  # type: ignore[method-assign]
        prob.walk_null_class_bound = cls
        return prob.test_random_walk(size=False)

    t_prof = refitted_q(problem(), cls=False)
    t_cb_prof = refitted_q(problem(), cls=True)
    # class-bounded, without the temperature course as a nuisance term of the test
    prob = problem()
    prob.walk_null_class_bound = True
    prob.d_temp = np.zeros_like(prob.d_temp)
    prob.temp_direction = np.zeros_like(prob.temp_direction)
    t_cb_notemp = prob.test_random_walk(size=False)
    # class-bounded, T_c at its true value (not re-fitted)
    prob = problem()
    prob.walk_null_class_bound = True
    for k in range(3):
        prob._set_tc(k, float(truth.tc[k]))
    prob._fit_q()
    prob.refit_drift = lambda: None  # type: ignore[method-assign]
    t_cb_tc = prob.test_random_walk(size=False)

    # the full profile likelihood ratio (T_c and q re-fitted in both hypotheses), q bounded by the warm-up's share
    # alone (the default's null) and by the class too
    prob = problem()
    prob.walk_profile_tc = True
    t_pr_share = prob.test_random_walk(size=False)
    prob = problem()
    prob.walk_profile_tc = True
    prob.walk_null_class_bound = True
    t0 = time.process_time()
    t_pr_cb = prob.test_random_walk(size=False)
    cpu_pr = time.process_time() - t0
    # class-bounded, the class's bound at the unit's true |b_drift| (as the reference class test has it), not at
    # the station's estimate of it
    prob = problem()
    prob.q_class = class_drift_noise("gyro", truth.b_drift)
    prob.walk_null_class_bound = True
    t_cb_true_class = prob.test_random_walk(size=False)
    # the reference class test (every mean term known) with the class's bound at the station's estimate of |b_drift|
    k2_ref = float(np.median(truth.white)) / round(BLOCK_S * (len(truth.t_s) - 1)
                                                   / (truth.t_s[-1] - truth.t_s[0])) / float(truth.t_s[-1])
    class_est = _class_gain(Oracle(truth), q_cls, k2_ref, range(-4, 1))

    prob = problem()
    for k in range(3):
        prob._set_tc(k, float(truth.tc[k]))
    q_true = [float(q) for q in truth.q]

    def fixed_q(k: int, k2: float, extra: np.ndarray | None, q_max: float = math.inf, *, reml: bool = False
                ) -> tuple[float, float]:
        return q_true[k], prob._axis_nll(k, q_true[k], k2, extra, reml=reml)

    prob._profile_q = fixed_q  # type: ignore[method-assign]
    prob.refit_drift = lambda: None  # type: ignore[method-assign]
    prob.q = np.array(q_true)
    t_true = prob.test_random_walk(size=False)
    return {"gain": t.gain, "threshold": t.threshold, "passes": float(t.passes),
            "gain_share": t_share.gain, "gain_prof": t_prof.gain, "gain_qtrue": t_true.gain,
            "pr_share": t_pr_share.gain, "pr_cb": t_pr_cb.gain, "cpu_pr": cpu_pr,
            "cb_true_class": t_cb_true_class.gain, "class_est": class_est, "cb_prof": t_cb_prof.gain,
            "cb_notemp": t_cb_notemp.gain, "cb_tc": t_cb_tc.gain,
            "q_max_over_class": ratio}


def indep_case(seed: int, k_dps: float) -> tuple[Session, Truth]:
    # indepgen's magnitude: the accelerometer's K (m/s^2/sqrt(s)); the gyro's is 0.1 x it in deg/s/sqrt(s)
    rec = indepgen.generate(seed, {"bias_random_walk": k_dps / 0.1} if k_dps > 0 else {})
    s, tr = rec.session, rec.truth
    b = s.gyro_radps - np.asarray(tr["gyro_deterministic"])
    q = np.asarray(tr["gyro_drift_noise_var"], dtype=float)
    return s, Truth(s.t_s, b, q, np.asarray(tr["gyro_tc"], dtype=float), np.asarray(tr["gyro_white_var"], dtype=float),
                    np.sqrt(q) / 0.01)


def sim_case(seed: int, k_dps: float) -> tuple[Session, Truth]:
    plan = random_plan(np.random.default_rng(10_000 + seed))
    eff = Effects(bias_random_walk=k_dps / GYRO_PER_ACCEL) if k_dps > 0 else Effects()
    on = simulate_session(seed, plan=plan, effects=eff)
    g = on.truth.gyro
    # the same unit without drift noise, white noise and ADC (lsb 0: no rounding, whose error would be constant in
    # every rest and pose); its streams are its own, so the deterministic part is the same to the last bit
    quiet = replace(on.truth, gyro=replace(g, drift_noise=np.zeros(3), noise_std=np.zeros(3), lsb=0.0))
    clean = simulate_session(seed, plan=plan, unit=quiet)
    res = on.session.gyro_radps - clean.session.gyro_radps
    white = g.noise_std**2 + g.lsb**2 / 12.0
    return on.session, Truth(on.session.t_s, res, g.drift_noise**2, g.correlation_time_s, white, g.bias_drift)


def _two_kl(c1: np.ndarray, c0: np.ndarray) -> float:
    """2 KL(N(0, c1) || N(0, c0)): the expected likelihood-ratio gain of data from c1 against c0."""
    ch = linalg.cholesky(c0, lower=True)
    a = linalg.solve_triangular(ch, linalg.solve_triangular(ch, c1, lower=True).T, lower=True)
    ev = np.clip(linalg.eigvalsh(0.5 * (a + a.T)), 1e-300, None)
    return float(np.sum(ev - 1.0 - np.log(ev)))


def plan_table(mults: list[float]) -> None:
    """Noncentrality of the walk on a still recording of S minutes (one axis times three; a typical unit of the class:
    |b_drift| 0.15 deg/s, drift noise 1 % of it, T_c 2000 s, noise 0.0115 deg/s at 100 Hz), for the oracle (q known)
    for the class test (q anywhere in [0, q_class]: the null's best q, min over a grid), and for a class that states the
    drift noise without a margin (q in [0, q_true]), and for a test that leaves q free (up to 1e5 q_true: the walk told
    from the drift noise by its shape alone, T_c known); 90 % power at ~31."""
    b, tc, sigma, fs = 0.15 * DEG, 2000.0, 0.0115 * DEG, 100.0
    q_true = (0.01 * b) ** 2
    q_cls = float(class_drift_noise("gyro", np.full(3, b))[0])
    minutes = (5, 10, 15, 30, 60, 120, 240)
    print(f"walk noncentrality on a still recording, 3 axes (unit: |b_drift| 0.15 deg/s, T_c {tc:.0f} s, drift noise "
          f"1 %, class bound {math.sqrt(q_cls / q_true):.0f}x that std); columns: K in deg/s/sqrt(s)")
    print(f"{'minutes':>7s} " + " ".join(f"{'oracle ' + format(x * K_GEN_DPS, '.0e'):>14s} "
                                          f"{'class ' + format(x * K_GEN_DPS, '.0e'):>13s} "
                                          f"{'q<=true ' + format(x * K_GEN_DPS, '.0e'):>13s} "
                                          f"{'free ' + format(x * K_GEN_DPS, '.0e'):>11s}" for x in mults))
    for mins in minutes:
        span = 60.0 * mins
        m = 300
        width = span / m
        t = (np.arange(m) + 0.5) * width
        dist = np.abs(t[:, None] - t[None, :])
        gm = power_on_gm_correlation(t, dist, tc)
        walk = np.minimum(t[:, None], t[None, :])
        walk[np.diag_indices(m)] -= width / 6.0
        white = np.eye(m) * sigma**2 / (width * fs)
        cells = []
        for x in mults:
            k2 = (x * K_GEN_DPS * DEG) ** 2
            c1 = white + q_true * gm + k2 * walk
            oracle = 3.0 * _two_kl(c1, white + q_true * gm)
            cls = 3.0 * min(_two_kl(c1, white + q * gm) for q in [0.0, *(q_cls * np.logspace(-3, 0, 19))])
            tight = 3.0 * min(_two_kl(c1, white + q * gm) for q in [0.0, *(q_true * np.logspace(-3, 0, 19))])
            free = 3.0 * min(_two_kl(c1, white + q * gm) for q in [0.0, *(q_true * np.logspace(-3, 5, 49))])
            cells.append(f"{oracle:14.1f} {cls:13.1f} {tight:13.1f} {free:11.2f}")
        print(f"{mins:7d} " + " ".join(cells))


#: The summary table's columns (row key, header): every gain against the critical value.
COLUMNS = (
    ("oracle", "oracle"), ("class", "class"), ("class_mean", "class+mean"), ("class_mean_tc", "class+mean+T_c"),
    ("class_est", "class(b est)"), ("free", "free q"), ("gain_qtrue", "q known"), ("gain_prof", "q refit"),
    ("gain_share", "default"), ("pr_share", "profile"), ("gain", "class-b"), ("cb_prof", "cb q refit"),
    ("cb_notemp", "cb no temp"), ("cb_tc", "cb T_c true"), ("cb_true_class", "cb b true"), ("pr_cb", "cb profile"),
)


def openaxes_table(log: Path) -> None:
    """The walk test's gain on the real OpenAXES BMI160 gyroscope (rig-free; ``log``: its CSV), judged against the
    station's Table 1 class and against its own data-sheet class (fixtures/limits/openaxes-bmi160.toml), with eq. 3's
    drift noise in the null bounded by: the warm-up's share (the default), the class too, nothing (q free); and the
    profile likelihood ratio (``WALK_PROFILE_TC``: T_c and q re-fitted in both hypotheses) with either bound."""
    from station.diagnose.locator import TABLE1_DRIFT, DriftClass
    from station.diagnose.rigfree_diagnosis import rig_free_baseline
    from station.kernel.limits_file import load_limits
    from station.session.multipos_import import import_openaxes

    baseline = rig_free_baseline(import_openaxes(log, accel="adxl355"))
    sd = baseline.sensor("gyro")
    own = DriftClass.from_limits(load_limits(Path(__file__).resolve().parents[1] / "fixtures" / "limits"
                                             / "openaxes-bmi160.toml"))
    print(f"OpenAXES BMI160 gyroscope: {len(sd.t_s)} blocks over {float(sd.t_s.max()):.0f} s; walk test gain "
          f"(critical {CRIT:.1f})")
    print(f"{'class':16s} {'q/q_class':>20s} {'default':>8s} {'class-b':>8s} {'q free':>7s} {'profile':>8s} "
          f"{'cb profile':>10s}")
    for name, cls in (("Table 1", TABLE1_DRIFT), ("openaxes-bmi160", own)):
        gains = []
        for bound, profile, free in ((False, False, False), (True, False, False), (False, False, True),
                                     (False, True, False), (True, True, False)):
            prob = SensorProblem(baseline, sd)
            prob.q_class = class_drift_noise("gyro", sd.params.bias_drift, cls)
            prob.walk_null_class_bound, prob.walk_profile_tc = bound, profile
            if free:
                prob.drift_noise_max = lambda k: math.inf  # type: ignore[method-assign]
            gains.append(prob.test_random_walk(size=False).gain)
        ratio = ",".join(f"{x:.3g}" for x in prob.q / prob.q_class)
        print(f"{name:16s} {ratio:>20s} " + " ".join(f"{g:8.1f}" for g in gains))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--base", type=int, default=340_000)
    ap.add_argument("--per", type=int, default=4, help="recordings per size and generator")
    ap.add_argument("--nulls", type=int, default=4, help="recordings without a walk per generator")
    ap.add_argument("--mults", default="0.1,0.3,1,3,10",
                    help="sizes, times the independent generator's 3e-5 deg/s/sqrt(s)")
    ap.add_argument("--generators", default="indep,sim")
    ap.add_argument("--no-diagnose", action="store_true", help="only the tests, not the whole diagnosis")
    ap.add_argument("--class-bound", action="store_true",
                    help="diagnose with the walk test's null bounded by the class (WALK_NULL_CLASS_BOUND on)")
    ap.add_argument("--plan", action="store_true", help="only the noncentrality by recording length (no recordings)")
    ap.add_argument("--openaxes", type=Path, help="only the walk test on this real OpenAXES log (no recordings)")
    args = ap.parse_args()
    if args.openaxes is not None:
        openaxes_table(args.openaxes)
        return
    if args.plan:
        plan_table([float(x) for x in args.mults.split(",")])
        return
    likelihood.WALK_NULL_CLASS_BOUND = args.class_bound
    tc = warmup_tc()
    mults = [0.0, *(float(x) for x in args.mults.split(","))]
    cases = {"indep": indep_case, "sim": sim_case}
    table: dict[tuple[str, float], list[dict[str, float]]] = {}
    seed = args.base
    cpu: list[float] = []
    for gen in args.generators.split(","):
        for mult in mults:
            for _ in range(args.nulls if mult == 0.0 else args.per):
                k_dps = mult * K_GEN_DPS
                session, truth = cases[gen](seed, k_dps)
                row = oracle_tests(truth, k_dps * DEG)
                row.update(station_test(session, tc, truth))
                row["named"] = math.nan
                if not args.no_diagnose:
                    t0 = time.process_time()
                    rep = diagnose(session, warmup_tc_s=tc).report
                    cpu.append(time.process_time() - t0)
                    walk = [f for f in rep.findings if f.effect == "bias_random_walk" and f.sensor == "gyro"]
                    row["named"] = float(bool(walk))
                    row["named_k"] = float(walk[0].theta[0]) / DEG if walk and walk[0].theta is not None else math.nan
                    std = walk[0].theta_std if walk else None
                    # the named size against the truth, in its own standard deviations
                    row["named_z"] = ((row["named_k"] - k_dps) / (float(std[0]) / DEG)
                                      if std is not None and float(std[0]) > 0 else math.nan)
                table.setdefault((gen, mult), []).append(row)
                print(f"  {gen:5s} seed {seed} K {k_dps:.2e}: lambda {row['lambda']:8.1f} oracle {row['oracle']:8.1f} "
                      f"(K {row['oracle_k']:.2e}) class {row['class']:7.1f} | station: q true {row['gain_qtrue']:7.1f} "
                      f"q re-fitted {row['gain_prof']:7.1f} share only {row['gain_share']:6.1f} "
                      f"class-bounded {row['gain']:6.1f} [q refit {row['cb_prof']:6.1f} no temp "
                      f"{row['cb_notemp']:6.1f} T_c true {row['cb_tc']:6.1f}] free {row['free']:6.1f} "
                      f"class+mean {row['class_mean']:6.1f} class+mean+T_c {row['class_mean_tc']:6.1f} "
                      f"class(est b_drift) {row['class_est']:6.1f} "
                      f"cb(true b_drift) {row['cb_true_class']:6.1f} profile LR: share {row['pr_share']:6.1f} "
                      f"class-bounded {row['pr_cb']:6.1f} ({row['cpu_pr']:.1f} s) "
                      f"named {row['named']:.0f}"
                      + (f" K {row['named_k']:.2e} z {row['named_z']:+.2f}"
                         if row.get("named_k", math.nan) == row.get("named_k", math.nan) else "")
                      + f"  q_max/q_class {row['q_max_over_class']:.1f}", flush=True)
                seed += 1
    print()
    print(f"gyro bias random walk: detections at half chi^2_1 > {CRIT:.1f} (ALPHA {ALPHA:g}), "
          f"seeds {args.base}-{seed - 1}")
    cols = [(key, label) for key, label in COLUMNS]
    print(f"{'gen':5s} {'K deg/s/rt(s)':>13s} {'n':>3s} {'lambda':>7s} {'P pred':>6s} "
          + " ".join(f"{label:>{max(len(label), 5)}s}" for _, label in cols) + f" {'named':>6s}")
    keys = [key for key, _ in cols]
    for (gen, mult), rows in table.items():
        n = len(rows)
        lam = float(np.median([r["lambda"] for r in rows]))
        pred = float(np.mean([stats.norm.sf(math.sqrt(CRIT) - math.sqrt(r["lambda"])) for r in rows]))
        det = [f"{sum(r[key] > CRIT for r in rows):d}/{n}" for key in keys]
        named = f"{sum(r['named'] > 0 for r in rows)}/{n}" if not args.no_diagnose else "-"
        print(f"{gen:5s} {mult * K_GEN_DPS:13.2e} {n:3d} {lam:7.1f} {pred:6.2f} "
              + " ".join(f"{d:>{max(len(label), 5)}s}" for d, (_, label) in zip(det, cols, strict=True))
              + f" {named:>6s}")
    zs = [(gen, mult, r["named_z"]) for (gen, mult), rows in table.items() for r in rows
          if r.get("named_z", math.nan) == r.get("named_z", math.nan)]
    if zs:
        print("named walks' size against the truth, (K - truth) / std: " + ", ".join(
            f"{g} {m * K_GEN_DPS:.0e} {z:+.2f}" for g, m, z in zs)
              + f"; within 3 std {sum(abs(z) <= 3.0 for _, _, z in zs)}/{len(zs)}")
    nulls = [r for (g, m), rows in table.items() if m == 0.0 for r in rows]
    if nulls:
        print("nulls: gains above 2.71 (5 % of half chi^2_1): " + ", ".join(
            f"{key} {sum(r[key] > 2.71 for r in nulls)}/{len(nulls)}" for key in keys))
    if cpu:
        print(f"diagnosis CPU median {sorted(cpu)[len(cpu) // 2]:.1f} s over {len(cpu)}")


if __name__ == "__main__":
    main()
