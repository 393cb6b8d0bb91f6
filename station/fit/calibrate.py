"""The full parameter fit of one session: eq. (1) for both triads, with the drift of eq. (3).

Everything is read from the recording (segments, kinds, references, metadata): no
pose order, rate list, duration or sample rate is assumed.

* Accelerometer: all settled rest and pose samples in one maximum-likelihood problem per
  output axis (row of M_a, b_stat, b_drift, T_c; :mod:`station.fit.axis_ml`).
* Gyroscope: all settled rest, pose and rate samples likewise (row of M_w, optionally
  g-sensitivity); without rate steps, M_w from known-angle rotations (``angle.N``,
  :mod:`station.fit.angle`).
* Noise: white-noise std per sample (the paper's sigma) from sample differences, Allan
  deviation with IEEE 952 coefficients on the rest residual.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from scipy.ndimage import uniform_filter1d
from threadpoolctl import threadpool_limits

from station import __version__
from station.fit import allan
from station.fit.angle import fit_known_angles
from station.fit.axis_ml import AxisFit, fit_axis
from station.fit.blocks import Blocks, block_exp_mean, make_blocks
from station.fit.boundary import numerics
from station.fit.checks import check_session
from station.fit.consistency import check_rotations
from station.fit.determinability import assess
from station.fit.goodness import Rows, TriadResidual, goodness_of_fit
from station.fit.scale_polynomial import (
    Polynomial,
    identifiable_terms,
    no_rate_note,
    select_polynomial,
    with_polynomial,
)
from station.fit.temperature_terms import (
    assess_temperature,
    axis_regressors,
    order_caps,
    select_orders,
    temperature_columns,
)
from station.fit.time_offset import estimate_time_offset
from station.kernel.errors import FitError
from station.kernel.parameters import (
    MAX_TEMP_ORDER,
    AllanCoefficients,
    FitQuality,
    GoodnessOfFit,
    NonlinearityNote,
    ParameterSet,
    ResidualFigures,
    ThermalFit,
    TimeOffsetNote,
    TriadParams,
)
from station.session.model import Kind, Session

AXES = "xyz"
#: Values of :attr:`FitOptions.thermal`.
THERMAL_MODES = ("auto", "off", "require")
#: Values of :attr:`FitOptions.scale_nonlinearity`.
NONLINEARITY_MODES = ("auto", "off")


@dataclass(frozen=True)
class FitOptions:
    """Knobs of the fit.

    Attributes:
        max_blocks: about how many block means the session is reduced to per triad.
        g_sensitivity: also fit the gyro's response to specific force (rad/s per m/s^2).
        min_pose_samples: a settled segment shorter than this is refused.
        outlier_sigma: samples further than this many robust sigmas from their local
            mean are outliers and left out of the fit.
        drift_lr_threshold: Wald-statistic threshold for keeping the exponential drift (9: 3 sigma).
        moving_average_length: n of Algorithm 1's moving average (eq. 6); the paper uses 40.
        tc_range_s: the sensor class's range of eq. 3's T_c (s) per triad (``'accel'``, ``'gyro'``), a
            prior on T_c (the limits file's ``correlation_time_s``); a triad without one is fitted
            from the record alone.
        thermal: the temperature terms (bias and scale polynomials in ``T - T_ref`` per output axis,
            :mod:`station.fit.temperature_terms`): ``'auto'`` fits them when the recording's temperature course
            separates them from the warm-up (else :class:`~station.kernel.parameters.ThermalFit` says why not,
            status ``'not_separable'``), ``'require'`` refuses (FitError) a recording that cannot separate
            them, ``'off'`` (the default: eq. 1 alone, as callers from before the thermal model expect, e.g. the
            diagnosis's base model) never. ``station fit`` uses ``'auto'``.
        thermal_max_order: highest polynomial order tried (1..3).
        thermal_order_wald: Wald statistic (z^2) an order's coefficient must exceed to be kept (9: 3 sigma).
        min_temperature_span_k: the settled data's temperature must span at least this (K).
        min_temperature_independent_k: RMS of the temperature course not explained by a warm-up shape
            ``a + b exp(-t/tau)`` (any tau), at least this (K).
        reference_temperature_degc: T_ref (degC); None: the unit's temperature at power-on (mean of the
            first second of the recording).
        scale_nonlinearity: the scale-factor polynomial ``y = u + k2 u^2 + k3 u^3`` per output axis (``u`` = M
            ref; Algorithm 1's line 6' inverts it), of the gyro (IEEE Std 952) and of the accelerometer:
            ``'auto'`` fits the odd k3 on the axes whose blocks hold at least two distinct input magnitudes (with
            one, ``u^3`` is ``|u|^2 u``, a scale error M already holds), the gyro's even k2 where its rate steps
            also hold both signs, the accelerometer's where its poses hold +g, -g and 0 along the axis
            (:mod:`station.fit.scale_polynomial`), and keeps each term where its Wald statistic exceeds
            ``nonlinearity_wald``; ``'off'`` (the default) never. The result says which
            (``quality['scale_nonlinearity']`` for the gyro, ``quality['accel_scale_polynomial']``). (The older
            ``u + k u|u|`` term is no longer fitted; sets that hold it still load and are applied.)
        nonlinearity_wald: Wald statistic (z^2) a term must exceed to be kept (9: 3 sigma).
        time_offset: the sensor's lag behind the rig's reference (:mod:`station.fit.time_offset`): ``'auto'``
            estimates it on the transitions (moves, rate ramps) and keeps it where its Wald statistic exceeds
            ``time_offset_wald``; ``'off'`` (the default) never.
        time_offset_wald: Wald statistic (z^2) the offset must exceed to be kept (9: 3 sigma).
        censored_saturation: the caller censored the saturated settled segments by taking their triad's reference
            away (:func:`station.fit.checks.check_session`'s ``censored``; only the diagnosis does,
            :mod:`station.diagnose.censoring`). False (the default, ``station fit``): a saturated axis is refused.
    """

    max_blocks: int = 70
    g_sensitivity: bool = False
    min_pose_samples: int = 50
    outlier_sigma: float = 6.0
    drift_lr_threshold: float = 9.0
    moving_average_length: int = 40
    tc_range_s: Mapping[str, tuple[float, float]] = field(default_factory=dict)
    thermal: str = "off"
    thermal_max_order: int = 3
    thermal_order_wald: float = 9.0
    min_temperature_span_k: float = 5.0
    min_temperature_independent_k: float = 1.0
    reference_temperature_degc: float | None = None
    scale_nonlinearity: str = "off"
    nonlinearity_wald: float = 9.0
    time_offset: str = "off"
    time_offset_wald: float = 9.0
    censored_saturation: bool = False

    def __post_init__(self) -> None:
        if self.time_offset not in NONLINEARITY_MODES:
            raise ValueError(f"FitOptions.time_offset must be one of {', '.join(NONLINEARITY_MODES)}, "
                             f"got {self.time_offset!r}")
        if self.scale_nonlinearity not in NONLINEARITY_MODES:
            raise ValueError(f"FitOptions.scale_nonlinearity must be one of {', '.join(NONLINEARITY_MODES)}, "
                             f"got {self.scale_nonlinearity!r}")
        if self.thermal not in THERMAL_MODES:
            raise ValueError(f"FitOptions.thermal must be one of {', '.join(THERMAL_MODES)}, got {self.thermal!r}")
        if not 1 <= int(self.thermal_max_order) <= MAX_TEMP_ORDER:
            raise ValueError(f"FitOptions.thermal_max_order must be 1..{MAX_TEMP_ORDER}, got {self.thermal_max_order}")


@dataclass(frozen=True)
class NoiseEstimate:
    """A triad's white noise (:func:`white_noise`), shared with the rig-free fit."""

    sigma: np.ndarray  # (3,) white-noise std per sample
    sigma_std: np.ndarray  # (3,)
    keep: np.ndarray  # (n,) bool: not an outlier on any axis
    outliers: np.ndarray  # (3,) count per axis


def settled_runs(session: Session, kinds: tuple[Kind, ...], ref: np.ndarray) -> list[tuple[int, int, int]]:
    runs = []
    for seg in session.segments_of(*kinds):
        if np.all(np.isfinite(ref[seg.start:seg.stop])):
            runs.append((seg.index, seg.start, seg.stop))
    return runs


def white_noise(
    session: Session, data: np.ndarray, runs: list[tuple[int, int, int]], outlier_sigma: float
) -> NoiseEstimate:
    """White-noise std from first differences within settled runs (robust to outliers), and outlier flags."""
    keep = np.ones(len(session), dtype=bool)
    # robust std of a difference of two samples is sqrt(2) sigma (one axis at a time: a third of the memory)
    mad = np.empty(3)
    for j in range(3):
        d = np.concatenate([np.diff(data[a:b, j]) for _, a, b in runs])
        mad[j] = np.median(np.abs(d - np.median(d)))
        del d
    sigma_robust = 1.4826 * mad / np.sqrt(2.0)
    sigma_robust = np.maximum(sigma_robust, 1e-12)
    outliers = np.zeros(3, dtype=int)
    for _, a, b in runs:
        x = data[a:b]
        window = max(3, min(b - a, 101))
        local = uniform_filter1d(x, size=window, axis=0, mode="nearest")
        bad = np.abs(x - local) > outlier_sigma * sigma_robust
        outliers += bad.sum(axis=0)
        keep[a:b] &= ~bad.any(axis=1)
    # the plain std of the clean differences is efficient; use it for the value

    def clean() -> Iterator[np.ndarray]:  # each run's differences of kept neighbours, a piece at a time
        for _, a, b in runs:
            for lo in range(a, b - 1, _ROWS):
                hi = min(lo + _ROWS, b - 1)
                yield (data[lo + 1:hi + 1] - data[lo:hi])[keep[lo + 1:hi + 1] & keep[lo:hi]]

    sigma, count = _std_of_rows(clean)
    sigma = sigma / np.sqrt(2.0)
    # differences of white noise: lag-1 correlation -1/2 inflates the variance of the estimate by 1.5
    sigma_std = sigma * np.sqrt(1.5 / (2.0 * max(count - 1, 1)))
    return NoiseEstimate(sigma=sigma, sigma_std=sigma_std, keep=keep, outliers=outliers)


def _sum_of_rows(parts: Iterator[np.ndarray]) -> tuple[np.ndarray, int]:
    """Column sums of the rows of ``parts`` (each (k, 3)) added in row order, as ``np.sum(axis=0)`` of the rows
    stacked adds them (the same numbers, without the stack), and the number of rows."""
    total: np.ndarray | None = None
    count = 0
    for part in parts:
        total = np.add.reduce(part if total is None else np.concatenate([total[None, :], part]), axis=0)
        count += len(part)
    return (np.zeros(3) if total is None else total), count


def _std_of_rows(parts: Callable[[], Iterator[np.ndarray]]) -> tuple[np.ndarray, int]:
    """``np.std(rows, axis=0)`` of the rows of ``parts()`` stacked (numpy's two passes: the mean, then the mean
    squared deviation), one part at a time; and the number of rows."""
    total, count = _sum_of_rows(parts())
    mean = total / count
    squares, _ = _sum_of_rows(_squared(x - mean) for x in parts())
    return np.sqrt(squares / count), count


def _squared(d: np.ndarray) -> np.ndarray:
    return np.multiply(d, d, out=d)


#: Samples per piece where a per-sample quantity is summed a piece at a time.
_ROWS = 1 << 18


@dataclass(frozen=True)
class TriadLinear:
    """Per-axis fits of one triad, and how to evaluate the mean model."""

    fits: list[AxisFit]
    n_ref: int  # number of reference columns (3 with M, 0 when M comes from angles)
    extra: int  # extra regressor columns (3 for g-sensitivity)
    nonlin_col: tuple[tuple[int, int], ...] = ()  # per axis: design columns of k2 u^2, k3 u^3 (-1: not fitted)


def _design(blocks: Blocks, with_ref: bool, g_sens: bool) -> np.ndarray:
    cols = [blocks.ref] if with_ref else []
    cols.append(np.ones((len(blocks), 1)))
    if g_sens:
        cols.append(blocks.force)
    return np.column_stack(cols)


def _fit_triad(
    session: Session,
    data: np.ndarray,
    ref: np.ndarray,
    runs: list[tuple[int, int, int]],
    noise: NoiseEstimate,
    options: FitOptions,
    *,
    with_ref: bool,
    g_sens: bool,
    triad: str,
    nonlin_m: Polynomial | None = None,
) -> tuple[TriadLinear, Blocks]:
    blocks = make_blocks(  # NaN references count as 0 there
        session.t_s, data, ref, session.ref_accel_mps2, noise.keep, runs, 1.0 / session.sample_rate_hz,
        options.max_blocks,
    )
    design = _design(blocks, with_ref, g_sens)
    tc_range = options.tc_range_s.get(triad)
    fits, cols = [], []
    for k in range(3):
        d_k, col = with_polynomial(design, blocks, nonlin_m, k)
        fits.append(fit_axis(blocks, k, d_k, float(noise.sigma[k]), lr_threshold=options.drift_lr_threshold,
                             tc_range_s=tc_range))
        cols.append(col)
    tri = TriadLinear(fits=fits, n_ref=3 if with_ref else 0, extra=3 if g_sens else 0,
                       nonlin_col=tuple(cols) if nonlin_m is not None else ())
    return tri, blocks


def _fit_triad_thermal(
    session: Session,
    data: np.ndarray,
    ref: np.ndarray,
    runs: list[tuple[int, int, int]],
    noise: NoiseEstimate,
    options: FitOptions,
    *,
    with_ref: bool,
    g_sens: bool,
    triad: str,
    dt: np.ndarray,
    m_hat: np.ndarray | None,
    orders: tuple[list[int], list[int]] | None = None,
    nonlin_m: Polynomial | None = None,
) -> tuple[TriadLinear, Blocks, dict[str, np.ndarray], tuple[list[int], list[int]]]:
    """The triad fit with the temperature terms (:mod:`station.fit.temperature_terms`), orders chosen or given.

    Returns the fits, the blocks, the temperature coefficients with their stds (``temp_bias_coeff``,
    ``temp_scale_coeff``, ``*_std``, each (3, 3)) and the (bias, scale) orders per axis.
    """
    blocks = make_blocks(  # NaN references count as 0 there; the temperature columns made a few blocks at a time
        session.t_s, data, ref, session.ref_accel_mps2, noise.keep, runs, 1.0 / session.sample_rate_hz,
        options.max_blocks, extra=lambda lo, hi: temperature_columns(dt[lo:hi], ref[lo:hi] if with_ref else None),
    )
    base = _design(blocks, with_ref, g_sens)
    tc_range = options.tc_range_s.get(triad)
    top = int(options.thermal_max_order)
    coeff = {k: np.zeros((3, MAX_TEMP_ORDER)) for k in (
        "temp_bias_coeff", "temp_bias_coeff_std", "temp_scale_coeff", "temp_scale_coeff_std")}
    fits: list[AxisFit] = []
    n_bias: list[int] = []
    n_scale: list[int] = []
    cols: list[tuple[int, int]] = []
    for k in range(3):
        m_row = None if (m_hat is None or not with_ref) else m_hat[k]
        if orders is not None:
            nb, ns = orders[0][k], orders[1][k]
        else:
            nb, ns = order_caps(blocks, m_row, top)
        design = np.column_stack([base, axis_regressors(blocks, m_row, nb, ns)])
        fit = fit_axis(blocks, k, design, float(noise.sigma[k]), lr_threshold=options.drift_lr_threshold,
                       tc_range_s=tc_range)
        if orders is None:
            nb2, ns2 = select_orders(blocks, k, base, m_row, float(noise.sigma[k]), fit, top,
                                     options.thermal_order_wald, start=(nb, ns))
            if (nb2, ns2) != (nb, ns):
                nb, ns = nb2, ns2
                design = np.column_stack([base, axis_regressors(blocks, m_row, nb, ns)])
                fit = fit_axis(blocks, k, design, float(noise.sigma[k]), lr_threshold=options.drift_lr_threshold,
                               tc_range_s=tc_range)
        if nonlin_m is not None:  # orders chosen without it: refit with the nonlinearity column last
            design, col = with_polynomial(design, blocks, nonlin_m, k)
            if max(col) >= 0:
                fit = fit_axis(blocks, k, design, float(noise.sigma[k]), lr_threshold=options.drift_lr_threshold,
                               tc_range_s=tc_range)
            cols.append(col)
        std = np.sqrt(np.clip(np.diag(fit.beta_cov), 0.0, None))
        off = base.shape[1]
        coeff["temp_bias_coeff"][k, :nb] = fit.beta[off:off + nb]
        coeff["temp_bias_coeff_std"][k, :nb] = std[off:off + nb]
        off += nb
        coeff["temp_scale_coeff"][k, :ns] = fit.beta[off:off + ns]
        coeff["temp_scale_coeff_std"][k, :ns] = std[off:off + ns]
        fits.append(fit)
        n_bias.append(nb)
        n_scale.append(ns)
    tri = TriadLinear(fits=fits, n_ref=3 if with_ref else 0, extra=3 if g_sens else 0, nonlin_col=tuple(cols))
    return tri, blocks, coeff, (n_bias, n_scale)


def _thermal_triad(
    session: Session, data: np.ndarray, ref: np.ndarray, runs: list[tuple[int, int, int]], noise: NoiseEstimate,
    options: FitOptions, first: TriadLinear, *, with_ref: bool, g_sens: bool, triad: str, dt: np.ndarray,
) -> tuple[TriadLinear, Blocks, dict[str, np.ndarray], tuple[list[int], list[int]]]:
    """Two passes: orders chosen with M^ from the fit without temperature terms, then refitted with M^ from
    the first pass (the scale regressor ``(M^_k . ref) dT^j``)."""
    m_hat = unpack_triad(first)["misalignment"] if with_ref else None
    tri, blocks, coeff, orders = _fit_triad_thermal(session, data, ref, runs, noise, options, with_ref=with_ref,
                                                    g_sens=g_sens, triad=triad, dt=dt, m_hat=m_hat)
    if with_ref:
        m_hat = unpack_triad(tri)["misalignment"]
        tri, blocks, coeff, orders = _fit_triad_thermal(session, data, ref, runs, noise, options, with_ref=with_ref,
                                                        g_sens=g_sens, triad=triad, dt=dt, m_hat=m_hat, orders=orders)
    return tri, blocks, coeff, orders


def _temperature_terms(p: dict[str, np.ndarray], dt: np.ndarray, ref: np.ndarray | None) -> np.ndarray:
    """Per-sample temperature bias and scale terms of a triad, (n, 3) (zeros without coefficients)."""
    out = np.zeros((dt.shape[0], 3))
    cb, cs = p.get("temp_bias_coeff"), p.get("temp_scale_coeff")
    powers = np.column_stack([dt**j for j in range(1, MAX_TEMP_ORDER + 1)])
    if cb is not None:
        out += powers @ cb.T
    if cs is not None and ref is not None and np.any(cs):
        out += (np.nan_to_num(ref) @ p["misalignment"].T) * (powers @ cs.T)
    return out


def unpack_triad(tri: TriadLinear) -> dict[str, np.ndarray]:
    """Arrange per-axis results into M, b_stat, b_drift, T_c, ... with uncertainties."""
    m = np.full((3, 3), np.nan)
    m_std = np.full((3, 3), np.nan)
    g = np.zeros((3, 3))
    g_std = np.zeros((3, 3))
    out: dict[str, np.ndarray] = {k: np.zeros(3) for k in (
        "bias_static", "bias_static_std", "bias_drift", "bias_drift_std", "correlation_time_s",
        "correlation_time_s_std", "drift_noise", "drift_noise_std",
    )}
    for k, f in enumerate(tri.fits):
        std = np.sqrt(np.clip(np.diag(f.beta_cov), 0.0, None))
        r = tri.n_ref
        if r:
            m[k], m_std[k] = f.beta[:r], std[:r]
        out["bias_static"][k], out["bias_static_std"][k] = f.beta[r], std[r]
        if tri.extra:
            g[k], g_std[k] = f.beta[r + 1:r + 1 + tri.extra], std[r + 1:r + 1 + tri.extra]
        out["bias_drift"][k], out["bias_drift_std"][k] = f.beta[-1], std[-1]  # 0 when unresolved
        out["correlation_time_s"][k], out["correlation_time_s_std"][k] = f.tc_s, f.tc_std_s
        out["drift_noise"][k], out["drift_noise_std"][k] = f.drift_noise, f.drift_noise_std
    out.update(misalignment=m, misalignment_std=m_std, g_sensitivity=g, g_sensitivity_std=g_std)
    if tri.nonlin_col:
        terms = {name: np.zeros(3) for name in ("scale_quadratic", "scale_quadratic_std", "scale_cubic",
                                                "scale_cubic_std")}
        for k, (f, cols) in enumerate(zip(tri.fits, tri.nonlin_col, strict=True)):
            for name, col in zip(("scale_quadratic", "scale_cubic"), cols, strict=True):
                if col >= 0:
                    terms[name][k] = f.beta[col]
                    terms[f"{name}_std"][k] = float(np.sqrt(max(f.beta_cov[col, col], 0.0)))
        out.update(terms)
    return out


def mean_model(
    p: dict[str, np.ndarray], t_s: np.ndarray, ref: np.ndarray, force: np.ndarray, dt: np.ndarray | None = None
) -> np.ndarray:
    """The fitted eq. (1) without noise: M ref + b_stat + b_drift exp(-t/T_c) (+ G force), and with ``dt``
    (T - T_ref per sample, K) the temperature terms of :mod:`station.fit.temperature_terms`."""
    lin = np.nan_to_num(ref) @ p["misalignment"].T
    out = lin + p["bias_static"]
    k_nl = p.get("scale_nonlinearity")
    if k_nl is not None and np.any(k_nl):
        out += k_nl * lin * np.abs(lin)  # y = u + k u|u| (the physics' scale nonlinearity)
    k2, k3 = p.get("scale_quadratic"), p.get("scale_cubic")
    if k2 is not None and np.any(k2):
        out += k2 * lin**2  # IEEE 952: y = u + k2 u^2 + k3 u^3
    if k3 is not None and np.any(k3):
        out += k3 * lin**3
    tc = p["correlation_time_s"]
    for k in range(3):
        if np.isfinite(tc[k]) and p["bias_drift"][k] != 0.0:
            out[:, k] += p["bias_drift"][k] * np.exp(-t_s / tc[k])
    if np.any(p["g_sensitivity"]):
        out += np.nan_to_num(force) @ p["g_sensitivity"].T
    if dt is not None:
        out += _temperature_terms(p, dt, ref)
    return out


def residual_allan(session: Session, residual: Rows | np.ndarray, keep: np.ndarray) -> AllanCoefficients:
    """IEEE 952 coefficients from the longest still segment's residual."""
    still = session.segments_of(Kind.REST) or session.segments_of(Kind.POSE)
    seg = max(still, key=len)
    x = residual[seg.start:seg.stop]
    k = keep[seg.start:seg.stop]
    x = np.where(k[:, None], x, np.nan)
    # replace outliers by the local mean: the Allan variance needs a gap-free record
    x = np.where(np.isnan(x), np.nanmean(x, axis=0), x)
    vals: dict[str, list[float]] = {n: [] for n in (
        "random_walk", "random_walk_std", "bias_instability", "bias_instability_std",
        "rate_random_walk", "rate_random_walk_std",
    )}
    for j in range(3):
        fit = allan.fit_ieee952(allan.overlapping_allan_deviation(x[:, j], session.sample_rate_hz))
        for name in vals:
            vals[name].append(float(getattr(fit, name)))
    return AllanCoefficients(**{n: np.array(v) for n, v in vals.items()})


def residual_figures(
    residual: Rows | np.ndarray, runs: list[tuple[int, int, int]], keep: np.ndarray
) -> ResidualFigures:
    rms_seg = {}
    for seg, a, b in runs:
        r = residual[a:b][keep[a:b]]
        rms_seg[str(seg)] = tuple(np.sqrt(np.mean(r**2, axis=0)).round(9).tolist())
    total, count = _sum_of_rows(r**2 for r in _kept_rows(residual, runs, keep))
    return ResidualFigures(rms=tuple(np.sqrt(total / count).round(9).tolist()), segments=rms_seg, samples=count)


def _sample_design(
    n: int, ref: np.ndarray | None, force: np.ndarray | None, *, nonlinearity: np.ndarray | None = None,
    dt: np.ndarray | None = None, order: int = 1,
) -> Rows:
    """The linear regressors of eq. (1) per sample: reference (if M is fitted here), 1, force (g-sensitivity);
    with ``nonlinearity`` (the triad's reference) the polynomial's regressors (a superset: ``ref_i^2``,
    ``ref_i^3``); with ``dt`` the temperature regressors the fit used up to ``order`` (a superset for the scale:
    every ``ref_i dT^j``).
    Made for the rows asked only (the goodness of fit reads them per segment)."""

    def rows(lo: int, hi: int) -> np.ndarray:
        cols = [np.nan_to_num(ref[lo:hi])] if ref is not None else []
        cols.append(np.ones((hi - lo, 1)))
        if force is not None:
            cols.append(np.nan_to_num(force[lo:hi]))
        design = np.column_stack(cols)
        if nonlinearity is not None:
            r = np.nan_to_num(nonlinearity[lo:hi])
            design = np.column_stack([design, r**2, r**3])
        if dt is not None:
            design = np.column_stack([design, temperature_columns(dt[lo:hi], None if ref is None else ref[lo:hi],
                                                                  order)])
        return design

    return Rows(n, rows)


def _residual(session: Session, data: np.ndarray, p: dict[str, np.ndarray], ref: np.ndarray,
              dt: np.ndarray | None) -> Rows:
    """``data`` minus the fitted mean model, (n, 3), made for the rows asked (each row's numbers are those of
    one pass over the whole recording): the quality figures and the goodness of fit read it per segment."""

    def rows(lo: int, hi: int) -> np.ndarray:
        return data[lo:hi] - mean_model(p, session.t_s[lo:hi], ref[lo:hi], session.ref_accel_mps2[lo:hi],
                                        None if dt is None else dt[lo:hi])

    return Rows(len(data), rows)


def _kept_rows(residual: np.ndarray | Rows, runs: list[tuple[int, int, int]], keep: np.ndarray
               ) -> Iterator[np.ndarray]:
    """The residual's kept samples of each run, in the order of the samples."""
    for _, a, b in sorted(runs, key=lambda r: r[1]):
        yield residual[a:b][keep[a:b]]


def _triad_residual(
    name: str, res: Rows, design: Rows, runs: list[tuple[int, int, int]], noise: NoiseEstimate,
    tri: TriadLinear, blocks: Blocks, scale: float, unit: str, reference_var: float = 0.0,
) -> TriadResidual:
    return TriadResidual(
        name=name, residual=res, design=design, runs=runs, keep=noise.keep, sigma=noise.sigma,
        drift_var=np.array([f.drift_noise**2 for f in tri.fits]), drift_tc_s=np.array([f.tc_s for f in tri.fits]),
        blocks=blocks, block_residual=np.column_stack([f.residual for f in tri.fits]), unit_scale=scale, unit=unit,
        reference_var=reference_var,
    )


def fit_session(session: Session, options: FitOptions | None = None) -> ParameterSet:
    """Fit the full parameter set of eq. (1) to a session recording.

    Raises :class:`station.kernel.errors.FitError` with a one-line reason when the recording
    cannot give a trustworthy result (see :mod:`station.fit.checks`).
    """
    # The linear algebra here is on ~100x100 matrices: BLAS threads only spin.
    with threadpool_limits(limits=1, user_api="blas"), numerics(f"fit of {session.serial!r}"):
        return _fit_session(session, options or FitOptions())


def _top(note: ThermalFit, triad: str) -> int:
    """The highest order fitted in a triad (bias or scale, any axis), at least 1."""
    o = note.orders.get(triad, {})
    return max([1, *o.get("bias", []), *o.get("scale", [])])


def _triad_polynomial(
    session: Session, triad: str, ref: np.ndarray, runs: list[tuple[int, int, int]], noise: NoiseEstimate,
    options: FitOptions, p0: dict[str, np.ndarray], tri0: TriadLinear, blocks0: Blocks, *,
    dt: np.ndarray | None, orders: tuple[list[int], list[int]] | None,
) -> tuple[dict[str, np.ndarray], TriadLinear, Blocks, dict[str, Any]]:
    """A triad refitted with the IEEE scale polynomial ``u + k2 u^2 + k3 u^3`` (see
    :attr:`FitOptions.scale_nonlinearity`) on the axes and terms its blocks identify
    (:func:`station.fit.scale_polynomial.identifiable_terms`: the gyro's rate steps, the accelerometer's poses).
    Two passes, the regressors' M^ from the previous one; a term is kept where its Wald statistic passes.
    Returns the triad's parameters, fits, blocks and a note (``status`` fitted / not_identifiable /
    not_significant; per axis the terms identifiable, kept and their z); the first three unchanged when no term
    is kept."""
    gyro = triad == "gyro"
    data = session.gyro_radps if gyro else session.accel_mps2
    g_sens = options.g_sensitivity and gyro
    m_hat = np.asarray(p0["misalignment"], dtype=float)
    use, base = identifiable_terms(blocks0, m_hat, options.nonlinearity_wald, triad)

    def refit(poly: Polynomial) -> tuple[dict[str, np.ndarray], tuple[TriadLinear, Blocks]]:
        if dt is None:
            tri, blocks = _fit_triad(session, data, ref, runs, noise, options, with_ref=True, g_sens=g_sens,
                                     triad=triad, nonlin_m=poly)
            return unpack_triad(tri), (tri, blocks)
        tri, blocks, coeff, _ = _fit_triad_thermal(
            session, data, ref, runs, noise, options, with_ref=True, g_sens=g_sens, triad=triad, dt=dt,
            m_hat=poly[0], orders=orders, nonlin_m=poly)
        return {**unpack_triad(tri), **coeff}, (tri, blocks)

    fitted, note = select_polynomial(refit, m_hat, use, base, options.nonlinearity_wald)
    if fitted is None:
        return p0, tri0, blocks0, note
    p, (tri, blocks) = fitted
    return p, tri, blocks, note


def _fit_session(session: Session, options: FitOptions) -> ParameterSet:
    gyro_method = check_session(session, min_pose_samples=options.min_pose_samples,
                                censored=options.censored_saturation)
    ts = 1.0 / session.sample_rate_hz

    # --- accelerometer: rest + poses -----------------------------------------
    a_runs = settled_runs(session, (Kind.REST, Kind.POSE), session.ref_accel_mps2)
    with numerics("accelerometer fit (rest and poses)"):
        a_noise = white_noise(session, session.accel_mps2, a_runs, options.outlier_sigma)
        a_tri, a_blocks = _fit_triad(session, session.accel_mps2, session.ref_accel_mps2, a_runs, a_noise, options,
                              with_ref=True, g_sens=False, triad="accel")
    a = unpack_triad(a_tri)

    # --- gyroscope: rest + poses + rate steps, or static + known angles --------
    if gyro_method == "rate":
        g_runs = settled_runs(session, (Kind.REST, Kind.POSE, Kind.RATE), session.ref_gyro_radps)
        g_ref = session.ref_gyro_radps
    else:
        static_ref = np.where(np.isnan(session.ref_gyro_radps), 0.0, session.ref_gyro_radps)
        g_runs = settled_runs(session, (Kind.REST, Kind.POSE), static_ref)
        g_ref = static_ref
    with numerics(f"gyroscope fit ({'rest, poses and rate steps' if gyro_method == 'rate' else 'rest and poses'})"):
        g_noise = white_noise(session, session.gyro_radps, g_runs, options.outlier_sigma)
        g_tri, g_blocks = _fit_triad(session, session.gyro_radps, g_ref, g_runs, g_noise, options,
                              with_ref=gyro_method == "rate", g_sens=options.g_sensitivity, triad="gyro")
    g = unpack_triad(g_tri)

    # --- temperature terms, when the recording's temperature course separates them from the warm-up ---
    course = assess_temperature(
        session, sorted(set(a_runs) | set(g_runs), key=lambda r: r[1]), mode=options.thermal,
        min_span_k=options.min_temperature_span_k, min_independent_k=options.min_temperature_independent_k,
        reference_degc=options.reference_temperature_degc,
    )
    if options.thermal == "require" and not course.fit:
        raise FitError(f"temperature terms required: {course.note.reason}")
    dt = course.dt
    thermal_note = course.note
    if dt is not None:
        with numerics("accelerometer fit with temperature terms"):
            a_tri, a_blocks, a_coeff, a_orders = _thermal_triad(
                session, session.accel_mps2, session.ref_accel_mps2, a_runs, a_noise, options, a_tri,
                with_ref=True, g_sens=False, triad="accel", dt=dt)
        with numerics("gyroscope fit with temperature terms"):
            g_tri, g_blocks, g_coeff, g_orders = _thermal_triad(
                session, session.gyro_radps, g_ref, g_runs, g_noise, options, g_tri,
                with_ref=gyro_method == "rate", g_sens=options.g_sensitivity, triad="gyro", dt=dt)
        a = {**unpack_triad(a_tri), **a_coeff}
        g = {**unpack_triad(g_tri), **g_coeff}
        thermal_note = replace(thermal_note, orders={
            "accel": {"bias": a_orders[0], "scale": a_orders[1]},
            "gyro": {"bias": g_orders[0], "scale": g_orders[1]},
        })
    nonlin_note: dict[str, Any] | None = None
    a_poly_note: dict[str, Any] | None = None
    if options.scale_nonlinearity != "off":
        with numerics("accelerometer fit with the scale polynomial"):
            a, a_tri, a_blocks, a_poly_note = _triad_polynomial(
                session, "accel", session.ref_accel_mps2, a_runs, a_noise, options, a, a_tri, a_blocks, dt=dt,
                orders=a_orders if dt is not None else None)
        if gyro_method != "rate":
            nonlin_note = no_rate_note(options.nonlinearity_wald)
        else:
            with numerics("gyroscope fit with the scale nonlinearity"):
                g, g_tri, g_blocks, nonlin_note = _triad_polynomial(
                    session, "gyro", g_ref, g_runs, g_noise, options, g, g_tri, g_blocks, dt=dt,
                    orders=g_orders if dt is not None else None)
    angle_report: dict[str, Any] = {}
    if gyro_method == "angle":
        bias_t = g["bias_static"] + np.zeros((len(session), 3))
        if dt is not None:
            bias_t += _temperature_terms(g, dt, None)
        for k in range(3):
            if np.isfinite(g["correlation_time_s"][k]) and g["bias_drift"][k] != 0:
                bias_t[:, k] += g["bias_drift"][k] * np.exp(-session.t_s / g["correlation_time_s"][k])
        if np.any(g["g_sensitivity"]):
            bias_t += np.nan_to_num(session.ref_accel_mps2) @ g["g_sensitivity"].T
        check_rotations(session, bias_t, g_noise.sigma)
        with numerics("known-angle gyro fit (angle.N moves)"):
            angle_fit = fit_known_angles(session, bias_t, g["bias_static_std"], g_noise.sigma)
        g["misalignment"], g["misalignment_std"] = angle_fit.misalignment, angle_fit.misalignment_std
        angle_report = angle_fit.report

    offset_note: TimeOffsetNote | None = None
    offset, offset_std = 0.0, 0.0
    if options.time_offset != "off":
        with numerics("time offset on the transitions"):
            offset_note, offset, offset_std = estimate_time_offset(
                session, lambda t, r, f, d: mean_model(g, t, r, f, d), g_noise.sigma, dt,
                wald=options.time_offset_wald)

    # --- residuals, noise figures and quality ----------------------------------
    a_res = _residual(session, session.accel_mps2, a, session.ref_accel_mps2, dt)
    g_res = _residual(session, session.gyro_radps, g, g_ref, dt)
    quality = FitQuality(
        accel=residual_figures(a_res, a_runs, a_noise.keep),
        gyro=residual_figures(g_res, g_runs, g_noise.keep),
        gyro_scale_method=gyro_method,
        outliers={"accel": tuple(a_noise.outliers.tolist()), "gyro": tuple(g_noise.outliers.tolist())},
        drift_likelihood_ratio={
            "accel": tuple(round(f.lr, 3) for f in a_tri.fits),
            "gyro": tuple(round(f.lr, 3) for f in g_tri.fits),
        },
        known_angle=angle_report or None,
        scale_nonlinearity=None if nonlin_note is None else NonlinearityNote.from_dict(nonlin_note),
        accel_scale_polynomial=None if a_poly_note is None else NonlinearityNote.from_dict(a_poly_note),
        time_offset=offset_note,
    )
    deg = float(np.degrees(1.0))
    a_design = _sample_design(len(session), session.ref_accel_mps2, None,
                              nonlinearity=session.ref_accel_mps2 if (np.any(a.get("scale_quadratic", 0.0))
                                                                      or np.any(a.get("scale_cubic", 0.0))) else None,
                              dt=dt, order=_top(thermal_note, "accel"))
    g_design = _sample_design(len(session), g_ref if gyro_method == "rate" else None,
                              session.ref_accel_mps2 if options.g_sensitivity else None,
                              nonlinearity=g_ref if (np.any(g.get("scale_quadratic", 0.0))
                                                     or np.any(g.get("scale_cubic", 0.0))) else None,
                              dt=dt, order=_top(thermal_note, "gyro"))
    verdict = goodness_of_fit(session, [
        _triad_residual("accel", a_res, a_design, a_runs, a_noise, a_tri, a_blocks, 1.0, "m/s^2",
                        (0.5 * (session.meta_float("reference_tolerance_mps2") or 0.0)) ** 2),
        _triad_residual("gyro", g_res, g_design, g_runs, g_noise, g_tri, g_blocks, deg, "deg/s"),
    ], angle_report or None)
    quality = replace(quality, goodness_of_fit=GoodnessOfFit.from_dict(verdict))

    def triad(
        p: dict[str, np.ndarray], noise: NoiseEstimate, res: Rows, runs: list[tuple[int, int, int]]
    ) -> TriadParams:
        squares, count = _sum_of_rows(r**2 for r in _kept_rows(res, runs, noise.keep))  # np.mean(res[mask]**2, 0)
        return TriadParams(
            noise_std=noise.sigma,
            noise_std_std=noise.sigma_std,
            allan=residual_allan(session, res, noise.keep),
            residual_rms=np.sqrt(squares / count),
            **p,
        )

    params = ParameterSet(
        serial=session.serial,
        sample_period_s=ts,
        moving_average_length=options.moving_average_length,
        accel=triad(a, a_noise, a_res, a_runs),
        gyro=triad(g, g_noise, g_res, g_runs),
        quality=quality,
        reference_temperature_degc=course.reference_degc if dt is not None else float("nan"),
        thermal=thermal_note,
        time_offset_s=offset,
        time_offset_std_s=offset_std,
        source={
            "software": f"station {__version__}",
            "samples": len(session),
            "duration_s": round(session.duration_s, 6),
            "sample_rate_hz": session.sample_rate_hz,
            **({"tc_prior_s": {k: [float(v[0]), float(v[1])] for k, v in options.tc_range_s.items()}}
               if options.tc_range_s else {}),
        },
    )
    return assess(params, float(session.t_s[-1]))


__all__ = ["FitOptions", "block_exp_mean", "fit_session", "mean_model"]
