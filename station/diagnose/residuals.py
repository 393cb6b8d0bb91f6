"""Compare a recording with the fitted base model and locate where they disagree.

The base model is the paper's eq. (1) with the Gauss-Markov drift of eq. (3), fitted by
:func:`station.fit.calibrate.fit_session`. Its mean (``M x + b_stat + b_drift exp(-t/T_c)``)
is subtracted from every sample; what is left is cut into *blocks*: contiguous runs of
samples inside one segment (settled rest, pose and rate steps, and the rig's moves where
its reference is known). Block means are the data of the diagnosis: averaging shrinks the
white noise by ``sqrt(n)``, so an effect far below the noise of any single sample shows
up, while the drift and the correlated noise are handled by the block covariance in
:mod:`station.diagnose.selection`.

Units: SI (accelerometer m/s^2, gyroscope rad/s, time s, temperature K).
"""

from __future__ import annotations

import functools
import itertools
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from scipy.ndimage import uniform_filter1d

from station.fit.calibrate import FitOptions, fit_session, mean_model
from station.fit.goodness import Rows
from station.kernel.parameters import ParameterSet, TriadParams
from station.session.model import Kind, Session

SENSORS = ("accel", "gyro")
#: Block length in the rig's moves (s): short enough to keep the shape of a ramp or tumble.
MOVE_BLOCK_S = 0.5
#: Samples further than this many noise sigmas from their local mean are outliers.
OUTLIER_SIGMA = 6.0


