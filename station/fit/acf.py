"""The paper's correlation-time and drift estimators (Kolhoff & Kemper, eq. (4) and sec. 3).

Implemented faithfully, as the reference the project's joint fit is benchmarked against:

1. Low-pass the still record from power-on ("a high-order FIR low-pass filter"): here a
   block mean to about 10 samples per ``lowpass_s`` (1 Hz for the default 10 s at 100 Hz),
   then a zero-phase FIR: a 61-tap Hamming-window low-pass with cutoff 1 / ``lowpass_s``
   Hz applied forward and backward (one symmetric 121-tap convolution), with odd
   (point-symmetric) extension at both edges so the local slope survives there
   (:func:`lowpass_record`).
2. b_drift (:func:`drift_amplitude`): "the effective values at the beginning of the
   measuring process (static value) and at the end (asymptotic value) are determined, the
   difference of them is the drifting bias" -- the filtered value at the first sample
   minus the mean of the filtered record over its last ``asymptote_fraction``. (The paper
   calls the beginning value "static"; in this project's model, eq. (1), the bias is
   b_stat + b_drift at power-on and settles to b_stat, so b_drift = beginning - end.)
3. T_c (:func:`correlation_time_acf`): "after the asymptotic value is removed from the
   filtered data, only the exponentially shaped part remains", its ACF Phi(tau) (eq. 4, as
   a sum over the finite record) is computed and T_c read where Phi has decayed to
   exp(-1) of Phi(0).

Units: input samples in sensor units U (m/s^2 or rad/s), times in s, Phi in U^2 s.

Known weaknesses (documented, deliberately not fixed here). Numbers from an exponential
b_drift exp(-t/T_c) plus white noise at 100 Hz (scripts in the test module's spirit):

* Short record -> T_c biased LOW. Over a record of length L the mean of the last 20 %
  still contains part of the transient, so removing it as "asymptote" makes the
  remainder cross zero, and the finite sum truncates Phi; both make the ACF fall faster.
  Without noise the reading is T_c times 1.00 (L >= 10 T_c), 0.96 (5), 0.82 (3),
  0.64 (2), 0.51 (1.5), 0.37 (1), 0.30 (0.8). Because the finite-sum ACF always falls
  to ~0 at the longest lags, it practically always "decays" -- a record much shorter
  than T_c (e.g. a 1 h gyro record with T_c of 1000-3800 s, paper Table 1) returns a
  small number, not NaN. NaN comes only from a flat record.
* White noise -> T_c biased LOW, and the bias GROWS with the record length: the filtered
  noise adds energy eps * Phi(0) to the lag-0 value (and almost nothing at lags beyond
  the filter width), raising the exp(-1) threshold; the reading becomes about
  T_c (1 + ln(1 - eps)), eps = noise energy / Phi(0) (``AcfResult.noise_energy_fraction``,
  which grows linearly with L while the transient energy b_drift^2 T_c / 2 is fixed).
  Example, T_c = 60 s, b_drift = 0.01, sigma = 0.02 per sample (paper Table 1 range):
  0.87 T_c at L = 5 T_c, 0.83 at 10, 0.74 at 20, 0.53 at 40.
* The stochastic part of the drift (w_g in eq. 3) is not a deterministic exponential; a
  single realisation's "ACF" over a few T_c is itself a random variable with a large
  spread, which no uncertainty here accounts for.
* b_drift: the beginning value of a zero-phase symmetric filter with odd edge extension
  equals the first decimated sample exactly, so it carries the white noise of the first
  block (sigma / sqrt(decimation)); the end value is biased toward the beginning when the
  record is not many T_c long (b_drift reads 0.98 at L = 5 T_c, 0.93 at 3, 0.83 at 2,
  0.59 at 1).

Uncertainties (``*_std``) are the white-sensor-noise part only, propagated exactly
through decimation, filter and asymptote removal (adjoint of the linear filter, noise
level from the robust first-difference estimate); for T_c by the delta method at the
crossing. They exclude every bias above and all slow noise, so they are lower bounds.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy import signal

from station.fit.allan import white_noise_std
from station.kernel.errors import FitError

_E_INV = math.exp(-1.0)


def _frozen(a: np.ndarray) -> np.ndarray:
    arr = np.array(a, dtype=np.float64, copy=True)
    arr.flags.writeable = False
    return arr


@dataclass(frozen=True, eq=False)
class LowpassRecord:
    """A still record after block-mean decimation and zero-phase FIR low-pass.

    Attributes:
        t_s: time of each filtered sample (s) from the first raw sample (block centres).
        values: filtered record (U).
        rate_hz: sample rate of the filtered record (Hz).
        decimation: raw samples per block.
        numtaps: FIR length (applied forward and backward).
        lowpass_s: cutoff period (s); the cutoff frequency is 1 / lowpass_s (Hz).
        block_noise_std: white-noise std of one block mean (U), from the robust
            first-difference estimate of the raw record (``WhiteNoiseEstimate.robust_std``)
            divided by sqrt(decimation).
    """

    t_s: np.ndarray
    values: np.ndarray
    rate_hz: float
    decimation: int
    numtaps: int
    lowpass_s: float
    block_noise_std: float

    def noise_std_of(self, u: np.ndarray) -> float:
        """Std (U) of sum_i u_i values_i due to the white sensor noise alone (exact, via the filter's adjoint)."""
        kernel = _zero_phase_kernel(self.numtaps, self.lowpass_s, self.rate_hz)
        return self.block_noise_std * float(np.linalg.norm(_zero_phase_fir_adjoint(u, kernel)))


def _zero_phase_kernel(numtaps: int, lowpass_s: float, rate_hz: float) -> np.ndarray:
    """FIR b (Hamming window, cutoff 1/lowpass_s Hz) convolved with itself reversed: |B(f)|^2, zero phase."""
    b = signal.firwin(numtaps, 1.0 / lowpass_s, fs=rate_hz)
    return np.convolve(b, b[::-1])


def _zero_phase_fir(x: np.ndarray, kernel: np.ndarray) -> np.ndarray:
    """Forward-backward FIR as one symmetric convolution, odd (point-symmetric) extension at both edges."""
    half = kernel.size // 2
    ext = np.concatenate((2.0 * x[0] - x[half:0:-1], x, 2.0 * x[-1] - x[-2 : -half - 2 : -1]))
    return np.convolve(ext, kernel, mode="valid")


def _zero_phase_fir_adjoint(u: np.ndarray, kernel: np.ndarray) -> np.ndarray:
    """Transpose of :func:`_zero_phase_fir` applied to ``u``: the weights of each input sample in u . filtered."""
    half = kernel.size // 2
    n = u.size
    v = np.convolve(u, kernel[::-1], mode="full")  # adjoint of the 'valid' convolution, length n + 2 half
    g = v[half : half + n].copy()
    left = v[:half]  # ext[p] = 2 x_0 - x_{half - p}
    g[0] += 2.0 * left.sum()
    g[half:0:-1] -= left
    right = v[half + n :]  # ext[half + n + p] = 2 x_{n-1} - x_{n-2-p}
    g[n - 1] += 2.0 * right.sum()
    g[-2 : -half - 2 : -1] -= right
    return g


def lowpass_record(x: np.ndarray, rate_hz: float, *, lowpass_s: float = 10.0) -> LowpassRecord:
    """Low-pass a still record ``x`` (U) sampled at ``rate_hz`` (Hz) with cutoff 1/``lowpass_s`` (Hz).

    Block mean over q = max(1, floor(rate_hz * lowpass_s / 10)) samples (the tail that does
    not fill a block is dropped), then a scipy.signal.firwin low-pass (Hamming, about 6
    cutoff periods long) applied forward and backward as one symmetric convolution (zero
    phase, magnitude response squared, odd edge extension that keeps the local slope at the
    edges). Raises FitError for non-finite samples or a record shorter than twice the FIR.
    """
    xr = np.asarray(x, dtype=np.float64)
    if xr.ndim != 1:
        raise FitError(f"low-pass: expected a 1-D record of one axis, got shape {xr.shape}")
    if not np.all(np.isfinite(xr)):
        raise FitError("low-pass: record contains NaN or inf samples")
    if not (rate_hz > 0.0 and lowpass_s > 0.0):
        raise FitError(f"low-pass: rate ({rate_hz} Hz) and lowpass_s ({lowpass_s} s) must be positive")
    q = max(1, math.floor(rate_hz * lowpass_s / 10.0))
    fs_d = rate_hz / q
    if 1.0 / lowpass_s >= 0.5 * fs_d:
        raise FitError(f"low-pass: cutoff 1/{lowpass_s} Hz is not below the Nyquist frequency of {rate_hz} Hz")
    numtaps = 2 * round(3.0 * lowpass_s * fs_d) + 1
    n_d = xr.size // q
    if n_d <= 2 * numtaps:
        raise FitError(
            f"low-pass: record of {xr.size / rate_hz:.1f} s is too short for a {lowpass_s} s low-pass "
            f"(need more than {2 * numtaps * q / rate_hz:.1f} s)"
        )
    blocks = xr[: n_d * q].reshape(n_d, q).mean(axis=1)
    noise = white_noise_std(xr).robust_std / math.sqrt(q)
    return LowpassRecord(
        t_s=_frozen((np.arange(n_d) * q + 0.5 * (q - 1)) / rate_hz),
        values=_frozen(_zero_phase_fir(blocks, _zero_phase_kernel(numtaps, lowpass_s, fs_d))),
        rate_hz=fs_d,
        decimation=q,
        numtaps=numtaps,
        lowpass_s=float(lowpass_s),
        block_noise_std=noise,
    )


def _tail_weights(n: int, asymptote_fraction: float) -> np.ndarray:
    if not 0.0 < asymptote_fraction <= 1.0:
        raise FitError(f"asymptote_fraction must be in (0, 1], got {asymptote_fraction}")
    n_tail = max(1, round(asymptote_fraction * n))
    w = np.zeros(n)
    w[n - n_tail :] = 1.0 / n_tail
    return w


# --------------------------------------------------------------------------- b_drift


@dataclass(frozen=True, eq=False)
class DriftAmplitude:
    """The paper's drifting-bias amplitude of one axis (U).

    Attributes:
        initial_value: filtered record at its first sample ("static value" in the paper).
        asymptotic_value: mean of the filtered record over its last ``asymptote_fraction``.
        b_drift: initial_value - asymptotic_value.
        ``*_std``: standard uncertainties from the white sensor noise only (propagated
            exactly through decimation and filter); they do not include the drift's own
            process noise, flicker or rate random walk, nor the bias of an asymptote
            taken before the transient has died out.
        lowpass: the filtered record.
    """

    initial_value: float
    initial_value_std: float
    asymptotic_value: float
    asymptotic_value_std: float
    b_drift: float
    b_drift_std: float
    asymptote_fraction: float
    lowpass: LowpassRecord


def drift_amplitude(
    x: np.ndarray,
    rate_hz: float,
    *,
    lowpass_s: float = 10.0,
    asymptote_fraction: float = 0.2,
) -> DriftAmplitude:
    """b_drift the paper's way (sec. 3) from a still record ``x`` (U) from power-on at ``rate_hz`` (Hz)."""
    rec = lowpass_record(x, rate_hz, lowpass_s=lowpass_s)
    tail = _tail_weights(rec.values.size, asymptote_fraction)
    first = np.zeros(rec.values.size)
    first[0] = 1.0
    start = float(rec.values[0])
    asym = float(tail @ rec.values)
    return DriftAmplitude(
        initial_value=start,
        initial_value_std=rec.noise_std_of(first),
        asymptotic_value=asym,
        asymptotic_value_std=rec.noise_std_of(tail),
        b_drift=start - asym,
        b_drift_std=rec.noise_std_of(first - tail),
        asymptote_fraction=float(asymptote_fraction),
        lowpass=rec,
    )


# --------------------------------------------------------------------------- T_c from the ACF


@dataclass(frozen=True, eq=False)
class AcfResult:
    """The paper's correlation time of one axis (eq. 4, sec. 3).

    Attributes:
        correlation_time_s: T_c (s), the lag where Phi / Phi(0) first reaches exp(-1),
            linearly interpolated between lags; NaN when ``decayed`` is False.
        correlation_time_std_s: standard uncertainty (s) from the white sensor noise only
            (delta method: the first-order noise-induced scatter of Phi(T_c)/Phi(0),
            propagated exactly through filter and asymptote removal, divided by the ACF's
            slope at the crossing). A LOWER BOUND on the real uncertainty: it leaves
            out the drift's process noise, flicker and random-walk noise and the
            finite-record bias (see the module docstring); NaN when not decayed.
        decayed: whether Phi / Phi(0) reached exp(-1) within the record.
        note: why T_c is NaN, or "" when it is not.
        acf_lags_s: lags (s), shape (n,), step 1 / lowpass.rate_hz.
        acf: Phi(tau) / Phi(0), shape (n,).
        acf_zero: Phi(0) (U^2 s), the energy of the transient.
        asymptote: the removed asymptotic value (U).
        asymptote_fraction: the fraction of the record the asymptote was averaged over.
        crossing_index: first lag index with acf <= exp(-1), or -1.
        noise_energy_fraction: expected share eps of Phi(0) that is filtered white sensor
            noise rather than transient (from the robust noise level; can exceed 1 when the
            record holds no visible transient). A diagnostic of the noise bias: for an
            exponential the paper's reading is about T_c (1 + ln(1 - eps)).
        record_length_s: length of the filtered record (s).
        lowpass: the filtered record.
    """

    correlation_time_s: float
    correlation_time_std_s: float
    decayed: bool
    note: str
    acf_lags_s: np.ndarray
    acf: np.ndarray
    acf_zero: float
    asymptote: float
    asymptote_fraction: float
    crossing_index: int
    noise_energy_fraction: float
    record_length_s: float
    lowpass: LowpassRecord

    @property
    def record_over_correlation_time(self) -> float:
        """Record length / T_c; below about 20 the estimate is noticeably biased low."""
        return self.record_length_s / self.correlation_time_s


def finite_record_acf(y: np.ndarray) -> np.ndarray:
    """S_k = sum_{t=0}^{n-1-k} y_t y_{t+k} for k = 0..n-1 (eq. 4 as a finite sum, no 1/(n-k)), via FFT."""
    n = y.size
    nfft = 1 << (2 * n - 1).bit_length()
    spec = np.fft.rfft(y, nfft)
    return np.fft.irfft(spec * np.conj(spec), nfft)[:n]


def correlation_time_acf(
    x: np.ndarray,
    rate_hz: float,
    *,
    asymptote_fraction: float = 0.2,
    lowpass_s: float = 10.0,
) -> AcfResult:
    """T_c (s) of the drifting bias by the paper's ACF method from a still record ``x`` (U) at ``rate_hz`` (Hz).

    Steps (sec. 3): low-pass (:func:`lowpass_record`), subtract the asymptote (mean of
    the filtered record's last ``asymptote_fraction``), Phi(k) = sum_t y_t y_{t+k} / fs
    (eq. 4 over the finite record), T_c = first lag with Phi(k) <= exp(-1) Phi(0), linearly
    interpolated. Biased low unless the record is many T_c long (module docstring).
    """
    rec = lowpass_record(x, rate_hz, lowpass_s=lowpass_s)
    n = rec.values.size
    tail = _tail_weights(n, asymptote_fraction)
    asym = float(tail @ rec.values)
    y = rec.values - asym
    s = finite_record_acf(y)
    lags = np.arange(n) / rec.rate_hz
    record_s = n / rec.rate_hz
    s0 = float(s[0])
    # a record flat to rounding (|y| at the 1e-10 relative level) has no transient to read
    if not np.max(np.abs(y)) > 1e-10 * np.max(np.abs(rec.values)):
        s0 = 0.0
    if not s0 > 0.0:
        r = np.full(n, np.nan)
        below = np.empty(0, dtype=np.int64)
    else:
        r = s / s0
        below = np.flatnonzero(r <= _E_INV)
    kernel = _zero_phase_kernel(rec.numtaps, rec.lowpass_s, rec.rate_hz)
    noise_energy = rec.block_noise_std**2 * n * float(kernel @ kernel)
    common: dict[str, Any] = {  # the fields both results share
        "noise_energy_fraction": noise_energy / s0 if s0 > 0.0 else math.inf,
        "acf_lags_s": _frozen(lags),
        "acf": _frozen(r),
        "acf_zero": s0 / rec.rate_hz,
        "asymptote": asym,
        "asymptote_fraction": float(asymptote_fraction),
        "record_length_s": record_s,
        "lowpass": rec,
    }
    if below.size == 0:
        note = (
            "flat record: nothing left after removing the asymptote"
            if not s0 > 0.0
            else f"ACF did not decay to exp(-1) within the {record_s:.0f} s record (min {np.min(r):.3f})"
        )
        return AcfResult(
            correlation_time_s=math.nan,
            correlation_time_std_s=math.nan,
            decayed=False,
            note=note,
            crossing_index=-1,
            **common,
        )
    k = int(below[0])  # k >= 1 because r[0] = 1
    frac = (r[k - 1] - _E_INV) / (r[k - 1] - r[k])
    tc = (k - 1 + frac) / rec.rate_hz
    # Delta method: r_k = S_k / S_0 is, to first order in a perturbation dy of the record,
    # dr_k = sum_u dy_u (y_{u-k} + y_{u+k} - 2 r_k y_u) / S_0; dy = filtered noise minus its tail mean.
    kc = min(max(round(tc * rec.rate_hz), 1), n - 1)
    h = -2.0 * r[kc] * y
    h[kc:] += y[: n - kc]
    h[: n - kc] += y[kc:]
    h /= s0
    g = h - tail * h.sum()
    dr_std = rec.noise_std_of(g)
    slope = (r[k] - r[k - 1]) * rec.rate_hz  # d(Phi/Phi0)/d tau at the crossing (1/s)
    tc_std = dr_std / abs(slope) if slope != 0.0 else math.nan
    return AcfResult(
        correlation_time_s=tc,
        correlation_time_std_s=tc_std,
        decayed=True,
        note="",
        crossing_index=k,
        **common,
    )
