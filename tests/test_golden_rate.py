"""The golden check's stated false-stop rate and its sensitivity, against known truth (pure numbers, no peers).

Registration runs and checks are drawn from known normal distributions for ``m`` parameters; a stable station
must fail a check at the stated family-wise rate (Bonferroni over ``m`` independent parameters gives
``1 - (1 - alpha/m)^m``, just under ``alpha``), and a shift of ``d`` true sigmas on one parameter must be caught
with the probability integrated over the registered sigma's chi-square distribution (scipy), both within
the binomial interval of the simulated count.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import integrate, stats

from station.kernel.golden import (
    allowance_multiple,
    check_golden,
    detectable_shift,
    register_golden,
    student_t_quantile,
    student_t_two_sided_tail,
)


def _binomial_interval(p: float, trials: int, z: float = 3.29) -> tuple[float, float]:
    """The 99.9 % (normal approximation) range of a count with probability ``p`` over ``trials``."""
    h = z * math.sqrt(trials * p * (1 - p))
    return trials * p - h, trials * p + h


@pytest.mark.parametrize("dof", [1, 2, 3, 4, 5, 8, 9, 19, 29, 64, 199])
def test_t_quantile_and_tail_equal_scipy(dof: int) -> None:
    for p in (0.5, 0.6, 0.9, 0.975, 0.99865, 1 - 0.0027 / 132, 1 - 1e-6):
        q = student_t_quantile(p, dof)
        assert q == pytest.approx(float(stats.t.ppf(p, dof)), rel=1e-8, abs=1e-12)
    for t in (0.0, 0.3, 1.0, 2.5, 6.0, 30.0):
        assert student_t_two_sided_tail(t, dof) == pytest.approx(float(2 * stats.t.sf(t, dof)), rel=1e-8,
                                                                 abs=1e-15)


def test_k_for_the_default_rate_over_66_parameters() -> None:
    # the numbers the documentation quotes; scipy: t.ppf(1 - 0.0027 / 132, n - 1) * sqrt(1 + 1/n)
    for n, k in ((5, 21.34403), (10, 7.764205), (20, 5.430311)):
        assert allowance_multiple(0.0027, n, 66) == pytest.approx(k, rel=1e-6)
        assert allowance_multiple(0.0027, n, 66) == pytest.approx(
            float(stats.t.ppf(1 - 0.0027 / 132, n - 1)) * math.sqrt(1 + 1 / n), rel=1e-8)
    # the chance a shift of k true sigmas crosses +-k (s = sigma): one half, give or take the far side
    assert detectable_shift(5.43, 20) == pytest.approx(5.43, abs=1e-6)


@pytest.mark.parametrize(("alpha", "runs", "m", "trials"), [(0.05, 10, 66, 20000), (0.0027, 20, 66, 60000),
                                                             (0.01, 5, 8, 40000)])
def test_a_stable_station_fails_at_the_stated_rate(alpha: float, runs: int, m: int, trials: int) -> None:
    rng = np.random.default_rng(20261128)
    sigma = rng.uniform(0.5, 3.0, m)  # each parameter its own scatter and mean
    mean = rng.normal(0.0, 10.0, m)
    k = allowance_multiple(alpha, runs, m)
    reg = mean + sigma * rng.normal(size=(trials, runs, m))
    ref, s = reg.mean(axis=1), reg.std(axis=1, ddof=1)
    new = mean + sigma * rng.normal(size=(trials, m))
    stops = int(np.sum(np.any(np.abs(new - ref) > k * s, axis=1)))
    truth = 1 - (1 - alpha / m) ** m  # exact for independent parameters: each fails with alpha / m
    lo, hi = _binomial_interval(truth, trials)
    assert lo <= stops <= hi, (stops, truth * trials)
    # and not the old rule: max(4 s, ...) over 5 runs stops far more often
    if runs == 5:
        old = int(np.sum(np.any(np.abs(new - ref) > 4 * s, axis=1)))
        assert old > 2 * hi


def test_the_kernel_registration_and_check_keep_the_rate_end_to_end() -> None:
    """Through :func:`register_golden` and :func:`check_golden` themselves (smaller: pure Python)."""
    rng = np.random.default_rng(7)
    alpha, runs, m, trials = 0.2, 10, 12, 1500
    names = [f"p{i}" for i in range(m)]
    stops = 0
    for _ in range(trials):
        reg = rng.normal(size=(runs, m))
        g = register_golden("G", "", [{n: (float(v), "1", None, None) for n, v in zip(names, row, strict=True)}
                                      for row in reg], false_stop_rate=alpha)
        assert g.rule is not None and g.rule.parameters == m
        stops += not check_golden(g, dict(zip(names, map(float, rng.normal(size=m)), strict=True))).passed
    lo, hi = _binomial_interval(1 - (1 - alpha / m) ** m, trials)
    assert lo <= stops <= hi


@pytest.mark.parametrize("d", [3.0, 6.0, 8.0])
def test_a_shift_of_d_sigma_is_caught_with_the_predicted_probability(d: float) -> None:
    rng = np.random.default_rng(int(d * 10))
    alpha, runs, m, trials = 0.0027, 20, 66, 40000
    k = allowance_multiple(alpha, runs, m)
    reg = rng.normal(size=(trials, runs))
    ref, s = reg.mean(axis=1), reg.std(axis=1, ddof=1)
    new = d + rng.normal(size=trials)
    caught = int(np.sum(np.abs(new - ref) > k * s))
    # new - ref ~ N(d, 1 + 1/n), independent of s, (n - 1) s^2 ~ chi2_{n-1}: integrate the normal tails over
    # the chi2 density (scipy.stats.nct gives nan in this far tail with scipy 1.17)
    c = math.sqrt(1 + 1 / runs)
    chi2 = stats.chi2(runs - 1)

    def caught_given(x: float) -> float:
        a = k * math.sqrt(x / (runs - 1))
        return float((stats.norm.sf((a - d) / c) + stats.norm.cdf((-a - d) / c)) * chi2.pdf(x))

    p = integrate.quad(caught_given, 0, chi2.ppf(1 - 1e-12), limit=200)[0]
    lo, hi = _binomial_interval(p, trials)
    assert lo <= caught <= hi, (caught, p * trials)
