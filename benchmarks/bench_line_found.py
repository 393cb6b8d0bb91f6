"""The found terms in the line: the joint fit with and without the time offset and the gyro's IEEE 952 polynomial.

Units from the independent line generator (``gen_line_indep.py``: its own kinematics, sampling, unit draw and noise;
its own code for the time offset and the polynomial) or, with ``--generator sim``, from the station's simulator
(``station.sim.line_sim``). Per unit: the line's rack rest (``--rack-s``) and rig part of one power-on, fitted by
the joint fit (:func:`station.fit.joint.fit_joint`) twice, with the found terms (``scale_nonlinearity`` and
``time_offset`` ``'auto'``, as the station's composition root fits) and without (as the line fitted before); a
validation recording of another power-on on the full plan (poses, 50/100/200 deg/s both signs about each axis,
references in the moves) is corrected by Algorithm 1 (:func:`station.correct.correct_session`) with each set:

* **pose RMS**: RMS over the six poses and three axes of the corrected pose mean minus the reference (mm/s^2);
* **worst rate error**: the largest |corrected mean rate about the step's axis - commanded| / commanded over the 18
  rate steps (%);
* **held-out gyro error**: RMS over the validation's move and rate samples of the corrected rate minus the
  reference through eq. 6's one-sided moving average (deg/s; :func:`station.diagnose.compensation_gain.held_out_error`):
  the whole validation recording is held out from the fit.

Rows (``--units`` each; unit ``i`` uses seed ``--seed0 + 1000 i``):

* ``two rates, tau + k2 + k3``: the line's rig part with +-50 and +-200 deg/s about each axis (both terms
  identifiable), a time offset drawn in +-[1, 5] ms and k2, k3 on every axis of 0.05-0.1 % at 200 deg/s, signs drawn;
* ``two rates, tau only`` and ``two rates, k2 + k3 only``: one of the two planted (the same draws);
* ``default line, tau + k2 + k3``: the same unit physics on the default line rig part (+-100 deg/s only: the
  polynomial is not identifiable, the time offset is);
* ``two rates, null``: neither term planted (what is kept falsely, and that nothing gets worse).

Every row uses the same seeds: the same units, noise and (where planted) the same tau, k2 and k3.

    PYTHONPATH=. python benchmarks/bench_line_found.py [--units 10] [--seed0 N] [--rack-s 3600] [--generator indep]
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from station.correct.session_correct import correct_session
from station.diagnose.compensation_gain import held_out_error
from station.fit.calibrate import FitOptions
from station.fit.joint import fit_joint
from station.kernel.limits_file import load_limits
from station.kernel.line_plan import LinePlan, line_rig_plan
from station.kernel.parameters import ParameterSet
from station.kernel.plan import RigPlan, default_plan
from station.physics.effects import Effects, EffectShapes
from station.session.model import Kind, Session

W200 = math.radians(200.0)
DEG = math.degrees(1.0)
SKIP_S = 0.5  # the moving average's span (0.4 s) at the start of a settled segment
TWO_RATES = replace(line_rig_plan(), rate_steps=tuple((a, s * r) for a in "zxy" for r in (50.0, 200.0)
                                                      for s in (1.0, -1.0)))
ROWS = (("two rates, tau + k2 + k3", TWO_RATES, ("tau", "poly")), ("two rates, tau only", TWO_RATES, ("tau",)),
        ("two rates, k2 + k3 only", TWO_RATES, ("poly",)),
        ("default line, tau + k2 + k3", line_rig_plan(), ("tau", "poly")), ("two rates, null", TWO_RATES, ()))


def planted(seed: int) -> tuple[float, np.ndarray, np.ndarray]:
    """The unit's time offset (s) and gyro k2 (1/(rad/s)), k3 (1/(rad/s)^2) per axis, from its seed."""
    rng = np.random.default_rng(np.random.SeedSequence([seed, 952]))
    tau = float(rng.choice([-1.0, 1.0]) * rng.uniform(1e-3, 5e-3))
    k2 = rng.choice([-1.0, 1.0], 3) * rng.uniform(0.5, 1.0, 3) * 1e-3 / W200
    k3 = rng.choice([-1.0, 1.0], 3) * rng.uniform(0.5, 1.0, 3) * 1e-3 / W200**2
    return tau, k2, k3


