"""The paper's ACF correlation time and b_drift (eq. 4, sec. 3) against known truth, bias included."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.signal import lfilter

from station.fit.acf import (
    _zero_phase_fir,
    _zero_phase_fir_adjoint,
    _zero_phase_kernel,
    correlation_time_acf,
    drift_amplitude,
    finite_record_acf,
    lowpass_record,
)
from station.kernel.errors import FitError

FS = 20.0  # Hz; block mean to 1 Hz with the default 10 s low-pass, like 100 Hz data


def _transient(rng: np.random.Generator, t_c: float, length_s: float, b_drift: float, sigma: float, fs: float = FS):
    """b_stat + b_drift exp(-t/T_c) + white noise (eq. 1 and 3 without the process noise)."""
    t = np.arange(round(length_s * fs)) / fs
    return 0.3 + b_drift * np.exp(-t / t_c) + sigma * rng.standard_normal(t.size)


def test_finite_record_acf_is_the_plain_sum() -> None:
    y = np.random.default_rng(0).standard_normal(57)
    direct = np.array([np.dot(y[: y.size - k], y[k:]) for k in range(y.size)])
    assert np.allclose(finite_record_acf(y), direct)


def test_zero_phase_filter_keeps_ramps_and_its_adjoint_is_exact() -> None:
    kernel = _zero_phase_kernel(61, 10.0, 1.0)
    assert kernel.sum() == pytest.approx(1.0)
    assert np.allclose(kernel, kernel[::-1])
    ramp = 0.2 + 0.01 * np.arange(300)
    assert np.allclose(_zero_phase_fir(ramp, kernel), ramp)  # odd extension: lines pass untouched
    rng = np.random.default_rng(1)
    for n in (123, 1000):
        x, u = rng.standard_normal(n), rng.standard_normal(n)
        assert u @ _zero_phase_fir(x, kernel) == pytest.approx(x @ _zero_phase_fir_adjoint(u, kernel), rel=1e-10)


def test_lowpass_record_layout() -> None:
    x = np.random.default_rng(2).standard_normal(100 * 600)  # 600 s at 100 Hz
    rec = lowpass_record(x, 100.0)
    assert rec.decimation == 100 and rec.rate_hz == 1.0 and rec.numtaps == 61
    assert rec.values.size == 600
    assert rec.t_s[0] == pytest.approx(0.495) and rec.t_s[1] - rec.t_s[0] == pytest.approx(1.0)
    assert rec.block_noise_std == pytest.approx(0.1, rel=0.02)


def test_long_record_gives_tc_within_ten_percent() -> None:
    # 20 T_c, b_drift 0.01 with white noise 0.002 per sample at 20 Hz (0.0045 at 100 Hz: the same noise
    # per 1 s block); at the paper's Table 1 noise (0.02 at 100 Hz) the noise bias alone is -25 %
    t_c = 60.0
    for seed in (3, 4, 5):
        res = correlation_time_acf(_transient(np.random.default_rng(seed), t_c, 20 * t_c, 0.01, 0.002), FS)
        assert res.decayed and res.note == ""
        assert res.correlation_time_s == pytest.approx(t_c, rel=0.10)
        assert 0.0 < res.correlation_time_std_s < 0.1 * t_c
        assert res.record_over_correlation_time == pytest.approx(20.0, rel=0.15)
        assert res.acf[0] == 1.0
        assert res.acf[res.crossing_index] <= math.exp(-1.0) < res.acf[res.crossing_index - 1]
        assert res.asymptote == pytest.approx(0.3, abs=0.001)


def test_tc_uncertainty_matches_the_noise_scatter() -> None:
    # low noise: the delta-method std (white noise only) should describe the seed-to-seed scatter
    t_c, runs = 60.0, 30
    est, std = [], []
    for seed in range(runs):
        res = correlation_time_acf(_transient(np.random.default_rng(100 + seed), t_c, 20 * t_c, 0.01, 0.003), FS)
        est.append(res.correlation_time_s)
        std.append(res.correlation_time_std_s)
    ratio = np.std(est, ddof=1) / np.mean(std)
    assert 0.7 < ratio < 1.4


def test_short_record_is_biased_low() -> None:
    # the documented bias: at 2 T_c the asymptote still holds part of the transient; the reading is
    # about 0.64 T_c without noise
    t_c = 100.0
    readings = [
        correlation_time_acf(_transient(np.random.default_rng(seed), t_c, 2 * t_c, 0.01, 0.002), FS).correlation_time_s
        for seed in (6, 7, 8)
    ]
    for r in readings:
        assert 0.5 * t_c < r < 0.8 * t_c
    long = correlation_time_acf(_transient(np.random.default_rng(9), t_c, 20 * t_c, 0.01, 0.002), FS)
    assert max(readings) < 0.85 * long.correlation_time_s
    # far shorter than T_c (a 1 h gyro record with T_c of an hour): still a number, just a small one
    very_short = correlation_time_acf(_transient(np.random.default_rng(10), 1000.0, 600.0, 0.01, 0.002), FS)
    assert very_short.decayed
    assert very_short.correlation_time_s < 0.3 * 1000.0


def test_noise_bias_grows_with_record_length_as_documented() -> None:
    # noise energy eps * Phi(0) raises the exp(-1) threshold: reading ~ T_c (1 + ln(1 - eps))
    t_c = 60.0
    # sigma 0.009 at 20 Hz leaves the same noise per 1 s block as 0.02 at 100 Hz
    res = correlation_time_acf(_transient(np.random.default_rng(11), t_c, 40 * t_c, 0.01, 0.009), FS)
    eps = res.noise_energy_fraction
    assert 0.2 < eps < 0.6
    assert res.correlation_time_s < 0.8 * t_c
    assert res.correlation_time_s / t_c == pytest.approx(1.0 + math.log(1.0 - eps), abs=0.12)


def test_stationary_gauss_markov_without_transient() -> None:
    # eq. (4) on stationary GM realisations (no power-on transient), 200 T_c long: single readings
    # scatter by 10-20 % (the tail mean is not the record mean), their median is near T_c
    t_c, s, n = 30.0, 0.01, round(200 * 30.0 * FS)
    a = math.exp(-1.0 / (FS * t_c))
    readings = []
    for seed in range(10):
        rng = np.random.default_rng(12 + seed)
        w = rng.standard_normal(n)
        g, _ = lfilter([math.sqrt(1.0 - a * a) * s], [1.0, -a], w, zi=[a * s * rng.standard_normal()])
        readings.append(correlation_time_acf(g + 0.002 * rng.standard_normal(n), FS).correlation_time_s)
    assert np.median(readings) == pytest.approx(t_c, rel=0.2)


def test_drift_amplitude_long_record() -> None:
    t_c, b_drift, sigma = 60.0, 0.01, 0.005
    d = drift_amplitude(_transient(np.random.default_rng(13), t_c, 20 * t_c, b_drift, sigma), FS)
    expected = b_drift * math.exp(-d.lowpass.t_s[0] / t_c)  # value at the first block centre
    assert abs(d.b_drift - expected) < 4.0 * d.b_drift_std
    assert d.asymptotic_value == pytest.approx(0.3, abs=4.0 * d.asymptotic_value_std)
    # the beginning value is the first block mean: its std is sigma / sqrt(block length)
    assert d.initial_value_std == pytest.approx(sigma / math.sqrt(d.lowpass.decimation), rel=0.05)
    assert d.b_drift == pytest.approx(d.initial_value - d.asymptotic_value)


def test_drift_amplitude_uncertainty_matches_scatter() -> None:
    values, stds = [], []
    for seed in range(150):
        d = drift_amplitude(0.02 * np.random.default_rng(200 + seed).standard_normal(round(300 * FS)), FS)
        values.append(d.b_drift)
        stds.append(d.b_drift_std)
    assert np.std(values, ddof=1) / np.mean(stds) == pytest.approx(1.0, abs=0.15)
    assert abs(np.mean(values)) < 3.0 * np.mean(stds) / math.sqrt(len(values))


def test_drift_amplitude_short_record_biased_low() -> None:
    # at 2 T_c the asymptote is taken before the transient has died out: ~0.83 b_drift
    t_c, b_drift = 100.0, 0.01
    d = drift_amplitude(_transient(np.random.default_rng(14), t_c, 2 * t_c, b_drift, 0.001), FS)
    assert 0.75 * b_drift < d.b_drift < 0.9 * b_drift


def test_flat_record_gives_nan_with_a_note() -> None:
    res = correlation_time_acf(np.full(round(600 * FS), 0.25), FS)
    assert not res.decayed
    assert math.isnan(res.correlation_time_s) and math.isnan(res.correlation_time_std_s)
    assert res.crossing_index == -1
    assert "flat" in res.note


def test_bad_input_raises_fit_error() -> None:
    with pytest.raises(FitError):
        correlation_time_acf(np.zeros(round(100 * FS)), FS)  # shorter than twice the filter
    with pytest.raises(FitError):
        correlation_time_acf(np.array([0.0, np.nan] * 10_000), FS)
    with pytest.raises(FitError):
        correlation_time_acf(np.zeros(round(600 * FS)), FS, asymptote_fraction=0.0)
    with pytest.raises(FitError):
        lowpass_record(np.zeros(1000), 0.1, lowpass_s=10.0)  # cutoff above Nyquist
