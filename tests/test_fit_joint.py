"""The line's joint fit (rack rest + rig recording of one power-on) against known truth, and the
power-interruption check."""

from __future__ import annotations

import numpy as np
import pytest

from station.fit.calibrate import FitOptions
from station.fit.joint import BOOT_KEY, WALL_KEY, check_power, fit_joint
from station.kernel.errors import FitError
from station.sim.line_sim import POWER_ON_WALL_S, simulate_line

SEEDS = range(2001, 2009)
#: the limits file's T_c ranges: the prior production fits use
OPTIONS = FitOptions(tc_range_s={"accel": (50.0, 167.0), "gyro": (1030.0, 3760.0)})
KEYS = ("misalignment", "bias_static", "bias_drift", "correlation_time_s")


@pytest.fixture(scope="module")
def study() -> dict[str, np.ndarray]:
    z: dict[str, list[np.ndarray]] = {}
    for seed in SEEDS:
        line = simulate_line(seed)
        params = fit_joint(line.rack, line.rig, OPTIONS)
        for name in ("accel", "gyro"):
            est, tru = getattr(params, name), getattr(line.truth, name)
            for key in KEYS:
                e, s, t = np.asarray(getattr(est, key)), np.asarray(getattr(est, f"{key}_std")), getattr(tru, key)
                z.setdefault(f"{name}.{key}", []).append(((e - t) / s).ravel())
        z.setdefault("rack_gravity", []).append(
            np.array(params.quality.extra["line"]["rack_gravity_mps2"]) - line.rig.gravity_mps2)
    return {k: np.concatenate(v) for k, v in z.items()}


@pytest.mark.parametrize("name", [f"{s}.{k}" for s in ("accel", "gyro") for k in KEYS])
def test_joint_fit_recovers_the_truth_within_its_uncertainties(study: dict[str, np.ndarray], name: str) -> None:
    z = study[name]
    if name == "gyro.correlation_time_s":
        # the hour in the rack resolves the gyro's slow warm-up (T_c 1030-3760 s), which no rig plan does
        assert np.mean(np.isfinite(z)) >= 0.9, f"{name}: z = {np.round(z, 2)}"
    z = z[np.isfinite(z)]  # T_c of an axis whose drift is not significant is NaN (and its b_drift 0 +- std)
    assert np.mean(np.abs(z) <= 3.0) >= 0.9, f"{name}: z = {np.round(z, 2)}"
    assert np.max(np.abs(z)) < 5.0, f"{name}: z = {np.round(z, 2)}"
    assert 0.4 < float(np.std(z)) < 1.6, f"{name}: spread of z {np.std(z):.2f}"


def test_the_rack_offsets_imply_local_gravity(study: dict[str, np.ndarray]) -> None:
    # |M^-1 o| is the specific force in the slot: gravity, within a few mm/s^2 (M's uncertainty)
    assert np.max(np.abs(study["rack_gravity"])) < 5e-3


def test_one_power_on_is_continuous() -> None:
    line = simulate_line(2001)
    power = check_power(line.rack, line.rig)
    assert power.continuous and power.reason == ""
    assert power.sensor_gap_s == pytest.approx(60.0, abs=0.02)
    assert power.wall_gap_s == pytest.approx(60.0, abs=0.02)


def test_a_power_cycle_between_rack_and_rig_is_detected_and_refused() -> None:
    line = simulate_line(2002, power_cycled=True)
    power = check_power(line.rack, line.rig)
    assert not power.continuous
    assert "power-on counter changed" in power.reason
    with pytest.raises(FitError, match="not one power-on"):
        fit_joint(line.rack, line.rig, OPTIONS)
    # without the counter in the metadata: the sensor time restarted at 0
    rig = line.rig.replace(metadata={k: v for k, v in line.rig.metadata.items() if k != BOOT_KEY})
    power = check_power(line.rack, rig)
    assert not power.continuous and "sensor time restarted" in power.reason


def test_a_sensor_time_that_disagrees_with_the_station_clock_is_an_interruption() -> None:
    line = simulate_line(2003)
    # the station's clock says 20 minutes passed, the sensor's time says one: its counter jumped
    late = {**line.rig.metadata, WALL_KEY: repr(POWER_ON_WALL_S + 3600.0 + 1200.0)}
    power = check_power(line.rack, line.rig.replace(metadata=late))
    assert not power.continuous and "disagree" in power.reason
    # a transfer longer than allowed
    power = check_power(line.rack, line.rig, max_transfer_s=30.0)
    assert not power.continuous and "transfer" in power.reason


def test_the_recordings_of_two_units_are_not_one_power_on() -> None:
    line = simulate_line(2004)
    rig = line.rig.replace(metadata={**line.rig.metadata, "serial": "OTHER"})
    assert "two units" in check_power(line.rack, rig).reason