def recordings(generator: str, seed: int, rig: RigPlan, rack_s: float, tau: float, k2: np.ndarray,
               k3: np.ndarray) -> tuple[Session, Session, Session]:
    """Rack rest, rig part (one power-on) and a full-plan validation recording (another power-on)."""
    if generator == "indep":
        import gen_line_indep

        u = gen_line_indep.generate_unit(seed, rack_s=rack_s, hour_s=1.0, rig=replace(rig, rest_s=2.0),
                                         time_offset_s=tau, gyro_k2=k2, gyro_k3=k3)
        return u.rack, u.rig, u.val_full
    from station.sim.line_sim import simulate_line
    from station.sim.session_sim import simulate_session

    truth = Effects(time_offset=tau * 1e3).realize(EffectShapes.draw(np.random.default_rng(seed)))
    truth = replace(truth, gyro_quadratic=k2, gyro_cubic=k3)
    line = simulate_line(seed, plan=LinePlan(rack_s=rack_s, rig=rig), effect_truth=truth)
    val = simulate_session(seed + 202, plan=default_plan(), unit=line.truth, effect_truth=truth).session
    return line.rack, line.rig, val


def figures(val: Session, params: ParameterSet) -> dict[str, float]:
    out = correct_session(val, params)
    skip = round(SKIP_S * val.sample_rate_hz)
    pose = [out.accel_mps2[g.start + skip:g.stop].mean(axis=0) - val.ref_accel_mps2[g.start]
            for g in val.segments_of(Kind.POSE)]
    worst = 0.0
    for g in val.segments_of(Kind.RATE):
        ref = val.ref_gyro_radps[g.start]
        k = int(np.argmax(np.abs(ref)))
        worst = max(worst, abs(float(out.gyro_radps[g.start + skip:g.stop, k].mean()) - ref[k]) / abs(ref[k]) * 100)
    mask = np.isin(val.kind, [int(Kind.MOVE), int(Kind.RATE)])
    return {"pose": 1e3 * float(np.sqrt(np.mean(np.square(pose)))), "rate": worst,
            "held": DEG * held_out_error(val, params, mask, "gyro")}


def study(generator: str, seed: int, rig: RigPlan, plant: tuple[str, ...], rack_s: float, options: FitOptions
          ) -> dict[str, Any]:
    tau, k2, k3 = planted(seed)
    if "tau" not in plant:
        tau = 0.0
    if "poly" not in plant:
        k2, k3 = np.zeros(3), np.zeros(3)
    rack, rig_s, val = recordings(generator, seed, rig, rack_s, tau, k2, k3)
    found = fit_joint(rack, rig_s, replace(options, scale_nonlinearity="auto", time_offset="auto"))
    before = fit_joint(rack, rig_s, options)
    row: dict[str, Any] = {"with": figures(val, found), "without": figures(val, before), "tau": tau}
    note = found.quality.time_offset
    row["tau_status"] = note.status if note is not None else "-"
    row["tau_z"] = (found.time_offset_s - tau) / found.time_offset_std_s if found.time_offset_s else math.nan
    poly = found.quality.scale_nonlinearity
    row["poly_status"] = poly.status if poly is not None else "-"
    zs = []
    kept = [0, 0]
    for j, (name, true) in enumerate((("scale_quadratic", k2), ("scale_cubic", k3))):
        k, k_std = getattr(found.gyro, name), getattr(found.gyro, f"{name}_std")
        kept[j] = int(np.count_nonzero(k))
        on = k != 0
        zs += [float(v) for v in (k[on] - true[on]) / k_std[on]]
    row["kept"], row["z"] = kept, zs
    return row


