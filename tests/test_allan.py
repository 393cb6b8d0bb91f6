"""Allan deviation, IEEE 952 fit and white-noise estimators against known truth (seeded)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.signal import lfilter

from station.fit.allan import (
    BIAS_INSTABILITY_FACTOR,
    AllanCurve,
    AllanFit,
    allan_coefficients,
    default_cluster_sizes,
    fit_ieee952,
    overlapping_allan_deviation,
    overlapping_avar_edf,
    random_walk_from_white_std,
    white_noise_std,
    white_std_from_random_walk,
)
from station.kernel.errors import FitError
from station.kernel.parameters import AllanCoefficients

FS = 100.0


def _white(rng: np.random.Generator, sigma: float, n: int) -> np.ndarray:
    return sigma * rng.standard_normal(n)


def _rrw(rng: np.random.Generator, k: float, n: int, fs: float = FS) -> np.ndarray:
    """Rate random walk with coefficient K (U/s/sqrt(Hz)): x_k = x_{k-1} + K sqrt(dt) xi_k."""
    return np.cumsum(k / math.sqrt(fs) * rng.standard_normal(n))


def _naive_avar(x: np.ndarray, fs: float, m: int) -> float:
    """Overlapping AVAR straight from the definition: differences of adjacent m-sample means."""
    means = np.convolve(x, np.ones(m) / m, mode="valid")  # mean of x[k:k+m]
    d = means[m:] - means[:-m]
    return float(np.mean(d**2) / 2.0)


def test_adev_matches_the_definition() -> None:
    rng = np.random.default_rng(1)
    x = 3.0 + _white(rng, 0.5, 2000) + _rrw(rng, 0.05, 2000)
    curve = overlapping_allan_deviation(x, FS, taus=np.array([0.01, 0.03, 0.1, 0.5, 2.0, 9.0]))
    assert list(curve.cluster_sizes) == [1, 3, 10, 50, 200, 900]
    for m, avar, n_terms in zip(curve.cluster_sizes, curve.avar, curve.n_terms, strict=True):
        assert avar == pytest.approx(_naive_avar(x, FS, int(m)), rel=1e-9)
        assert n_terms == 2000 - 2 * m + 1
    assert np.allclose(curve.adev, np.sqrt(curve.avar))


def test_default_taus_are_log_spaced_unique_to_a_fifth_of_the_record() -> None:
    m = default_cluster_sizes(360_000)
    assert m[0] == 1 and m[-1] == 72_000
    assert np.all(np.diff(m) > 0)
    per_decade = (m.size - 1) / math.log10(72_000)
    assert 8.0 < per_decade < 11.0


def test_white_noise_adev_follows_n_over_sqrt_tau_within_its_uncertainty() -> None:
    sigma = 0.02
    rng = np.random.default_rng(2)
    curve = overlapping_allan_deviation(_white(rng, sigma, 360_000), FS)
    n_true = random_walk_from_white_std(sigma, FS)
    z = (curve.adev - n_true / np.sqrt(curve.taus_s)) / curve.adev_std
    assert np.sqrt(np.mean(z**2)) < 1.5
    assert np.max(np.abs(z)) < 4.0
    # the conservative edf is never larger than the white-noise one
    assert np.all(curve.edf <= overlapping_avar_edf(curve.n_samples, curve.cluster_sizes, "white") + 1e-9)


def test_edf_formulas_match_a_monte_carlo() -> None:
    # 400 white-noise records of 2000 samples: scatter of AVAR at m vs sqrt(2/edf)
    rng = np.random.default_rng(3)
    m = np.array([1, 10, 100])
    avars = np.array(
        [overlapping_allan_deviation(rng.standard_normal(2000), 1.0, taus=m.astype(float)).avar for _ in range(400)]
    )
    rel = avars.std(axis=0) / avars.mean(axis=0)
    expected = np.sqrt(2.0 / overlapping_avar_edf(2000, m, "white"))
    assert np.allclose(rel, expected, rtol=0.15)


def test_gauss_markov_adev_matches_the_analytic_curve() -> None:
    # first-order GM (eq. 3 without the transient), T = 5 s, stationary std s = 1, at 10 Hz
    fs, t_c, s, n = 10.0, 5.0, 1.0, 400_000
    rng = np.random.default_rng(4)
    a = math.exp(-1.0 / (fs * t_c))
    x, _ = lfilter([math.sqrt(1.0 - a * a) * s], [1.0, -a], rng.standard_normal(n), zi=[a * s * rng.standard_normal()])
    curve = overlapping_allan_deviation(x, fs, taus=np.array([1.0, 2.0, 5.0, 10.0, 20.0, 50.0, 200.0]))
    tau = curve.taus_s
    # AVAR of an exponentially correlated process (continuous-time; tau >> 1/fs)
    u = tau / t_c
    theory = s**2 * t_c / tau**2 * (2.0 * tau - t_c * (3.0 - 4.0 * np.exp(-u) + np.exp(-2.0 * u)))
    z = (curve.avar - theory) / (theory * np.sqrt(2.0 / curve.edf))
    assert np.max(np.abs(z)) < 3.5
    # the curve peaks near 1.89 T_c, where a GM looks like bias instability: no flicker here,
    # the IEEE model's flat term is then an artefact of the bump
    assert curve.adev[np.argmax(curve.adev)] == pytest.approx(np.sqrt(theory.max()), rel=0.05)


def test_fit_recovers_random_walk_of_white_noise() -> None:
    sigma = 0.02
    rng = np.random.default_rng(5)
    fit = fit_ieee952(overlapping_allan_deviation(_white(rng, sigma, 360_000), FS))
    n_true = random_walk_from_white_std(sigma, FS)
    assert abs(fit.random_walk - n_true) < 3.0 * fit.random_walk_std
    assert fit.random_walk == pytest.approx(n_true, rel=0.01)
    assert fit.random_walk_std / n_true < 0.01
    # no flicker and no rate random walk in the data: both consistent with 0 (in variance space)
    assert fit.significance[1] < 3.0 and fit.significance[2] < 3.0
    assert fit.significance[0] > 100.0 and math.isnan(fit.significance[3])
    assert math.isnan(fit.rate_ramp) and math.isnan(fit.rate_ramp_std)
    assert fit.classic_random_walk == pytest.approx(n_true, rel=0.03)


def test_fit_recovers_rate_random_walk() -> None:
    k_true = 1e-4
    rng = np.random.default_rng(6)
    x = _rrw(rng, k_true, 360_000) + _white(rng, 1e-4, 360_000)
    fit = fit_ieee952(overlapping_allan_deviation(x, FS))
    assert abs(fit.rate_random_walk - k_true) < 3.0 * fit.rate_random_walk_std
    assert fit.rate_random_walk == pytest.approx(k_true, rel=0.4)
    assert fit.classic_rate_random_walk == pytest.approx(k_true, rel=0.5)


def test_fit_recovers_white_plus_rate_random_walk() -> None:
    n_true, k_true = 0.002, 0.002 * math.sqrt(3.0) / 100.0  # slopes cross at tau = 100 s
    rng = np.random.default_rng(7)
    x = _white(rng, white_std_from_random_walk(n_true, FS), 360_000) + _rrw(rng, k_true, 360_000)
    curve = overlapping_allan_deviation(x, FS)
    fit = fit_ieee952(curve)
    assert abs(fit.random_walk - n_true) < 3.0 * fit.random_walk_std
    assert abs(fit.rate_random_walk - k_true) < 3.0 * fit.rate_random_walk_std
    assert fit.random_walk == pytest.approx(n_true, rel=0.02)
    assert fit.rate_random_walk == pytest.approx(k_true, rel=0.5)
    # the fitted model follows the curve
    model = fit.model_avar(curve.taus_s)
    assert np.all(np.abs(np.sqrt(model) / curve.adev - 1.0) < 4.0 * curve.rel_uncertainty + 0.02)
    # thinning: about 3 points per decade from 10 samples to the end
    decades = math.log10(curve.taus_s[-1] / 0.1)
    assert abs(fit.taus_used_s.size - (3 * decades + 1)) <= 2


def test_fit_uncertainties_cover_the_scatter() -> None:
    # 40 short records, white + RRW: (estimate - truth) / std should have RMS about 1
    n_true, k_true, n = 0.002, 0.002 * math.sqrt(3.0) / 10.0, 30_000
    rng = np.random.default_rng(8)
    zn, zk = [], []
    for _ in range(40):
        x = _white(rng, white_std_from_random_walk(n_true, FS), n) + _rrw(rng, k_true, n)
        fit = fit_ieee952(overlapping_allan_deviation(x, FS))
        zn.append((fit.random_walk - n_true) / fit.random_walk_std)
        zk.append((fit.rate_random_walk - k_true) / fit.rate_random_walk_std)
    assert 0.5 < math.sqrt(np.mean(np.square(zn))) < 1.5
    assert 0.5 < math.sqrt(np.mean(np.square(zk))) < 1.6


def test_fit_rate_ramp_only_when_asked() -> None:
    r_true = 5e-6  # U/s
    n = 360_000
    rng = np.random.default_rng(9)
    x = _white(rng, 0.02, n) + r_true * np.arange(n) / FS
    curve = overlapping_allan_deviation(x, FS)
    with_ramp = fit_ieee952(curve, include_rate_ramp=True)
    assert abs(with_ramp.rate_ramp - r_true) < 3.0 * with_ramp.rate_ramp_std
    assert with_ramp.rate_ramp == pytest.approx(r_true, rel=0.35)
    # (a ramp only shows in the last few, low-edf points: its significance stays modest, ~1.5-3)
    without = fit_ieee952(curve)
    assert math.isnan(without.rate_ramp)
    # without the ramp term the ramp leaks into K
    assert without.rate_random_walk > with_ramp.rate_random_walk


def test_bias_instability_plateau() -> None:
    # flicker rate noise with one-sided PSD B^2 / (pi f): ADEV floor = 0.664 B
    b_true, n = 1e-3, 2**18
    rng = np.random.default_rng(10)
    f = np.fft.rfftfreq(n, 1.0 / FS)
    psd = np.zeros_like(f)
    psd[1:] = b_true**2 / (math.pi * f[1:])
    amp = np.sqrt(psd * n * FS / 4.0)
    flicker = np.fft.irfft(amp * (rng.standard_normal(f.size) + 1j * rng.standard_normal(f.size)), n)
    x = flicker + _white(rng, 1e-3, n)
    curve = overlapping_allan_deviation(x, FS)
    fit = fit_ieee952(curve)
    assert abs(fit.bias_instability - b_true) < 3.0 * fit.bias_instability_std
    assert fit.bias_instability == pytest.approx(b_true, rel=0.3)
    # the classic reading takes the minimum of a noisy plateau: biased low
    assert 0.4 * b_true < fit.classic_bias_instability < 1.1 * b_true
    assert pytest.approx(0.6643, abs=1e-4) == BIAS_INSTABILITY_FACTOR


def test_coefficient_at_bound_gets_upper_bound_uncertainty() -> None:
    # an exact white-noise curve (N^2 / tau, no scatter): B and K sit at the NNLS bound 0
    n_true, n_samples = 0.002, 360_000
    m = default_cluster_sizes(n_samples)
    avar = n_true**2 / (m / FS)
    edf = overlapping_avar_edf(n_samples, m, "random_walk")
    curve = AllanCurve(
        taus_s=m / FS,
        cluster_sizes=m,
        adev=np.sqrt(avar),
        avar=avar,
        edf=edf,
        rel_uncertainty=1.0 / np.sqrt(2.0 * edf),
        n_terms=n_samples - 2 * m + 1,
        rate_hz=FS,
        n_samples=n_samples,
    )
    fit = fit_ieee952(curve)
    assert fit.random_walk == pytest.approx(n_true, rel=1e-9)
    assert set(fit.terms_at_bound) == {"bias_instability", "rate_random_walk"}
    for k, term in ((1, "bias_instability"), (2, "rate_random_walk")):
        assert getattr(fit, term) == 0.0
        std = getattr(fit, f"{term}_std")
        # "X = 0, below sqrt(s) at 1 sigma", s from the all-terms-free covariance
        assert std == pytest.approx(math.sqrt(math.sqrt(fit.variance_covariance[k, k])))
        assert std > 0.0
        assert fit.significance[k] == 0.0


def test_allan_coefficients_pack_three_axes() -> None:
    rng = np.random.default_rng(12)
    fits: list[AllanFit] = [
        fit_ieee952(overlapping_allan_deviation(_white(rng, s, 50_000), FS)) for s in (0.01, 0.02, 0.03)
    ]
    coeffs = allan_coefficients(fits)
    assert isinstance(coeffs, AllanCoefficients)
    assert coeffs.random_walk.shape == (3,)
    assert np.allclose(coeffs.random_walk, [f.random_walk for f in fits])
    assert np.allclose(coeffs.random_walk / random_walk_from_white_std(np.array([0.01, 0.02, 0.03]), FS), 1, atol=0.03)
    with pytest.raises(FitError):
        allan_coefficients(fits[:2])


def test_white_noise_std_estimators() -> None:
    sigma, n = 0.02, 100_000
    rng = np.random.default_rng(13)
    x = 9.81 + _white(rng, sigma, n)
    est = white_noise_std(x)
    for value, std in (
        (est.paper_std, est.paper_std_std),
        (est.diff_std, est.diff_std_std),
        (est.robust_std, est.robust_std_std),
    ):
        assert abs(value - sigma) < 4.0 * std
    assert est.n_tail == 20_000
    assert est.paper_std_std == pytest.approx(sigma / math.sqrt(2 * 20_000), rel=0.02)
    assert est.diff_std_std == pytest.approx(sigma * math.sqrt(0.75 / n), rel=0.02)
    assert est.robust_std_std == pytest.approx(sigma * math.sqrt(0.75 / n), rel=0.02)
    assert abs(est.lag1_autocorrelation) < 4.0 / math.sqrt(20_000)
    assert est.outlier_fraction == 0.0
    assert random_walk_from_white_std(sigma, FS) == pytest.approx(0.002)
    assert white_std_from_random_walk(0.002, FS) == pytest.approx(sigma)


def test_white_noise_std_with_drift_and_outliers() -> None:
    # a decaying drift plus 8-sigma outliers at 1e-3 per sample: the robust one stays put
    sigma, n = 0.02, 200_000
    rng = np.random.default_rng(14)
    t = np.arange(n) / FS
    x = 0.5 * np.exp(-t / 100.0) + _white(rng, sigma, n)
    hits = rng.random(n) < 1e-3
    x[hits] += 8.0 * sigma * rng.choice([-1.0, 1.0], size=int(hits.sum()))
    whole = white_noise_std(x, tail_fraction=1.0, detrend="mean")
    assert abs(whole.robust_std - sigma) < 4.0 * whole.robust_std_std
    assert whole.paper_std > 1.5 * sigma  # the drift inflates the paper's figure over the whole record
    assert whole.diff_std > sigma + 4.0 * whole.diff_std_std  # outliers inflate the plain difference figure
    # the paper's way: the end of the set (drift has died out), linear trend removed
    tail = white_noise_std(x)
    # 6-sigma threshold: all but the few outliers that land on noise of the opposite sign (~2 %)
    assert 0.9 * hits[-tail.n_tail :].mean() <= tail.outlier_fraction <= hits[-tail.n_tail :].mean()
    assert tail.paper_std == pytest.approx(sigma * math.sqrt(1.0 + 1e-3 * 64.0), rel=0.02)  # outliers only
    assert tail.paper_std > sigma + 4.0 * tail.paper_std_std


def test_robust_std_is_not_stuck_on_the_quantisation_lattice() -> None:
    # sigma = 0.9 LSB, rounded to whole LSB: the MAD of the differences is exactly 1 LSB for any
    # sigma near 1; the clipped std follows the real spread sqrt(sigma^2 + 1/12) (Sheppard)
    rng = np.random.default_rng(17)
    x = np.round(0.9 * rng.standard_normal(100_000))
    est = white_noise_std(x, tail_fraction=1.0)
    expected = math.sqrt(0.81 + 1.0 / 12.0)
    assert abs(est.robust_std - expected) < 4.0 * est.robust_std_std
    assert abs(est.paper_std - expected) < 4.0 * est.paper_std_std


def test_correlated_samples_show_in_lag1() -> None:
    rng = np.random.default_rng(15)
    x = np.convolve(rng.standard_normal(50_001), [0.5, 0.5], mode="valid")  # rho1 = 0.5
    est = white_noise_std(x, tail_fraction=1.0)
    assert est.lag1_autocorrelation == pytest.approx(0.5, abs=0.02)
    # difference-based figure is off by sqrt(1 - rho1); the paper's one is right
    assert est.robust_std == pytest.approx(math.sqrt(0.5) * math.sqrt(0.5), rel=0.03)
    assert est.paper_std == pytest.approx(math.sqrt(0.5), rel=0.02)


def test_bad_input_raises_fit_error() -> None:
    with pytest.raises(FitError):
        overlapping_allan_deviation(np.array([1.0, np.nan] * 20), FS)
    with pytest.raises(FitError):
        overlapping_allan_deviation(np.zeros(5), FS)
    with pytest.raises(FitError):
        overlapping_allan_deviation(np.zeros(100), FS, taus=np.array([10.0]))
    with pytest.raises(FitError):
        white_noise_std(np.zeros((10, 3)))
    rng = np.random.default_rng(16)
    curve = overlapping_allan_deviation(rng.standard_normal(200), FS)
    with pytest.raises(FitError):
        fit_ieee952(curve, tau_min_s=0.2)
    with pytest.raises(FitError, match="constant"):
        fit_ieee952(overlapping_allan_deviation(np.full(5000, 0.3), FS))
