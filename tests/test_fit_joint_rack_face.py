"""A rack of any orientation whose unit lies on one of its faces: the joint fit finds the face from the rest and ties
the rack's level along gravity to its norm; a rest on no face keeps the free offsets (and is not refused)."""

from __future__ import annotations

import numpy as np
import pytest

from station.fit.calibrate import FitOptions
from station.fit.joint import FREE_OFFSETS, fit_joint, nearest_face
from station.kernel.geometry import AXIS_INDEX
from station.kernel.line_plan import LinePlan
from station.sim.line_sim import simulate_line

OPTIONS = FitOptions(tc_range_s={"accel": (50.0, 167.0), "gyro": (1030.0, 3760.0)})
PLAN = LinePlan(rack_s=1800.0)  # rack_orientation "any"
SEEDS = (3101, 3102, 3103, 3104)


@pytest.fixture(scope="module")
def fits() -> list[tuple[object, object, object]]:
    out = []
    for seed in SEEDS:
        line = simulate_line(seed, plan=PLAN, any_tilt_deg=4.0)
        out.append((line, fit_joint(line.rack, line.rig, OPTIONS),
                    fit_joint(line.rack, line.rig, OPTIONS, rack_orientation=FREE_OFFSETS)))
    return out


def test_the_face_is_found_and_its_level_tied_to_the_norm_of_gravity(fits: list) -> None:
    faces, tied_err, free_err = set(), [], []
    for line, tied, free in fits:
        rec = tied.quality.extra["line"]
        assert rec["rack_face"] == line.rack_up, rec
        assert rec["rack_face_angle_deg"][0] == pytest.approx(np.degrees(np.linalg.norm(line.rack_tilt_rad)), abs=0.01)
        assert f"found lying on a face ({line.rack_up} up)" in rec["rule"]
        assert "rack_face" not in free.quality.extra["line"]
        faces.add(line.rack_up)
        k = AXIS_INDEX[line.rack_up[1]]
        c_true = line.rack_specific_force()
        c_tied = np.array(rec["rack_specific_force_mps2"][0])
        c_free = np.array(free.quality.extra["line"]["rack_specific_force_mps2"][0])
        tied_err.append(abs(c_tied[k] - c_true[k]))
        free_err.append(abs(c_free[k] - c_true[k]))
        # second order: the tilt across up times the error of the components across up, over g
        across = np.delete(np.arange(3), k)
        second = np.linalg.norm(c_true[across]) * np.linalg.norm(c_tied[across] - c_true[across]) / 9.8
        assert tied_err[-1] <= 1.2 * second + 1e-5, (tied_err[-1], second)
    assert len(faces) >= 2, faces  # the seeds put the units on more than one face
    # along gravity: to the b_stat std with free offsets (0.1-0.3 mm/s^2), a few hundredths tied
    # along gravity: to the b_stat std with free offsets (0.1-0.8 mm/s^2 here), a few hundredths of it tied
    assert max(tied_err) < 0.1 * max(free_err), (tied_err, free_err)
    assert max(free_err) > 3e-4, free_err


def test_a_rest_on_no_face_keeps_the_free_offsets() -> None:
    line = simulate_line(3106, plan=LinePlan(rack_s=900.0, rack_orientation="+z"), rack_tilt_deg=20.0)  # 12.7 deg
    assert np.degrees(np.linalg.norm(line.rack_tilt_rad)) > 5.0  # farther from +z than the tolerance
    p = fit_joint(line.rack, line.rig, OPTIONS)
    rec = p.quality.extra["line"]
    assert rec["rack_face"] is None and "no tie to the norm of gravity" in rec["rule"]
    free = fit_joint(line.rack, line.rig, OPTIONS, rack_orientation=FREE_OFFSETS)
    np.testing.assert_allclose(p.accel.bias_static, free.accel.bias_static, atol=1e-12)


def test_nearest_face() -> None:
    assert nearest_face(np.array([0.1, -9.8, 0.2])) == ("-y", pytest.approx(np.degrees(np.arctan2(np.hypot(0.1, 0.2),
                                                                                                   9.8)), abs=1e-9))
    assert nearest_face(np.array([0.0, 0.0, 9.81])) == ("+z", 0.0)
