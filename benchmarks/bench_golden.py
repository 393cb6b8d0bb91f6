"""A drifting golden unit on the simulated station: at which shift does its chart catch the drift?

    python benchmarks/bench_golden.py [--seeds 3] [--base 500] [--shifts 12] [--drift 0.5] [--scale 120] [--short]
                                      [--registration-runs 20] [--false-stop-rate 0.0027] [--fraction 0.1]

Per seed: the golden unit is registered from ``--registration-runs`` runs (allowed deviations for the stated
family-wise false-stop rate per check, and at least ``--fraction`` of the limit width; 0: the rate alone),
then run once per shift with its accelerometer x static
bias moved by ``--drift`` registered repeatabilities per shift (default plan, in-process simulated station).
Prints per seed the shift at which the individuals chart (Nelson rules) first signals and the shift at which
the golden check first fails its limits, against the chart rules' prediction for that drift (Monte Carlo of
``z_k = d k + r N(0, 1)``, r the true over the registered repeatability: median and 5-95 % range), then
over all seeds the observed fraction of units caught by each shift against the predicted probability (with the
binomial 95 % interval of the observed fraction), and how many seeds fell inside the predicted 5-95 % range.
``--short``: a shorter plan (120 s rest, 15 s poses, 6 s rate holds, as in ``tests/test_golden_drift.py``), so
that enough seeds fit in the time. Then the false stops: checks that failed on a parameter other than the
drifting one (all stable) by a deviation outside its allowance, against the stated rate (at most ``rate`` per
check), and the first check failure on
the drifting parameter against :func:`predicted_check_failure`; apart, the checks stopped because a referenced
parameter was not measured (the fit could not determine it), which the rate does not cover.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np

from station.kernel.plan import RigPlan
from station.sim.golden_study import PARAMETER, predicted_check_failure, predicted_detection, run_drifting_golden


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
    ap.add_argument("--registration-runs", type=int, default=20)
    ap.add_argument("--false-stop-rate", type=float, default=0.0027)
    ap.add_argument("--fraction", type=float, default=0.1, help="the allowance's floor, of the limit width")
    ap.add_argument("--short", action="store_true", help="the short plan of tests/test_golden_drift.py")
    ap.add_argument("--station-id", default="golden-sim", help="the simulated rig's name (two benches at once "
                                                                "need two)")
    args = ap.parse_args()
    plan = RigPlan(rest_s=120.0, pose_hold_s=15.0, rate_hold_s=6.0) if args.short else None
    pred = predicted_detection(args.drift, args.shifts, registration_runs=args.registration_runs)
    lo, med, hi = np.percentile(pred, [5, 50, 95])
    print(f"predicted first signal for {args.drift} sigma/shift: median shift {med:.0f}, 5-95 % {lo:.0f}-{hi:.0f} "
          f"(>{args.shifts}: none within the study)")
    print(f"{'seed':>6} {'sigma (m/s^2)':>14} {'signal at shift':>16} {'check fails at':>15} "
          f"{'on drift at':>12} {'pred. median':>12} {'false stops at':>15} {'unmeasured at':>14} {'k':>6} {'m':>4} "
          f"{'CPU s':>7}")
    observed: list[int] = []
    false_checks = 0
    seeds_with_false = 0
    unmeasured = 0
    drift_fail: list[int] = []
    check_pred: list[np.ndarray] = []
    for seed in range(args.base, args.base + args.seeds):
        out = Path(tempfile.mkdtemp(prefix="bench-golden-"))
        t0 = time.process_time()
        r = run_drifting_golden(f"sqlite:///{out / 'g.sqlite'}", seed=seed, shifts=args.shifts,
                                drift_sigmas=args.drift, scale=args.scale, out_dir=out / "runs", plan=plan,
                                station_id=args.station_id, registration_runs=args.registration_runs,
                                false_stop_rate=args.false_stop_rate, fraction=args.fraction)
        observed.append(r.first_signal_shift if r.first_signal_shift is not None else args.shifts + 1)
        assert r.golden is not None and r.golden.rule is not None
        ref = r.golden.reference(PARAMETER)
        assert ref is not None
        cp = predicted_check_failure(args.drift, ref.allowed / ref.repeatability, args.shifts, args.registration_runs,
                                     seed=seed)
        check_pred.append(cp)
        drift_fail.append(r.first_drift_fail_shift or args.shifts + 1)
        false_checks += len(r.false_stops)
        seeds_with_false += bool(r.false_stops)
        unmeasured += len(r.unmeasured_stops)
        med_cp = float(np.median(cp))
        print(f"{seed:>6} {r.repeatability:>14.3g} {r.first_signal_shift or '-':>16} "
              f"{r.first_limit_fail_shift or '-':>15} {r.first_drift_fail_shift or '-':>12} "
              f"{med_cp if med_cp <= args.shifts else float('nan'):>12.0f} "
              f"{','.join(map(str, r.false_stops)) or '-':>15} {','.join(map(str, r.unmeasured_stops)) or '-':>14} "
              f"{r.golden.rule.k:>6.2f} {r.golden.rule.parameters:>4} "
              f"{time.process_time() - t0:>7.0f}", flush=True)
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
    checks = n * args.shifts
    a, b = _wilson(false_checks, checks)
    print()
    print(f"false stops (a check failing on a stable parameter): {false_checks} of {checks} checks "
          f"(95 % interval {a:.4f}-{b:.4f}; stated rate at most {args.false_stop_rate} per check, about "
          f"{args.false_stop_rate * checks:.2f} expected); seeds with any: {seeds_with_false} of {n}; "
          f"checks stopped because a parameter was not measured: {unmeasured}")
    allp = np.concatenate(check_pred)
    df = np.array(drift_fail)
    print(f"check fails on the drifting parameter: observed median shift {np.median(df):.1f} "
          f"({int(np.sum(df <= args.shifts))} of {n} within {args.shifts}), predicted (pooled over the seeds' "
          f"registrations) median {np.median(allp):.1f}, P(within {args.shifts}) {np.mean(allp <= args.shifts):.2f}")


if __name__ == "__main__":
    main()
