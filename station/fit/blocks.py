"""Block means of settled samples: the sufficient statistics of the triad fit.

Within a block the rig reference is constant (a settled rest, pose or rate step)
and the drift ``exp(-t/T_c)`` varies little, so the least-squares problem over
all samples equals the problem over block means weighted by their counts (the
exponential is averaged exactly over each block, see :func:`block_exp_mean`).
This keeps the joint fit of eq. (1) over a whole session small and fast.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from station.kernel.errors import FitError


@dataclass(frozen=True, eq=False)
class Blocks:
    """Block means of one triad's samples.

    Attributes:
        t_s: block centre time since power-on (s), shape (m,).
        width_s: time spanned by the block's samples plus one sample period (s), (m,).
        count: samples in the block, (m,).
        y: mean measurement per axis (sensor unit), (m, 3).
        ref: mean rig reference (sensor unit), (m, 3).
        force: mean rig specific-force reference (m/s^2), (m, 3); for g-sensitivity.
        segment: segment index the block belongs to, (m,).
        extra: block means of the ``extra`` per-sample columns given to :func:`make_blocks`, (m, k);
            None when none were given (e.g. powers of the temperature for the thermal terms).
    """

    t_s: np.ndarray
    width_s: np.ndarray
    count: np.ndarray
    y: np.ndarray
    ref: np.ndarray
    force: np.ndarray
    segment: np.ndarray
    extra: np.ndarray | None = None

    def __len__(self) -> int:
        return int(self.t_s.shape[0])


#: Samples averaged per pass of :func:`make_blocks` (whole blocks; a longer block is one pass alone).
SPAN_SAMPLES = 1 << 18


def make_blocks(
    t_s: np.ndarray,
    y: np.ndarray,
    ref: np.ndarray,
    force: np.ndarray,
    keep: np.ndarray,
    runs: list[tuple[int, int, int]],
    sample_period_s: float,
    max_blocks: int,
    extra: np.ndarray | Callable[[int, int], np.ndarray] | None = None,
) -> Blocks:
    """Cut each run ``(segment, start, stop)`` into blocks and average the kept samples.

    The block length is chosen so that the whole session gives about ``max_blocks``
    blocks; every run gives at least one. ``keep`` masks out outliers. NaN in ``ref`` and
    ``force`` count as 0. ``extra``: per-sample columns (n, k), or a function giving the
    rows ``lo:hi`` of them (so that they are never all made at once).

    The runs do not overlap. The samples are read a few blocks at a time (about
    :data:`SPAN_SAMPLES`), so that no per-sample copy of the inputs is made; each block's sum
    is added up in sample order as one pass over all samples would (the same numbers).
    """
    total = sum(float(t_s[b - 1] - t_s[a]) + sample_period_s for _, a, b in runs)
    block_s = max(total / max_blocks, 20 * sample_period_s)
    bounds: list[tuple[int, int, int]] = []
    for seg, a, b in runs:
        dur = float(t_s[b - 1] - t_s[a]) + sample_period_s
        k = max(1, round(dur / block_s))
        edges = np.linspace(a, b, k + 1).round().astype(int)
        bounds.extend((seg, int(lo), int(hi)) for lo, hi in itertools.pairwise(edges) if hi > lo)
    starts = np.array([lo for _, lo, _ in bounds])
    stops = np.array([hi for _, _, hi in bounds])
    m = len(bounds)
    count = np.zeros(m)
    sums: dict[str, np.ndarray] = {}

    def add(name: str, i0: int, i1: int, lab: np.ndarray, v: np.ndarray) -> None:
        v = v.reshape(len(v), -1)
        if name not in sums:
            sums[name] = np.zeros((m, v.shape[1]))
        for j in range(v.shape[1]):
            sums[name][i0:i1, j] = np.bincount(lab, weights=v[:, j], minlength=i1 - i0)

    for i0, i1 in _spans(starts, stops):
        lo, hi = int(starts[i0:i1].min()), int(stops[i0:i1].max())
        label = np.full(hi - lo, -1, dtype=np.int64)
        for i in range(i0, i1):
            label[starts[i] - lo:stops[i] - lo] = i - i0
        sel = (label >= 0) & keep[lo:hi]
        lab = label[sel]
        count[i0:i1] = np.bincount(lab, minlength=i1 - i0)
        add("y", i0, i1, lab, np.asarray(y[lo:hi])[sel])
        add("ref", i0, i1, lab, np.nan_to_num(ref[lo:hi][sel]))
        add("force", i0, i1, lab, np.nan_to_num(force[lo:hi][sel]))
        if extra is not None:
            rows = extra(lo, hi) if callable(extra) else extra.reshape(len(t_s), -1)[lo:hi]
            add("extra", i0, i1, lab, np.asarray(rows, dtype=np.float64).reshape(hi - lo, -1)[sel])
    if np.any(count == 0):
        seg = bounds[int(np.flatnonzero(count == 0)[0])][0]
        raise FitError(f"segment {seg}: a block of it has no usable sample (every sample is an outlier)")

    def mean(name: str) -> np.ndarray:
        v = sums[name]
        return v[:, 0] / count if name == "y" and np.ndim(y) == 1 else v / count[:, None]

    t_first = t_s[starts]
    t_last = t_s[stops - 1]
    return Blocks(
        t_s=0.5 * (t_first + t_last),
        width_s=t_last - t_first + sample_period_s,
        count=count,
        y=mean("y"),
        ref=mean("ref"),
        force=mean("force"),
        segment=np.array([seg for seg, _, _ in bounds]),
        extra=None if extra is None else mean("extra"),
    )


def _spans(starts: np.ndarray, stops: np.ndarray) -> list[tuple[int, int]]:
    """Consecutive blocks grouped into passes of about :data:`SPAN_SAMPLES` samples: [(first, last + 1)]."""
    out: list[tuple[int, int]] = []
    i0 = 0
    for i in range(1, len(starts) + 1):
        if i == len(starts) or stops[i] - starts[i0] > SPAN_SAMPLES:
            out.append((i0, i))
            i0 = i
    return out


def block_exp_mean(t_s: np.ndarray, width_s: np.ndarray, tc_s: float | np.ndarray) -> np.ndarray:
    """Mean of ``exp(-t/T_c)`` over blocks centred at ``t_s`` of width ``width_s`` (s; arrays broadcast).

    For a block [t - h/2, t + h/2]: ``exp(-t/T_c) * sinh(x)/x`` with ``x = h/(2 T_c)``.
    """
    x = 0.5 * width_s / tc_s
    return np.exp(-t_s / tc_s) * _sinhc(x)


def power_on_gm_correlation(t_s: np.ndarray, dist_s: np.ndarray, tc_s: float) -> np.ndarray:
    """Correlation of eq. 3's Gauss-Markov drift noise started at 0 at power-on, between times ``t_s`` (s):
    ``exp(-|t_i - t_j|/T_c) - exp(-t_i/T_c) exp(-t_j/T_c)``, (m, m); ``dist_s`` is ``|t_i - t_j|`` (s).

    The power-on term is an outer product: one exponential per time, not per pair.
    """
    e = np.exp(-t_s / tc_s)
    k = np.exp(-dist_s / tc_s)
    k -= e[:, None] * e[None, :]
    return k


def _sinhc(x: np.ndarray) -> np.ndarray:
    """sinh(x)/x, accurate near 0."""
    small = np.abs(x) < 1e-4
    out = np.empty_like(x)
    xs = x[~small]
    out[~small] = np.sinh(xs) / xs
    out[small] = 1.0 + x[small] ** 2 / 6.0
    return out
