"""The gyro's scale-factor polynomial of IEEE Std 952, ``y = u + k2 u^2 + k3 u^3``, in the fit
(FitOptions.scale_nonlinearity), carried in the parameter set and inverted by Algorithm 1's line 6'.

The station's simulator gets the polynomial on the unit's truth (``EffectTruth.gyro_quadratic``, ``gyro_cubic``).
Seeds: development used 100-129; these tests use 300-306.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from station.correct.session_correct import correct_session
from station.fit.calibrate import FitOptions, fit_session
from station.kernel.plan import default_plan
from station.physics.effects import Effects, EffectShapes, EffectTruth
from station.session.model import Kind
from station.sim.session_sim import simulate_session

PRIOR = {"accel": (50.0, 167.0), "gyro": (1030.0, 3760.0)}
AUTO = FitOptions(scale_nonlinearity="auto", tc_range_s=PRIOR)
OFF = FitOptions(tc_range_s=PRIOR)
W200 = float(np.radians(200.0))


def poly_truth(k2_rel: float, k3_rel: float, seed: int = 0) -> EffectTruth:
    """A truth with the polynomial: relative scale errors k2 |u|, k3 u^2 at 200 deg/s, signs per axis."""
    sign = np.array([1.0, -1.0, 0.8])
    et = Effects().realize(EffectShapes.draw(np.random.default_rng(seed)))
    return replace(et, gyro_quadratic=sign * k2_rel / W200, gyro_cubic=-sign[::-1] * k3_rel / W200**2)


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
def test_polynomial_is_recovered_within_its_uncertainty_and_corrected(seed: int) -> None:
    truth = poly_truth(1e-3, 1e-3)
    sim = simulate_session(seed, effect_truth=truth)
    params = fit_session(sim.session, AUTO)
    note = params.quality.scale_nonlinearity
    assert note is not None
    assert note.status == "fitted" and note.axes == ("x", "y", "z"), note
    for name, true in (("scale_quadratic", truth.gyro_quadratic), ("scale_cubic", truth.gyro_cubic)):
        k, k_std = getattr(params.gyro, name), getattr(params.gyro, f"{name}_std")
        assert np.all(k_std > 0), (name, k_std)
        assert np.all(np.abs(k - true) < 4.0 * k_std), (name, k, true, k_std)
    assert not np.any(params.gyro.scale_nonlinearity)  # the u|u| term is no longer fitted
    without = fit_session(sim.session, OFF)
    assert not without.has_nonlinearity
    e_with, e_without = worst_rate_error(sim.session, params), worst_rate_error(sim.session, without)
    assert e_with < e_without / 3.0, (e_with, e_without)


def test_no_nonlinearity_is_not_fitted() -> None:
    sim = simulate_session(303)
    params = fit_session(sim.session, AUTO)
    note = params.quality.scale_nonlinearity
    assert note is not None
    assert note.status == "not_significant", note
    assert not params.has_nonlinearity and params.format == "station-params/2"


def test_one_rate_magnitude_cannot_identify_it() -> None:
    one = replace(default_plan(), rate_steps=tuple((a, s * 100.0) for a in "xyz" for s in (1.0, -1.0)))
    sim = simulate_session(304, plan=one, effect_truth=poly_truth(1e-3, 1e-3))
    params = fit_session(sim.session, AUTO)
    note = params.quality.scale_nonlinearity
    assert note is not None
    assert note.status == "not_identifiable" and "second magnitude" in note.reason, note
    assert note.detail["levels"] == [1, 1, 1]
    assert not params.has_nonlinearity


def test_one_sign_identifies_the_odd_term_only() -> None:
    """Rates in one direction only: u^2 is not separable from the bias and u^3; k2 is left out, named with the rig
    step that would separate it, and k3 is still fitted."""
    plan = replace(default_plan(), rate_steps=tuple((a, r) for a in "xyz" for r in (50.0, 100.0, 200.0)))
    truth = poly_truth(0.0, 1e-3)
    sim = simulate_session(306, plan=plan, effect_truth=truth)
    params = fit_session(sim.session, AUTO)
    note = params.quality.scale_nonlinearity
    assert note is not None and note.status == "fitted", note
    assert note.detail["identifiable"] == {"k2": [], "k3": ["x", "y", "z"]}
    assert any("other direction" in m for m in note.detail["not_identifiable"])
    assert not np.any(params.gyro.scale_quadratic)
    assert np.all(np.abs(params.gyro.scale_cubic - truth.gyro_cubic) < 4.0 * params.gyro.scale_cubic_std)


def test_the_default_fit_leaves_it_out_and_bad_modes_are_refused() -> None:
    sim = simulate_session(305, effect_truth=poly_truth(1e-3, 0.0))
    params = fit_session(sim.session, OFF)
    assert params.quality.scale_nonlinearity is None and not params.has_nonlinearity
    with pytest.raises(ValueError, match="scale_nonlinearity"):
        FitOptions(scale_nonlinearity="yes")
