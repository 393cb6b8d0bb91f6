"""The block problem's kept factorizations and re-fits give what a new computation gives, bit for bit; the walk's
restricted likelihood and a finding's stated uncertainty with the spread of its size are what they say.

``SensorProblem`` keeps Cholesky factors by (axis, T_c, q, K^2, white variance) and the drift's T_c re-fit by the
state it starts from (diagnosis CPU time); a kept value must be the value: here each is compared with a fresh
computation on the same state, including under an inflated white noise (``inflated_noise``), whose factors must not
be mixed up with the plain ones.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy import linalg

from station.diagnose.likelihood import SensorProblem
from station.diagnose.residuals import Baseline, fit_baseline
from station.diagnose.retest import SizeCheck
from station.kernel.plan import RigPlan
from station.physics.effects import Effects
from station.sim.session_sim import simulate_session

#: A short plan (~4 min at 100 Hz): rest, the six poses, rate steps about every axis.
PLAN = RigPlan(rest_s=60.0, pose_hold_s=10.0, rate_steps=tuple((a, s * 100.0) for a in "xyz" for s in (1.0, -1.0)),
               rate_hold_s=5.0)


@pytest.fixture(scope="module")
def baseline() -> Baseline:
    return fit_baseline(simulate_session(8, plan=PLAN, effects=Effects.parse("lever_arm=20")).session)


def _fresh_chol(prob: SensorProblem, k: int) -> np.ndarray:
    c = float(prob.q[k]) * prob.gm[k] + prob.k2 * prob.tmin
    c[np.diag_indices_from(c)] += prob.white[:, k]
    return linalg.cholesky(c, lower=True, check_finite=False)


def test_kept_cholesky_factors_are_the_factors(baseline: Baseline) -> None:
    prob = SensorProblem(baseline, baseline.gyro)
    for k in range(3):
        first = prob.chol(k, float(prob.q[k]), prob.k2)
        assert prob.chol(k, float(prob.q[k]), prob.k2) is first  # kept
        np.testing.assert_array_equal(first, _fresh_chol(prob, k))
    plain = prob.chol(0, float(prob.q[0]), prob.k2)
    phi = np.full((prob.m, 3), 2.0)
    with prob.inflated_noise(phi):
        inflated = prob.chol(0, float(prob.q[0]), prob.k2)
        np.testing.assert_array_equal(inflated, _fresh_chol(prob, 0))
        assert not np.array_equal(inflated, plain)
    np.testing.assert_array_equal(prob.chol(0, float(prob.q[0]), prob.k2), plain)
    # another q or T_c: another factor
    other = prob.chol(0, 3.0 * float(prob.q[0]) + 1e-12, prob.k2)
    assert not np.array_equal(other, plain)


def test_kept_drift_refit_is_the_refit(baseline: Baseline) -> None:
    prob = SensorProblem(baseline, baseline.accel)
    zb = np.zeros((prob.m, 3, 1))
    zb[:, :, 0] = np.linspace(-1.0, 1.0, prob.m)[:, None] * 1e-3  # a slow ramp: moves the drift's T_c
    start = prob._snapshot()
    with prob.given(zb):
        prob.refit_drift()
        kept_tc, kept_q = prob.tc.copy(), prob.q.copy()
        prob._restore(start)
        prob.refit_drift()  # from the same state: the kept outcome
        np.testing.assert_array_equal(prob.tc, kept_tc)
        np.testing.assert_array_equal(prob.q, kept_q)
        prob._restore(start)
        prob._refit_drift()  # a new computation
        np.testing.assert_array_equal(prob.tc, kept_tc)
        np.testing.assert_array_equal(prob.q, kept_q)
    prob._restore(start)
    prob.refit_drift()  # without the ramp: another state, its own outcome
    fresh = SensorProblem(baseline, baseline.accel)
    fresh._restore(start)
    fresh._refit_drift()
    np.testing.assert_array_equal(prob.tc, fresh.tc)
    np.testing.assert_array_equal(prob.q, fresh.q)
    # the ramp's outcome is another one: a cache that ignored the accepted effects would have returned it here
    assert not (np.array_equal(prob.tc, kept_tc) and np.array_equal(prob.q, kept_q))


def test_restricted_likelihood_adds_half_the_log_determinant(baseline: Baseline) -> None:
    prob = SensorProblem(baseline, baseline.gyro)
    k, q, k2 = 1, float(prob.q[1]), 1e-9
    ch = prob.chol(k, q, k2)
    xw = linalg.solve_triangular(ch, prob.base[k], lower=True)
    _, logdet = np.linalg.slogdet(xw.T @ xw)
    diff = prob._axis_nll(k, q, k2, None, reml=True) - prob._axis_nll(k, q, k2, None)
    assert diff == pytest.approx(0.5 * logdet, rel=1e-9)


def test_stated_std_holds_the_spread_of_the_size_between_the_fits() -> None:
    size = SizeCheck("time_offset", "gyro", reported=np.array([5.0e-3]), final=np.array([5.004e-3]),
                     final_class_q=np.array([5.001e-3]), std=np.array([3e-6]))
    np.testing.assert_allclose(size.spread, [4e-6], rtol=1e-9)
    np.testing.assert_allclose(size.stated_std(np.array([3e-6])), [5e-6], rtol=1e-9)
    stable = SizeCheck("lever_arm", "accel", reported=np.ones(3), final=np.ones(3), final_class_q=np.ones(3),
                       std=np.full(3, 0.1))
    np.testing.assert_array_equal(stable.stated_std(np.full(3, 0.1)), np.full(3, 0.1))


def test_covariance_built_in_place_is_the_plain_sum_bit_for_bit(baseline: Baseline) -> None:
    # SensorProblem._covariance leaves out the walk's term where K^2 = 0: the same bytes as q GM + K^2 tmin + white,
    # signed zeros included (q = 0 makes -0 of GM's tiny negative entries; the plain sum turns them into +0)
    prob = SensorProblem(baseline, baseline.gyro)
    for k, q, k2 in ((0, float(prob.q[0]), 0.0), (1, 0.0, 0.0), (2, float(prob.q[2]), 1e-9), (0, 0.0, 3e-8)):
        plain = q * prob.gm[k] + k2 * prob.tmin
        plain[np.diag_indices_from(plain)] += prob.white[:, k]
        built = prob._covariance(k, q, k2)
        np.testing.assert_array_equal(built, plain)
        np.testing.assert_array_equal(np.signbit(built), np.signbit(plain))
        assert built.tobytes() == plain.tobytes()
    assert prob._tmin_nonneg
