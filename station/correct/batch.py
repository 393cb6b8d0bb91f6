"""Algorithm 1 over a whole record at once, vectorized; same output as the streaming loop.

Same conventions as :mod:`station.correct.streaming` (sample i since power-on sees
g_i = (1 - T_sampl/T_c)^i; the moving average, eq. (6), averages the samples available
during the first n - 1 samples; drift dropped where T_c is NaN or b_drift is 0).

Lines 5-8 of Algorithm 1 are linear, so they are reordered (exact algebra, different rounding):

    x_i = M^-1 x_MA,i = M^-1 (S_i - n b_stat - D_i) / n,   S_i = sum of the raw x~ over the window,

with D_i = sum over the window of b_drift g. For the Euler drift (eq. 3, line 4) g is
geometric, so D_i = b_drift G rho^(i - n + 1), G = sum_{m<n} rho^m, rho = 1 - T_sampl/T_c.
The first n - 1 samples (window not yet full) take a direct cumulative-sum path.

How it is made fast (2-core AMD EPYC VM, numpy 2.4 + scipy's OpenBLAS; see
benchmarks/bench_correct.py, where a sample is one six-channel time step):

* Chunks of up to 16384 samples (both triads together, buffers of shape (2, 3 rows));
  each chunk reads its n - 1 samples of history straight from the input arrays. Larger
  chunks would make OpenBLAS run the dgemm below multi-threaded (m n k > 262144), which
  is ~100x slower on a loaded 2-core machine.
* All elementwise work runs on flat interleaved (x, y, z, x, y, z, ...) buffers: numpy
  broadcasting of a (3,) vector over (n, 3) rows runs an inner loop of length 3 and is
  ~4x slower than a flat operation. Per-channel constants are repeated over a block of
  rows and broadcast block-wise.
* S is built by doubling, S_2w[i] = S_w[i] + S_w[i - w], then the binary digits of n
  (n = 40: five doublings and one add, the shortest addition chain for 40); the first
  doubling reads the raw input, so the record is never copied. A running cumsum is
  latency-bound (~4 ns a value, slower than the six adds) and its growing sum loses
  precision; here each output is a tree sum of exactly its n inputs, so a non-finite
  input spoils only the n outputs whose window holds it.
* The drift D is one table b_drift G rho^(a + m) over the chunk's rows m, made once per
  call and advanced one chunk with a single multiply by rho^chunk: two passes per chunk
  and no pow() per sample (relative agreement with the streaming product ~1e-14 after a
  day). Once every channel's D is below 1e-150 (SI units) it is no longer subtracted:
  its effect is far below rounding, and denormal arithmetic (slow on x86) stays out.
* Line 8 is one BLAS dgemm per chunk and triad with M^-1 / n precomputed, written
  straight into the output. The output rows are first filled with -M^-1 b_stat and dgemm
  adds onto them (beta = 1): that fill replaces the zero fill BLAS does for beta = 0, so
  the static bias costs no pass of its own.
* Fresh outputs are one (2, n, 3) allocation (two views): two separate 8.6 MB arrays,
  freed one after the other, are returned to the kernel by glibc's heap trimming and
  page-faulted in again on the next call (~4 ms for an hour at 100 Hz); one block stays
  in the heap. Pass ``out=`` to reuse arrays.
"""

from __future__ import annotations

import math
from dataclasses import replace
from functools import lru_cache

import numpy as np
from scipy.linalg.blas import dgemm

from station.correct.streaming import CorrectionConstants, compensate_extended, shift_block
from station.kernel.parameters import ParameterSet

DEFAULT_CHUNK_ROWS = 16384
_ROW_BLOCK = 64  # chunk rows are a multiple of this
# OpenBLAS runs dgemm multi-threaded once m n k > 262144 (here m n k = 9 chunk rows); on a loaded
# 2-core machine that is 100x slower, so chunks stay below it.
_MAX_CHUNK_ROWS = 16384
_MAX_BROADCAST_ROWS = 2048  # rows per broadcast block (per-channel constants repeated over rows)
_NEGLIGIBLE_DRIFT = 1e-150  # sum-domain drift (SI units) below which it is no longer subtracted


