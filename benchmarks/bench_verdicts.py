"""Verdicts of simulated units under the old and the guard-banded rule, and their stability to move durations.

For each unit (the demo's four, then ``--units`` drawn from ``--seed``), a session on the default plan is
simulated three times, with the rig's moves taking 0.5x, 1x and 1.5x as long
(:func:`station.kernel.plan.with_move_time_scale`; the unit, its noise streams and the holds are the same),
and each is fitted and judged twice:

* old: the rule of ``station-limits/1`` (a value passes within its range widened by 3 standard
  uncertainties, no limit on the gyro b_stat uncertainty) and a fit from the recording alone;
* new: the default limits file (ISO 14253-1 guard bands, k = 2, inconclusive -> FAIL, gyro b_stat
  uncertainty limit) and the fit with the sensor class's T_c range as its prior.

Prints the verdict table (old vs new at 1x), how many units change verdict between 0.5x, 1x and 1.5x, how
many change in a repeat measurement at 1x (the same unit, other noise: the repeatability of a verdict at a
limit), and how much the b_stat uncertainty moves with the move durations (the mechanism: without a prior an
unidentified T_c makes b_stat an extrapolation whose uncertainty depends on how long the moves took).

    python benchmarks/bench_verdicts.py --units 50 --seed 5000
"""

from __future__ import annotations

import argparse
import collections
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from station.fit.calibrate import FitOptions, fit_session
from station.kernel.limits_file import LimitsFile, load_limits
from station.kernel.plan import default_plan, with_move_time_scale
from station.kernel.sensor_class import TABLE1
from station.physics.unit import UnitTruth, draw_unit
from station.sequence.limits import check_limits
from station.sequence.records import Outcome
from station.sequence.runner import unit_verdict
from station.sim.session_sim import simulate_session

FACTORS = (0.5, 1.0, 1.5)
REPEAT = "repeat"  # 1x move durations, other noise


def old_rule(limits: LimitsFile) -> LimitsFile:
    """The default limits judged as ``station-limits/1`` did: widen by 3 u, no gyro b_stat uncertainty limit."""
    fq = replace(limits.fit_quality, gyro_bias_static_std_radps=None)
    product = replace(limits.product, rule="widen", k_sigma=3.0, fit_quality=fq, marginal_fraction=0.0)
    return replace(limits, product=product, fit_quality=fq)


def demo_units(seed: int = 0, n: int = 4) -> list[UnitTruth]:
    """The units ``station demo --seed SEED`` draws (as :class:`station.sim.station_sim.SimStation` does)."""
    out = []
    for k in range(n):
        unit_ss = np.random.SeedSequence(seed, spawn_key=(k,)).spawn(3)[0]
        out.append(draw_unit(TABLE1, np.random.default_rng(unit_ss)))
    return out


def unit_of(seed: int) -> UnitTruth:
    """The unit :func:`simulate_session` draws from ``seed``."""
    return draw_unit(TABLE1, np.random.default_rng(np.random.SeedSequence(seed).spawn(2)[0]))


def verdicts(
    truth: UnitTruth, seed: int, limits: LimitsFile
) -> tuple[dict[tuple[str, float | str], Outcome], dict[str, float]]:
    """(rule, move-time factor or REPEAT) -> the unit's outcome; per rule the largest ratio of a b_stat std
    between the move-time factors (accelerometer and gyroscope, every axis)."""
    old, prior = old_rule(limits), FitOptions(tc_range_s=dict(limits.correlation_time_s))
    out: dict[tuple[str, float | str], Outcome] = {}
    stds: dict[str, list[np.ndarray]] = {"old": [], "new": []}
    runs = [(f, seed) for f in FACTORS] + [(REPEAT, seed + 100_000)]
    for f, noise_seed in runs:
        factor = 1.0 if f == REPEAT else float(f)
        session = simulate_session(noise_seed, unit=truth, plan=with_move_time_scale(default_plan(), factor)).session
        for rule, lim, opt in (("old", old, None), ("new", limits, prior)):
            params = fit_session(session, opt)
            out[(rule, f)] = unit_verdict(check_limits(params, lim.product), lim.product)[0]
            if f != REPEAT:
                stds[rule].append(np.concatenate([params.accel.bias_static_std, params.gyro.bias_static_std]))
    ratio = {rule: float(np.max(np.max(v, axis=0) / np.min(v, axis=0))) for rule, v in stds.items()}
    return out, ratio


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--units", type=int, default=50, help="simulated units besides the demo's four")
    ap.add_argument("--seed", type=int, default=5000, help="first seed of the simulated units")
    args = ap.parse_args()
    limits = load_limits()
    units: list[tuple[str, int, UnitTruth]] = [(f"demo-{k}", 7000 + k, t) for k, t in enumerate(demo_units())]
    units += [(f"sim-{s}", s, unit_of(s)) for s in range(args.seed, args.seed + args.units)]
    t0 = time.monotonic()
    table = collections.Counter()
    changed: dict[str, list[str]] = {"old": [], "new": []}
    repeat: dict[str, list[str]] = {"old": [], "new": []}
    ratios: dict[str, list[float]] = {"old": [], "new": []}
    for name, seed, truth in units:
        v, ratio = verdicts(truth, seed, limits)
        table[(v[("old", 1.0)].value, v[("new", 1.0)].value)] += 1
        for rule in ("old", "new"):
            ratios[rule].append(ratio[rule])
            if len({v[(rule, f)] for f in FACTORS}) > 1:
                changed[rule].append(f"{name} " + "/".join(v[(rule, f)].value for f in FACTORS))
            if v[(rule, REPEAT)] != v[(rule, 1.0)]:
                repeat[rule].append(f"{name} {v[(rule, 1.0)].value}->{v[(rule, REPEAT)].value}")
        print(f"{name:10s} old {'/'.join(v[('old', f)].value for f in (*FACTORS, REPEAT)):21s} "
              f"new {'/'.join(v[('new', f)].value for f in (*FACTORS, REPEAT))}  b_stat std ratio "
              f"old {ratio['old']:.3g} new {ratio['new']:.3g}", flush=True)
    n = len(units)
    print(f"\n{n} units ({args.units} simulated from seed {args.seed} + the demo's 4), {time.monotonic() - t0:.0f} s")
    print("\n| old rule (widen 3u, no prior) | guard-banded (k = 2, T_c prior) | units |\n| --- | --- | --- |")
    for (old, new), count in sorted(table.items()):
        print(f"| {old} | {new} | {count} |")
    print("\n| rule | verdict changes between 0.5x, 1x, 1.5x move durations | verdict changes in a repeat at 1x "
          "(other noise) | largest b_stat std ratio between move durations: median / max |\n| --- | --- | --- | --- |")
    for rule in ("old", "new"):
        r = np.asarray(ratios[rule])
        moved, repeated = ", ".join(changed[rule]) or "-", ", ".join(repeat[rule]) or "-"
        print(f"| {rule} | {len(changed[rule])} of {n}: {moved} | {len(repeat[rule])} of {n}: {repeated} | "
              f"{np.median(r):.3g} / {np.max(r):.3g} |")


if __name__ == "__main__":
    main()
