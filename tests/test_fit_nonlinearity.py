"""The gyro's scale nonlinearity ``y = u + k u|u|`` in the fit (FitOptions.scale_nonlinearity), carried in the
parameter set and inverted by Algorithm 1's line 6' (issue 18, item 4).

Seeds: development used 100-129; these tests use 300-305.
"""

from __future__ import annotations

import numpy as np
import pytest

from station.correct.session_correct import correct_session
from station.fit.calibrate import FitOptions, fit_session
from station.kernel.plan import default_plan
from station.physics.effects import Effects
from station.session.model import Kind
from station.sim.session_sim import simulate_session

PRIOR = {"accel": (50.0, 167.0), "gyro": (1030.0, 3760.0)}
AUTO = FitOptions(scale_nonlinearity="auto", tc_range_s=PRIOR)
OFF = FitOptions(tc_range_s=PRIOR)


def worst_rate_error(session, params) -> float:
    """Worst relative error of the corrected rate over the rate steps' settled second halves."""
    out = correct_session(session, params)
    worst = 0.0
    for seg in session.segments_of(Kind.RATE):
        half = slice(seg.start + (seg.stop - seg.start) // 2, seg.stop)
        ref = session.ref_gyro_radps[half].mean(axis=0)
        err = out.gyro_radps[half].mean(axis=0) - ref
        worst = max(worst, float(np.linalg.norm(err) / np.linalg.norm(ref)))
    return worst


@pytest.mark.parametrize("seed", [300, 301, 302])
def test_nonlinearity_is_recovered_within_its_uncertainty_and_corrected(seed: int) -> None:
    sim = simulate_session(seed, effects=Effects(scale_nonlinearity=0.001))  # 0.1 % at 200 deg/s
    params = fit_session(sim.session, AUTO)
    note = params.quality.scale_nonlinearity
    assert note is not None
    assert note.status == "fitted" and note.axes == ("x", "y", "z"), note
    truth = sim.effect_truth.gyro_nonlinearity
    k, k_std = params.gyro.scale_nonlinearity, params.gyro.scale_nonlinearity_std
    assert np.all(k_std > 0)
    assert np.all(np.abs(k - truth) < 4.0 * k_std), (k, truth, k_std)
    # the corrected rate: the model with the term is several times better than without it
    without = fit_session(sim.session, OFF)
    assert not np.any(without.gyro.scale_nonlinearity)
    e_with, e_without = worst_rate_error(sim.session, params), worst_rate_error(sim.session, without)
    assert e_with < e_without / 3.0, (e_with, e_without)


def test_no_nonlinearity_is_not_fitted() -> None:
    sim = simulate_session(303)
    params = fit_session(sim.session, AUTO)
    note = params.quality.scale_nonlinearity
    assert note is not None
    assert note.status == "not_significant", note
    assert not np.any(params.gyro.scale_nonlinearity) and not params.has_nonlinearity


def test_one_rate_magnitude_cannot_identify_it() -> None:
    plan = default_plan()
    from dataclasses import replace

    one = replace(plan, rate_steps=tuple((a, s * 100.0) for a in "xyz" for s in (1.0, -1.0)))
    sim = simulate_session(304, plan=one, effects=Effects(scale_nonlinearity=0.001))
    params = fit_session(sim.session, AUTO)
    note = params.quality.scale_nonlinearity
    assert note is not None
    assert note.status == "not_identifiable" and "second magnitude" in note.reason, note
    assert note.detail["levels"] == [1, 1, 1]
    assert not np.any(params.gyro.scale_nonlinearity)


def test_the_default_fit_leaves_it_out_and_bad_modes_are_refused() -> None:
    sim = simulate_session(305, effects=Effects(scale_nonlinearity=0.001))
    params = fit_session(sim.session, OFF)
    assert params.quality.scale_nonlinearity is None
    with pytest.raises(ValueError, match="scale_nonlinearity"):
        FitOptions(scale_nonlinearity="yes")
