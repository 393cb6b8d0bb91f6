"""The diagnosis on recordings with a saturated (clipped) gyro axis: located, censored, never a finding.

The recordings are ``tests/test_diagnose_censoring.py``'s generator: ``tests/indepgen.py``'s rig and sensor (not
``station.sim``) with one gyro axis clipping at a rail of 85-97 % of its output at the plan's top rate (drawn per
seed). Per recording: right = an ``unexplained`` entry with ``censored`` on the clipped axis (gyro, that axis, in
the rate segments), at the rail (within 1e-3 deg/s), no finding, nothing ``not_determined``; the other gyro axes'
rows of M_w and all of M_a within 4 of their stated standard uncertainties of the truth (``within``); and the
unclipped recording's diagnosis gives the same findings and the same other unexplained entries (``same``).

Run: ``python benchmarks/bench_diagnose_censoring.py --base 325000 --n 10`` (seeds base .. base + n - 1; the
development seeds were 320000-324999).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

from test_diagnose_censoring import DEG, clipped_gyro

from station.diagnose import diagnose


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--base", type=int, default=325_000)
    ap.add_argument("--n", type=int, default=10)
    args = ap.parse_args()
    print(f"{'seed':>7s} {'Hz':>4s} {'axis':>4s} {'rail deg/s':>10s} {'right':>5s} {'within':>6s} {'same':>4s} "
          f"{'cpu s':>6s}  unexplained")
    rows = []
    for seed in range(args.base, args.base + args.n):
        rec, session, axis, level = clipped_gyro(seed)
        t0 = time.process_time()
        d = diagnose(session)
        cpu = time.process_time() - t0
        rep = d.report
        mine = [u for u in rep.unexplained if u.censored is not None]
        right = (bool(mine) and not rep.findings
                 and all(u.sensor == "gyro" and u.axes == ("xyz"[axis],) and "rate" in u.segment_kinds
                         and np.allclose(np.abs(u.censored.levels), level / DEG, atol=1e-3)
                         and not u.censored.not_determined
                         for u in mine))
        within = d.baseline is not None
        if d.baseline is not None:
            p = d.baseline.params
            for tri, truth, ks in ((p.gyro, rec.truth["gyro_m"], [k for k in range(3) if k != axis]),
                                   (p.accel, rec.truth["accel_m"], [0, 1, 2])):
                for k in ks:
                    within &= bool(np.all(np.abs(tri.misalignment[k] - np.asarray(truth)[k])
                                          <= 4.0 * tri.misalignment_std[k] + 1e-9))
        plain = diagnose(rec.session).report
        same = (plain.effects == rep.effects and {(u.sensor, u.axes, u.segment_kinds) for u in plain.unexplained}
                == {(u.sensor, u.axes, u.segment_kinds) for u in rep.unexplained if u.censored is None})
        rows.append((right, within, same, cpu))
        where = "; ".join(f"{u.sensor} {''.join(u.axes)} {'/'.join(u.segment_kinds)}: {u.covariate[:50]}"
                          for u in rep.unexplained)
        named = f" | findings {rep.effects}" if rep.effects else ""
        print(f"{seed:7d} {rec.plan.rate_hz:4.0f} {'xyz'[axis]:>4s} {level / DEG:10.2f} {right!s:>5s} "
              f"{within!s:>6s} {same!s:>4s} {cpu:6.1f}  {where}{named}", flush=True)
    n = len(rows)
    cpu = sorted(r[3] for r in rows)
    right, within, same = (sum(r[i] for r in rows) for i in range(3))
    print(f"right {right}/{n}, within {within}/{n}, same {same}/{n}; "
          f"diagnosis CPU time of the clipped recordings: median {cpu[n // 2]:.1f} s, max {cpu[-1]:.1f} s")


if __name__ == "__main__":
    main()
