"""Fit benchmark: speed of a full fit, against imucal; and the paper's T_c method against ours.

    python benchmarks/bench_fit.py [--units N]

1. Time of a full fit (station.fit.calibrate.fit_session) of a simulated 15-minute 100 Hz
   session, median of 9 (wall clock and CPU time), against imucal 2.6.0's FerrarisCalibration.compute on the same
   session (its six pose means and three integrated rotations: one rate step per axis),
   measured in the same run, as a ratio.
2. Correlation time T_c: the paper's ACF method (eq. 4: autocorrelation of the low-passed
   power-on rest after removing the asymptote, read at e^-1) against the joint ML fit, on
   N simulated Table 1 units: median absolute relative error and bias.
"""

from __future__ import annotations

import os
import statistics
import sys
import time
from dataclasses import replace

import numpy as np
import pandas as pd
from rich.console import Console
from rich.table import Table

from station.fit.acf import correlation_time_acf
from station.fit.calibrate import fit_session
from station.kernel.plan import default_plan
from station.session.model import Kind, Session
from station.sim.session_sim import simulate_session


def fifteen_minute_session(seed: int = 1) -> Session:
    plan = default_plan()
    # stretch the power-on rest so the whole recording lasts 15 minutes at 100 Hz
    base = simulate_session(seed, plan=plan).session.duration_s
    plan = replace(plan, rest_s=plan.rest_s + max(0.0, 900.0 - base))
    return simulate_session(seed, plan=plan).session


def imucal_compute(session: Session) -> float:
    """Seconds imucal needs to compute its calibration on this session's segments (median of 5)."""
    from imucal import FerrarisCalibration, ferraris_regions_from_df

    labels = np.full(len(session), None, dtype=object)
    for seg in session.segments_of(Kind.POSE):
        ref = session.ref_accel_mps2[seg.start]
        j = int(np.argmax(np.abs(ref)))
        labels[seg.slice] = f"{'xyz'[j]}_{'p' if ref[j] > 0 else 'a'}"
    done = set()
    for seg in session.segments_of(Kind.RATE):
        j = int(np.argmax(np.abs(session.ref_gyro_radps[seg.start])))
        if j not in done:
            labels[seg.slice] = f"{'xyz'[j]}_rot"
            done.add(j)
    df = pd.DataFrame(np.hstack([session.accel_mps2, np.degrees(session.gyro_radps)]),
                      columns=["acc_x", "acc_y", "acc_z", "gyr_x", "gyr_y", "gyr_z"])
    df["part"] = labels
    df = df.dropna(subset=["part"]).set_index("part")
    times = []
    for _ in range(5):
        t0 = time.perf_counter()
        regions = ferraris_regions_from_df(df)
        FerrarisCalibration().compute(regions, session.sample_rate_hz, "m/s^2", "deg/s")
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def fit_time(session: Session, runs: int = 9) -> tuple[float, float, float]:
    """(wall-clock median, CPU-time median, first call) in s; the first call (imports, caches) is not in the medians."""
    t0 = time.perf_counter()
    fit_session(session)
    first = time.perf_counter() - t0
    wall, cpu = [], []
    for _ in range(runs):
        t0, c0 = time.perf_counter(), time.process_time()
        fit_session(session)
        wall.append(time.perf_counter() - t0)
        cpu.append(time.process_time() - c0)
    return statistics.median(wall), statistics.median(cpu), first


def tc_comparison(units: int) -> dict[str, list[float]]:
    err: dict[str, list[float]] = {"paper accel": [], "ML accel": [], "paper gyro": [], "ML gyro": []}
    for i in range(units):
        sim = simulate_session(2000 + i)
        s = sim.session
        rest = max(s.segments_of(Kind.REST), key=len)
        params = fit_session(s)
        for name, data, est, tru in (
            ("accel", s.accel_mps2, params.accel, sim.truth.accel),
            ("gyro", s.gyro_radps, params.gyro, sim.truth.gyro),
        ):
            for k in range(3):
                true_tc = tru.correlation_time_s[k]
                paper = correlation_time_acf(data[rest.slice, k], s.sample_rate_hz).correlation_time_s
                err[f"paper {name}"].append((paper - true_tc) / true_tc)
                err[f"ML {name}"].append((est.correlation_time_s[k] - true_tc) / true_tc)
    return err


def main(argv: list[str]) -> None:
    units = int(argv[argv.index("--units") + 1]) if "--units" in argv else 20
    console = Console()
    s = fifteen_minute_session()
    load_before = os.getloadavg()[0]
    (ours, ours_cpu, first), theirs = fit_time(s), imucal_compute(s)
    t = Table(title=f"Full fit of a {s.duration_s / 60:.1f}-minute {s.sample_rate_hz:.0f} Hz session "
                    f"(station: median of 9 after a first call; imucal: median of 5)")
    for col in ("tool", "what it computes", "median s", "ratio to imucal"):
        t.add_column(col)
    t.add_row("station fit_session", "ML fit of eq. (1)+(3), uncertainties, Allan, quality", f"{ours:.3f}",
              f"{ours / theirs:.0f}x")
    t.add_row("imucal 2.6.0 compute", "6 pose means + 3 integrals (Ferraris)", f"{theirs:.4f}", "1x")
    console.print(t)
    console.print(f"station CPU-time median {ours_cpu:.3f} s, first call {first:.3f} s; "
                  f"load average {load_before:.2f} before, {os.getloadavg()[0]:.2f} after")
    verdict = "met" if ours < 0.5 else "NOT met"
    console.print(f"target: full fit under 0.5 s -> {verdict} ({ours:.3f} s wall-clock median)")

    err = tc_comparison(units)
    t = Table(title=f"T_c relative error over {units} Table 1 units x 3 axes (power-on rest {300} s)")
    for col in ("estimator", "resolved", "median |error|", "median error (bias)", "90th pct |error|"):
        t.add_column(col, justify="right")
    for name, e in err.items():
        a = np.array(e)
        ok = np.isfinite(a)
        t.add_row(name, f"{ok.sum()}/{a.size}", f"{np.median(np.abs(a[ok])) * 100:.1f} %",
                  f"{np.median(a[ok]) * 100:+.1f} %", f"{np.percentile(np.abs(a[ok]), 90) * 100:.1f} %")
    console.print(t)


if __name__ == "__main__":
    main(sys.argv[1:])