def table(name: str, rows: list[dict[str, Any]]) -> str:
    def med(part: str, key: str) -> float:
        return float(np.median([r[part][key] for r in rows]))

    def rng(part: str, key: str) -> str:
        v = [r[part][key] for r in rows]
        return f"{min(v):.4g}-{max(v):.4g}"

    n = len(rows)
    tau_kept = sum(r["tau_status"] == "fitted" for r in rows)
    tz = [abs(r["tau_z"]) for r in rows if math.isfinite(r["tau_z"])]
    z = [abs(v) for r in rows for v in r["z"]]
    within = f"{sum(v <= 3 for v in z)}/{len(z)}" if z else "-"
    tau_within = f"{sum(v <= 3 for v in tz)}/{len(tz)}" if tz else "-"
    k2 = sum(r["kept"][0] for r in rows)
    k3 = sum(r["kept"][1] for r in rows)
    statuses = ", ".join(f"{s} {sum(r['poly_status'] == s for r in rows)}" for s in sorted({r["poly_status"]
                                                                                          for r in rows}))
    return (f"| {name} | {n} | {tau_kept}/{n} ({tau_within}) | {k2}/{3 * n}, {k3}/{3 * n} ({within}; {statuses}) | "
            f"{med('with', 'pose'):.3f} / {med('without', 'pose'):.3f} | "
            f"{med('with', 'rate'):.4f} / {med('without', 'rate'):.4f} ({rng('with', 'rate')} / "
            f"{rng('without', 'rate')}) | {med('with', 'held'):.4f} / {med('without', 'held'):.4f} "
            f"({rng('with', 'held')} / {rng('without', 'held')}) |")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--units", type=int, default=10, help="units per row")
    ap.add_argument("--seed0", type=int, default=700000, help="first seed (unit i: seed0 + 1000 i)")
    ap.add_argument("--rack-s", type=float, default=3600.0, help="rest in the rack from power-on (s)")
    ap.add_argument("--generator", choices=["indep", "sim"], default="indep")
    args = ap.parse_args()
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    options = FitOptions(tc_range_s=dict(load_limits().correlation_time_s))
    cpu0 = time.process_time()
    lines = []
    for name, rig, plant in ROWS:
        rows = []
        for i in range(args.units):
            seed = args.seed0 + 1000 * i
            r = study(args.generator, seed, rig, plant, args.rack_s, options)
            rows.append(r)
            print(f"  {name}, seed {seed}: tau {r['tau'] * 1e3:+.2f} ms {r['tau_status']} (z {r['tau_z']:+.2f}), "
                  f"polynomial {r['poly_status']} kept k2 {r['kept'][0]} k3 {r['kept'][1]}, max |z| "
                  f"{max((abs(v) for v in r['z']), default=math.nan):.2f}; rate error with/without "
                  f"{r['with']['rate']:.4f}/{r['without']['rate']:.4f} %, held-out {r['with']['held']:.4f}/"
                  f"{r['without']['held']:.4f} deg/s, pose {r['with']['pose']:.3f}/{r['without']['pose']:.3f} "
                  "mm/s^2", flush=True)
        lines.append(table(name, rows))
    print(f"\n{args.generator} generator, {args.units} units per row (seeds {args.seed0} + 1000 i), rack "
          f"{args.rack_s:.0f} s; with / without the found terms, medians (ranges):\n")
    print("| row | units | tau kept (within 3 sigma) | k2 kept, k3 kept axes (within 3 sigma; note status) "
          "| pose RMS (mm/s^2) | worst rate error (%) | held-out gyro error (deg/s) |")
    print("|---|---|---|---|---|---|---|")
    print("\n".join(lines))
    print(f"\nCPU time {time.process_time() - cpu0:.0f} s")


if __name__ == "__main__":
    main()
