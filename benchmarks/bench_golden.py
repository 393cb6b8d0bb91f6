"""A drifting golden unit on the simulated station: at which shift does its chart catch the drift?

    python benchmarks/bench_golden.py [--seeds 3] [--base 500] [--shifts 12] [--drift 0.5] [--scale 120]

Per seed: the golden unit is registered from 5 runs, then run once per shift with its accelerometer x static
bias moved by ``--drift`` registered repeatabilities per shift (default plan, in-process simulated station).
Prints per seed the shift at which the individuals chart (Nelson rules) first signals and the shift at which
the golden check first fails its limits, against the chart rules' prediction for that drift (Monte Carlo of
``z_k = d k + r N(0, 1)``, r the true over the 5-run registered repeatability: median and 5-95 % range).
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np

from station.sim.golden_study import predicted_detection, run_drifting_golden


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--base", type=int, default=500)
    ap.add_argument("--shifts", type=int, default=12)
    ap.add_argument("--drift", type=float, default=0.5)
    ap.add_argument("--scale", type=float, default=120.0)
    args = ap.parse_args()
    pred = predicted_detection(args.drift, args.shifts)
    lo, med, hi = np.percentile(pred, [5, 50, 95])
    print(f"predicted first signal for {args.drift} sigma/shift: median shift {med:.0f}, 5-95 % {lo:.0f}-{hi:.0f} "
          f"(>{args.shifts}: none within the study)")
    print(f"{'seed':>6} {'sigma (m/s^2)':>14} {'signal at shift':>16} {'check fails at':>15} {'wall s':>7}")
    for seed in range(args.base, args.base + args.seeds):
        out = Path(tempfile.mkdtemp(prefix="bench-golden-"))
        t0 = time.monotonic()
        r = run_drifting_golden(f"sqlite:///{out / 'g.sqlite'}", seed=seed, shifts=args.shifts,
                                drift_sigmas=args.drift, scale=args.scale, out_dir=out / "runs")
        print(f"{seed:>6} {r.repeatability:>14.3g} {r.first_signal_shift or '-':>16} "
              f"{r.first_limit_fail_shift or '-':>15} {time.monotonic() - t0:>7.0f}")


if __name__ == "__main__":
    main()
