"""Session CSV v1 I/O speed on a synthetic 1-hour, 100 Hz recording (360 000 rows).

Run: /work/venv/bin/python benchmarks/bench_session_io.py [--repeats 5]

Prints rows, file size (MB), median wall time (s) and rows/s for: read_session (happy path),
write_session, and read_session of the same file with an error on its last line (the slow,
line-by-line scan that names the line).
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from station.kernel.errors import SessionFormatError
from station.session import Kind, Session, read_session, write_session


def synthetic_hour(rate_hz: float = 100.0, duration_s: float = 3600.0, seed: int = 1) -> Session:
    """Random but well-formed session: SI units, 60 s segments cycling rest/pose/move/rate."""
    rng = np.random.default_rng(seed)
    n = round(rate_hz * duration_s)
    t = np.arange(n) / rate_hz
    segment = (t // 60.0).astype(np.int64)
    kind = np.array([Kind.REST, Kind.POSE, Kind.MOVE, Kind.RATE], dtype=np.int8)[segment % 4]
    unknown = (kind == Kind.MOVE)[:, None]
    return Session(
        metadata={"serial": "BENCH-1", "sample_rate_hz": repr(rate_hz), "gravity_mps2": "9.8128"},
        t_s=t,
        segment=segment,
        kind=kind,
        accel_mps2=rng.normal(0.0, 6.0, (n, 3)),
        gyro_radps=rng.normal(0.0, 1.0, (n, 3)),
        temp_degc=25.0 + rng.normal(0.0, 1.0, n),
        ref_accel_mps2=np.where(unknown, np.nan, rng.normal(0.0, 6.0, (n, 3))),
        ref_gyro_radps=np.where(unknown, np.nan, rng.normal(0.0, 1.0, (n, 3))),
    )


def median_time(action: Callable[[], object], repeats: int) -> float:
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        action()
        times.append(time.perf_counter() - start)
    return statistics.median(times)


def expect_error(path: Path) -> None:
    try:
        read_session(path)
    except SessionFormatError:
        return
    raise AssertionError("the broken file was accepted")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    session = synthetic_hour()
    rows = len(session)
    with tempfile.TemporaryDirectory() as tmp:
        good = Path(tmp) / "hour.csv"
        write_session(session, good)
        size_mb = good.stat().st_size / 1e6
        read_s = median_time(lambda: read_session(good), args.repeats)
        write_s = median_time(lambda: write_session(session, Path(tmp) / "out.csv"), args.repeats)
        broken = Path(tmp) / "broken.csv"
        text = good.read_text()
        broken.write_text(text[: text.rstrip("\n").rfind("\n") + 1] + "1e9,0,spin" + ",0" * 13 + "\n")
        error_s = median_time(lambda: expect_error(broken), max(1, min(args.repeats, 3)))
    print(f"{'operation':<28} {'rows':>8} {'MB':>7} {'median s':>9} {'rows/s':>11}")
    for name, seconds in (
        ("read_session", read_s),
        ("write_session", write_s),
        ("read_session, error at end", error_s),
    ):
        print(f"{name:<28} {rows:>8d} {size_mb:>7.1f} {seconds:>9.3f} {rows / seconds:>11,.0f}")


if __name__ == "__main__":
    main()
