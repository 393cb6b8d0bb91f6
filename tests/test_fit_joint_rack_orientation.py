"""A rack that holds its units in one orientation: the joint fit ties the rack's level along gravity to its norm,
and refuses a unit that rested in another orientation; the line plan carries the setting."""

from __future__ import annotations

import numpy as np
import pytest

from station.fit.calibrate import FitOptions
from station.fit.joint import FREE_OFFSETS, fit_joint, tied_rack_force
from station.kernel.errors import FitError, RackOrientationError
from station.kernel.line_plan import LinePlan, default_line_plan, line_plan_from_json, line_plan_to_json
from station.kernel.plan import PlanError
from station.sequence.records import Outcome
from station.sequence.runner import refusal_outcome
from station.sim.line_sim import simulate_line

OPTIONS = FitOptions(tc_range_s={"accel": (50.0, 167.0), "gyro": (1030.0, 3760.0)})
PLAN = LinePlan(rack_s=1800.0, rack_orientation="+z")
SEEDS = (2101, 2102, 2103)


@pytest.fixture(scope="module")
def fits() -> list[tuple[object, object, object]]:
    out = []
    for seed in SEEDS:
        line = simulate_line(seed, plan=PLAN, rack_tilt_deg=4.0)
        out.append((line, fit_joint(line.rack, line.rig, OPTIONS, rack_orientation=FREE_OFFSETS),
                    fit_joint(line.rack, line.rig, OPTIONS, rack_orientation="+z")))
    return out


def test_the_tied_rack_level_along_gravity_is_the_true_one_to_second_order(fits: list) -> None:
    free_err, tied_err = [], []
    for line, free, tied in fits:
        c_true = line.rack_specific_force()
        assert 0.1 < np.degrees(np.linalg.norm(line.rack_tilt_rad)) <= 4.0  # a slot that is not level
        c_free = np.array(free.quality.extra["line"]["rack_specific_force_mps2"][0])
        c_tied = np.array(tied.quality.extra["line"]["rack_specific_force_mps2"][0])
        free_err.append(abs(c_free[2] - c_true[2]))
        tied_err.append(abs(c_tied[2] - c_true[2]))
        # across gravity the tie changes nothing: the slot's tilt is still one free offset per axis
        np.testing.assert_allclose(c_tied[:2], c_free[:2], atol=2e-6)
        np.testing.assert_allclose(tied.accel.misalignment[:2], free.accel.misalignment[:2], atol=1e-9)
    # free offsets: the level along gravity is known to the b_stat std (0.1-0.3 mm/s^2); tied: to the tilt's
    # error times the tilt (second order, a few hundredths of a mm/s^2)
    assert max(tied_err) < 3e-5, tied_err
    assert max(free_err) > 5e-5, free_err


def test_the_tie_makes_the_level_at_plus_z_that_of_the_truth(fits: list) -> None:
    # the corrected z output of a +z power-on rest, model only: M g + b(t) inverted with the fit; the tie brings
    # the z axis's error to the rig fit's size, within the stated uncertainty of b_stat
    for line, _free, tied in fits:
        p, t = tied.accel, line.truth.accel
        g = np.array([0.0, 0.0, float(np.linalg.norm(line.rack_specific_force()))])
        times = np.arange(0.0, 60.0, 1.0)
        y = t.misalignment @ g + t.bias_at(times)
        drift = np.where(np.isfinite(p.correlation_time_s), p.bias_drift, 0.0)
        tc = np.where(np.isfinite(p.correlation_time_s), p.correlation_time_s, 1.0)
        est = p.bias_static + drift * np.exp(-times[:, None] / tc)
        x = np.linalg.solve(p.misalignment, (y - est).T).T
        assert np.sqrt(np.mean((x[:, 2] - g[2]) ** 2)) < 3.0 * np.hypot(p.bias_static_std[2], 3e-4)


def test_the_rule_and_the_tilt_are_recorded(fits: list) -> None:
    for line, free, tied in fits:
        rec = tied.quality.extra["line"]
        assert rec["rack_orientation"] == "+z" and "sqrt(g^2" in rec["rule"]
        assert rec["rack_tilt_deg"][0] == pytest.approx(np.degrees(np.linalg.norm(line.rack_tilt_rad)), abs=0.01)
        assert "free offset per axis" in free.quality.extra["line"]["rule"]
        assert rec["gravity_mps2"] == pytest.approx(line.rig.gravity_mps2, abs=1e-9)


def test_a_unit_that_rested_another_way_is_refused_as_a_line_fault() -> None:
    line = simulate_line(2104, plan=LinePlan(rack_s=900.0, rack_orientation="-x"))
    with pytest.raises(RackOrientationError, match=r"rested 90\.\d deg from \+z up"):
        fit_joint(line.rack, line.rig, OPTIONS, rack_orientation="+z")
    err = RackOrientationError("x")
    assert isinstance(err, FitError) and refusal_outcome(err)[0] is Outcome.ERROR
    tilted = simulate_line(2105, plan=LinePlan(rack_s=900.0, rack_orientation="+z"), rack_tilt_deg=0.0)
    with pytest.raises(RackOrientationError):  # within 5 deg on the simulated tilt, not within 0.01 deg
        fit_joint(tilted.rack, tilted.rig, OPTIONS, rack_orientation="-z")


def test_tied_force_keeps_the_norm_and_the_components_across() -> None:
    c = np.array([0.3, -0.2, 9.79])
    tied, angle = tied_rack_force(c, "+z", 9.81, 5.0)
    assert tied[:2].tolist() == [0.3, -0.2] and np.linalg.norm(tied) == pytest.approx(9.81, abs=1e-12)
    assert angle == pytest.approx(np.degrees(np.arctan2(np.hypot(0.3, 0.2), 9.79)), abs=1e-9)
    tied, _ = tied_rack_force(np.array([-9.8, 0.1, 0.2]), "-x", 9.81, 5.0)
    assert tied[0] == pytest.approx(-np.sqrt(9.81**2 - 0.05), abs=1e-12)
    with pytest.raises(RackOrientationError):
        tied_rack_force(c, "+x", 9.81, 5.0)


def test_the_plan_carries_the_rack_orientation() -> None:
    assert '"rack_orientation"' not in line_plan_to_json(default_line_plan())  # the default's bytes as before
    plan = LinePlan(rack_orientation="+z", rack_tilt_tolerance_deg=3.0)
    back = line_plan_from_json(line_plan_to_json(plan))
    assert (back.rack_orientation, back.rack_tilt_tolerance_deg) == ("+z", 3.0)
    for bad in ({"rack_orientation": "up"}, {"rack_orientation": "+z", "rack_tilt_tolerance_deg": 0.0}):
        with pytest.raises(PlanError):
            LinePlan(**bad)  # type: ignore[arg-type]
