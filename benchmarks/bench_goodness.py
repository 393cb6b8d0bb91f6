"""The goodness-of-fit verdict: false alarms on good simulated recordings, and detection.

    python benchmarks/bench_goodness.py --seeds 300:380 [--random-plan]      # false alarms
    python benchmarks/bench_goodness.py --seeds 500:510 --power               # detection of contradictions

False alarms: the share of good recordings (``simulate_session(seed)``) whose fit fails
``quality.goodness_of_fit`` (target: about 1e-3, the test's stated rate). Power: one pose (x up) of the
same recordings offset across (y) or along (x) its reference, one rate step's scale changed.
"""

from __future__ import annotations

import argparse

import numpy as np

from station.fit.calibrate import fit_session
from station.kernel.plan import random_plan
from station.session.model import Kind, Session
from station.sim.session_sim import simulate_session

POWER_CASES = [("across", 0.002), ("across", 0.005), ("across", 0.01), ("along", 0.005), ("along", 0.02),
               ("along", 0.05), ("rate", 0.001), ("rate", 0.003), ("rate", 0.01)]


def _recording(seed: int, random: bool) -> Session:
    plan = random_plan(np.random.default_rng(seed)) if random else None
    return simulate_session(seed, plan=plan).session if plan is not None else simulate_session(seed).session


def _contradicted(s: Session, kind: str, size: float) -> Session:
    if kind == "rate":
        seg = s.segments_of(Kind.RATE)[3]
        gyro = s.gyro_radps.copy()
        gyro[seg.slice] *= 1.0 + size
        return s.replace(gyro_radps=gyro)
    seg = next(p for p in s.segments_of(Kind.POSE) if s.ref_accel_mps2[p.start, 0] > 5.0)
    acc = s.accel_mps2.copy()
    acc[seg.slice, 1 if kind == "across" else 0] += size
    return s.replace(accel_mps2=acc)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", default="300:380", help="first:stop")
    ap.add_argument("--random-plan", action="store_true")
    ap.add_argument("--power", action="store_true")
    args = ap.parse_args()
    first, stop = (int(x) for x in args.seeds.split(":"))
    seeds = range(first, stop)
    if args.power:
        hits = dict.fromkeys(POWER_CASES, 0)
        for seed in seeds:
            s = _recording(seed, args.random_plan)
            for kind, size in POWER_CASES:
                hits[(kind, size)] += not fit_session(_contradicted(s, kind, size)).quality.passed
        for (kind, size), n in hits.items():
            unit = "relative" if kind == "rate" else "m/s^2"
            print(f"{kind} {size:g} {unit}: found in {n}/{len(seeds)}")
        return
    failed, ratio = [], []
    for seed in seeds:
        gof = fit_session(_recording(seed, args.random_plan)).quality.goodness_of_fit
        assert gof is not None
        verdict = gof.report
        ratio.append(max(max(abs(t["worst_z"]) / verdict["z_limit"],
                             t["chi2"] / t["chi2_limit"] if t["chi2_limit"] else 0.0) for t in verdict["tests"]))
        if not gof.passed:
            failed.append((seed, list(gof.failed)))
    print(f"false alarms: {len(failed)}/{len(seeds)} {failed}; largest statistic / limit {max(ratio):.3f}, "
          f"median {float(np.median(ratio)):.3f}")


if __name__ == "__main__":
    main()
