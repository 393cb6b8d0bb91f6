"""The price of the line's short plan in %GRR: the same crossed study on the full plan and on the line's plan.

    python benchmarks/bench_msa_plans.py [--parts 10] [--nests 4] [--repeats 3] [--seed 0] [--line-plan FILE]

Each part (a simulated unit of ``--seed``) is measured ``nests x repeats`` times with fresh noise on two plans:

* ``full``: the default rig plan (300 s warm-up rest on the rig, poses, rates), one recording, the station's fit
  (``station.fit.calibrate.fit_session``);
* ``line``: the calibration line's short plan (``--line-plan``, a file written by ``station plan``; default
  ``station.kernel.line_plan.default_line_plan()``: one hour in the soak rack, then the rig part), the rack and rig
  recordings of one power-on (``station.sim.line_sim.simulate_line``) and the line's joint fit
  (``station.line.rigrole.fit_line_unit``).

The nests are perfect here (what a nest calibration leaves, ``bench_msa.py`` measures how well it does that on the
station's own sequence), so the "nests" are labels and the study's GRR is the plan's repeatability: that is the
part a plan changes. Unlike ``bench_msa.py`` it runs the recordings offline (no station sequence, no simulated
clock), which is what makes 240 recordings affordable. Prints per limited parameter %GRR of the tolerance and ndc on
both plans, and the CPU time.
"""

from __future__ import annotations

import argparse
import math
import time
from pathlib import Path

import numpy as np

from station.fit.calibrate import fit_session
from station.kernel.limits_file import load_limits
from station.kernel.line_plan import default_line_plan, line_plan_from_json
from station.kernel.plan import default_plan
from station.line.rigrole import fit_line_unit
from station.msa.study import StudyPoint, StudyReport, analyse
from station.sequence.limits import check_limits
from station.sim.line_sim import simulate_line
from station.sim.session_sim import simulate_session


def _fmt(x: float | None) -> str:
    return "-" if x is None or not math.isfinite(x) else f"{x:.1f}"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--parts", type=int, default=10)
    ap.add_argument("--nests", type=int, default=4)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--line-plan", type=Path, default=None, help="a plan file written by `station plan`")
    args = ap.parse_args()
    line_plan = default_line_plan() if args.line_plan is None else line_plan_from_json(args.line_plan.read_text())
    limits = load_limits(None).product
    full_plan = default_plan()
    rng = np.random.default_rng(np.random.SeedSequence(args.seed, spawn_key=(91,)))
    part_seeds = [int(s) for s in rng.integers(0, 2**31, args.parts)]
    truths = [simulate_session(s, plan=full_plan).truth for s in part_seeds]
    points: dict[str, list[StudyPoint]] = {"full": [], "line": []}
    cpu = {"full": 0.0, "line": 0.0}
    failed = {"full": 0, "line": 0}
    for p, truth in enumerate(truths):
        for j in range(args.nests):
            for r in range(args.repeats):
                noise = int(rng.integers(0, 2**31))
                for label in ("full", "line"):
                    t0 = time.process_time()
                    try:
                        if label == "full":
                            params = fit_session(simulate_session(noise, plan=full_plan, unit=truth).session)
                        else:
                            sim = simulate_line(noise, plan=line_plan, unit=truth)
                            params = fit_line_unit(sim.rack, sim.rig)
                    except Exception as exc:  # a refused fit is counted, not fatal
                        failed[label] += 1
                        print(f"{label} part {p} nest {j} repeat {r}: fit refused: {exc}")
                        continue
                    finally:
                        cpu[label] += time.process_time() - t0
                    for m in check_limits(params, limits):
                        if m.name.startswith("fit.") or not math.isfinite(m.value):
                            continue
                        points[label].append(StudyPoint(m.name, m.unit, truth.serial, f"nest {j + 1}", m.value,
                                                        m.low if math.isfinite(m.low) else None,
                                                        m.high if math.isfinite(m.high) else None))
    reports: dict[str, StudyReport] = {k: analyse(v) for k, v in points.items()}
    n = args.parts * args.nests * args.repeats
    print(f"{args.parts} parts x {args.nests} nests x {args.repeats} repeats = {n} recordings per plan; "
          f"seed {args.seed}")
    print(f"line plan: rack {line_plan.rack_s:.0f} s, rig {line_plan.rig}")
    for k in ("full", "line"):
        print(f"{k}: {cpu[k]:.0f} s CPU (simulation and fit), {failed[k]} fits refused")
    full = {s.parameter: s for s in reports["full"].parameters}
    line = {s.parameter: s for s in reports["line"].parameters}
    print()
    print(f"{'parameter':24s} {'%GRR tol full -> line':>22s} {'ndc full -> line':>17s}  verdict (full -> line)")
    for name in sorted(set(full) | set(line), key=lambda s: (list(full) + list(line)).index(s)):
        a, b = full.get(name), line.get(name)
        sa, sb = (a.study if a else None), (b.study if b else None)
        if sa is None or sb is None:
            why = [f"{k}: {s.reason if s else 'no values'}" for k, s, st in (("full", a, sa), ("line", b, sb))
                   if st is None]
            print(f"{name:24s} not analysed ({'; '.join(why)})")
            continue
        print(f"{name:24s} {_fmt(sa.grr.pct_tolerance):>10s} -> {_fmt(sb.grr.pct_tolerance):>8s} "
              f"{sa.ndc:>7d} -> {sb.ndc:<7d}  {sa.verdict} -> {sb.verdict}")
        for label, ps in (("full", a), ("line", b)):
            st = ps.study if ps is not None else None
            if ps is None or st is None or not (st.grr.pct_tolerance or 0.0) > 30:
                continue
            # where the spread comes from: the part whose repeats scatter most
            worst = max(ps.cells, key=lambda c: float(np.ptp(c[2])))
            tol = next(pt for pt in points[label] if pt.parameter == name)
            width = (tol.high - tol.low) if tol.high is not None and tol.low is not None else math.nan
            print(f"{'':24s} {label}: widest repeats part {worst[0]} {worst[1]}: range {np.ptp(worst[2]):.3g} "
                  f"{ps.unit} ({100 * np.ptp(worst[2]) / width:.0f} % of the tolerance)")


if __name__ == "__main__":
    main()