@dataclass(frozen=True, eq=False)
class SensorData:
    """One triad's residual against the base model, per sample and per block.

    Attributes:
        sensor: ``accel`` or ``gyro``.
        params: the base fit of this triad.
        ref: rig reference used by the base model (m/s^2 or rad/s), NaN -> 0, (n, 3).
        u: ``M ref``, the modelled true input through the misalignment (n, 3): made when asked (a property),
            :meth:`u_rows` for some rows.
        residual: measurement minus base mean model, (n, 3): a :class:`station.fit.goodness.Rows` that makes the
            rows asked (``residual[a:b]``, ``residual[a:b, k]``; ``residual[:]`` the whole) from the measurement and
            the model, the same numbers as the whole array's rows (not kept: two (n, 3) arrays held through the
            whole diagnosis were the largest part of its memory after the session's); an array where a caller
            gives one.
        sigma: white-noise std per sample, (3,).
        keep: samples that are not outliers (n,).
        outlier_count: outliers per axis among the settled samples, (3,); settled_samples: their number.
        label: block index per sample, -1 outside any block, (n,).
        t_s, width_s, count: block centre time (s), span (s) and sample count, (m,).
        y: block-mean residual, (m, 3).
        segment, kind: segment index and :class:`Kind` code per block, (m,).
        tc_range_s: the sensor class's range of eq. 3's correlation time T_c (s), (low, high), that the
            diagnosis keeps the warm-up drift in; None: the recording alone decides T_c.
        extra_var: variance added to each block mean's white-noise variance, (m, 3), in the sensor's unit
            squared: known physics of unknown phase (a rig-free recording's horizontal Earth rate, whose
            heading each pose draws anew, :mod:`station.diagnose.rigfree_diagnosis`); None: none.
        censored: per sample, whether it lies in a segment censored from this triad's data (a saturated axis,
            :mod:`station.diagnose.censoring`; the segment has no reference for the triad); None: none censored.
    """

    sensor: str
    params: TriadParams
    ref: np.ndarray
    residual: Rows | np.ndarray
    sigma: np.ndarray
    keep: np.ndarray
    outlier_count: np.ndarray
    settled_samples: int
    label: np.ndarray
    t_s: np.ndarray
    width_s: np.ndarray
    count: np.ndarray
    y: np.ndarray
    segment: np.ndarray
    kind: np.ndarray
    tc_range_s: tuple[float, float] | None = None
    extra_var: np.ndarray | None = None
    censored: np.ndarray | None = None

    @property
    def u(self) -> np.ndarray:
        """``M ref`` (n, 3), made anew at each use (not kept: a long recording's (n, 3) arrays are what a diagnosis
        holds); :meth:`u_rows` for a piece of rows."""
        return self.u_rows(0, len(self.ref))

    def u_rows(self, lo: int, hi: int) -> np.ndarray:
        """Rows lo:hi of :attr:`u` (each row ``M ref_i``: the same numbers as the whole)."""
        return self.ref[lo:hi] @ np.nan_to_num(self.params.misalignment).T

    def residual_less(self, fitted: np.ndarray) -> Rows:
        """``residual - fitted`` (``fitted``: a per-sample signal, (n, 3)) as :class:`Rows`, made for the rows asked:
        no (n, 3) difference is held."""
        return Rows(len(self.label), lambda lo, hi: self.residual[lo:hi] - fitted[lo:hi])

    def clip_tc(self, tc_s: np.ndarray | float) -> np.ndarray:
        """``tc_s`` (s) clipped into :attr:`tc_range_s` (unchanged without a range)."""
        tc = np.asarray(tc_s, dtype=float)
        return tc if self.tc_range_s is None else np.clip(tc, *self.tc_range_s)

    @functools.cached_property
    def pieces(self) -> tuple[tuple[int, int], ...]:
        """Row ranges (lo, hi) covering the samples, about :data:`PIECE_ROWS` each, cut only where a block starts:
        every block lies in one piece, so block sums taken a piece at a time are those of one pass."""
        n = len(self.label)
        rows = np.flatnonzero(self.label >= 0)
        labels = self.label[rows]
        # blocks follow the samples' order (_blocks); otherwise one piece
        if n <= PIECE_ROWS or not len(rows) or np.any(np.diff(labels) < 0):
            return ((0, n),)
        starts = rows[np.flatnonzero(np.diff(labels, prepend=-1) != 0)]
        cuts = np.unique(starts[np.searchsorted(starts, np.arange(PIECE_ROWS, n, PIECE_ROWS)).clip(0, len(starts) - 1)])
        cuts = cuts[(cuts > 0) & (cuts < n)]
        edges = [0, *(int(c) for c in cuts), n]
        return tuple((lo, hi) for lo, hi in itertools.pairwise(edges) if hi > lo)

    def block_mean_of(self, rows: Callable[[int, int], np.ndarray]) -> np.ndarray:
        """:meth:`block_mean` of the per-sample values that ``rows(lo, hi)`` gives for the samples lo:hi, (hi - lo,
        ...), asked a piece at a time (:attr:`pieces`): the values of the whole recording are never held at once.

        Each block's kept samples are summed in sample order from zero (``np.bincount``), as one pass over the
        whole recording sums them (the same numbers bit for bit)."""
        m = len(self.t_s)
        out: np.ndarray | None = None
        shape: tuple[int, ...] = ()
        for lo, hi in self.pieces:
            v = np.asarray(rows(lo, hi), dtype=float)
            flat = v.reshape(hi - lo, -1)
            if out is None:
                shape = v.shape[1:]
                out = np.zeros((m, flat.shape[1]))
            lab = self.label[lo:hi] + 1  # bin 0: samples in no block
            for j in range(flat.shape[1]):
                out[:, j] += np.bincount(lab, weights=flat[:, j], minlength=m + 1)[1:]
        assert out is not None
        return (out / self.count[:, None]).reshape((m, *shape))

    def block_mean(self, values: np.ndarray) -> np.ndarray:
        """Mean of per-sample ``values`` (n, ...) over each block's kept samples, (m, ...), a piece of samples at a
        time (:meth:`block_mean_of`): no copy of ``values``."""
        return self.block_mean_of(lambda lo, hi: values[lo:hi])


#: Samples per piece of :meth:`SensorData.block_mean_of` (and of the candidates' regressors asked for a piece).
PIECE_ROWS = 1 << 16


@dataclass(frozen=True, eq=False)
class Baseline:
    """The base fit of a session and both triads' residuals.

    Attributes:
        session: the recording.
        params: the base parameter set (eq. 1 + eq. 3).
        d_temp: sensor temperature minus its power-on value (K), smoothed, NaN-free (zeros without
            a temperature channel), (n,).
        accel, gyro: :class:`SensorData`.
    """

    session: Session
    params: ParameterSet
    d_temp: np.ndarray
    accel: SensorData
    gyro: SensorData

    def sensor(self, name: str) -> SensorData:
        return self.accel if name == "accel" else self.gyro


def _triad_dict(p: TriadParams) -> dict[str, np.ndarray]:
    return {
        "misalignment": np.nan_to_num(p.misalignment), "bias_static": p.bias_static, "bias_drift": p.bias_drift,
        "correlation_time_s": p.correlation_time_s, "g_sensitivity": p.g_sensitivity,
    }


