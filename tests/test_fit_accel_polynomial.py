"""The accelerometer's scale polynomial ``y = u + k2 u^2 + k3 u^3`` (``FitOptions.scale_nonlinearity``), by the
gyro's rule: fitted where the poses hold two magnitudes of specific force along an axis (here four corner poses,
gravity along a body diagonal: +-g/sqrt(3) besides the faces' +-g), flagged not determined on a 1 g rig of face
poses, and a kept term carried in the set and applied by Algorithm 1.

The recordings come from the independent generator (``tests/indepgen.py``: its own rig, sensor and noise code; it
bends each sensing element's input before its misalignment, the fit's model after it, which differs by the
cross-axis terms times k2, about 1 % of k2). Seeds: development 400000-403999; these tests use 404000-404011.
"""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest

from station.correct.session_correct import correct_session
from station.fit.calibrate import FitOptions, fit_session
from station.kernel.parameters import ParameterSet
from station.session.model import Kind, Session
from tests.indepgen import CORNER_POSES, Recording, generate, random_plan

AUTO = FitOptions(scale_nonlinearity="auto")
#: k2 as a relative scale error at 1 g (the generator's unit for the accelerometer).
K2_REL = 5e-4


def with_corners(seed: int, effects: dict[str, float] | None = None) -> Recording:
    """The generator's own plan for ``seed`` with the four corner poses added after its face poses."""
    plan = random_plan(np.random.default_rng([seed, 16]))
    return generate(seed, effects, replace(plan, poses=(*plan.poses, *CORNER_POSES)))


def pose_error_rms(session: Session, params: ParameterSet) -> float:
    """RMS over the poses' settled second halves of the corrected specific force against the rig's (m/s^2)."""
    out = correct_session(session, params)
    errs = []
    for seg in session.segments_of(Kind.POSE):
        half = slice(seg.start + (seg.stop - seg.start) // 2, seg.stop)
        errs.append(np.mean(out.accel_mps2[half] - session.ref_accel_mps2[half], axis=0))
    return float(np.sqrt(np.mean(np.square(errs))))


@pytest.mark.parametrize("seed", [404000, 404001, 404002])
def test_k2_fitted_within_its_uncertainty_where_the_poses_hold_two_magnitudes(seed: int) -> None:
    rec = with_corners(seed, {"scale_nonlinearity_even": K2_REL})
    params = fit_session(rec.session, AUTO)
    note = params.quality.accel_scale_polynomial
    assert note is not None and note.status == "fitted" and note.axes == ("x", "y", "z")
    assert note.detail["identifiable"] == {"k2": ["x", "y", "z"], "k3": ["x", "y", "z"]}
    k2, k2_std = params.accel.scale_quadratic, params.accel.scale_quadratic_std
    truth = np.asarray(rec.truth["scale_nonlinearity_even accel"])
    assert np.all(k2_std > 0) and np.all(np.abs(k2 - truth) < 3 * k2_std), (k2, k2_std, truth)
    assert np.all(k2_std < 0.1 * np.abs(truth))  # resolved, not merely kept
    assert np.all(params.accel.scale_cubic == 0.0)  # none planted: estimated, not kept
    assert params.quality.goodness_of_fit is not None and params.quality.goodness_of_fit.passed


@pytest.mark.parametrize("seed", [404003, 404004, 404005])
def test_a_linear_accelerometer_keeps_no_term(seed: int) -> None:
    params = fit_session(with_corners(seed).session, AUTO)
    note = params.quality.accel_scale_polynomial
    assert note is not None and note.status == "not_significant"
    assert np.all(params.accel.scale_quadratic == 0.0) and np.all(params.accel.scale_cubic == 0.0)


def test_face_poses_alone_leave_both_terms_not_determined() -> None:
    """+-g and 0 along each axis: k3 is a scale error there, and k2 would leave the three levels untested (one
    pose off its reference taken for a k2); neither is fitted, the note names the poses that would help."""
    rec = generate(404007, {"scale_nonlinearity_even": K2_REL})
    params = fit_session(rec.session, AUTO)
    note = params.quality.accel_scale_polynomial
    assert note is not None and note.status == "not_identifiable" and note.axes == ()
    assert np.all(params.accel.scale_quadratic == 0.0) and np.all(params.accel.scale_cubic == 0.0)
    assert all("tilted" in m for m in note.detail["not_identifiable"]) and len(note.detail["not_identifiable"]) == 3


def test_kept_k2_is_carried_and_applied() -> None:
    rec = with_corners(404006, {"scale_nonlinearity_even": K2_REL})
    params = fit_session(rec.session, AUTO)
    assert np.all(params.accel.scale_quadratic != 0.0)
    # the set's JSON keeps the values and the note; the loader reads them back
    again = ParameterSet.from_dict(json.loads(params.to_json()))
    assert np.array_equal(again.accel.scale_quadratic, params.accel.scale_quadratic)
    assert again.quality.accel_scale_polynomial == params.quality.accel_scale_polynomial
    # Algorithm 1 inverts it: the poses' corrected error is smaller with it than with the same set without it
    without = replace(params, accel=replace(params.accel, scale_quadratic=np.zeros(3)))
    assert pose_error_rms(rec.session, params) < 0.5 * pose_error_rms(rec.session, without)
