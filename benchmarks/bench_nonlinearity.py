"""Recovery of the gyro scale nonlinearity ``y = u + k u|u|`` and what it does to the corrected rate.

    python benchmarks/bench_nonlinearity.py [--seed 9000] [--units 10] [--nulls 40] [--independent 20]

Units of the station's simulator with ``scale_nonlinearity=0.001`` (0.1 % at 200 deg/s) on the default plan
(50/100/200 deg/s): the fitted k against the truth in stated standard uncertainties, and the worst corrected
rate-step error (Algorithm 1) with the term and without; then units without the effect: how often the term is
kept anyway. Report seeds 9000+ (tests: 300-305; development: 100-129).

``--independent N``: the same on recordings of the independent generator (``tests/indepgen.py``: other rig
kinematics, sample rates, rate lists, and the IEEE polynomial ``x + k2 x^2 + k3 x^3`` instead of ``u + k u|u|``),
seeds 20000+ (never used while developing): N without any effect, N with an odd ``k3`` (1e-3 at 200 deg/s), N
with an even ``k2``: how often the term is kept, and the worst corrected rate-step error with and without it.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from station.correct.session_correct import correct_session
from station.fit.calibrate import FitOptions, fit_session
from station.physics.effects import Effects
from station.session.model import Kind
from station.sim.session_sim import simulate_session

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

import indepgen

PRIOR = {"accel": (50.0, 167.0), "gyro": (1030.0, 3760.0)}


def worst_rate_error(session, params) -> float:
    out = correct_session(session, params)
    worst = 0.0
    for seg in session.segments_of(Kind.RATE):
        half = slice(seg.start + (seg.stop - seg.start) // 2, seg.stop)
        ref = session.ref_gyro_radps[half].mean(axis=0)
        err = out.gyro_radps[half].mean(axis=0) - ref
        worst = max(worst, float(np.linalg.norm(err) / np.linalg.norm(ref)))
    return worst


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=9000)
    ap.add_argument("--units", type=int, default=10)
    ap.add_argument("--nulls", type=int, default=40)
    ap.add_argument("--independent", type=int, default=0, help="recordings per row on the independent generator")
    args = ap.parse_args()
    auto = FitOptions(scale_nonlinearity="auto", tc_range_s=PRIOR)
    off = FitOptions(tc_range_s=PRIOR)
    print("| seed | status | max abs z | worst rate error with (%) | without (%) |")
    print("|---:|---|---:|---:|---:|")
    zs = []
    for seed in range(args.seed, args.seed + args.units):
        sim = simulate_session(seed, effects=Effects(scale_nonlinearity=0.001))
        p, o = fit_session(sim.session, auto), fit_session(sim.session, off)
        k, k_std = p.gyro.scale_nonlinearity, p.gyro.scale_nonlinearity_std
        z = np.divide(k - sim.effect_truth.gyro_nonlinearity, k_std, out=np.full(3, np.nan), where=k_std > 0)
        zs.extend(z[np.isfinite(z)])
        print(f"| {seed} | {p.quality.scale_nonlinearity.status} | {np.nanmax(np.abs(z)):.2f} | "
              f"{100 * worst_rate_error(sim.session, p):.4f} | {100 * worst_rate_error(sim.session, o):.4f} |")
    zs_a = np.abs(np.array(zs))
    if zs_a.size:
        print(f"\nwithin 1/2/3 sigma: {np.mean(zs_a < 1):.0%} / {np.mean(zs_a < 2):.0%} / {np.mean(zs_a < 3):.0%} "
              f"of {zs_a.size}")
    start = args.seed + 100
    status = [fit_session(simulate_session(s).session, auto).quality.scale_nonlinearity["status"]
              for s in range(start, start + args.nulls)]
    if status:
        print(f"without the effect (seeds {start}-{start + args.nulls - 1}): "
              + ", ".join(f"{k} {status.count(k)}" for k in sorted(set(status))))
    if args.independent:
        independent(args.independent, auto, off)


def independent(n: int, auto: FitOptions, off: FitOptions) -> None:
    """Rows on the independent generator (seeds 20000+)."""
    print("\nindependent generator (tests/indepgen.py), seeds 20000+:")
    print("| row | kept (fitted) | axes kept | worst rate error with (%), median | without (%), median |")
    print("|---|---:|---:|---:|---:|")
    rows = (("none", {}), ("odd k3 1e-3", {"scale_nonlinearity_odd": 1e-3}),
            ("even k2 1e-3", {"scale_nonlinearity_even": 1e-3}))
    for i, (name, effects) in enumerate(rows):
        kept = axes = 0
        e_with, e_without = [], []
        for seed in range(20000 + 1000 * i, 20000 + 1000 * i + n):
            session = indepgen.generate(seed, effects).session
            p, o = fit_session(session, auto), fit_session(session, off)
            note = p.quality.scale_nonlinearity
            kept += note["status"] == "fitted"
            axes += len(note.get("axes", []))
            e_with.append(100 * worst_rate_error(session, p))
            e_without.append(100 * worst_rate_error(session, o))
        print(f"| {name} | {kept}/{n} | {axes}/{3 * n} | {np.median(e_with):.4f} | {np.median(e_without):.4f} |")


if __name__ == "__main__":
    main()
