"""Recovery of known parameters from simulated units drawn from the paper's Table 1.

Issue targets: on >= 50 units every fitted parameter lies within 3 of its own standard
uncertainties of the truth in >= 95 % of cases, and the uncertainties are honest: the
spread of the normalized errors z = (estimate - truth) / std over units is within a
factor 1.5 of 1.
"""

from __future__ import annotations

import os

import numpy as np
import pytest

from station.fit.calibrate import fit_session
from station.sim.session_sim import simulate_session

N_UNITS = 50
#: first seeds of the 50-unit sets studied; more sets, e.g. 150 units:
#: ``STATION_RECOVERY_SEEDS=1000,3000,5000 pytest -s tests/test_fit_recovery.py``
SEED0S = [int(s) for s in os.environ.get("STATION_RECOVERY_SEEDS", "1000").split(",")]


def _effective_noise(tri: object) -> np.ndarray:
    # the white noise a sensor shows includes ADC quantization noise (LSB^2 / 12)
    return np.sqrt(np.asarray(tri.noise_std) ** 2 + tri.lsb**2 / 12.0)


@pytest.fixture(scope="module")
def study() -> dict[str, list[np.ndarray]]:
    z: dict[str, list[np.ndarray]] = {}
    resolved = {"accel": 0, "gyro": 0}
    for seed in (s0 + i for s0 in SEED0S for i in range(N_UNITS)):
        res = simulate_session(seed)
        params = fit_session(res.session)
        for name in ("accel", "gyro"):
            est, tru = getattr(params, name), getattr(res.truth, name)
            pairs = {
                "misalignment": (est.misalignment, est.misalignment_std, tru.misalignment),
                "bias_static": (est.bias_static, est.bias_static_std, tru.bias_static),
                "bias_drift": (est.bias_drift, est.bias_drift_std, tru.bias_drift),
                "noise_std": (est.noise_std, est.noise_std_std, _effective_noise(tru)),
                "drift_noise": (est.drift_noise, est.drift_noise_std, tru.drift_noise),
            }
            ok = np.isfinite(est.correlation_time_s)
            resolved[name] += int(ok.sum())
            pairs["correlation_time_s"] = (
                est.correlation_time_s[ok], est.correlation_time_s_std[ok], tru.correlation_time_s[ok]
            )
            for key, (e, s, t) in pairs.items():
                z.setdefault(f"{name}.{key}", []).append(((np.asarray(e) - t) / s).ravel())
    out = {k: np.concatenate(v) for k, v in z.items()}
    out["_resolved"] = resolved  # type: ignore[assignment]
    return out  # type: ignore[return-value]


# Targets that were missed until 2026-11-21 (50 units, this file): the stds of accel b_stat and
# b_drift were conservative (spread of z 0.46 / 0.59) with q at its 95 % upper edge, and gyro
# drift_noise was 90.7 % within 3 sigma with T_c profiled out. Both now integrate over the
# restricted likelihood of (q, T_c) (station.fit.axis_ml._ProfileGrid). On 150 units
# (STATION_RECOVERY_SEEDS=1000,3000,5000) every parameter meets both targets; the tightest are
# accel T_c (spread 0.67, conservative) and gyro b_stat (spread 1.43). Alone, the 50-unit set from
# seed 3000 misses T_c (accel spread 0.47, gyro 94.6 % within) and the one from seed 5000 the gyro
# b_stat / b_drift spread (2.10 / 1.64: one unit, seed 5049, with a tiny drift fitted at T_c 195 s
# against a true 3333 s, z = 19).
# An entry here marks a parameter as a known miss: xfail(strict) with the numbers.
KNOWN_MISSES: dict[str, str] = {}

PARAMS = [
    pytest.param(name, marks=pytest.mark.xfail(reason=KNOWN_MISSES[name], strict=True))
    if name in KNOWN_MISSES
    else name
    for name in (
        f"{s}.{p}"
        for s in ("accel", "gyro")
        for p in ("misalignment", "bias_static", "bias_drift", "correlation_time_s", "noise_std", "drift_noise")
    )
]


@pytest.mark.slow
@pytest.mark.parametrize("name", PARAMS)
def test_within_three_sigma_and_honest(study: dict[str, np.ndarray], name: str) -> None:
    z = study[name]
    assert z.size >= N_UNITS * 3 * 0.5, f"{name}: too few estimates ({z.size})"
    assert np.all(np.isfinite(z)), f"{name}: non-finite normalized error"
    within = float(np.mean(np.abs(z) <= 3.0))
    spread = float(np.std(z))
    print(f"{name}: n={z.size} within3={within:.3f} spread={spread:.2f}")
    assert within >= 0.95, f"{name}: only {within:.1%} within 3 sigma"
    assert 1 / 1.5 <= spread <= 1.5, f"{name}: spread of z is {spread:.2f}"


@pytest.mark.slow
def test_drift_resolved_for_most_axes(study: dict[str, object]) -> None:
    resolved = study["_resolved"]
    # Table 1's drift ranges include values near zero: those cannot be resolved, the rest must be
    units = N_UNITS * len(SEED0S)
    assert resolved["accel"] >= 0.75 * 3 * units
    assert resolved["gyro"] >= 0.75 * 3 * units
