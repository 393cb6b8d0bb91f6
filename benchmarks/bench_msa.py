"""Gage R&R of the simulated station: parts x nests x repeats, nest errors on, before and after nest calibration.

    python benchmarks/bench_msa.py [--parts 10] [--nests 4] [--repeats 3] [--seed 0] [--scale 60]
                                   [--nest-error 0.3] [--out DIR] [--plan default|line|FILE]

Runs the study twice on the in-process simulated station with the default plan: once on a rig whose nests
carry mounting errors (``--nest-error`` deg per axis, drawn from ``--seed``) and no nest calibration, once
after ``station nest-cal`` (a reference unit in every nest, with its "laboratory calibration": the simulated
truth; ``--relative`` without it, the datum then the mean nest). Prints per limited parameter %GRR of the
tolerance and of the total variation, ndc and the verdict, before and after, and the wall time. ``--plan line``
runs the rig part of the calibration line's short plan (``station.kernel.line_plan.line_rig_plan``), ``--plan
FILE`` the rig part of a plan file written by ``station plan`` (``station-line-plan/1``). The
records go to two SQLite files in ``--out`` (default: a temporary directory), so ``station msa report``
can re-read them.
"""

from __future__ import annotations

import argparse
import math
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from station.commands.msa import study_report
from station.commands.nest_cal import describe, estimate_from_records
from station.kernel.line_plan import line_plan_from_json, line_rig_plan
from station.kernel.plan import RigPlan, default_plan
from station.msa.study import StudyReport
from station.sim.msa_study import StudyDesign, run_nest_calibration, run_study


def _fmt(x: float | None) -> str:
    return "-" if x is None or not math.isfinite(x) else f"{x:.1f}"


def _plan(choice: str) -> RigPlan:
    if choice == "default":
        return default_plan()
    if choice == "line":
        # the station's sequence opens with a rest (the power cycle and the stillness gate); 2 s as in
        # ``station demo --line``
        return replace(line_rig_plan(), rest_s=2.0)
    return line_plan_from_json(Path(choice).read_text()).rig


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--parts", type=int, default=10)
    ap.add_argument("--nests", type=int, default=4)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--scale", type=float, default=60.0)
    ap.add_argument("--nest-error", type=float, default=0.3)
    ap.add_argument("--out", type=Path, default=None)
    ap.add_argument("--relative", action="store_true",
                    help="calibrate the nests without the reference unit's laboratory calibration (datum: mean nest)")
    ap.add_argument("--plan", default="default",
                    help="default (the full plan), line (the line's short rig plan) or a station plan file")
    ap.add_argument("--station-id", default="msa-sim", help="the simulated rig's name (two studies at once need two)")
    args = ap.parse_args()
    plan = _plan(args.plan)
    out = args.out if args.out is not None else Path(tempfile.mkdtemp(prefix="bench-msa-"))
    out.mkdir(parents=True, exist_ok=True)
    design = StudyDesign(args.parts, args.nests, args.repeats, args.seed)
    rng = np.random.default_rng(np.random.SeedSequence(args.seed, spawn_key=(77,)))
    errors = [tuple(float(v) for v in rng.normal(0.0, args.nest_error, 3)) for _ in range(args.nests)]
    print(f"plan: {args.plan}: {plan}")
    print(f"nest mounting errors (deg): {[tuple(round(v, 3) for v in e) for e in errors]}")
    reports: dict[str, StudyReport] = {}
    for label, cal in (("before", False), ("after", True)):
        db = f"sqlite:///{out / f'msa-{label}.sqlite'}"
        t0 = time.monotonic()
        if cal:
            serial, _, lab = run_nest_calibration(args.nests, db, seed=args.seed, scale=args.scale,
                                                  nest_errors_deg=errors, out_dir=out / "runs", plan=plan,
                                                  station_id=args.station_id)
            cal = estimate_from_records(db, f"fake-rig://{args.station_id}", serial,
                                        reference=None if args.relative else lab)
            for line in describe(cal):
                print(line)
        results = run_study(design, db, label, scale=args.scale, nest_errors_deg=errors, out_dir=out / "runs",
                            nest_calibration=cal, plan=plan, station_id=args.station_id)
        outcomes: dict[str, int] = {}
        for r in results:
            for u in r.units:
                outcomes[u.outcome.value] = outcomes.get(u.outcome.value, 0) + 1
        print(f"{label}: {len(results)} runs in {time.monotonic() - t0:.0f} s wall; unit outcomes {outcomes}; "
              f"records {db}")
        reports[label] = study_report(db, lot=label)
    before = {p.parameter: p for p in reports["before"].parameters}
    after = {p.parameter: p for p in reports["after"].parameters}
    print()
    print(f"{'parameter':24s} {'%GRR tol':>17s} {'%GRR TV':>15s} {'ndc':>9s}  verdict (before -> after)")
    for name in before:
        b, a = before[name].study, after[name].study if name in after else None
        if b is None or a is None:
            why = before[name].reason if b is None else (after[name].reason if name in after else "missing")
            print(f"{name:24s} not analysed: {why}")
            continue
        print(f"{name:24s} {_fmt(b.grr.pct_tolerance):>7s} -> {_fmt(a.grr.pct_tolerance):>6s} "
              f"{_fmt(b.grr.pct_total):>6s} -> {_fmt(a.grr.pct_total):>5s} {b.ndc:>4d} -> {a.ndc:<4d} "
              f"{b.verdict} -> {a.verdict}")


if __name__ == "__main__":
    main()
