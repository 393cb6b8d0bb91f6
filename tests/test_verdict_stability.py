"""Verdicts and move durations: with the sensor class's T_c prior, b_stat's uncertainty no longer depends on
how long the rig's moves take, and a verdict changes only where a value sits at a limit.

Without a prior, a recording too short to identify T_c makes b_stat an extrapolation along exp(-t/T_c) whose
uncertainty depends on the timing of the plan: the same unit passed alone and failed on a busy host. The
units are the demo's four (``station demo``'s default seed) and four simulated units; their sessions are
simulated on the default plan with the moves taking 0.5x, 1x and 1.5x as long (same unit, same noise streams).
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
import pytest

from station.fit.calibrate import FitOptions, fit_session
from station.kernel.limits_file import load_limits
from station.kernel.measurement import Measurement
from station.kernel.plan import default_plan, with_move_time_scale
from station.sequence.limits import check_limits
from station.sim.session_sim import simulate_session

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
from bench_verdicts import FACTORS, demo_units, unit_of

pytestmark = pytest.mark.slow
LIMITS = load_limits()
PRIOR = FitOptions(tc_range_s=dict(LIMITS.correlation_time_s))
UNITS = [(7000 + k, t) for k, t in enumerate(demo_units())] + [(s, unit_of(s)) for s in range(5000, 5004)]


def _fits(seed: int, truth: object, options: FitOptions | None) -> list:
    return [fit_session(simulate_session(seed, unit=truth, plan=with_move_time_scale(default_plan(), f)).session,
                        options) for f in FACTORS]  # type: ignore[arg-type]


def _bstat_std_ratio(fits: list) -> float:
    s = np.array([np.concatenate([p.accel.bias_static_std, p.gyro.bias_static_std]) for p in fits])
    return float(np.max(s.max(axis=0) / s.min(axis=0)))


def test_the_prior_makes_b_stat_uncertainty_independent_of_move_durations() -> None:
    with_prior = [_bstat_std_ratio(_fits(seed, truth, PRIOR)) for seed, truth in UNITS[:4]]
    without = [_bstat_std_ratio(_fits(seed, truth, None)) for seed, truth in UNITS[:4]]
    assert max(with_prior) < 3.5, with_prior  # the demo units' b_stat std within 3.5x over 0.5x..1.5x moves
    assert max(without) > 3.5, without  # ... where the record alone lets it move several-fold


def _distance_in_std(c: Measurement) -> float:
    d = min(abs(c.value - c.low), abs(c.value - c.high))
    return d / c.std if math.isfinite(c.std) and c.std > 0 else math.inf


@pytest.mark.parametrize(("seed", "truth"), UNITS, ids=[str(s) for s, _ in UNITS])
def test_a_verdict_changes_only_at_a_limit(seed: int, truth: object) -> None:
    per_factor = [{c.name: c for c in check_limits(p, LIMITS.product)} for p in _fits(seed, truth, PRIOR)]
    for name in per_factor[0]:
        # PASS and MARGINAL are both a pass
        verdicts = {"pass" if pf[name].passed else pf[name].verdict.value for pf in per_factor if name in pf}
        if len(verdicts) > 1:  # then the value lies within a few standard uncertainties of a limit in every run
            assert all(_distance_in_std(pf[name]) < 4.0 for pf in per_factor if name in pf), name
