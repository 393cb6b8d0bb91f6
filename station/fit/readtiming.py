"""Stale per-axis reads of a gyro whose logger polls it on its own clock (read-timing model).

A logger that polls a sensor's data registers on its own timer, one axis after the other, and a sensor
that updates them at its own output data rate (ODR) on an independent oscillator: when the ODR is slower
than the read rate, the update instant drifts through the read cycle and each axis reads the same sample
twice once per beat period of ``P`` reads (``f_odr / f_read = (P - 1) / P``). The axes are read a little
apart in time, so each axis repeats at its own read: x at ``c_x + P j``, y and z a few reads later. Such
a repeat is harmless at rest but, during a hand move, it adds one extra sample period of that axis's rate
to the integrated rotation: on the OpenAXES recording (BMI160 read axis by axis over I2C, ``P`` ~ 130
reads, 3-15 stale reads per move) 0-2.4 deg per move, RMS 1.06 deg: the ~1 deg floor of the gravity
direction after a move (``benchmarks/compare_openaxes.py --gyro-study``, section 5b).

Model (the read index ``k``, the beat cycle ``j``)::

    k_i(j) = c_i + P j + Q j^2      (1)  stale read of axis i in cycle j (Q: the slow drift of the beat,
                                         e.g. the sensor's oscillator warming up)
    n_i(k) = k - #{j : k_i(j) <= k}  (2)  the sensor sample read by axis i at read k (j counted from the
                                         same cycle for every axis, so that the axes stay aligned)
    T_odr = T_read P_j / (P_j - 1),  P_j = P + 2 Q j   (3)  the sensor's sample period at cycle j

Estimation from the data alone (no pose, no reference): a *candidate* is a read whose axis value equals
the previous read's exactly while the axis is changing fast (``|y[k+1] - y[k-1]| > step_sigma * sigma``,
so a repeat by chance is improbable); the beat frequency is the one that concentrates the candidates'
phases most (Rayleigh statistic ``R``, searched over ``1/P_max .. 1/P_min``); its harmonics and
sub-harmonics (x 1/5 .. 5) concentrate them too, so (1) is fitted by least squares (outliers > 3 robust sigma,
at least 1 read, dropped) from each, and the beat is the grid that holds the most candidates less the stale
reads it predicts where the axis changes fast and the data show no repeat within 1 read.

**Selection rule** (on the repeats alone, never on the rotation fit's residuals): the model is used
when at least ``min_candidates`` (10) candidates are found, at least half of them lie within 1 read of
(1), and the Rayleigh p-value ``exp(-n R^2)``, times the number of independent frequencies searched, is
below ``p_max`` (1e-6). A recording without stale reads has few candidates and no concentration: not selected.
The stale read of each cycle is (1) rounded, moved to an exact repeat of that axis within 1 read if there
is one (the data locate it where the axis moves; the model where it does not).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = ["ReadTiming", "detect_stale_reads"]


@dataclass(frozen=True, eq=False)
class ReadTiming:
    """Result of :func:`detect_stale_reads`.

    Attributes:
        selected: whether the selection rule accepts the model (else every other field but the
            statistics is a placeholder and the reads are the sensor's samples).
        period_reads: P of eq. (1) at cycle 0 (reads per beat); period_std: its standard uncertainty.
        drift_reads: Q of eq. (1) (reads per cycle^2); drift_std: its standard uncertainty.
        offsets: c_i of eq. (1), (3,) (read index of axis i's stale read in cycle 0).
        candidates: exact repeats found while the axis changes fast; on_grid: those within 1 read of (1).
        rayleigh: R of the candidates' phases at the beat frequency; p_value: exp(-n R^2) times the
            number of independent frequencies searched.
        residual_reads: RMS of the kept candidates' residuals from (1) (reads).
        stale: (n, 3) bool, read k of axis i repeats the sample of read k - 1 (all False when not selected).
        lead: (3,) stale reads of each axis in the grid's cycles before the first read (eq. 2 counts them).
        reason: one line: why (not) selected.
    """

    selected: bool
    period_reads: float
    period_std: float
    drift_reads: float
    drift_std: float
    offsets: np.ndarray
    candidates: int
    on_grid: int
    rayleigh: float
    p_value: float
    residual_reads: float
    stale: np.ndarray
    reason: str
    lead: np.ndarray = field(default_factory=lambda: np.zeros(3, dtype=int))

    @classmethod
    def off(cls, n: int, reason: str) -> ReadTiming:
        """Not selected: the reads are the sensor's samples."""
        return _not_selected(n, reason)

    def sample_index(self) -> np.ndarray:
        """n_i(k) of eq. (2), (n, 3): the sensor sample each read of each axis holds."""
        return np.arange(len(self.stale))[:, None] - np.cumsum(self.stale, axis=0) - self.lead[None, :]

    def odr_ratio(self, k: float) -> float:
        """``T_odr / T_read`` at read ``k`` (eq. 3); 1 when not selected."""
        if not self.selected:
            return 1.0
        j = (k - float(np.mean(self.offsets))) / self.period_reads
        p = self.period_reads + 2.0 * self.drift_reads * j
        return p / (p - 1.0)

    def sensor_samples(self, data: np.ndarray, start: int, stop: int) -> np.ndarray:
        """The sensor's samples (m, 3) behind reads ``start:stop`` of ``data`` (n, 3): per axis the stale
        reads dropped and the axes aligned by sensor sample (eq. 2); the samples every axis covers."""
        seg = np.asarray(data[start:stop], dtype=float)
        if not self.selected:
            return seg.copy()
        n = self.sample_index()[start:stop]
        lo, hi = int(n[0].max()), int(n[-1].min())
        out = np.zeros((hi - lo + 1, 3))
        for i in range(3):
            sel = (n[:, i] >= lo) & (n[:, i] <= hi)
            out[n[sel, i] - lo, i] = seg[sel, i]  # a stale read writes its sample a second time: the same value
        return out


    def move_rates(self, data: np.ndarray, start: int, stop: int) -> np.ndarray:
        """The rates (m, 3) to integrate over reads ``start:stop`` with the *read* period as the step: the sensor's
        samples (:meth:`sensor_samples`) times ``T_odr / T_read`` at the move's middle (eq. 3; integrating
        ``w ratio`` with step ``T_read`` is integrating ``w`` with step ``T_odr``). The reads themselves when not
        selected."""
        return self.sensor_samples(data, start, stop) * self.odr_ratio(0.5 * (start + stop))


def _candidates(y: np.ndarray, sigma: np.ndarray, step_sigma: float) -> tuple[np.ndarray, np.ndarray]:
    """(read index k, axis i) of exact repeats ``y[k, i] == y[k-1, i]`` while ``|y[k+1, i] - y[k-1, i]|`` is large."""
    same = y[1:-1] == y[:-2]
    fast = np.abs(y[2:] - y[:-2]) > step_sigma * np.asarray(sigma)[None, :]
    k, i = np.nonzero(same & fast)
    return k + 1, i


def _rayleigh(k: np.ndarray, freq: np.ndarray) -> np.ndarray:
    """R = |mean exp(2 pi i f k)| for each frequency (cycles per read)."""
    out = np.empty(len(freq))
    for a in range(0, len(freq), 2048):
        ph = np.exp(2j * np.pi * np.outer(freq[a:a + 2048], k))
        out[a:a + 2048] = np.abs(ph.mean(axis=1))
    return out


def _not_selected(n: int, reason: str, candidates: int = 0, on_grid: int = 0, rayleigh: float = 0.0,
                  p_value: float = 1.0) -> ReadTiming:
    return ReadTiming(selected=False, period_reads=np.nan, period_std=np.nan, drift_reads=np.nan, drift_std=np.nan,
                      offsets=np.full(3, np.nan), candidates=candidates, on_grid=on_grid, rayleigh=rayleigh,
                      p_value=p_value, residual_reads=np.nan, stale=np.zeros((n, 3), dtype=bool), reason=reason)


def _fit_grid(k: np.ndarray, axis: np.ndarray, freq: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Eq. (1) by least squares to the candidates (read ``k`` of ``axis``), started from the beat ``freq``: the
    cycle numbers from the current fit, outliers (> 3 robust sigma, at least 1 read) dropped.
    Returns (x = (P, Q, c_x, c_y, c_z), its covariance (nan for an axis without candidates), residuals, kept)."""
    period = 1.0 / freq
    phase = float(np.angle(np.mean(np.exp(2j * np.pi * freq * k))) / (2.0 * np.pi)) % 1.0
    x = np.array([period, 0.0, *([phase * period] * 3)])  # j = 0 in the recording's first period
    keep = np.ones(len(k), dtype=bool)
    cov = np.full((5, 5), np.nan)
    res = np.zeros(len(k))
    for _ in range(10):
        j0 = (k - x[2:][axis]) / x[0]
        j = np.round(j0 - x[1] * j0**2 / x[0])  # eq. (1) inverted to first order in Q
        design = np.column_stack([j, j**2, axis == 0, axis == 1, axis == 2]).astype(float)
        cols = [0, 1] + [2 + a for a in range(3) if np.any(axis[keep] == a)]
        a = design[keep][:, cols]
        coef, *_ = np.linalg.lstsq(a, k[keep].astype(float), rcond=None)
        x_new = x.copy()
        x_new[cols] = coef
        res = k - design @ x_new
        scale = max(1.4826 * float(np.median(np.abs(res[keep] - np.median(res[keep])))), 0.3)
        keep_new = np.abs(res) <= max(3.0 * scale, 1.0)
        s2 = float(np.sum(res[keep] ** 2)) / max(int(keep.sum()) - len(cols), 1)
        cov = np.full((5, 5), np.nan)
        cov[np.ix_(cols, cols)] = s2 * np.linalg.pinv(a.T @ a)
        done = np.array_equal(keep_new, keep) and np.allclose(x_new, x)
        x, keep = x_new, keep_new
        if done or keep.sum() < 3:
            break
    seen = [a for a in range(3) if np.any(axis[keep] == a)] or [0, 1, 2]
    for i in range(3):  # an axis never seen takes the others' mean offset
        if i not in seen:
            x[2 + i] = float(np.mean(x[2:][seen]))
    return x, cov, res, keep


def _grid(x: np.ndarray, n: int) -> list[np.ndarray]:
    """Eq. (1) rounded: each axis's stale read in the same cycles, from one before the recording to one after
    (the same cycles for every axis, so that counting them keeps the axes aligned, eq. 2)."""
    js = np.arange(int(np.floor(-x[2:].max() / x[0])) - 2, int(np.ceil((n - x[2:].min()) / x[0])) + 3)
    return [np.round(x[2 + i] + x[0] * js + x[1] * js**2).astype(int) for i in range(3)]


def _misses(y: np.ndarray, fast: np.ndarray, grid: list[np.ndarray]) -> int:
    """Grid reads where the axis changes fast and no exact repeat lies within 1 read: stale reads the data deny."""
    n = len(y)
    count = 0
    for i, pos in enumerate(grid):
        for p in pos[(pos >= 1) & (pos < n)]:
            if fast[p, i] and not any(1 <= q < n and y[q, i] == y[q - 1, i] for q in (p - 1, p, p + 1)):
                count += 1
    return count


def detect_stale_reads(
    y: np.ndarray,
    sigma: np.ndarray,
    *,
    step_sigma: float = 10.0,
    period_range: tuple[float, float] = (8.0, 5000.0),
    min_candidates: int = 10,
    p_max: float = 1e-6,
) -> ReadTiming:
    """Find the beat of stale per-axis reads in a gyro record ``y`` (n, 3) with white noise ``sigma`` (3,)
    (see the module docstring for the model, the estimation and the selection rule)."""
    y = np.asarray(y, dtype=float)
    n = len(y)
    k, axis = _candidates(y, sigma, step_sigma)
    if len(k) < min_candidates:
        return _not_selected(n, f"{len(k)} exact repeats while the gyro turns (at least {min_candidates} needed): "
                                "no stale reads", len(k))
    kf = k.astype(float)
    span = float(k.max() - k.min() + 1)
    f_lo, f_hi = 1.0 / period_range[1], 1.0 / period_range[0]
    step = 1.0 / (8.0 * span)
    freq = np.arange(f_lo, f_hi, step)
    r = _rayleigh(kf, freq)
    f_best = float(freq[int(np.argmax(r))])
    # the beat or one of its harmonics / sub-harmonics: all concentrate the candidates' phases; the beat is the
    # grid that holds the most candidates less the stale reads it predicts where the axis turns fast and none is
    fast = np.zeros((n, 3), dtype=bool)
    fast[1:-1] = np.abs(y[2:] - y[:-2]) > step_sigma * np.asarray(sigma)[None, :]
    best: tuple[float, float, tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]] | None = None
    for ratio in (1 / 5, 1 / 4, 1 / 3, 1 / 2, 1.0, 2.0, 3.0, 4.0, 5.0):
        f0 = f_best * ratio
        if not f_lo <= f0 <= f_hi:
            continue
        loc = f0 + np.arange(-8, 9) * step
        f1 = float(loc[int(np.argmax(_rayleigh(kf, loc)))])
        fit = _fit_grid(kf, axis, f1)
        hits = int(np.sum(np.abs(fit[2]) <= 1.0))
        score = hits - _misses(y, fast, _grid(fit[0], n))
        if best is None or score > best[0]:
            best = (score, f1, fit)
    assert best is not None
    _, f_beat, (x, cov, res, keep) = best
    r_beat = float(_rayleigh(kf, np.array([f_beat]))[0])
    trials = max(1.0, (f_hi - f_lo) * span)
    p_value = float(min(1.0, np.exp(-len(k) * r_beat**2) * trials))
    on_grid = int(np.sum(np.abs(res) <= 1.0))
    if on_grid < 0.5 * len(k) or p_value > p_max:
        return _not_selected(n, f"{len(k)} exact repeats while the gyro turns, {on_grid} on a beat of "
                                f"{x[0]:.1f} reads (p = {p_value:.2g}): no periodic stale reads",
                             candidates=len(k), on_grid=on_grid, rayleigh=r_beat, p_value=p_value)
    # every axis's stale read in every cycle: eq. (1) rounded, moved to an exact repeat within 1 read
    stale = np.zeros((n, 3), dtype=bool)
    lead = np.zeros(3, dtype=int)
    for i, pos in enumerate(_grid(x, n)):
        for p in pos:
            q = next((q for q in (p, p - 1, p + 1) if 1 <= q < n and y[q, i] == y[q - 1, i]), p)
            if q < 1:
                lead[i] += 1  # a stale read of this cycle before the recording: counted, so the axes stay aligned
            elif q < n:
                stale[q, i] = True
    return ReadTiming(
        selected=True, period_reads=float(x[0]), period_std=float(np.sqrt(cov[0, 0])), drift_reads=float(x[1]),
        drift_std=float(np.sqrt(cov[1, 1])), offsets=x[2:].copy(), candidates=len(k), on_grid=on_grid,
        rayleigh=r_beat, p_value=p_value, residual_reads=float(np.sqrt(np.mean(res[keep] ** 2))), stale=stale,
        lead=lead,
        reason=f"{on_grid} of {len(k)} exact repeats while the gyro turns lie on a beat of {x[0]:.2f} reads "
               f"(p = {p_value:.2g}): stale per-axis reads, the moves integrated on the sensor's samples")
