"""Why the line's corrected pose RMS differs from the full plan's: the fit's part of the pose error, taken apart.

Per unit (``--source indep``: ``gen_line_indep.py``; ``--source sim``: ``station.sim`` as in ``bench_line.py``):
the full plan's rig fit and the line's joint fit, and on the validation recording (a full-plan power-on):

* ``pose``: the pose RMS of ``bench_line.pose_rms_mm`` (validation noise included);
* ``model``: the fit's part: per pose, the corrected *true mean output* ``M_true g + b_true(t)`` averaged over the
  pose's samples minus ``g``; RMS over poses and axes (no recording's noise or drift realization);
* ``m_part`` / ``b_part``: the same with the fit's bias replaced by the truth (the error of M alone) and with the
  fit's M replaced by the truth (the error of the bias model at the pose times alone);
* per accelerometer parameter: estimate - truth and its stated std (M in ppm, b in mm/s^2, T_c in s).

One JSON line per unit and fit to ``--out`` (appended), and a summary table::

    PYTHONPATH=. python benchmarks/line_pose_study.py --source indep --units 10 --seed0 7000000 --out X.jsonl
    PYTHONPATH=. python benchmarks/line_pose_study.py --summary X.jsonl
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import bench_line as bl

from station.fit.calibrate import FitOptions, fit_session
from station.fit.joint import fit_joint
from station.kernel.limits_file import load_limits
from station.kernel.line_plan import LinePlan
from station.kernel.plan import default_plan
from station.session.model import Kind, Session


class _Mixed:
    def __init__(self, m: np.ndarray, b: np.ndarray, d: np.ndarray, tc: np.ndarray) -> None:
        self.misalignment, self.bias_static, self.bias_drift, self.correlation_time_s = m, b, d, tc


def _triad(p: Any) -> tuple[np.ndarray, ...]:
    return tuple(np.asarray(getattr(p, n), dtype=float) for n in
                 ("misalignment", "bias_static", "bias_drift", "correlation_time_s"))


def pose_errors(fit: Any, truth: Any, s: Session) -> dict[str, np.ndarray]:
    """Per pose (6, 3), mm/s^2: the fit's part, its M part and its bias part (see the module docstring)."""
    ft, tt = _triad(fit), _triad(truth)
    out: dict[str, list[np.ndarray]] = {"model": [], "m_part": [], "b_part": [], "pose": []}
    x_meas = bl.correct(fit, s.t_s, s.accel_mps2)
    for g in s.segments_of(Kind.POSE):
        t = s.t_s[g.slice]
        ref = s.ref_accel_mps2[g.start]
        y = (tt[0] @ ref)[None, :] + bl.bias_at(truth, t)
        for name, p in (("model", fit), ("m_part", _Mixed(ft[0], *tt[1:])), ("b_part", _Mixed(tt[0], *ft[1:]))):
            out[name].append(1e3 * (bl.correct(p, t, y).mean(axis=0) - ref))
        out["pose"].append(1e3 * (x_meas[g.slice].mean(axis=0) - ref))
    return {k: np.array(v) for k, v in out.items()}


def _params(fit: Any, truth: Any) -> dict[str, Any]:
    ft, tt = _triad(fit), _triad(truth)
    d = {"dM_ppm": ((ft[0] - tt[0]) * 1e6).tolist(), "dM_ppm_std": (np.asarray(fit.misalignment_std) * 1e6).tolist(),
         "db_stat": ((ft[1] - tt[1]) * 1e3).tolist(), "db_stat_std": (np.asarray(fit.bias_static_std) * 1e3).tolist(),
         "db_drift": ((ft[2] - tt[2]) * 1e3).tolist(), "db_drift_std": (np.asarray(fit.bias_drift_std) * 1e3).tolist(),
         "dtc": (ft[3] - tt[3]).tolist(), "dtc_std": np.asarray(fit.correlation_time_s_std, dtype=float).tolist(),
         "tc_true": tt[3].tolist(), "b_drift_true": (tt[2] * 1e3).tolist()}
    return d


def study(seed: int, source: str, options: FitOptions, rack_s: float) -> list[dict[str, Any]]:
    if source == "indep":
        import gen_line_indep

        u = gen_line_indep.generate_unit(seed, rack_s=rack_s)
        truth = bl._Truth(u.unit.accel.m, u.unit.accel.b_stat, u.unit.accel.b_drift, u.unit.accel.tc)
        rack, rig, full_s, val = u.rack, u.rig, u.full, u.val_full
        extra = {"noise_mm": (u.unit.accel.sigma * 1e3).tolist()}
    else:
        from station.sim.line_sim import simulate_line
        from station.sim.session_sim import simulate_session

        line = simulate_line(seed, plan=LinePlan(rack_s=rack_s, rig=bl.line_rig(0.0)))
        truth = line.truth.accel
        rack, rig = line.rack, line.rig
        full_s = simulate_session(seed + 101, plan=default_plan(), unit=line.truth).session
        val = simulate_session(seed + 202, plan=default_plan(), unit=line.truth).session
        extra = {"noise_mm": (np.asarray(truth.noise_std) * 1e3).tolist()}
    rows = []
    for name, p in (("full", fit_session(full_s, options)), ("line", fit_joint(rack, rig, options))):
        e = pose_errors(p.accel, truth, val)
        rows.append({"seed": seed, "source": source, "fit": name, **{k: v.tolist() for k, v in e.items()},
                     **_params(p.accel, truth), **extra})
    e = pose_errors(truth, truth, val)
    rows.append({"seed": seed, "source": source, "fit": "truth", "pose": e["pose"].tolist(), **extra})
    return rows


