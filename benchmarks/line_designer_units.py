"""Are the plan designer's three units the sensor class? Stated stds of the line's joint fit per unit.

The designer predicts the line's accuracy from the joint fit's stated standard uncertainties on three simulated
units (``line_predict.DESIGN_SEEDS``; their noise and drift now stratified: ``plan_design.design_units``; the
units as drawn and as stratified are both shown). Here the same figure (RMS over the elements of accel M's std
and of gyro b_stat's std) on ``--units`` other units, its spread over random triples of them, and what drives
it per unit (correlation with the unit's white-noise std, gyro T_c and gyro |b_drift|: the simulated
stochastic drift is 1 % of |b_drift|).

    PYTHONPATH=. python benchmarks/line_designer_units.py --units 30 --seed0 5000000
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import bench_line as bl
import line_predict as lp

from station.fit.calibrate import FitOptions
from station.kernel.limits_file import load_limits
from station.kernel.line_plan import LinePlan
from station.sim.plan_design import design_units

_DPH = 180.0 / np.pi * 3600.0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--units", type=int, default=30)
    ap.add_argument("--seed0", type=int, default=5000000)
    args = ap.parse_args()
    limits = load_limits()
    opts = FitOptions(tc_range_s=dict(limits.correlation_time_s))
    plan = LinePlan(rack_s=3600.0, rig=bl.line_rig(0.0))
    rows = []
    seeds = [*lp.DESIGN_SEEDS, *lp.DESIGN_SEEDS, *(args.seed0 + 1000 * i for i in range(args.units))]
    units = [None, None, None, *design_units(lp.DESIGN_SEEDS), *([None] * args.units)]
    for seed, unit in zip(seeds, units, strict=True):
        p, truth = lp.fit_unit(seed, plan, opts, unit)
        rows.append((float(np.sqrt(np.mean(p.accel.misalignment_std ** 2))) * 1e6,
                     float(np.sqrt(np.mean(p.gyro.bias_static_std ** 2))) * _DPH,
                     float(np.sqrt(np.mean(truth.accel.noise_std ** 2))),
                     float(np.mean(truth.gyro.correlation_time_s)),
                     float(np.sqrt(np.mean(truth.gyro.bias_drift ** 2)))))
        print(f"  unit seed {seed}", flush=True)
    a = np.array(rows)
    design, strat, other = a[:3], a[3:6], a[6:]
    rng = np.random.default_rng(0)
    print(f"\n| figure | designer's 3 units as drawn | the same stratified (design_units) | {args.units} other units "
          "| ratio to as drawn / to stratified | random triples of the others, 5-95 % "
          "| as drawn: percentile among triples | corr. with noise std / gyro T_c / gyro abs(b_drift) |")
    print("|---|---|---|---|---|---|---|---|")
    for j, name in ((0, "accel M std (ppm)"), (1, "gyro b_stat std (deg/h)")):
        d, o = float(np.sqrt(np.mean(design[:, j] ** 2))), float(np.sqrt(np.mean(other[:, j] ** 2)))
        st = float(np.sqrt(np.mean(strat[:, j] ** 2)))
        trip = np.array([np.sqrt(np.mean(rng.choice(other[:, j], 3, replace=False) ** 2)) for _ in range(4000)])
        corr = [float(np.corrcoef(other[:, j], other[:, c])[0, 1]) for c in (2, 3, 4)]
        lo, hi = np.percentile(trip, [5, 95])
        print(f"| {name} | {d:.3g} | {st:.3g} | {o:.3g} | {o / d:.2f} / {o / st:.2f} | {lo:.3g}-{hi:.3g} "
              f"| {np.mean(trip < d) * 100:.0f} % | {' / '.join(f'{c:+.2f}' for c in corr)} |")


if __name__ == "__main__":
    main()