def _temperature(session: Session) -> np.ndarray:
    """Smoothed temperature rise since power-on (K); zeros without a temperature channel."""
    temp = np.asarray(session.temp_degc, dtype=float)
    if not np.isfinite(temp).any():
        return np.zeros(len(session))
    idx = np.arange(len(temp))
    ok = np.isfinite(temp)
    temp = np.interp(idx, idx[ok], temp[ok])
    window = max(3, round(5.0 * session.sample_rate_hz))  # 5 s: the temperature sensor's noise
    smooth = uniform_filter1d(temp, size=window, mode="nearest")
    return smooth - smooth[0]


def _blocks(session: Session, ref: np.ndarray, keep: np.ndarray, max_settled_blocks: int) -> np.ndarray:
    """Block label per sample (-1 outside): settled segments cut evenly, moves into ~0.5 s pieces."""
    fs = session.sample_rate_hz
    segs = [s for s in session.segments() if len(s) >= 10 and np.all(np.isfinite(ref[s.start:s.stop]))]
    settled = sum(len(s) for s in segs if s.kind != Kind.MOVE)
    settled_block = max(settled / max_settled_blocks, 20.0)
    move_block = max(MOVE_BLOCK_S * fs, 10.0)
    label = np.full(len(session), -1, dtype=np.int32)  # block indices (fewer than 2**31): 4 bytes a sample
    nxt = 0
    for s in segs:
        size = move_block if s.kind == Kind.MOVE else settled_block
        k = max(1, round(len(s) / size))
        edges = np.linspace(s.start, s.stop, k + 1).round().astype(int)
        for lo, hi in itertools.pairwise(edges):
            if np.count_nonzero(keep[lo:hi]) >= 5:
                label[lo:hi] = nxt
                nxt += 1
    label[~keep] = -1
    return label


def residual_rows(session: Session, p: TriadParams, data: np.ndarray, ref0: np.ndarray) -> Rows:
    """``data - mean model`` (eq. 1 + eq. 3 at ``p``) as :class:`Rows`: rows lo:hi are made from rows lo:hi of the
    measurement, the reference ``ref0`` (NaN-free) and the time, each row as the whole-recording computation makes
    it (the model is per sample)."""
    triad = _triad_dict(p)
    t, force = session.t_s, session.ref_accel_mps2
    return Rows(len(data), lambda lo, hi: data[lo:hi] - mean_model(triad, t[lo:hi], ref0[lo:hi], force[lo:hi]))


def _sensor_data(
    session: Session, name: str, p: TriadParams, data: np.ndarray, ref: np.ndarray, max_settled_blocks: int
) -> SensorData:
    ref0 = np.nan_to_num(ref) if np.isnan(ref).any() else ref  # a reference without NaN is not copied
    residual = residual_rows(session, p, data, ref0)
    sigma = np.maximum(np.asarray(p.noise_std, dtype=float), 1e-12)
    keep = np.ones(len(session), dtype=bool)
    outliers = np.zeros(3, dtype=int)
    settled_n = 0
    for s in session.segments():
        if len(s) < 10:
            continue
        x = residual[s.start:s.stop]
        local = uniform_filter1d(x, size=max(3, min(len(s), 101)), axis=0, mode="nearest")
        bad = np.abs(x - local) > OUTLIER_SIGMA * sigma
        keep[s.start:s.stop] &= ~bad.any(axis=1)
        if s.kind != Kind.MOVE and np.all(np.isfinite(ref[s.start:s.stop])):
            outliers += bad.sum(axis=0)
            settled_n += len(s)
    label = _blocks(session, ref, keep, max_settled_blocks)
    m = int(label.max()) + 1
    sel = label >= 0
    lab = label[sel]
    count = np.bincount(lab, minlength=m).astype(float)
    t = session.t_s
    first = np.full(m, np.inf)
    last = np.full(m, -np.inf)
    np.minimum.at(first, lab, t[sel])
    np.maximum.at(last, lab, t[sel])
    ts = 1.0 / session.sample_rate_hz
    seg_of = np.zeros(m, dtype=np.int64)
    kind_of = np.zeros(m, dtype=np.int64)
    seg_of[lab] = session.segment[sel]
    kind_of[lab] = session.kind[sel]
    sd = SensorData(
        sensor=name, params=p, ref=ref0, residual=residual, sigma=sigma, keep=keep, outlier_count=outliers,
        settled_samples=settled_n, label=label, t_s=0.5 * (first + last), width_s=last - first + ts, count=count,
        y=np.zeros((m, 3)), segment=seg_of, kind=kind_of,
    )
    # each block's residual summed in sample order from zero, a piece of samples at a time (as one pass sums it)
    return replace(sd, y=sd.block_mean_of(lambda lo, hi: residual[lo:hi]))


