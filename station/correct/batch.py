"""Algorithm 1 over a whole record at once, vectorized; same output as the streaming loop.

Same conventions as :mod:`station.correct.streaming` (sample i since power-on sees
g_i = (1 - T_sampl/T_c)^i; the moving average, eq. (6), averages the samples available
during the first n - 1 samples; drift dropped where T_c is NaN or b_drift is 0).

How it is made fast (measured on the 2-core dev machine; see benchmarks/bench_correct.py):

* Chunks of a few thousand samples (both triads together, buffers of shape (2, 3 rows))
  keep every intermediate in the CPU cache; each chunk carries n - 1 samples of history.
* All elementwise work runs on flat interleaved (x, y, z, x, y, z, ...) buffers: numpy
  broadcasting of a (3,) vector over (n, 3) rows runs an inner loop of length 3 and is
  ~4x slower than a flat operation.
* g is not evaluated with exp() per sample (numpy's float64 exp is not vectorized on this
  CPU, 7-11 ns a value): a table b_drift * rho^m over the chunk's rows is made once per
  call and scaled per chunk by rho^a0 (relative agreement with the streaming product
  ~2e-14 after an hour). Once rho^a0 underflows the drift term is exactly 0.
* The moving-average sum is built by doubling, S_2w[i] = S_w[i] + S_w[i - w], then the
  binary digits of n (n = 40: five doublings and one add). A running cumsum is
  latency-bound (~4 ns a value, slower than the six adds) and its growing sum loses
  precision; here each output is a tree sum of exactly its n inputs, so a non-finite
  input spoils only the n outputs whose window holds it.
* The solve is one BLAS matmul per chunk and triad with M^-1 / n precomputed (~2x
  faster than explicit column arithmetic on flat buffers, ~10x faster than broadcasting).
* Fresh output arrays cost page faults (~5 ms for an hour); pass ``out=`` to reuse them.
"""

from __future__ import annotations

import numpy as np

from station.correct.streaming import CorrectionConstants
from station.fit.params import ParameterSet

DEFAULT_CHUNK_ROWS = 8192
_ROW_BLOCK = 64  # chunk rows are a multiple of this, so (rows, 3) can be viewed as (rows/64, 192)


