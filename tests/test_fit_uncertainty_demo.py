"""Uncertainties on the units of ``station demo`` stay inside the default fit-quality limit.

Regression for 2026-11-21: averaging the (b_stat, b_drift) covariance over T_c wherever T_c's
upper 1-sigma edge exceeded half the record gave accel b_stat stds of 0.067 m/s^2 on demo unit 3
(actual error < 0.001 m/s^2), above the limit of 0.01 m/s^2: good units FAILed. The units are drawn
exactly as ``station.sim.station_sim.SimStation`` draws them (seed 0); the sessions are simulated
directly, not captured through the station (its timing differs slightly).
"""

from __future__ import annotations

import numpy as np
import pytest

from station.fit.calibrate import fit_session
from station.kernel.parameters import ParameterSet
from station.kernel.sensor_class import TABLE1
from station.physics.unit import UnitTruth, draw_unit
from station.sim.session_sim import simulate_session

#: fixtures/limits/default.toml: accel_bias_static_std_mps2
ACCEL_B_STD_LIMIT = 0.01


def _demo_unit(k: int) -> tuple[UnitTruth, ParameterSet]:
    unit_ss = np.random.SeedSequence(0, spawn_key=(k,)).spawn(3)[0]
    truth = draw_unit(TABLE1, np.random.default_rng(unit_ss))
    return truth, fit_session(simulate_session(k, unit=truth).session)


@pytest.mark.parametrize("k", [0, 1, 3])
def test_accel_bias_std_is_near_the_actual_error(k: int) -> None:
    truth, params = _demo_unit(k)
    std = params.accel.bias_static_std
    err = np.abs(params.accel.bias_static - truth.accel.bias_static)
    assert np.all(std < ACCEL_B_STD_LIMIT), std
    # within 3 sigma, and the std not a hundred times what the error could plausibly be
    assert np.all(err <= 3 * std), (err, std)
    assert np.all(std < 0.002), std


@pytest.mark.xfail(
    strict=True,
    reason="demo unit 2, accel z: T_c fitted 1140 s against 136 s true; b_stat std 0.116 m/s^2 for an "
    "error of 0.0039 m/s^2 (0.025 before the likelihood averaging). Its station-captured session passes.",
)
def test_accel_bias_std_unit_2() -> None:
    _truth, params = _demo_unit(2)
    assert np.all(params.accel.bias_static_std < ACCEL_B_STD_LIMIT), params.accel.bias_static_std