def fit_baseline(
    session: Session, *, max_settled_blocks: int = 150, warmup_tc_s: Mapping[str, tuple[float, float]] | None = None,
    censored: bool = False,
) -> Baseline:
    """Fit the base model to ``session`` and compute both triads' residuals and blocks.

    ``warmup_tc_s``: per sensor (``accel``, ``gyro``), the sensor class's range (low, high) of eq. 3's
    correlation time T_c in s (qualification data, e.g. a limits file's ``correlation_time_s``): the
    diagnosis then takes a warm-up that decays faster or slower than that for something other than eq. 3's
    drift. Sensors not in it, or None: the recording alone decides T_c.

    ``censored``: ``session`` is :func:`station.diagnose.censoring.censor`'s (saturated segments without their
    triad's reference): the base fit passes over them (``FitOptions.censored_saturation``).

    Raises :class:`station.kernel.errors.FitError` when the base fit refuses the recording, ValueError for a range
    that is not ``0 < low <= high``.
    """
    ranges: dict[str, tuple[float, float]] = {}
    for name, rng in (warmup_tc_s or {}).items():
        if name not in SENSORS:
            raise ValueError(f"warm-up T_c range for unknown sensor {name!r} (expected one of {SENSORS})")
        lo, hi = (float(v) for v in rng)
        if not (0.0 < lo <= hi and math.isfinite(hi)):
            raise ValueError(f"warm-up T_c range of the {name} must be 0 < low <= high (s), got {rng!r}")
        ranges[name] = (lo, hi)
    options = FitOptions(censored_saturation=True) if censored else None
    return baseline_from_params(session, fit_session(session, options), warmup_tc_s=ranges,
                                max_settled_blocks=max_settled_blocks)


def baseline_from_params(
    session: Session, params: ParameterSet, *, gyro_radps: np.ndarray | None = None,
    warmup_tc_s: Mapping[str, tuple[float, float]] | None = None, max_settled_blocks: int = 150,
) -> Baseline:
    """:func:`fit_baseline` with the base parameter set given (e.g. a rig-free fit's, whose references the
    caller wrote into ``session``); ``gyro_radps``: the gyro data to take the residual of (default the
    session's). ``warmup_tc_s`` as in :func:`fit_baseline` (not checked here)."""
    ranges = dict(warmup_tc_s or {})
    g_ref = session.ref_gyro_radps
    if params.quality.gyro_scale_method != "rate":
        g_ref = np.where(np.isnan(g_ref), 0.0, g_ref)
        static = np.isin(session.kind, [int(Kind.REST), int(Kind.POSE)])
        g_ref = np.where(static[:, None], g_ref, np.nan)
    accel = _sensor_data(session, "accel", params.accel, session.accel_mps2, session.ref_accel_mps2,
                         max_settled_blocks)
    gyro = _sensor_data(session, "gyro", params.gyro, session.gyro_radps if gyro_radps is None else gyro_radps,
                        g_ref, max_settled_blocks)
    accel = replace(accel, tc_range_s=ranges.get("accel"))
    gyro = replace(gyro, tc_range_s=ranges.get("gyro"))
    return Baseline(session=session, params=params, d_temp=_temperature(session), accel=accel, gyro=gyro)


def _corr(a: np.ndarray, b: np.ndarray, w: np.ndarray) -> float:
    """Weighted correlation of two block series (0 when either is constant)."""
    wa = a - np.average(a, weights=w)
    wb = b - np.average(b, weights=w)
    den = np.sqrt(np.average(wa**2, weights=w) * np.average(wb**2, weights=w))
    return float(np.average(wa * wb, weights=w) / den) if den > 0 else 0.0


@dataclass(frozen=True)
class WorstSegment:
    """A segment where the base model disagrees most: its index and mean chi^2 per block."""

    segment: int
    chi2_per_block: float


@dataclass(frozen=True)
class SensorLocation:
    """Where the base model disagrees, for one sensor (:func:`locate`): per kind of segment the normalized block
    residual (chi^2 per block per axis, 1 = white noise), the worst segments, per covariate the correlation of the
    block residual with it per axis, and the number of blocks."""

    chi2_per_block: Mapping[str, list[float]]
    worst_segments: tuple[WorstSegment, ...]
    correlation: Mapping[str, list[float]]
    blocks: int

    def to_json(self) -> dict[str, Any]:
        return {"chi2_per_block": dict(self.chi2_per_block),
                "worst_segments": [{"segment": w.segment, "chi2_per_block": w.chi2_per_block}
                                   for w in self.worst_segments],
                "correlation": dict(self.correlation), "blocks": self.blocks}

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> SensorLocation:
        return cls(d["chi2_per_block"], tuple(WorstSegment(w["segment"], w["chi2_per_block"])
                                              for w in d["worst_segments"]), d["correlation"], d["blocks"])


