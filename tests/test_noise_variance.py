"""The white-noise variance test (station/diagnose/noise_variance.py) against known truth.

The recordings here come from a small generator of this file (not station.sim): a single-axis rate table's plan of
rest, poses and rate holds joined by moves, a climate ramp, and white noise whose std is either constant, coloured
but stationary, below one converter step, or growing with the temperature.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from station.diagnose import noise_variance
from station.diagnose.report import diagnose
from station.session.model import Kind, Session
from station.sim.session_sim import simulate_session

FS = 100.0
G = 9.80665
SIGMA_A, SIGMA_G = 0.02, 0.002  # white noise std (m/s^2, rad/s)


def _plan(rng: np.random.Generator) -> list[tuple[Kind, float, np.ndarray, np.ndarray]]:
    """(kind, seconds, specific force, rate) per segment: a rest, then poses and rate holds with moves between."""
    faces = [np.array(v, float) * G for v in ((0, 0, 1), (0, 0, -1), (1, 0, 0), (-1, 0, 0), (0, 1, 0), (0, -1, 0))]
    out = [(Kind.REST, 60.0, faces[0], np.zeros(3))]
    for i in range(30):
        face = faces[i % 6]
        out.append((Kind.MOVE, 2.0, face, np.zeros(3)))
        if i % 3 == 2:  # a rate hold about the vertical axis of the face
            rate = face / G * math.radians(float(rng.uniform(20.0, 400.0))) * rng.choice([-1.0, 1.0])
            out.append((Kind.RATE, float(rng.uniform(6.0, 12.0)), face, rate))
        else:
            out.append((Kind.POSE, float(rng.uniform(6.0, 12.0)), face, np.zeros(3)))
    return out


def _recording(seed: int, noise: str = "white", growth: float = 0.0, lsb: float = 0.0) -> Session:
    """One recording. ``noise``: ``white``, ``ar1`` (AR(1), coefficient 0.9, same std) or ``shaped`` (0.8 white
    plus 0.6 first-differenced: sigma-delta shaping). ``growth``: the gyro's white-noise std is
    ``sigma (1 + growth (T - T_min) / 10 K)``. ``lsb``: a converter step for both sensors (0: none)."""
    rng = np.random.default_rng(seed)
    plan = _plan(rng)
    n_per = [round(s * FS) for _, s, _, _ in plan]
    n = sum(n_per)
    kind = np.repeat([int(k) for k, *_ in plan], n_per)
    segment = np.repeat(np.arange(len(plan)), n_per)
    force = np.repeat(np.array([f for *_, f, _ in plan]), n_per, axis=0)
    rate = np.repeat(np.array([w for *_, w in plan]), n_per, axis=0)
    t = np.arange(n) / FS
    temp = 25.0 + 15.0 * np.clip((t - 120.0) / 300.0, 0.0, 1.0)  # a climate ramp of 15 K

    def noise_of(sigma: float) -> np.ndarray:
        e = rng.standard_normal((n, 3))
        if noise == "ar1":
            out = np.empty_like(e)
            out[0] = e[0]
            for i in range(1, n):
                out[i] = 0.9 * out[i - 1] + math.sqrt(1 - 0.81) * e[i]
            e = out
        elif noise == "shaped":
            e = 0.8 * e + 0.6 * np.vstack([e[:1], np.diff(e, axis=0)]) / math.sqrt(2.0)
        return sigma * e

    bias_a, bias_g = rng.normal(0, 0.05, 3), rng.normal(0, 0.002, 3)
    drift = 0.003 * np.exp(-t / 200.0)[:, None]  # eq. 3's warm-up
    accel = force + bias_a + noise_of(SIGMA_A)
    gyro = rate + bias_g + drift + noise_of(SIGMA_G) * (1.0 + growth * (temp - temp.min()) / 10.0)[:, None]
    if lsb:
        accel, gyro = np.round(accel / lsb) * lsb, np.round(gyro / (lsb / 10.0)) * (lsb / 10.0)
    meta = {"serial": f"NV{seed}", "sample_rate_hz": str(FS), "gravity_mps2": str(G)}
    return Session(meta, t, segment, kind, accel, gyro, np.round(temp * 32) / 32, force, rate)


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_noise_growing_with_temperature_is_located_and_follows_temperature(seed: int) -> None:
    # std 1.45x over the 15 K ramp: what a drive loop losing Q does
    entries = noise_variance.unexplained(_recording(seed, growth=0.3))
    assert [u.sensor for u in entries] == ["gyro"]
    u = entries[0]
    assert u.axes == ("x", "y", "z")
    assert u.covariate.startswith("noise variance follows temperature")
    assert "pose" in u.segment_kinds and "rest" not in u.segment_kinds  # the rest is cold
    for a in noise_variance.test_sensor(_recording(seed, growth=0.3), "gyro"):
        assert a.covariate == "temperature"
        assert 1.3 < a.covariate_std_ratio < 1.6  # truth: 1 + 0.3 * 1.5 = 1.45


@pytest.mark.parametrize(("seed", "noise"), [(4, "white"), (5, "ar1"), (6, "shaped"), (7, "ar1")])
def test_stationary_noise_white_or_coloured_gives_no_entry(seed: int, noise: str) -> None:
    s = _recording(seed, noise=noise)
    assert noise_variance.unexplained(s) == ()
    tests = [*noise_variance.test_sensor(s, "accel"), *noise_variance.test_sensor(s, "gyro")]
    assert all(a.tested for a in tests)
    assert all(a.p_value > noise_variance.ALPHA_AXIS for a in tests)


def test_noise_below_one_converter_step_is_not_tested() -> None:
    # accel noise 0.02 m/s^2 on a 0.1 m/s^2 step: each pose's quantized variance depends on where its mean falls
    s = _recording(8, lsb=0.1)
    accel = noise_variance.test_sensor(s, "accel")
    assert noise_variance.quantum(s.accel_mps2[:, 0]) == pytest.approx(0.1, rel=1e-6)
    assert not any(a.tested for a in accel)
    assert all(u.sensor != "accel" for u in noise_variance.unexplained(s))


def test_diagnosis_reports_it_and_the_station_simulator_gives_none() -> None:
    sim = simulate_session(11).session
    assert noise_variance.unexplained(sim) == ()
    # the same recording with the gyro's white noise growing 1.5x over its temperature range
    rng = np.random.default_rng(12)
    temp = sim.temp_degc
    grow = 1.0 + 0.5 * (temp - np.nanmin(temp)) / np.ptp(temp)
    sigma = np.sqrt(np.mean(np.diff(sim.gyro_radps[sim.kind == int(Kind.REST)], axis=0) ** 2, axis=0) / 2.0)
    gyro = sim.gyro_radps + rng.standard_normal(sim.gyro_radps.shape) * sigma * np.sqrt(grow**2 - 1.0)[:, None]
    report = diagnose(sim.replace(gyro_radps=gyro), resamples=0).report.to_json()
    mine = [u for u in report["unexplained"] if u["covariate"].startswith("noise variance")]
    assert [u["sensor"] for u in mine] == ["gyro"], report["unexplained"]
    assert "temperature" in mine[0]["covariate"]
