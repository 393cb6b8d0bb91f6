"""Algorithm 1 throughput: vectorized batch vs the streaming loop vs a naive numpy-per-sample loop.

Run: /work/venv/bin/python benchmarks/bench_correct.py [--runs 15] [--sweep]

A "sample" is one time step of Algorithm 1: six channels, an accelerometer triad and a
gyroscope triad read at the same instant (the j = 1..6 loop of the paper). Record: 1 hour at
100 Hz (360 000 samples), paper-like parameters, n = 40.
Prints a table (median of several runs, wall clock and this thread's CPU time; on a shared
machine the CPU time is the steadier figure) and the largest |batch - streaming| over the hour.
"""

from __future__ import annotations

import argparse
import math
import os
import statistics
import time

import numpy as np

from station.correct import StreamingCorrector, correct_batch
from station.correct.batch import DEFAULT_CHUNK_ROWS
from station.kernel.parameters import AllanCoefficients, ParameterSet, TriadParams

TS = 0.01
HOUR = 360_000
DEG = math.pi / 180.0


def _triad(m: np.ndarray, b_stat: list[float], b_drift: list[float], tc: list[float]) -> TriadParams:
    z = np.zeros(3)
    return TriadParams(
        misalignment=m, misalignment_std=np.zeros((3, 3)), bias_static=b_stat, bias_static_std=z,
        bias_drift=b_drift, bias_drift_std=z, correlation_time_s=tc, correlation_time_s_std=z,
        drift_noise=z, drift_noise_std=z, noise_std=z, noise_std_std=z,
        allan=AllanCoefficients(z, z, z, z, z, z), residual_rms=z,
    )  # fmt: skip


def make_params() -> ParameterSet:
    """Table 1 of the paper, mid-range values."""
    m_a = np.array([[1.012, -0.021, 0.015], [0.018, 0.998, -0.030], [-0.011, 0.020, 1.019]])
    m_g = np.array([[0.985, 0.001, -0.0008], [0.0005, 1.002, 0.001], [-0.001, 0.0007, 0.97]])
    return ParameterSet(
        serial="BENCH",
        sample_period_s=TS,
        moving_average_length=40,
        accel=_triad(m_a, [-0.17, 0.026, 0.05], [0.018, -0.002, 0.01], [50.0, 100.0, 167.0]),
        gyro=_triad(m_g, [-0.726 * DEG, 2.739 * DEG, 1.0 * DEG], [0.347 * DEG, -0.115 * DEG, 0.2 * DEG],
                    [1030.0, 2000.0, 3760.0]),
    )  # fmt: skip


