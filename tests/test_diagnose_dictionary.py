"""The locator's covariate dictionary beyond rate, force and temperature: the temperature's rate, the force and the
rate through first-order lags (creep, settling), even functions of the force, a direction-dependent bias; and the
rivals that keep a library finding from standing in for such a term.

The recordings are ``tests/indepgen.py``'s rig and sensor (not ``station.sim``'s model) with the physics outside the
library added here, from the recording's own reference (the true rate and specific force) and a climate program of
this file: truth is known, and none of it is written by the code under test.
"""

from __future__ import annotations

import dataclasses
import math
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from scipy.signal import lfilter

from station.diagnose import locator

sys.path.insert(0, str(Path(__file__).resolve().parent))

DEG = math.pi / 180.0


def test_lag_excess_is_a_step_decaying_with_its_time_constant() -> None:
    fs, tau = 50.0, 3.0
    x = np.zeros((1000, 3))
    x[200:, 1] = 9.81  # a step of g on y at 4 s
    out = locator._lag_excess(x, fs, tau)
    t = (np.arange(1000) - 200) / fs
    assert np.all(out[:200] == 0.0) and np.all(out[:, [0, 2]] == 0.0)
    # after the step: the step times exp(-t / tau), sampled (one sample of the discrete lag's delay)
    assert out[200 + 150, 1] == pytest.approx(9.81 * math.exp(-t[350] / tau) * math.exp(-1.0 / (fs * tau)), rel=1e-9)
    assert abs(out[-1, 1]) < 9.81 * math.exp(-15.0 / tau)


def test_last_direction_holds_the_sign_of_the_last_rotation() -> None:
    rate = np.zeros((10, 3))
    rate[2:4, 0] = 0.5
    rate[6:7, 0] = -0.5
    rate[5, 2] = 0.01 * DEG  # slower than the threshold: no rotation
    d = locator._last_direction(rate)
    assert d[:, 0].tolist() == [0, 0, 1, 1, 1, 1, -1, -1, -1, -1]
    assert np.all(d[:, 1:] == 0)


def _climate(t: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """This file's climate program: the temperature ramps up and down (a triangle of 4-6 K, period 5-8 min) around
    a slow rise, read at 1/16 K."""
    period = rng.uniform(300.0, 480.0)
    amp = rng.uniform(4.0, 6.0)
    tri = 2.0 * np.abs(2.0 * ((t / period + rng.uniform()) % 1.0) - 1.0) - 1.0
    return np.asarray(25.0 + amp * tri + 0.5 * t / 600.0)


def _outside(seed: int, kind: str) -> tuple[Any, int]:
    """An indepgen recording (no library effect) with one physics outside the library on one axis: ``dtdt_scale``
    (accel, ``f_k (1 + c dT/dt)``, c 0.08 s/K), ``creep`` (accel, ``f_k + c (L[f_k] - f_k)``, ``L`` a 5 s lag, c
    5e-3), ``direction_bias`` (gyro, ``+-0.02 deg/s`` by the direction of the last rotation about the axis faster
    than 5 deg/s). Returns (session, axis)."""
    import indepgen

    s = indepgen.generate(seed).session
    rng = np.random.default_rng([seed, 27])
    k = int(rng.integers(3))
    fs = s.sample_rate_hz
    t = s.t_s
    accel, gyro, temp = s.accel_mps2.copy(), s.gyro_radps.copy(), s.temp_degc.copy()
    f = s.ref_accel_mps2
    if kind == "dtdt_scale":
        true_temp = _climate(t, rng)
        temp = np.round(true_temp * 16.0) / 16.0
        accel[:, k] += 0.08 * f[:, k] * np.gradient(true_temp, t)
    elif kind == "creep":
        a = math.exp(-1.0 / (fs * 5.0))
        lagged = lfilter([1.0 - a], [1.0, -a], f[:, k] - f[0, k]) + f[0, k]
        accel[:, k] += 5e-3 * (lagged - f[:, k])
    elif kind == "direction_bias":
        w = s.ref_gyro_radps[:, k]
        moving = np.abs(w) > 5.0 * DEG
        last = np.maximum.accumulate(np.where(moving, np.arange(len(w)), -1))
        gyro[:, k] += 0.02 * DEG * np.where(last >= 0, np.sign(w[np.maximum(last, 0)]), 0.0)
    else:
        raise ValueError(kind)
    return dataclasses.replace(s, accel_mps2=accel, gyro_radps=gyro, temp_degc=temp), k


def _diagnose(session: Any) -> dict[str, Any]:
    from station.diagnose import diagnose
    from station.kernel.limits_file import DEFAULT_LIMITS_PATH, load_limits

    tc = dict(load_limits(DEFAULT_LIMITS_PATH).correlation_time_s)
    return diagnose(session, warmup_tc_s=tc, resamples=0).report.to_json()


@pytest.mark.parametrize(("seed", "kind", "sensor", "words"), [
    (330101, "dtdt_scale", "accel", "temperature rate"),
    (330102, "creep", "accel", "creep since the last step"),
    (330103, "direction_bias", "gyro", "direction of the last rotation"),
])
def test_outside_physics_follows_its_new_covariate_and_is_not_named(seed: int, kind: str, sensor: str,
                                                                    words: str) -> None:
    session, k = _outside(seed, kind)
    rep = _diagnose(session)
    assert rep["findings"] == []
    mine = [u for u in rep["unexplained"] if u["sensor"] == sensor and "xyz"[k] in u["axes"]]
    assert mine
    assert words in dict(mine[0]["locator"]["covariate_per_axis"])["xyz"[k]]


@pytest.mark.parametrize(("seed", "effects", "named"), [
    (330111, {"temperature_scale": 300.0}, {"temperature_scale"}),
    (330112, {"time_offset": 5.0}, {"time_offset"}),
    (330113, {"temperature_scale": 300.0, "time_offset": 3.0}, {"temperature_scale", "time_offset"}),
])
def test_library_effects_are_still_named_beside_the_bigger_dictionary(seed: int, effects: dict[str, float],
                                                                      named: set[str]) -> None:
    import indepgen

    rep = _diagnose(indepgen.generate(seed, effects).session)
    assert {f["effect"] for f in rep["findings"]} == named
    assert not [r for r in rep.get("rejected", []) if "empirical dictionary" in r.get("reason", "")]
