"""Allan deviation, IEEE Std 952 noise coefficients and the white-noise level of a still record.

Everything here works on one axis of *rate* samples ``x`` in sensor units U (rad/s for a
gyroscope, m/s^2 for an accelerometer) taken at a constant rate ``rate_hz`` (Hz). Pure
numerics: arrays in, frozen dataclasses out, no I/O.

Noise model (IEEE Std 952-1997, annex C), Allan variance of the rate at cluster time tau (s):

    AVAR(tau) = N^2 / tau + (2 ln 2 / pi) B^2 + K^2 tau / 3 [+ R^2 tau^2 / 2]

with N the (angle/velocity) random walk (U/sqrt(Hz) = U sqrt(s)), B the bias instability
(U), K the rate random walk (U/s/sqrt(Hz) = U/sqrt(s)) and R the rate ramp (U/s).

Relation to the paper's per-sample white-noise std sigma (Kolhoff & Kemper, sec. 3, the
variance of the raw data at the end of each set): for noise that is white up to the
Nyquist frequency, ``N = sigma / sqrt(rate_hz)`` (:func:`random_walk_from_white_std`).

Which white-noise figure the fit should use: :attr:`WhiteNoiseEstimate.robust_std` (first
differences, iteratively 4-sigma clipped). It ignores any slow drift (the Gauss-Markov bias
of eq. (3), bias instability, rate random walk) and the rare large outliers the recordings
contain, whereas the paper's variance is inflated by both. Check
:attr:`WhiteNoiseEstimate.lag1_autocorrelation` first: a sensor-internal low-pass filter
makes neighbouring samples correlated (rho1 != 0) and then every first-difference
estimate is low by the factor sqrt(1 - rho1) (var(diff) = 2 sigma^2 (1 - rho1)); in that
case use ``paper_std`` from a drift-free stretch instead. This is not academic: the static
poses of /work/shared/real/imucal/example_ferraris_session.csv show rho1 = 0.15-0.38 and
difference-based figures 8-21 % below the paper's.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields
from typing import Literal

import numpy as np
from scipy.optimize import nnls

from station.kernel.errors import FitError
from station.kernel.parameters import AllanCoefficients

NoiseType = Literal["white", "flicker", "random_walk"]

#: sqrt(2 ln2 / pi): the flat floor of the Allan deviation of flicker rate noise is 0.664 B.
BIAS_INSTABILITY_FACTOR = math.sqrt(2.0 * math.log(2.0) / math.pi)
#: Consistency factor of the MAD for a Gaussian: sigma = 1.4826 * MAD (start of the clipping).
_MAD_TO_STD = 1.482602218505602
#: Clipping threshold (in sigma of the differences) of the robust white-noise estimator, and
#: the variance ratio of a Gaussian truncated there, 1 - 2 k phi(k) / (2 Phi(k) - 1).
_CLIP_K = 4.0
_CLIP_VAR_RATIO = 1.0 - 2.0 * _CLIP_K * math.exp(-0.5 * _CLIP_K**2) / math.sqrt(2.0 * math.pi) / math.erf(
    _CLIP_K / math.sqrt(2.0)
)
_TERMS = ("random_walk", "bias_instability", "rate_random_walk", "rate_ramp")


def _frozen(a: np.ndarray | list[float], dtype: type = np.float64) -> np.ndarray:
    arr: np.ndarray = np.array(a, dtype=dtype, copy=True)
    arr.flags.writeable = False
    return arr


def _as_record(x: np.ndarray, what: str, min_len: int) -> np.ndarray:
    arr = np.asarray(x, dtype=np.float64)
    if arr.ndim != 1:
        raise FitError(f"{what}: expected a 1-D record of one axis, got shape {arr.shape}")
    if arr.size < min_len:
        raise FitError(f"{what}: record has {arr.size} samples, need at least {min_len}")
    if not np.all(np.isfinite(arr)):
        raise FitError(f"{what}: record contains NaN or inf samples")
    return arr


# --------------------------------------------------------------------------- Allan deviation


def overlapping_avar_edf(n_samples: int, m: np.ndarray, noise: NoiseType) -> np.ndarray:
    """Equivalent chi-square degrees of freedom of the overlapping Allan variance.

    Simple approximations of Howe, Allan & Barnes (1981), as tabulated in NIST SP 1065
    (Table 5), for a record of ``n_samples`` rate samples (``n_samples + 1`` phase
    points) at cluster sizes ``m`` (samples). ``noise`` names the power-law type of the
    *rate*: "white" (angle random walk, white FM), "flicker" (bias instability, flicker
    FM), "random_walk" (rate random walk, random-walk FM).

    The relative standard uncertainty of the Allan *variance* is sqrt(2/edf), of the
    Allan *deviation* 1/sqrt(2 edf). Returns floats >= 1.
    """
    n = float(n_samples + 1)  # number of phase (integrated-rate) points
    mm = np.asarray(m, dtype=np.float64)
    if noise == "white":
        edf = (3.0 * (n - 1.0) / (2.0 * mm) - 2.0 * (n - 2.0) / n) * (4.0 * mm**2 / (4.0 * mm**2 + 5.0))
    elif noise == "flicker":
        edf = np.where(
            mm <= 1.0,
            2.0 * (n - 2.0) ** 2 / (2.3 * n - 4.9),
            5.0 * n**2 / (4.0 * mm * (n + 3.0 * mm)),
        )
    elif noise == "random_walk":
        edf = (n - 2.0) / (mm * (n - 3.0) ** 2) * ((n - 1.0) ** 2 - 3.0 * mm * (n - 1.0) + 4.0 * mm**2)
    else:
        raise ValueError(f"unknown noise type {noise!r}")
    return np.maximum(edf, 1.0)


@dataclass(frozen=True, eq=False)
class AllanCurve:
    """Overlapping Allan deviation of one axis.

    Attributes:
        taus_s: cluster times tau (s), increasing, shape (k,).
        cluster_sizes: tau in samples, m = tau * rate_hz, shape (k,).
        adev: Allan deviation (U), shape (k,).
        avar: Allan variance (U^2), shape (k,).
        edf: conservative equivalent degrees of freedom per point: the smallest of the
            white, flicker and random-walk rate-noise values of
            :func:`overlapping_avar_edf` (the noise mix is not known before a fit).
        rel_uncertainty: relative standard uncertainty of ``adev``, 1/sqrt(2 edf). For a
            non-overlapping estimate this would be the textbook 1/sqrt(2 (n/m - 1));
            overlapping estimates have more degrees of freedom, hence the edf.
        n_terms: number of (overlapping) second differences averaged per point, n - 2m + 1.
        rate_hz: sample rate of the record (Hz).
        n_samples: record length (samples).
    """

    taus_s: np.ndarray
    cluster_sizes: np.ndarray
    adev: np.ndarray
    avar: np.ndarray
    edf: np.ndarray
    rel_uncertainty: np.ndarray
    n_terms: np.ndarray
    rate_hz: float
    n_samples: int

    @property
    def adev_std(self) -> np.ndarray:
        """Standard uncertainty of each ``adev`` point (U)."""
        return self.adev * self.rel_uncertainty


def default_cluster_sizes(n_samples: int, per_decade: float = 10.0, max_fraction: float = 0.2) -> np.ndarray:
    """Log-spaced unique cluster sizes m from 1 to ``max_fraction * n_samples`` (samples)."""
    m_max = math.floor(max_fraction * n_samples)
    if m_max < 1:
        raise FitError(f"Allan deviation: {n_samples} samples are too few")
    decades = math.log10(m_max)
    count = max(math.ceil(per_decade * decades) + 1, 2)
    m = np.unique(np.round(np.logspace(0.0, decades, count)).astype(np.int64))
    return m[(m >= 1) & (m <= m_max)]


def overlapping_allan_deviation(x: np.ndarray, rate_hz: float, taus: np.ndarray | None = None) -> AllanCurve:
    """Overlapping Allan deviation of the rate samples ``x`` (U) taken at ``rate_hz`` (Hz).

    With theta the integrated signal (U*s, theta_0 = 0, theta_k = sum_{j<k} x_j / rate_hz)
    and tau = m / rate_hz:

        AVAR(tau) = sum_k (theta_{k+2m} - 2 theta_{k+m} + theta_k)^2 / (2 tau^2 (n - 2m + 1))

    over all n - 2m + 1 overlapping positions k. One vectorised pass per tau over the
    cumulative sum (a 360k-sample record with ~60 taus takes a fraction of a second). The
    mean is removed before integrating to keep the cumulative sum small; this does not
    change any second difference.

    ``taus`` (s) are rounded to whole samples and deduplicated; taus that round to 0 or
    leave fewer than one cluster pair (m > (n - 1) / 2) are dropped. Default: ~10 per
    decade from 1 / rate_hz to a fifth of the record length.
    """
    if not rate_hz > 0.0:
        raise FitError(f"Allan deviation: sample rate must be positive, got {rate_hz}")
    xr = _as_record(x, "Allan deviation", 10)
    n = xr.size
    if taus is None:
        m = default_cluster_sizes(n)
    else:
        m = np.unique(np.round(np.asarray(taus, dtype=np.float64) * rate_hz).astype(np.int64))
        m = m[(m >= 1) & (2 * m <= n - 1)]
        if m.size == 0:
            raise FitError("Allan deviation: none of the requested taus fits into the record")
    theta = np.empty(n + 1)
    theta[0] = 0.0
    np.cumsum((xr - xr.mean()) / rate_hz, out=theta[1:])
    avar = np.empty(m.size)
    for i, mi in enumerate(m):
        d = theta[2 * mi :] - 2.0 * theta[mi : n + 1 - mi] + theta[: n + 1 - 2 * mi]
        tau = mi / rate_hz
        avar[i] = float(np.dot(d, d)) / (2.0 * tau * tau * d.size)
    edf = np.minimum.reduce([overlapping_avar_edf(n, m, k) for k in ("white", "flicker", "random_walk")])
    return AllanCurve(
        taus_s=_frozen(m / rate_hz),
        cluster_sizes=_frozen(m, np.int64),
        adev=_frozen(np.sqrt(avar)),
        avar=_frozen(avar),
        edf=_frozen(edf),
        rel_uncertainty=_frozen(1.0 / np.sqrt(2.0 * edf)),
        n_terms=_frozen(n - 2 * m + 1, np.int64),
        rate_hz=float(rate_hz),
        n_samples=int(n),
    )


# --------------------------------------------------------------------------- IEEE 952 fit


@dataclass(frozen=True, eq=False)
class AllanFit:
    """IEEE Std 952 noise coefficients of one axis from an :class:`AllanCurve`.

    Weighted fit (see :func:`fit_ieee952`), unit U as in the curve:
        random_walk: N (U/sqrt(Hz)); bias_instability: B (U); rate_random_walk: K
        (U/s/sqrt(Hz)); rate_ramp: R (U/s), NaN unless the ramp term was fitted.
        ``*_std``: standard uncertainties. For a coefficient c = X^2 of the variance model
        with standard uncertainty s (from the weighted least-squares covariance), the
        reported uncertainty of X is the upper 1-sigma half-width sqrt(c + s) - sqrt(c).
        It equals the delta-method s / (2 sqrt(c)) when s << c, and when the coefficient
        is at the non-negativity bound (X = 0, listed in ``terms_at_bound``) it is
        sqrt(s), i.e. X = 0 with "std" sqrt(s) reads as "X below about sqrt(s) at
        1 sigma" -- an upper-bound style figure, not a Gaussian standard deviation.
        The square root compresses: for c within a few s of 0, X / X_std overstates the
        significance (c = 1.7 s gives X / X_std = 3.8); judge whether a term is present
        from :attr:`significance` (c / s, in variance space) instead.
        variance_coefficients: (N^2, B^2, K^2, R^2) as fitted (R^2 = 0 when not fitted).
        variance_covariance: their 4x4 covariance (rows/columns of unfitted terms 0);
            for terms at the bound the diagonal holds the all-terms-free variance.
        terms_at_bound: names of the terms fitted as exactly 0.
        chi2_reduced: chi^2 / dof of the final weighted fit (diagonal weights; values
            below 1 are normal because neighbouring points are correlated).
        taus_used_s: the cluster times that entered the fit (s).

    Classic graphical readings of the same curve, for comparison (NaN when the curve has
    no point whose local log-log slope is within 0.25 of the target):
        classic_random_walk: adev on the -1/2 slope line at tau = 1 s.
        classic_bias_instability: minimum adev / 0.664, at ``classic_bias_instability_tau_s``
            (an upper bound if the curve is still falling at its longest tau).
        classic_rate_random_walk: adev on the +1/2 slope line at tau = 3 s.
    """

    random_walk: float
    random_walk_std: float
    bias_instability: float
    bias_instability_std: float
    rate_random_walk: float
    rate_random_walk_std: float
    rate_ramp: float
    rate_ramp_std: float
    variance_coefficients: np.ndarray
    variance_covariance: np.ndarray
    terms_at_bound: tuple[str, ...]
    chi2_reduced: float
    taus_used_s: np.ndarray
    classic_random_walk: float
    classic_bias_instability: float
    classic_bias_instability_tau_s: float
    classic_rate_random_walk: float

    @property
    def significance(self) -> np.ndarray:
        """c_k / s_k for (N^2, B^2, K^2, R^2): fitted variance coefficient over its standard uncertainty.

        Below about 2-3 the term is not resolved by the curve. NaN for an unfitted ramp term.
        """
        s = np.sqrt(np.diag(self.variance_covariance))
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(s > 0.0, self.variance_coefficients / s, np.nan)

    def model_avar(self, taus_s: np.ndarray) -> np.ndarray:
        """The fitted Allan variance (U^2) at ``taus_s`` (s)."""
        return _design(np.asarray(taus_s, dtype=np.float64), 4) @ self.variance_coefficients


def _design(taus: np.ndarray, n_terms: int) -> np.ndarray:
    cols = [1.0 / taus, np.full_like(taus, BIAS_INSTABILITY_FACTOR**2), taus / 3.0, taus**2 / 2.0]
    return np.column_stack(cols[:n_terms])


def _thin(taus: np.ndarray, per_decade: float) -> np.ndarray:
    """Indices of the points nearest to a log grid with ``per_decade`` nodes per decade."""
    logt = np.log10(taus)
    grid = np.arange(logt[0], logt[-1] + 1e-9, 1.0 / per_decade)
    idx = np.unique(np.abs(logt[None, :] - grid[:, None]).argmin(axis=1))
    return idx


def _classic_slope_reading(curve: AllanCurve, target: float) -> tuple[float, int]:
    logt = np.log10(curve.taus_s)
    loga = np.log10(curve.adev)
    if logt.size < 3:
        return math.nan, -1
    slope = np.gradient(loga, logt)
    i = int(np.argmin(np.abs(slope - target)))
    if abs(slope[i] - target) > 0.25:
        return math.nan, i
    return float(curve.adev[i]), i


def _sqrt_with_std(c: float, s: float) -> tuple[float, float]:
    c = max(c, 0.0)
    s = max(s, 0.0)
    return math.sqrt(c), math.sqrt(c + s) - math.sqrt(c)


def fit_ieee952(
    curve: AllanCurve,
    *,
    include_rate_ramp: bool = False,
    tau_min_s: float | None = None,
    tau_max_s: float | None = None,
    points_per_decade: float = 3.0,
    correlation_inflation: float = 1.5,
    max_iterations: int = 20,
) -> AllanFit:
    """Fit N, B, K (and optionally R) to an Allan curve by weighted non-negative least squares.

    Model: AVAR(tau) = N^2/tau + (2 ln2/pi) B^2 + K^2 tau/3 [+ R^2 tau^2/2] (IEEE 952), linear
    in the variance coefficients (N^2, B^2, K^2, R^2) >= 0, fitted to the AVAR points.

    Weights: the standard uncertainty of an AVAR point is AVAR_model(tau) sqrt(2/edf), with
    the edf of :func:`overlapping_avar_edf` for the noise type that dominates the model at
    that tau. The model (not the scattered data point) sets the weight, so low points do
    not get excessive weight; this is iterated (iteratively reweighted NNLS, first pass
    with the measured AVAR and the conservative curve edf) until the coefficients settle.

    Correlation between neighbouring overlapping points: estimates at nearby taus share
    most of their data and are strongly correlated, which a diagonal weighting ignores.
    The fit therefore uses only the curve points nearest to a log grid of
    ``points_per_decade`` (default 3, i.e. taus about a factor 2.15 apart). Even so the
    remaining correlation makes the diagonal-weight covariance (X^T W X)^-1 too small:
    in a Monte Carlo of 360k-sample records at 100 Hz (white; white + flicker; white +
    rate random walk; all three; 80-150 records each) the RMS of (estimate - truth) /
    std was 1.26-1.34 for N, 1.2-1.25 for B and 1.6 for K (and the median chi2/dof was
    0.55-0.9, the signature of positively correlated points). The standard uncertainties
    are therefore multiplied by ``correlation_inflation`` (default 1.5; the same Monte
    Carlo then gives RMS 0.7-0.9 for N, 0.8-1.2 for B, 1.0-1.15 for K), and additionally
    by sqrt(max(1, chi2/dof)) (Birge ratio) so that model misfit widens, never narrows,
    them. Known bias: with white + rate random walk only, a spurious small B absorbs part
    of the K^2 tau/3 term and K reads about 13 % low on average (K's own scatter: 24 %).

    ``tau_min_s`` (default 10 samples) skips the shortest taus, where a sensor-internal
    anti-alias filter or quantisation bends the -1/2 slope; ``tau_max_s`` (default: the
    longest curve tau) bounds the other end.

    Raises FitError if fewer points than terms + 1 remain or the record was constant.
    """
    n_terms = 4 if include_rate_ramp else 3
    taus_all = np.asarray(curve.taus_s)
    lo = 10.0 / curve.rate_hz if tau_min_s is None else tau_min_s
    hi = taus_all[-1] if tau_max_s is None else tau_max_s
    sel = np.flatnonzero((taus_all >= lo * (1 - 1e-9)) & (taus_all <= hi * (1 + 1e-9)))
    if sel.size == 0:
        raise FitError(f"IEEE 952 fit: no Allan points between {lo:g} s and {hi:g} s")
    sel = sel[_thin(taus_all[sel], points_per_decade)]
    if sel.size < n_terms + 1:
        raise FitError(f"IEEE 952 fit: {sel.size} Allan points in range, need at least {n_terms + 1}")
    taus = taus_all[sel]
    y = np.asarray(curve.avar)[sel]
    if not np.all(np.isfinite(y)) or not np.any(y > 0.0):
        raise FitError("IEEE 952 fit: the Allan variance is zero (constant record) or not finite")
    m = np.asarray(curve.cluster_sizes)[sel]
    a = _design(taus, n_terms)
    edf_by_term = np.column_stack(
        [overlapping_avar_edf(curve.n_samples, m, k) for k in ("white", "flicker", "random_walk", "random_walk")]
    )[:, :n_terms]
    model = y.copy()
    edf = np.asarray(curve.edf)[sel]
    coef = np.zeros(n_terms)
    for _ in range(max_iterations):
        sigma = np.maximum(model, 1e-300) * np.sqrt(2.0 / edf)
        aw = a / sigma[:, None]
        yw = y / sigma
        scale = np.linalg.norm(aw, axis=0)
        sol, _ = nnls(aw / scale, yw)
        new = sol / scale
        contrib = a * new
        model = np.maximum(contrib.sum(axis=1), 1e-300)
        dominant = np.argmax(contrib, axis=1)
        edf = edf_by_term[np.arange(taus.size), dominant]
        converged = np.allclose(new, coef, rtol=1e-7, atol=1e-300)
        coef = new
        if converged:
            break
    sigma = model * np.sqrt(2.0 / edf)
    aw = a / sigma[:, None]
    resid = (y - a @ coef) / sigma
    free = coef > 0.0
    dof = taus.size - int(free.sum())
    chi2_red = float(resid @ resid / dof) if dof > 0 else math.nan
    inflate = correlation_inflation**2 * (max(1.0, chi2_red) if dof > 0 else 1.0)
    cov = np.zeros((4, 4))
    scale = np.linalg.norm(aw, axis=0)
    awn = aw / scale
    if free.any():
        fi = np.flatnonzero(free)
        cov_f = np.linalg.pinv(awn[:, fi].T @ awn[:, fi]) / np.outer(scale[fi], scale[fi])
        cov[np.ix_(fi, fi)] = cov_f * inflate
    bound = np.flatnonzero(~free)
    if bound.size:
        cov_all = np.linalg.pinv(awn.T @ awn) / np.outer(scale, scale)
        for k in bound:
            cov[k, k] = cov_all[k, k] * inflate
    c4 = np.zeros(4)
    c4[:n_terms] = coef
    values = [_sqrt_with_std(c4[k], math.sqrt(cov[k, k])) for k in range(4)]
    if not include_rate_ramp:
        values[3] = (math.nan, math.nan)
    n_read, i_n = _classic_slope_reading(curve, -0.5)
    k_read, ik = _classic_slope_reading(curve, 0.5)
    imin = int(np.argmin(curve.adev))
    return AllanFit(
        random_walk=values[0][0],
        random_walk_std=values[0][1],
        bias_instability=values[1][0],
        bias_instability_std=values[1][1],
        rate_random_walk=values[2][0],
        rate_random_walk_std=values[2][1],
        rate_ramp=values[3][0],
        rate_ramp_std=values[3][1],
        variance_coefficients=_frozen(c4),
        variance_covariance=_frozen(cov),
        terms_at_bound=tuple(_TERMS[k] for k in bound),
        chi2_reduced=chi2_red,
        taus_used_s=_frozen(taus),
        classic_random_walk=n_read * math.sqrt(curve.taus_s[i_n]) if math.isfinite(n_read) else math.nan,
        classic_bias_instability=float(curve.adev[imin]) / BIAS_INSTABILITY_FACTOR,
        classic_bias_instability_tau_s=float(curve.taus_s[imin]),
        classic_rate_random_walk=k_read * math.sqrt(3.0 / curve.taus_s[ik]) if math.isfinite(k_read) else math.nan,
    )


def allan_coefficients(fits: tuple[AllanFit, AllanFit, AllanFit] | list[AllanFit]) -> AllanCoefficients:
    """Pack the weighted-fit coefficients of the x, y, z axes into :class:`AllanCoefficients`."""
    if len(fits) != 3:
        raise FitError(f"Allan coefficients: need 3 axes, got {len(fits)}")
    names = [f.name for f in fields(AllanCoefficients)]
    return AllanCoefficients(**{name: np.array([getattr(f, name) for f in fits]) for name in names})


# --------------------------------------------------------------------------- white noise


@dataclass(frozen=True, eq=False)
class WhiteNoiseEstimate:
    """Per-sample white-noise standard deviation of one axis (U), three ways.

    Attributes:
        paper_std, paper_std_std: the paper's figure (sec. 3): standard deviation of the
            samples of the record's tail (``tail_fraction``) after removing a linear trend
            (or the mean); uncertainty sigma / sqrt(2 (n - p)) (exact for Gaussian white
            noise, p = 1 or 2 fitted trend parameters). Inflated by outliers and by any
            drift left in the window, as the paper itself notes.
        diff_std, diff_std_std: std(first differences) / sqrt(2) over the whole record;
            insensitive to slow drift, still inflated by outliers. Uncertainty
            sigma sqrt(3 / (4 (n - 1))) (the differences are MA(1) with lag-1 correlation
            -1/2, which raises the variance of their sample variance to 3/n relative).
        robust_std, robust_std_std: std of the first differences after iterative clipping at
            4 sigma (started from the MAD, corrected for the Gaussian truncation), / sqrt(2);
            insensitive to drift and to rare outliers, and, unlike a plain MAD, not stuck on
            the lattice of quantised data (a sensor with sigma near one LSB has MAD = 1 LSB
            whatever its noise). Uncertainty as for ``diff_std`` over the kept differences.
            **This is the one the fit should use.**
        lag1_autocorrelation: of the detrended tail. Near 0 for white noise; if it is
            clearly not (|rho1| >> 1/sqrt(n)), the difference-based figures are biased by
            sqrt(1 - rho1) and ``paper_std`` from a drift-free stretch is the better one.
        outlier_fraction: fraction of detrended tail samples beyond 6 robust sigma.
        n_samples: record length; n_tail: samples in the paper's tail window.
    """

    paper_std: float
    paper_std_std: float
    diff_std: float
    diff_std_std: float
    robust_std: float
    robust_std_std: float
    lag1_autocorrelation: float
    outlier_fraction: float
    n_samples: int
    n_tail: int


def _clipped_diff_std(d: np.ndarray) -> tuple[float, int]:
    """Per-sample sigma (U) from first differences ``d``: iterative 4-sigma clipping, truncation-corrected."""
    center = float(np.median(d))
    scale = _MAD_TO_STD * float(np.median(np.abs(d - center)))
    if not scale > 0.0:  # e.g. coarsely quantised data with most differences 0
        scale = float(np.std(d))
    if not scale > 0.0:
        return 0.0, d.size
    keep = np.ones(d.size, dtype=bool)
    for _ in range(20):
        new_keep = np.abs(d - center) <= _CLIP_K * scale
        kept = d[new_keep]
        center = float(kept.mean())
        scale = math.sqrt(float(np.mean((kept - center) ** 2)) / _CLIP_VAR_RATIO)
        if np.array_equal(new_keep, keep):
            break
        keep = new_keep
    return scale / math.sqrt(2.0), int(keep.sum())


def white_noise_std(
    x: np.ndarray,
    *,
    detrend: Literal["linear", "mean"] = "linear",
    tail_fraction: float = 0.2,
) -> WhiteNoiseEstimate:
    """White-noise std per sample (U) of a still record ``x`` (U), the paper's way and robustly.

    The paper (sec. 3) takes the variance of the raw data at the end of each set;
    ``tail_fraction`` (default 0.2, the window :mod:`station.fit.acf` uses for the
    asymptote) selects that end, ``detrend`` removes a linear trend or the mean from it.
    The difference-based estimators always use the whole record.
    """
    xr = _as_record(x, "white noise", 8)
    if not 0.0 < tail_fraction <= 1.0:
        raise FitError(f"white noise: tail_fraction must be in (0, 1], got {tail_fraction}")
    n = xr.size
    n_tail = max(round(tail_fraction * n), 8)
    tail = xr[n - n_tail :]
    t = np.arange(n_tail, dtype=np.float64)
    if detrend == "linear":
        resid = tail - np.polyval(np.polyfit(t, tail, 1), t)
        p = 2
    elif detrend == "mean":
        resid = tail - tail.mean()
        p = 1
    else:
        raise FitError(f"white noise: unknown detrend {detrend!r}")
    paper = math.sqrt(float(resid @ resid) / (n_tail - p))
    d = np.diff(xr)
    nd = d.size
    diff_std = float(np.std(d, ddof=1)) / math.sqrt(2.0)
    robust, n_kept = _clipped_diff_std(d)
    denom = float(resid @ resid)
    rho1 = float(resid[1:] @ resid[:-1]) / denom if denom > 0.0 else math.nan
    outliers = float(np.mean(np.abs(resid - np.median(resid)) > 6.0 * robust)) if robust > 0.0 else math.nan
    return WhiteNoiseEstimate(
        paper_std=paper,
        paper_std_std=paper / math.sqrt(2.0 * (n_tail - p)),
        diff_std=diff_std,
        diff_std_std=diff_std * math.sqrt(3.0 / (4.0 * nd)),
        robust_std=robust,
        robust_std_std=robust * math.sqrt(3.0 / (4.0 * max(n_kept, 1))),
        lag1_autocorrelation=rho1,
        outlier_fraction=outliers,
        n_samples=n,
        n_tail=n_tail,
    )


def random_walk_from_white_std(sigma: float | np.ndarray, rate_hz: float) -> float | np.ndarray:
    """N (U/sqrt(Hz)) from the per-sample white-noise std sigma (U) at ``rate_hz`` (Hz): sigma / sqrt(fs).

    Valid for noise that is white up to the Nyquist frequency (no internal low-pass).
    """
    return sigma / math.sqrt(rate_hz)


def white_std_from_random_walk(n: float | np.ndarray, rate_hz: float) -> float | np.ndarray:
    """Per-sample white-noise std sigma (U) from N (U/sqrt(Hz)) at ``rate_hz`` (Hz): N sqrt(fs)."""
    return n * math.sqrt(rate_hz)