@dataclass(frozen=True)
class BaseFitNoise:
    """The base fit's residual RMS and noise std per axis, accelerometer in m/s^2, gyroscope in deg/s."""

    accel_residual_rms_mps2: list[float]
    gyro_residual_rms_dps: list[float]
    accel_noise_std_mps2: list[float]
    gyro_noise_std_dps: list[float]

    @classmethod
    def of(cls, baseline: Baseline) -> BaseFitNoise:
        p = baseline.params
        return cls(np.round(p.accel.residual_rms, 9).tolist(), np.round(np.degrees(p.gyro.residual_rms), 9).tolist(),
                   np.round(p.accel.noise_std, 9).tolist(), np.round(np.degrees(p.gyro.noise_std), 9).tolist())

    def to_json(self) -> dict[str, Any]:
        return {"accel_residual_rms_mps2": self.accel_residual_rms_mps2,
                "gyro_residual_rms_dps": self.gyro_residual_rms_dps,
                "accel_noise_std_mps2": self.accel_noise_std_mps2, "gyro_noise_std_dps": self.gyro_noise_std_dps}

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> BaseFitNoise:
        return cls(d["accel_residual_rms_mps2"], d["gyro_residual_rms_dps"], d["accel_noise_std_mps2"],
                   d["gyro_noise_std_dps"])


def warmup_ranges(baseline: Baseline) -> dict[str, tuple[float, float]] | None:
    """The sensor class's T_c range per sensor the base fit kept eq. 3's warm-up in (None: none given)."""
    return {s: sd.tc_range_s for s in SENSORS if (sd := baseline.sensor(s)).tc_range_s is not None} or None


def locate(baseline: Baseline) -> dict[str, SensorLocation]:
    """Where the base model disagrees: per sensor and axis, the normalized block residual
    (chi^2 per block, 1 = as expected from white noise) per kind of segment, the worst
    segments, and correlations of the block residual with temperature, rate, |rate|,
    rate sign, specific force and time.
    """
    out: dict[str, SensorLocation] = {}
    force, rate = baseline.session.ref_accel_mps2, baseline.session.ref_gyro_radps  # NaN -> 0 a piece at a time
    for name in SENSORS:
        sd = baseline.sensor(name)
        z = sd.y * np.sqrt(sd.count)[:, None] / sd.sigma  # block residual in block-noise sigmas
        per_kind: dict[str, list[float]] = {}
        for kind in Kind:
            sel = sd.kind == int(kind)
            if np.any(sel):
                per_kind[kind.label] = np.mean(z[sel] ** 2, axis=0).round(3).tolist()
        seg_chi = {}
        for seg in np.unique(sd.segment):
            sel = sd.segment == seg
            seg_chi[int(seg)] = float(np.mean(z[sel] ** 2))
        worst = sorted(seg_chi, key=lambda s: -seg_chi[s])[:5]
        variables = {
            "temperature": sd.block_mean(baseline.d_temp),
            "time": sd.t_s,
        }
        r_b = sd.block_mean_of(lambda lo, hi: np.nan_to_num(rate[lo:hi]))
        f_b = sd.block_mean_of(lambda lo, hi: np.nan_to_num(force[lo:hi]))
        corr: dict[str, list[float]] = {}
        w = sd.count
        for k in range(3):
            cols = dict(variables)
            cols.update({"rate": r_b[:, k], "abs_rate": np.abs(r_b[:, k]), "rate_sign": np.sign(r_b[:, k]),
                         "specific_force": f_b[:, k]})
            for vname, v in cols.items():
                corr.setdefault(vname, []).append(round(_corr(sd.y[:, k], v, w), 3))
        out[name] = SensorLocation(per_kind, tuple(WorstSegment(s, round(seg_chi[s], 3)) for s in worst), corr,
                                   len(sd.t_s))
    return out


__all__ = [
    "SENSORS", "BaseFitNoise", "Baseline", "SensorData", "SensorLocation", "WorstSegment", "baseline_from_params",
    "fit_baseline", "locate", "warmup_ranges",
]