def _round_up(value: int, step: int) -> int:
    return -(-value // step) * step


def _repeat_rows(values: np.ndarray, rows: int) -> np.ndarray:
    """Per-channel values (k, 3) repeated over ``rows`` samples, interleaved: (k, 3 rows), by doubling copies."""
    out = np.empty((values.shape[0], 3 * rows))
    out[:, :3] = values
    w = 3
    while w < out.shape[1]:
        k = min(w, out.shape[1] - w)
        out[:, w : w + k] = out[:, :k]
        w *= 2
    return out


def _interleaved_powers(rho: np.ndarray, rows: int) -> np.ndarray:
    """rho^m for sample rows m = 0 .. rows - 1, interleaved: shape (2, 3 rows) from rho (2, 3).

    ``rows`` is a multiple of 64. The first 64 rows come from pow(); then blocks are
    doubled, rows [w, 2w) = rows [0, w) * rho^w, with rho^w repeated over one 64-row block
    and broadcast (a strided transpose of a whole (2, 3, rows) table is ~10x slower).
    Within a few ulp of pow() (at most log2(rows / 64) + 1 roundings).
    """
    out = np.empty((2, 3 * rows))
    seed = min(rows, _ROW_BLOCK)
    out[:, : 3 * seed] = (rho[:, None, :] ** np.arange(seed, dtype=np.float64)[None, :, None]).reshape(2, -1)
    steps = []
    w = seed
    while w < rows:
        steps.append(w)
        w *= 2
    if steps:
        exponents = np.array(steps, dtype=np.float64)[:, None, None]
        factors = _repeat_rows((rho[None] ** exponents).reshape(-1, 3), _ROW_BLOCK).reshape(len(steps), 2, 1, -1)
        for w, factor in zip(steps, factors, strict=True):
            k = min(w, rows - w)  # both multiples of 64
            src = out[:, : 3 * k].reshape(2, -1, 3 * _ROW_BLOCK)
            np.multiply(src, factor, out=out[:, 3 * w : 3 * (w + k)].reshape(src.shape))
    return out


def _as_samples(x: np.ndarray, name: str) -> np.ndarray:
    a = np.ascontiguousarray(x, dtype=np.float64)
    if a.ndim != 2 or a.shape[1] != 3:
        raise ValueError(f"{name} must have shape (n, 3), got {a.shape}")
    return a


def _drift_stop(rho: np.ndarray, coefficient: np.ndarray) -> float:
    """Smallest exponent a with |coefficient| rho^a < _NEGLIGIBLE_DRIFT for every channel.

    inf if a channel with a non-negligible coefficient never decays (rho = 1, T_c = inf).
    """
    stop = 0.0
    for r, c in zip(rho.ravel().tolist(), np.abs(coefficient).ravel().tolist(), strict=True):
        if c < _NEGLIGIBLE_DRIFT:
            continue
        if r >= 1.0:
            return math.inf
        # rho = 0 (T_c <= T_sampl, clamped): only exponent 0 carries drift
        need = 1.0 if r <= 0.0 else math.ceil(math.log(_NEGLIGIBLE_DRIFT / c) / math.log(r))
        stop = max(stop, need)
    return stop


class _WindowSumPlan:
    """Which doubling levels exist and where they live (see module doc).

    Level k (window 2^k) of a chunk holds, at buffer index j, the sum of the 2^k raw
    samples starting j rows after the chunk's first history row. Level 0 is the raw input
    itself; levels 1 .. top live in scratch buffers, reused once no longer needed. The
    window of n samples ending at a row is tiled by the levels of the binary digits of n,
    the widest ending at that row.
    """

    def __init__(self, n: int) -> None:
        self.top = n.bit_length() - 1  # highest level: window 2^top <= n
        self.keep = [k for k in range(self.top + 1) if n >> k & 1]  # binary digits of n
        assign: dict[int, int] = {}
        busy: set[int] = set()
        for k in range(1, self.top + 1):
            assign[k] = next(b for b in range(k + 1) if b not in busy)
            busy.add(assign[k])
            if k - 1 >= 1 and k - 1 not in self.keep:
                busy.discard(assign[k - 1])
        kept = {assign[k] for k in self.keep if k >= 1}
        self.sum_buffer = next(b for b in range(self.top + 2) if b not in kept)  # holds S (and S - D)
        self.assign = assign
        self.n_buffers = max([*assign.values(), self.sum_buffer]) + 1
        # parts of the window: (level, first buffer index relative to the chunk's first output row)
        self.parts: list[tuple[int, int]] = []
        width = 0
        for k in reversed(self.keep):
            width += 1 << k
            self.parts.append((k, n - width))


@lru_cache(maxsize=16)
def _window_sum_plan(n: int) -> _WindowSumPlan:
    """The (read-only) plan for window length n, shared between calls."""
    return _WindowSumPlan(n)


class _ChunkViews:
    """Scratch views for chunks of ``count`` output rows (built once per distinct count)."""

    def __init__(self, pipe: _Pipeline, count: int) -> None:
        plan = pipe.plan
        bufs = pipe.buffers
        rows = count + pipe.n - 1  # history + chunk
        self.level1 = bufs[plan.assign[1]][:, : 3 * rows - 3] if plan.top >= 1 else None
        self.doublings: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []  # S_2w = S_w[i] + S_w[i - w]
        length = rows - 1
        for k in range(2, plan.top + 1):
            w = 1 << (k - 1)
            src = bufs[plan.assign[k - 1]]
            length -= w
            self.doublings.append(
                (src[:, 3 * w : 3 * (length + w)], src[:, : 3 * length], bufs[plan.assign[k]][:, : 3 * length])
            )
        self.sums = bufs[plan.sum_buffer][:, : 3 * count]
        # window parts: buffer views (both triads) or, for level 0, the offset into the raw input
        self.parts = [(j, None if k == 0 else bufs[plan.assign[k]][:, 3 * j : 3 * (j + count)]) for k, j in plan.parts]
        self.from_buffers = all(v is not None for _, v in self.parts)
        self.drift = None if pipe.drift is None else pipe.drift[:, : 3 * count]
        # dgemm operands (S^T per triad, F-contiguous (3, count)) for S in the sum buffer or in a single part
        self.gemm_sums = [self.sums[t].reshape(-1, 3).T for t in (0, 1)]
        single = self.parts[0][1] if len(self.parts) == 1 else None
        self.gemm_single = None if single is None else [single[t].reshape(-1, 3).T for t in (0, 1)]


class _Pipeline:
    """Chunked Algorithm 1 for both triads; one instance per call (holds the scratch buffers)."""

    def __init__(self, c: CorrectionConstants, chunk_rows: int, start_index: int) -> None:
        n = c.ma_length
        self.n = n
        self.chunk = chunk = min(_round_up(max(chunk_rows, 1), _ROW_BLOCK), _MAX_CHUNK_ROWS)
        self.block = _ROW_BLOCK  # broadcast block rows: a power of two dividing the chunk
        while self.block < _MAX_BROADCAST_ROWS and chunk % (2 * self.block) == 0:
            self.block *= 2
        self.plan = _window_sum_plan(n)
        scratch = np.empty((self.plan.n_buffers, 2, 3 * (chunk + n - 1)))  # one allocation (see module doc)
        self.buffers = list(scratch)
        # line 8 as out^T = (M^-1 / n) S^T (BLAS column-major); eq. (6)'s 1/n folded in
        self.matrices = [np.asfortranarray(m / n) for m in (c.accel_inverse, c.gyro_inverse)]
        bias = np.stack([c.accel_inverse @ c.bias_static[:3], c.gyro_inverse @ c.bias_static[3:]])
        rho = c.rho.reshape(2, 3)
        drift = c.bias_drift.reshape(2, 3)
        self.drift: np.ndarray | None = None
        self.drift_stop = 0.0
        if not np.any(drift != 0):
            self.fill = _repeat_rows(-bias, self.block)  # -M^-1 b_stat over one block of rows, (2, 3 block)
        else:
            coefficient = drift * (rho[:, :, None] ** np.arange(n, dtype=np.float64)).sum(axis=-1)  # b_drift G
            self.drift_stop = _drift_stop(rho, coefficient)
            # per block of rows: the fill, rho^chunk (one chunk on), b_drift G rho^start_index
            blocks = _repeat_rows(np.concatenate([-bias, rho**chunk, coefficient * rho**start_index]), self.block)
            self.fill = blocks[0:2]
            self.advance = blocks[2:4, None, :]
            # table for the first chunk, whose row m has exponent start_index + m
            self.drift = _interleaved_powers(rho, chunk)
            stepped = self.drift.reshape(2, -1, blocks.shape[-1])
            np.multiply(stepped, blocks[4:6, None, :], out=stepped)
        self._views: dict[int, _ChunkViews] = {}

    def _fill(self, o: np.ndarray, t: int, count: int) -> None:
        """Rows [0, count) of the flat output o := -M^-1 b_stat (triad t)."""
        width = 3 * self.block
        full = count // self.block
        if full:
            np.copyto(o[: width * full].reshape(full, width), self.fill[t])
        if count > full * self.block:
            o[width * full : 3 * count] = self.fill[t, : 3 * count - width * full]

    def run(self, accel: np.ndarray, gyro: np.ndarray, out: tuple[np.ndarray, np.ndarray], start_index: int) -> None:
        """Rows [n - 1, total) of the record (the window is full there)."""
        n = self.n
        total = accel.shape[0]
        inputs = (accel.reshape(-1), gyro.reshape(-1))
        table = self.drift
        drift = table is not None
        for s in range(n - 1, total, self.chunk):  # chunk of output rows [s, e)
            e = min(s + self.chunk, total)
            count = e - s
            lo = s - n + 1  # first history row
            v = self._views.get(count)
            if v is None:
                v = self._views[count] = _ChunkViews(self, count)
            # line 7: S by doubling; level 1 straight from the raw input
            if v.level1 is not None:
                for t in (0, 1):
                    x = inputs[t]
                    np.add(x[3 * lo + 3 : 3 * e], x[3 * lo : 3 * e - 3], out=v.level1[t])
            for a, b, dst in v.doublings:
                np.add(a, b, out=dst)
            sums, gemm_b = v.sums, v.gemm_sums
            if v.gemm_single is not None:  # n a power of two: S is the top level itself
                top = v.parts[0][1]
                assert top is not None  # a single part is a buffer view (gemm_single is built from it)
                sums, gemm_b = top, v.gemm_single
            elif v.from_buffers:
                buffers = [p for _, p in v.parts if p is not None]  # all of them (from_buffers)
                np.add(buffers[0], buffers[1], out=sums)
                for p in buffers[2:]:
                    sums += p
            else:  # a raw-input part (odd n): per triad
                for t in (0, 1):
                    views = [inputs[t][3 * (lo + j) : 3 * (lo + j + count)] if p is None else p[t] for j, p in v.parts]
                    if len(views) == 1:
                        sums[t] = views[0]
                    else:
                        np.add(views[0], views[1], out=sums[t])
                        for p in views[2:]:
                            sums[t] += p
            # lines 4-6: the drift, summed over the window
            if drift and start_index + lo >= self.drift_stop:
                drift = False
            if drift and table is not None and v.drift is not None:
                if s > n - 1:  # next chunk: exponents grow by one chunk
                    stepped = table.reshape(2, -1, self.advance.shape[-1])
                    np.multiply(stepped, self.advance, out=stepped)
                np.subtract(sums, v.drift, out=v.sums)
                gemm_b = v.gemm_sums
            # line 8 and the static bias: out = -M^-1 b_stat + (M^-1 / n) (S - D)
            for t in (0, 1):
                o = out[t][s:e]
                self._fill(o.reshape(-1), t, count)
                ot = o.T
                res = dgemm(1.0, self.matrices[t], gemm_b[t], 1.0, ot, 0, 0, 1)
                if res is not ot:  # BLAS could not work in place (never for C-contiguous outputs)
                    np.copyto(ot, res)


def _startup(
    c: CorrectionConstants,
    accel: np.ndarray,
    gyro: np.ndarray,
    out: tuple[np.ndarray, np.ndarray],
    start_index: int,
    rows: int,
) -> None:
    """The first ``rows`` (< n) samples: eq. (6) over the samples available, lines 4-8 directly."""
    i = np.arange(rows)
    g = c.rho[None, :] ** (start_index + i)[:, None].astype(np.float64)  # line 4, g_i = rho^i
    x_temp = np.hstack([accel[:rows], gyro[:rows]]) - c.bias_static - g * c.bias_drift  # lines 5-6
    x_ma = np.cumsum(x_temp, axis=0) / (i + 1.0)[:, None]  # line 7
    out[0][:rows] = x_ma[:, :3] @ c.accel_inverse.T  # line 8
    out[1][:rows] = x_ma[:, 3:] @ c.gyro_inverse.T


def _check_out(o: np.ndarray, shape: tuple[int, ...], name: str) -> np.ndarray:
    if not isinstance(o, np.ndarray) or o.shape != shape or o.dtype != np.float64:
        raise ValueError(f"{name} must be a float64 array of shape {shape}")
    if not (o.flags.c_contiguous and o.flags.writeable):
        raise ValueError(f"{name} must be C-contiguous and writeable")
    return o


def correct_batch(
    accel_mps2: np.ndarray,
    gyro_radps: np.ndarray,
    params: ParameterSet,
    start_index: int = 0,
    *,
    chunk_rows: int = DEFAULT_CHUNK_ROWS,
    out: tuple[np.ndarray, np.ndarray] | None = None,
    temp_degc: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Algorithm 1 over a whole record.

    Args:
        accel_mps2: raw specific force, shape (n, 3), m/s^2.
        gyro_radps: raw angular rate, shape (n, 3), rad/s.
        params: the unit's parameter set.
        start_index: samples since power-on of the first row (0 when the record starts
            at power-on); g starts at (1 - T_sampl/T_c)^start_index and the moving
            average starts empty.
        chunk_rows: samples per processing chunk (performance only; rounded up to a
            multiple of 64, at most 16384).
        out: optional preallocated (accel, gyro) outputs, float64 C-contiguous (n, 3);
            they must not overlap the inputs. Saves the page faults of fresh arrays.
        temp_degc: the unit's temperature per sample (n,), degC; required when the set compensates
            temperature (line 6' of :mod:`station.correct.streaming`), ignored otherwise.

    Returns:
        (corrected specific force (n, 3) in m/s^2, corrected angular rate (n, 3) in rad/s),
        equal to :class:`~station.correct.streaming.StreamingCorrector` output to rounding.
        Fresh outputs are two views of one (2, n, 3) array.
    """
    a = _as_samples(accel_mps2, "accel_mps2")
    w = _as_samples(gyro_radps, "gyro_radps")
    if a.shape != w.shape:
        raise ValueError(f"accel and gyro must have the same shape, got {a.shape} and {w.shape}")
    if int(start_index) != start_index or start_index < 0:
        raise ValueError(f"start_index must be a non-negative integer, got {start_index!r}")
    start_index = int(start_index)
    c = CorrectionConstants.from_params(params)
    total = a.shape[0]
    if c.shift[0]:  # line 0: the raw input onto the rig's time (the first row held before itself)
        x = shift_block(c, np.hstack([a, w]))
        a, w = np.ascontiguousarray(x[:, :3]), np.ascontiguousarray(x[:, 3:])
    if c.extended:
        # line 6' is per sample and not linear: lines 4-6' directly (g_i = rho^i by pow, within rounding of the
        # streaming product), then lines 7-8 by the pipeline below with zero bias and no drift
        if c.uses_temperature:
            if temp_degc is None:
                raise ValueError("the parameter set compensates temperature: correct_batch needs temp_degc")
            if np.shape(temp_degc) != (total,):
                raise ValueError(f"temp_degc must have shape ({total},), got {np.shape(temp_degc)}")
        expo = (start_index + np.arange(total, dtype=np.float64))[:, None]
        g = np.where(c.bias_drift != 0, c.rho ** expo, 0.0)
        v = np.hstack([a, w]) - g * c.bias_drift - c.bias_static
        x = compensate_extended(c, v, temp_degc)
        a, w = np.ascontiguousarray(x[:, :3]), np.ascontiguousarray(x[:, 3:])
        c = replace(c, rho=np.ones(6), bias_drift=np.zeros(6), bias_static=np.zeros(6))
    if out is None:
        block = np.empty((2, total, 3))
        outputs = (block[0], block[1])
    else:
        outputs = (_check_out(out[0], a.shape, "out[0]"), _check_out(out[1], w.shape, "out[1]"))
        if any(np.may_share_memory(o, x) for o in outputs for x in (a, w)) or np.may_share_memory(*outputs):
            raise ValueError("out arrays must not overlap each other or the inputs (chunks read n - 1 rows back)")
    head = min(c.ma_length - 1, total)
    if head:
        _startup(c, a, w, outputs, start_index, head)
    if total > head:
        _Pipeline(c, min(chunk_rows, total - head), start_index).run(a, w, outputs, start_index)
    return outputs