def make_record(count: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    t = np.arange(count) * TS
    accel = np.column_stack([0.5 * np.sin(0.3 * t), -0.3 * np.cos(0.11 * t), 9.81 + 0.0 * t])
    gyro = np.column_stack([0.2 * np.sin(0.05 * t), 0.0 * t, -0.4 * np.cos(0.02 * t)])
    return accel + rng.normal(0, 0.02, (count, 3)), gyro + rng.normal(0, 0.012 * DEG, (count, 3))


class NaiveCorrector:
    """The obvious per-sample implementation: numpy arrays and np.linalg.solve every sample."""

    def __init__(self, params: ParameterSet) -> None:
        tc = np.concatenate([params.accel.correlation_time_s, params.gyro.correlation_time_s])
        self.rho = 1.0 - params.sample_period_s / tc
        self.b_drift = np.concatenate([params.accel.bias_drift, params.gyro.bias_drift])
        self.b_stat = np.concatenate([params.accel.bias_static, params.gyro.bias_static])
        self.m_a = np.asarray(params.accel.misalignment)
        self.m_g = np.asarray(params.gyro.misalignment)
        self.n = params.moving_average_length
        self.g = np.ones(6)
        self.window: list[np.ndarray] = []

    def step(self, accel: np.ndarray, gyro: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        x = np.concatenate([accel, gyro])
        x_temp = x - self.g * self.b_drift - self.b_stat
        self.g = self.g * self.rho
        self.window.append(x_temp)
        if len(self.window) > self.n:
            self.window.pop(0)
        x_ma = np.mean(self.window, axis=0)
        return np.linalg.solve(self.m_a, x_ma[:3]), np.linalg.solve(self.m_g, x_ma[3:])


def _times(fn, runs: int, cpu: list[float] | None = None) -> list[float]:
    """Wall-clock seconds per call; this thread's CPU seconds appended to ``cpu`` if given."""
    times = []
    for _ in range(runs):
        c0 = time.thread_time()
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
        if cpu is not None:
            cpu.append(time.thread_time() - c0)
    return times


def _cpu_model() -> str:
    try:
        with open("/proc/cpuinfo", encoding="ascii", errors="replace") as f:
            for line in f:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return "unknown CPU"


def _median_time(fn, runs: int) -> float:
    return statistics.median(_times(fn, runs))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--runs", type=int, default=15, help="timed runs per implementation (median reported)")
    ap.add_argument("--sweep", action="store_true", help="also time batch for several chunk sizes")
    args = ap.parse_args()

    params = make_params()
    accel, gyro = make_record(HOUR)
    out = (np.empty_like(accel), np.empty_like(gyro))
    correct_batch(accel, gyro, params, out=out)  # warm-up, touches the output pages
    # the first calls with new outputs grow the heap (page faults); time them apart from the steady state
    cold = _times(lambda: correct_batch(accel, gyro, params), 2)

    load_before = os.getloadavg()[0]
    alloc: list[float] = []
    prealloc: list[float] = []
    cpu_alloc: list[float] = []
    cpu_prealloc: list[float] = []
    for _ in range(args.runs):  # interleaved, so both see the same machine load
        alloc += _times(lambda: correct_batch(accel, gyro, params), 1, cpu_alloc)
        prealloc += _times(lambda: correct_batch(accel, gyro, params, out=out), 1, cpu_prealloc)
    t_alloc, t_prealloc = statistics.median(alloc), statistics.median(prealloc)
    load_after = os.getloadavg()[0]

    stream_n = 20_000
    t_stream = _median_time(lambda: StreamingCorrector(params).run(accel[:stream_n], gyro[:stream_n]), 5) / stream_n

    naive_n = 5_000
    a_rows, g_rows = accel[:naive_n], gyro[:naive_n]

    def naive() -> None:
        c = NaiveCorrector(params)
        for a, g in zip(a_rows, g_rows, strict=True):
            c.step(a, g)

    t_naive = _median_time(naive, 3) / naive_n

    # agreement over the full hour
    s_a, s_g = StreamingCorrector(params).run(accel, gyro)
    b_a, b_g = correct_batch(accel, gyro, params)
    diff = max(float(np.max(np.abs(s_a - b_a))), float(np.max(np.abs(s_g - b_g))))
    c = NaiveCorrector(params)
    naive_out = np.array([np.concatenate(c.step(a, g)) for a, g in zip(accel[:2000], gyro[:2000], strict=True)])
    naive_diff = float(np.max(np.abs(naive_out - np.hstack([s_a[:2000], s_g[:2000]]))))

    per_alloc = t_alloc / HOUR
    per_pre = t_prealloc / HOUR
    rows = [
        (f"batch, 1 h record, new outputs (chunk {DEFAULT_CHUNK_ROWS})", per_alloc),
        ("batch, 1 h record, preallocated outputs", per_pre),
        (f"streaming StreamingCorrector.step ({stream_n} samples)", t_stream),
        (f"naive numpy-per-sample loop ({naive_n} samples)", t_naive),
    ]
    print(
        f"Algorithm 1, n = 40; sample = 6 channels (accel + gyro triad); {_cpu_model()}, "
        f"{os.cpu_count()} CPUs; load average {load_before:.2f} before, {load_after:.2f} after the batch runs"
    )
    print(f"{'implementation (wall clock, median)':<58} {'us/sample':>10} {'samples/s':>12} {'x batch':>9}")
    for name, per in rows:
        print(f"{name:<58} {per * 1e6:>10.4f} {1 / per:>12.3g} {per / per_alloc:>9.1f}")
    print(
        f"batch best of {args.runs}: new outputs {HOUR / min(alloc):.3g} samples/s, "
        f"preallocated {HOUR / min(prealloc):.3g} samples/s"
    )
    print(
        f"batch, new outputs, first two calls (heap growth, page faults): "
        f"{cold[0] * 1e3:.1f} ms, {cold[1] * 1e3:.1f} ms (steady-state median {t_alloc * 1e3:.1f} ms)"
    )
    print(
        f"batch CPU time (median of {args.runs}): new outputs {HOUR / statistics.median(cpu_alloc):.3g} samples/s, "
        f"preallocated {HOUR / statistics.median(cpu_prealloc):.3g} samples/s"
    )
    print(f"batch / naive speed-up: {t_naive / per_alloc:.0f}x; streaming / naive speed-up: {t_naive / t_stream:.1f}x")
    print(f"max |batch - streaming| over 1 h at 100 Hz: {diff:.2e} (SI units)")
    print(f"max |naive - streaming| over the first 2000 samples: {naive_diff:.2e}")

    if args.sweep:
        print(f"\n{'chunk rows':>10} {'ms (median, preallocated)':>26} {'samples/s':>12}")
        for chunk in (1024, 2048, 4096, 8192, 16384):  # larger requests are clamped to 16384
            t = _median_time(
                lambda chunk=chunk: correct_batch(accel, gyro, params, chunk_rows=chunk, out=out), args.runs
            )
            print(f"{chunk:>10} {t * 1e3:>26.2f} {HOUR / t:>12.3g}")


if __name__ == "__main__":
    main()
