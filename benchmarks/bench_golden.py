"""A drifting golden unit on the simulated station: at which shift does its chart catch the drift?

    python benchmarks/bench_golden.py [--seeds 3] [--base 500] [--shifts 12] [--drift 0.5] [--scale 120] [--short]

Per seed: the golden unit is registered from 5 runs, then run once per shift with its accelerometer x static
bias moved by ``--drift`` registered repeatabilities per shift (default plan, in-process simulated station).
Prints per seed the shift at which the individuals chart (Nelson rules) first signals and the shift at which
the golden check first fails its limits, against the chart rules' prediction for that drift (Monte Carlo of
``z_k = d k + r N(0, 1)``, r the true over the 5-run registered repeatability: median and 5-95 % range), then
over all seeds the observed fraction of units caught by each shift against the predicted probability (with the
binomial 95 % interval of the observed fraction), and how many seeds fell inside the predicted 5-95 % range.
``--short``: a shorter plan (120 s rest, 15 s poses, 6 s rate holds, as in ``tests/test_golden_drift.py``), so
that enough seeds fit in the time.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np

from station.kernel.plan import RigPlan
from station.sim.golden_study import predicted_detection, run_drifting_golden


def _wilson(k: int, n: int, z: float = 1.96) -> tuple[float, float]:
    """Wilson's 95 % interval of a binomial fraction k / n."""
    p = k / n
    d = 1 + z * z / n
    c = (p + z * z / (2 * n)) / d
    h = z * np.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / d
    return max(0.0, c - h), min(1.0, c + h)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--base", type=int, default=500)
    ap.add_argument("--shifts", type=int, default=12)
    ap.add_argument("--drift", type=float, default=0.5)
    ap.add_argument("--scale", type=float, default=120.0)
    ap.add_argument("--short", action="store_true", help="the short plan of tests/test_golden_drift.py")
    ap.add_argument("--station-id", default="golden-sim", help="the simulated rig's name (two benches at once "
                                                                "need two)")
    args = ap.parse_args()
    plan = RigPlan(rest_s=120.0, pose_hold_s=15.0, rate_hold_s=6.0) if args.short else None
    pred = predicted_detection(args.drift, args.shifts)
    lo, med, hi = np.percentile(pred, [5, 50, 95])
    print(f"predicted first signal for {args.drift} sigma/shift: median shift {med:.0f}, 5-95 % {lo:.0f}-{hi:.0f} "
          f"(>{args.shifts}: none within the study)")
    print(f"{'seed':>6} {'sigma (m/s^2)':>14} {'signal at shift':>16} {'check fails at':>15} {'CPU s':>7}")
    observed: list[int] = []
    for seed in range(args.base, args.base + args.seeds):
        out = Path(tempfile.mkdtemp(prefix="bench-golden-"))
        t0 = time.process_time()
        r = run_drifting_golden(f"sqlite:///{out / 'g.sqlite'}", seed=seed, shifts=args.shifts,
                                drift_sigmas=args.drift, scale=args.scale, out_dir=out / "runs", plan=plan,
                                station_id=args.station_id)
        observed.append(r.first_signal_shift if r.first_signal_shift is not None else args.shifts + 1)
        print(f"{seed:>6} {r.repeatability:>14.3g} {r.first_signal_shift or '-':>16} "
              f"{r.first_limit_fail_shift or '-':>15} {time.process_time() - t0:>7.0f}", flush=True)
    n = len(observed)
    obs = np.array(observed)
    inside = int(np.sum((obs >= lo) & (obs <= hi)))
    print()
    print(f"{n} seeds: observed median shift {np.median(obs):.1f} (predicted {med:.0f}); {inside} of {n} inside the "
          f"predicted 5-95 % range {lo:.0f}-{hi:.0f} (expected about {0.9 * n:.0f})")
    print(f"{'by shift':>8} {'predicted P(caught)':>20} {'observed':>9} {'95 % interval':>15}")
    for k in range(1, args.shifts + 1):
        p_k = float(np.mean(pred <= k))
        c = int(np.sum(obs <= k))
        a, b = _wilson(c, n)
        print(f"{k:>8} {p_k:>20.2f} {c / n:>9.2f} {f'{a:.2f}-{b:.2f}':>15}")


if __name__ == "__main__":
    main()