def _round_up(value: int, step: int) -> int:
    return -(-value // step) * step


def _powers(rho: np.ndarray, count: int) -> np.ndarray:
    """rho^m for m = 0 .. count - 1 along a new last axis: shape (*rho.shape, count).

    Built by doubling (entries [w, 2w) = entries [0, w) * rho^w, rho^w from pow()): much
    faster than np.power and within a few ulp of it (at most log2(count) + 1 roundings).
    """
    out = np.empty((*rho.shape, count))
    out[..., 0] = 1.0
    w = 1
    while w < count:
        k = min(w, count - w)
        np.multiply(out[..., :k], (rho**w)[..., None], out=out[..., w : w + k])
        w *= 2
    return out


def _interleave(values: np.ndarray, rows: int) -> np.ndarray:
    """(2, 3) per-channel values repeated over ``rows`` samples: shape (2, 3 * rows), by doubling copies."""
    out = np.empty((values.shape[0], 3 * rows))
    out[:, :3] = values
    w = 3
    while w < out.shape[1]:
        k = min(w, out.shape[1] - w)
        out[:, w : w + k] = out[:, :k]
        w *= 2
    return out


def _as_samples(x: np.ndarray, name: str) -> np.ndarray:
    a = np.ascontiguousarray(x, dtype=np.float64)
    if a.ndim != 2 or a.shape[1] != 3:
        raise ValueError(f"{name} must have shape (n, 3), got {a.shape}")
    return a


class _WindowSumPlan:
    """Sum of the last n rows of flat interleaved buffers, by doubling (see module doc).

    Buffers have shape (2, 3 * rows): one row per triad, samples interleaved (x, y, z).
    ``run(buffers, rows, out_rows)`` reads P_0 (the values to average) from
    ``buffers[0]`` and returns a (2, 3 * out_rows) view holding, for each of the last
    ``out_rows`` samples, the sum of the n samples ending there. Level k of the doubling
    (window 2^k) lives in buffer ``assign[k]``; buffers are reused once no longer needed.
    """

    def __init__(self, n: int) -> None:
        self.top = n.bit_length() - 1  # highest level: window 2^top <= n
        self.keep = [k for k in range(self.top + 1) if n >> k & 1]  # binary digits of n
        assign = {0: 0}
        busy = {0}
        for k in range(1, self.top + 1):
            assign[k] = next(b for b in range(k + 2) if b not in busy)
            busy.add(assign[k])
            if k - 1 not in self.keep:
                busy.discard(assign[k - 1])
        kept = {assign[k] for k in self.keep}
        self.out_buffer = next(b for b in range(self.top + 3) if b not in kept)
        self.assign = assign
        self.n_buffers = max(max(assign.values()), self.out_buffer) + 1

    def run(self, buffers: list[np.ndarray], rows: int, out_rows: int) -> np.ndarray:
        lengths = [rows]
        for k in range(1, self.top + 1):  # S_2w[i] = S_w[i] + S_w[i - w]
            w = 1 << (k - 1)
            src = buffers[self.assign[k - 1]][:, : 3 * lengths[-1]]
            lengths.append(lengths[-1] - w)
            np.add(src[:, 3 * w :], src[:, : -3 * w], out=buffers[self.assign[k]][:, : 3 * lengths[-1]])
        # tile the window [i - n + 1, i] with the kept levels, the widest ending at i
        parts = []
        offset = 0
        for k in reversed(self.keep):
            stop = lengths[k] - offset
            parts.append(buffers[self.assign[k]][:, 3 * (stop - out_rows) : 3 * stop])
            offset += 1 << k
        if len(parts) == 1:
            return parts[0]
        out = buffers[self.out_buffer][:, : 3 * out_rows]
        np.add(parts[0], parts[1], out=out)
        for p in parts[2:]:
            out += p
        return out


class _Pipeline:
    """Chunked Algorithm 1 for both triads; one instance per call (holds the scratch buffers)."""

    def __init__(self, c: CorrectionConstants, chunk_rows: int) -> None:
        n = c.ma_length
        self.n = n
        self.history = _round_up(n - 1, _ROW_BLOCK)  # rows of history in front of each chunk
        self.chunk = _round_up(max(chunk_rows, 1), _ROW_BLOCK)
        rows = self.history + self.chunk
        self.rows = rows
        self.rho = c.rho.reshape(2, 3)
        drift = c.bias_drift.reshape(2, 3)
        self.bias = _interleave(c.bias_static.reshape(2, 3), rows)  # b_stat, interleaved, (2, 3 rows)
        self.bias_block = self.bias[:, : 3 * _ROW_BLOCK]  # the same for whole 64-row blocks
        self.has_drift = bool(np.any(drift != 0))
        if self.has_drift:  # table b_drift * rho^m, m = buffer row
            table = _powers(self.rho, rows)  # (2, 3, rows)
            table *= drift[:, :, None]
            self.drift = np.ascontiguousarray(table.transpose(0, 2, 1)).reshape(2, 3 * rows)
            self.scale = np.empty((2, 1, 3 * _ROW_BLOCK))
        # x = M^-1 x_MA per row, as rows @ (M^-1)^T; 1/n of eq. (6) folded in
        self.matrices = (np.ascontiguousarray(c.accel_inverse.T / n), np.ascontiguousarray(c.gyro_inverse.T / n))
        self.plan = _WindowSumPlan(n)
        self.buffers = [np.empty((2, 3 * rows)) for _ in range(max(2, self.plan.n_buffers))]
        self.scratch = self.buffers[1]  # free until the window sums run

    def _subtract_drift(self, valid: np.ndarray, first_sample: int, r0: int, r1: int, rows: int) -> None:
        """valid -= b_drift * g for buffer rows [r0, r1), g = rho^(first_sample + row - r0), lines 4-5."""
        a0 = first_sample - r0  # absolute sample index of buffer row 0
        if a0 < 0:  # first chunk, near power-on: the table's rows are the samples
            valid -= self.drift[:, 3 * first_sample : 3 * (first_sample + r1 - r0)]
            return
        factor = self.rho**a0  # rho^a0 per channel, exactly 0 once it underflows
        if not factor.any():
            return
        self.scale.reshape(2, _ROW_BLOCK, 3)[...] = factor[:, None, :]
        blocks = rows // _ROW_BLOCK
        width = 3 * _ROW_BLOCK
        np.multiply(
            self.drift.reshape(2, -1, width)[:, :blocks],
            self.scale,
            out=self.scratch.reshape(2, -1, width)[:, :blocks],
        )
        valid -= self.scratch[:, 3 * r0 : 3 * r1]

    def run(self, accel: np.ndarray, gyro: np.ndarray, out: tuple[np.ndarray, np.ndarray], start_index: int) -> None:
        total = accel.shape[0]
        inputs = (accel.reshape(-1), gyro.reshape(-1))
        u = self.buffers[0]
        h = self.history
        for s in range(0, total, self.chunk):
            e = min(s + self.chunk, total)
            lo = s - h  # record sample in buffer row 0 (negative in the first chunk)
            r0 = max(0, -lo)  # first buffer row inside the record
            r1 = e - lo  # one past the last
            rows = _round_up(r1, _ROW_BLOCK)
            if r0:
                u[:, : 3 * r0] = 0.0  # before the record: nothing to average
            valid = u[:, 3 * r0 : 3 * r1]
            aligned = r0 == 0 and r1 % _ROW_BLOCK == 0
            for t in (0, 1):  # line 6, static part
                x = inputs[t][3 * (lo + r0) : 3 * e]
                if aligned:  # broadcast one block of b_stat: keeps the table out of the cache
                    width = 3 * _ROW_BLOCK
                    np.subtract(x.reshape(-1, width), self.bias_block[t], out=valid[t].reshape(-1, width))
                else:
                    np.subtract(x, self.bias[t, 3 * r0 : 3 * r1], out=valid[t])
            if self.has_drift:  # lines 4-6, drifting part
                self._subtract_drift(valid, start_index + lo + r0, r0, r1, rows)
            sums = self.plan.run(self.buffers, rows, rows - h)  # line 7: n x_MA, eq. (6)
            for t in (0, 1):  # line 8
                np.matmul(sums[t, : 3 * (e - s)].reshape(-1, 3), self.matrices[t], out=out[t][s:e])
        startup = min(self.n - 1, total)
        if startup > 0:  # eq. (6) over the samples available: divide by i + 1, not n
            factor = (self.n / np.arange(1, startup + 1, dtype=np.float64))[:, None]
            for o in out:
                o[:startup] *= factor


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
) -> tuple[np.ndarray, np.ndarray]:
    """Algorithm 1 over a whole record.

    Args:
        accel_mps2: raw specific force, shape (n, 3), m/s^2.
        gyro_radps: raw angular rate, shape (n, 3), rad/s.
        params: the unit's parameter set.
        start_index: samples since power-on of the first row (0 when the record starts
            at power-on); g starts at (1 - T_sampl/T_c)^start_index and the moving
            average starts empty.
        chunk_rows: samples per processing chunk (performance only; rounded up to 64).
        out: optional preallocated (accel, gyro) outputs, float64 C-contiguous (n, 3);
            they must not overlap the inputs. Saves the page faults of fresh arrays.

    Returns:
        (corrected specific force (n, 3) in m/s^2, corrected angular rate (n, 3) in rad/s),
        equal to :class:`~station.correct.streaming.StreamingCorrector` output to rounding.
    """
    a = _as_samples(accel_mps2, "accel_mps2")
    w = _as_samples(gyro_radps, "gyro_radps")
    if a.shape != w.shape:
        raise ValueError(f"accel and gyro must have the same shape, got {a.shape} and {w.shape}")
    if int(start_index) != start_index or start_index < 0:
        raise ValueError(f"start_index must be a non-negative integer, got {start_index!r}")
    c = CorrectionConstants.from_params(params)
    if out is None:
        outputs = (np.empty_like(a), np.empty_like(w))
    else:
        outputs = (_check_out(out[0], a.shape, "out[0]"), _check_out(out[1], w.shape, "out[1]"))
        if any(np.may_share_memory(o, x) for o in outputs for x in (a, w)) or np.may_share_memory(*outputs):
            raise ValueError("out arrays must not overlap each other or the inputs (chunks read n - 1 rows back)")
    if a.shape[0]:
        _Pipeline(c, min(chunk_rows, a.shape[0])).run(a, w, outputs, int(start_index))
    return outputs
