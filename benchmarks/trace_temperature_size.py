"""A temperature bias's size at the drift re-fit's T_c against the size with T_c integrated out, on the independent
generator (``tests/indepgen.py``, the temperature bias alone).

Per recording and sensor: the block problem of the diagnosis (``SensorProblem``) with the temperature bias tested
(``test_mean``: the value and the T_c-conditional std of the selection step) and accepted (the drift's T_c re-fitted),
the T_c it settled on against the class's range and the generator's T_c, and the size with T_c integrated out
(``SensorProblem.tc_marginal``). z = (value - truth) / std per axis. The diagnosis's selection is not run: every
recording is traced, named or not.

Run: ``python benchmarks/trace_temperature_size.py [--base 198000] [--n 6]`` (development seeds 198000-198999).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
sys.path.insert(0, str(Path(__file__).resolve().parent))

import indepgen
from bench_diagnose_indep import warmup_tc

from station.diagnose.effect_registry import LIBRARY
from station.diagnose.likelihood import SensorProblem
from station.diagnose.residuals import fit_baseline


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--base", type=int, default=198_000)
    ap.add_argument("--n", type=int, default=6)
    args = ap.parse_args()
    tc_range = warmup_tc()
    z_old: list[float] = []
    z_new: list[float] = []
    at_bound = total = 0
    for seed in range(args.base, args.base + args.n):
        rec = indepgen.generate(seed, {"temperature_bias": 1.0})
        baseline = fit_baseline(rec.session, warmup_tc_s=tc_range)
        for sensor in ("accel", "gyro"):
            truth = np.asarray(rec.truth[f"temperature_bias {sensor}"])
            sd = baseline.sensor(sensor)
            prob = SensorProblem(baseline, sd)
            zb = sd.block_mean(LIBRARY["temperature_bias"].build(baseline, sd))
            test = prob.test_mean("temperature_bias", zb)
            prob.accept(zb)
            out = prob.tc_marginal(len(prob.accepted) - 1)
            if out is None:
                continue
            mean, std, _ = out
            zc = (test.theta - truth) / np.sqrt(np.diag(test.cov))
            zm = (mean - truth) / std
            lo, hi = sd.tc_range_s or (np.nan, np.nan)
            bound = np.isclose(prob.tc, lo) | np.isclose(prob.tc, hi)
            at_bound += int(bound.sum())
            total += 3
            z_old += zc.tolist()
            z_new += zm.tolist()
            print(f"seed {seed} {sensor:5s} passes {test.passes!s:5s} T_c re-fit {np.round(prob.tc).tolist()} "
                  f"(class {lo:g}-{hi:g} s; generator {np.round(rec.truth[f'{sensor}_tc']).tolist()})\n"
                  f"    value/truth at re-fit T_c {np.round(test.theta / truth, 3).tolist()} "
                  f"z {np.round(zc, 2).tolist()}\n"
                  f"    value/truth T_c integrated {np.round(mean / truth, 3).tolist()} z {np.round(zm, 2).tolist()}",
                  flush=True)
    zo, zn = np.asarray(z_old), np.asarray(z_new)
    print(f"\nT_c re-fit at a bound of the class's range: {at_bound}/{total} axes")
    for label, z in (("at the re-fit's T_c (conditional std)", zo), ("T_c integrated out", zn)):
        print(f"{label:40s} mean z {z.mean():+.2f} sd {z.std():.2f}  |z| <= 3: {np.mean(np.abs(z) <= 3):.0%} "
              f"of {len(z)}")


if __name__ == "__main__":
    main()