def _rms(a: Any) -> float:
    return float(np.sqrt(np.mean(np.square(a))))


def summary(paths: list[Path]) -> None:
    rows = [json.loads(x.replace("dM_std_ppm", "dM_ppm_std")) for path in paths
            for x in path.read_text().splitlines() if x.strip()]
    for source in sorted({r["source"] for r in rows}):
        by = {(r["seed"], r["fit"]): r for r in rows if r["source"] == source}
        seeds = sorted({s for s, _ in by})
        print(f"\n{source}: {len(seeds)} units")
        print("| fit | pose RMS median | fit's part: median / RMS over units | M part RMS | bias part RMS "
              "| per axis fit's part RMS x / y / z | z of M / b_stat / b_drift / T_c (RMS) |")
        print("|---|---|---|---|---|---|---|")
        for fit in ("truth", "full", "line"):
            rs = [by[(s, fit)] for s in seeds if (s, fit) in by]
            pose = [_rms(r["pose"]) for r in rs]
            if fit == "truth":
                print(f"| {fit} | {np.median(pose):.3f} | | | | | |")
                continue
            model = [_rms(r["model"]) for r in rs]
            axes = np.array([np.sqrt(np.mean(np.square(r["model"]), axis=0)) for r in rs])
            zs = []
            for k in ("dM_ppm", "db_stat", "db_drift", "dtc"):
                z = np.concatenate([np.ravel(r[k]) / np.maximum(np.ravel(r[k + "_std"]), 1e-30) for r in rs])
                zs.append(_rms(z[np.isfinite(z)]))
            print(f"| {fit} | {np.median(pose):.3f} | {np.median(model):.3f} / {_rms(model):.3f} | "
                  f"{_rms([r['m_part'] for r in rs]):.3f} | {_rms([r['b_part'] for r in rs]):.3f} | "
                  + " / ".join(f"{_rms(axes[:, k]):.3f}" for k in range(3))
                  + " | " + " / ".join(f"{z:.2f}" for z in zs) + " |")
        full = np.array([_rms(by[(s, "full")]["pose"]) for s in seeds])
        line = np.array([_rms(by[(s, "line")]["pose"]) for s in seeds])
        fm = np.array([_rms(by[(s, "full")]["model"]) for s in seeds])
        lm = np.array([_rms(by[(s, "line")]["model"]) for s in seeds])
        print(f"fit's part, line / full, RMS over the units: {_rms(lm) / _rms(fm):.3f}")
        print(bl.ratio_noise(full, line))
        idx = np.random.default_rng(2).integers(0, len(seeds), (4000, 30))
        r30 = np.median(line[idx], axis=1) / np.median(full[idx], axis=1)
        print(f"30 units drawn from these: ratio of medians above 1.2 in {np.mean(r30 > 1.2) * 100:.1f} % of draws")
        for fit in ("full", "line"):
            per_pose = np.sqrt(np.mean([np.mean(np.square(by[(s, fit)]["model"]), axis=1) for s in seeds], axis=0))
            bias = np.sqrt(np.mean([np.mean(np.square(by[(s, fit)]["b_part"]), axis=1) for s in seeds], axis=0))
            print(f"  {fit}: fit's part per validation pose (in the plan's order) RMS {np.round(per_pose, 3)}, its "
                  f"bias part {np.round(bias, 3)} mm/s^2")
        for fit in ("full", "line"):
            rs = [by[(s, fit)] for s in seeds]
            for k, unit in (("db_stat", "mm/s^2"), ("db_drift", "mm/s^2"), ("dtc", "s")):
                err = np.array([r[k] for r in rs])
                std = np.array([r[k + "_std"] for r in rs], dtype=float)
                print(f"  {fit} {k}: RMS error per axis {np.round(np.sqrt(np.nanmean(err**2, axis=0)), 3)} {unit}, "
                      f"RMS stated {np.round(np.sqrt(np.nanmean(std**2, axis=0)), 3)}, mean error "
                      f"{np.round(np.nanmean(err, axis=0), 3)}")
            dm = np.array([r["dM_ppm"] for r in rs])
            print(f"  {fit} dM RMS (ppm):\n{np.round(np.sqrt(np.mean(dm**2, axis=0)), 1)}\n  mean (ppm):\n"
                  f"{np.round(np.mean(dm, axis=0), 1)}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--source", choices=["indep", "sim"], default="indep")
    ap.add_argument("--units", type=int, default=10)
    ap.add_argument("--seed0", type=int, default=7000000)
    ap.add_argument("--rack-s", type=float, default=3600.0)
    ap.add_argument("--out", type=Path)
    ap.add_argument("--summary", type=Path, nargs="+", help="summarize these files' units (pooled per source)")
    args = ap.parse_args()
    if args.summary:
        summary(args.summary)
        return
    limits = load_limits()
    options = FitOptions(tc_range_s=dict(limits.correlation_time_s))
    t0 = time.monotonic()
    for i in range(args.units):
        seed = args.seed0 + 1000 * i
        rows = study(seed, args.source, options, args.rack_s)
        with args.out.open("a") as f:
            for r in rows:
                f.write(json.dumps(r) + "\n")
        pr = {r["fit"]: _rms(r["pose"]) for r in rows}
        print(f"{args.source} {seed}: pose truth {pr['truth']:.3f} full {pr['full']:.3f} line {pr['line']:.3f} "
              f"({time.monotonic() - t0:.0f} s)", flush=True)
    summary([args.out])


if __name__ == "__main__":
    main()

