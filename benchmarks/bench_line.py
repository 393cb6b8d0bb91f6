"""The calibration line against the full rig plan: rig time per unit and verified accuracy.

Two parts, one command, one table each:

1. **Rig time per unit** at N = 1, 4, 16 units on one rig, for the full plan (300 s power-on
   rest, six 30 s poses, 18 rate steps of 12 s) and the line's rig part (a 2 s rest, six 25 s
   poses, +-100 deg/s about each axis held 3 s: :func:`station.kernel.line_plan.line_rig_plan`): the real station
   code on a simulated clock
   (:func:`bench_sequence.run_one`: a simulated Modbus rig on 127.0.0.1, sensors on ptys), rig time
   = station-clock seconds from start until the rig is confirmed at rest, divided by N.

2. **Verified accuracy** over ``--units`` simulated units (Table 1) drawn from report seeds
   (``--seed0``; the tests and development used seeds 1000-1049, 2001-2008 and 2001 here). Per unit,
   four independent recordings of the same unit (own noise and drift realization each):

   * the full plan's recording, fitted by the rig fit (:func:`station.fit.calibrate.fit_session`);
   * the line's rack rest (``--rack-s``, from power-on, unknown orientation) and rig recording of one
     power-on, fitted together (:func:`station.fit.joint.fit_joint`);
   * validation A, a full-plan recording: each fit corrects it (eq. 1 inverted with eq. 3's drift,
     Algorithm 1 without the moving average) and the corrected output is compared with the rig's
     reference: **pose RMS** (RMS over the six poses and three axes of the pose-mean specific-force
     error, mm/s^2), **worst rate-step error** (per unit the largest |mean rate about the step's axis -
     commanded| / commanded over the 18 steps, %; median and largest over the units), **first-minute
     error** (RMS over the first 60 s of the norm of
     10 s means of the specific-force error during the power-on rest, mm/s^2);
   * validation B, one hour at rest from power-on: **gyro bias error over the first hour** (RMS over
     the hour of the norm of 60 s means of the corrected rate; the true rate is 0: the simulation
     has no Earth rate by default), deg/s; also the fitted eq. 3 bias against the true one (same RMS,
     without the recording's noise and stochastic drift: ``model``).

   The row "truth" corrects with the unit's true parameters: the floor of each figure. Below the table: the pose
   RMS ratio (line / full) with a paired bootstrap over the units (:func:`ratio_noise`); why the figure is noisy
   and what the line's fit gives up: ``line_pose_study.py``.

3. **Predicted against measured accuracy** (``--parts predict``; ``line_predict.py``): the plan designer's
   predicted standard uncertainties per parameter group against the RMS error (estimate - truth) over
   ``--predict-units`` units (seeds ``--predict-seed0`` + 1000 i).

4. **The same accuracy on an independent generator** (``--parts indep``; ``gen_line_indep.py``: its own
   kinematics, sampling, unit draw and noise): per unit the line's rack rest and rig part, a full-plan recording
   and the two validation recordings, the same figures as part 2 (no ``model-only`` column).

5. **Line throughput** (``--parts throughput``; ``line_throughput.py``): a ``--rack-slots`` rack and one rig at
   ``--line-rig-units``, from the plan designer and from a simulated run of the rack and rig roles.

``--rack-orientation +z`` (parts 2 and 4): the rack holds every unit +z up, tilted by up to ``--rack-tilt-deg``
(station.sim: a tilt angle uniform in [0, max] about a random horizontal axis; the independent generator: rotation
vector components uniform in +-max), and the line's joint fit ties the rack's level along gravity to its norm
(``fit_joint(..., rack_orientation="+z")``); the row "line, free offsets" fits the same recordings with free rack
offsets on every axis (``rack_orientation="free"``). The validation's power-on rest is also +z up: that comparison
is the one this rack is built for. With the default rack of any orientation the "line" row is the fit of ``"any"``
(the level along gravity tied to its norm when the rest is found on a face, see :mod:`station.fit.joint`) and part 2
also prints "line, free offsets"; ``--any-tilt-deg`` tilts part 2's slots up to that against their face (the
simulated rack is level).

6. **Overhead** (``--parts overhead``, not in the default parts): rig time at N=1 of the line's rig part with
   the rate axes in the order x, y, z and z-first (one tumble less), against the trajectory's duration, at the
   clock scales ``--overhead-scales``.

    PYTHONPATH=. python benchmarks/bench_line.py [--parts rig accuracy indep predict throughput] [--units 30]
        [--seed0 900000] [--rig-units 1 4 16] [--predict-units 20] [--predict-seed0 N] [--rack-slots 64]
        [--line-rig-units 16] [--throughput-rate 10]
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

from station.fit.calibrate import FitOptions, fit_session
from station.fit.joint import FREE_OFFSETS, fit_joint
from station.kernel.limits_file import load_limits
from station.kernel.line_plan import LinePlan, line_rig_plan
from station.kernel.parameters import ParameterSet
from station.kernel.plan import RigPlan, default_plan
from station.physics.unit import UnitTruth
from station.session.model import Kind, Session
from station.sim.line_sim import simulate_line
from station.sim.session_sim import simulate_session

_DEG = 180.0 / math.pi


def line_rig(rest_s: float = 2.0) -> RigPlan:
    """The line's rig part as the sequence runs it: a short rest first (the runner's first step)."""
    return replace(line_rig_plan(), rest_s=rest_s)


# --- correction ------------------------------------------------------------------------------------

def _triad_model(p: object) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    m = np.asarray(p.misalignment, dtype=float)  # type: ignore[attr-defined]
    b = np.asarray(p.bias_static, dtype=float)  # type: ignore[attr-defined]
    d = np.asarray(p.bias_drift, dtype=float)  # type: ignore[attr-defined]
    tc = np.asarray(p.correlation_time_s, dtype=float)  # type: ignore[attr-defined]
    d = np.where(np.isfinite(tc), d, 0.0)
    tc = np.where(np.isfinite(tc) & (tc > 0), tc, 1.0)
    return m, b, d, tc


def bias_at(p: object, t: np.ndarray) -> np.ndarray:
    _, b, d, tc = _triad_model(p)
    return b + d * np.exp(-t[:, None] / tc)


def correct(p: object, t: np.ndarray, y: np.ndarray) -> np.ndarray:
    """x = M^-1 (y - b_stat - b_drift exp(-t/T_c)): eq. 1 inverted (Algorithm 1 lines 4-6 and 8)."""
    m = _triad_model(p)[0]
    return np.linalg.solve(m, (y - bias_at(p, t)).T).T


# --- figures ---------------------------------------------------------------------------------------

def pose_rms_mm(acc: object, s: Session) -> float:
    x = correct(acc, s.t_s, s.accel_mps2)
    errs = [x[g.slice].mean(axis=0) - s.ref_accel_mps2[g.start] for g in s.segments_of(Kind.POSE)]
    return 1e3 * float(np.sqrt(np.mean(np.square(errs))))


def worst_rate_pct(gyr: object, s: Session) -> float:
    x = correct(gyr, s.t_s, s.gyro_radps)
    worst = 0.0
    for g in s.segments_of(Kind.RATE):
        ref = s.ref_gyro_radps[g.start]
        k = int(np.argmax(np.abs(ref)))
        worst = max(worst, abs(float(x[g.slice, k].mean()) - ref[k]) / abs(ref[k]) * 100.0)
    return worst


def first_minute_mm(acc: object, s: Session) -> float:
    rest = s.segments_of(Kind.REST)[0]
    sel = np.arange(rest.start, rest.stop)[s.t_s[rest.start:rest.stop] < 60.0]
    err = correct(acc, s.t_s[sel], s.accel_mps2[sel]) - s.ref_accel_mps2[sel]
    n = round(10.0 * s.sample_rate_hz)
    k = len(err) // n
    means = err[: k * n].reshape(k, n, 3).mean(axis=1)
    return 1e3 * float(np.sqrt(np.mean(np.sum(means**2, axis=1))))


def minute_model_mm(acc: object, truth: object, s: Session, *, any_pose: bool = False) -> float:
    """The first-minute error without the validation recording's noise and drift realization: RMS over the
    first 60 s of |corrected - reference| for the true mean output ``M_true g + b_true(t)`` in the orientation of
    ``s``'s power-on rest (what the fit contributes to :func:`first_minute_mm`; the rest is the floor).
    ``any_pose``: RMS over a power-on in each of the six orientations +-x, +-y, +-z instead (the full plan's own
    rest is in the validation's orientation, the line's rack in an unknown one)."""
    rest = s.segments_of(Kind.REST)[0]
    g0 = s.ref_accel_mps2[rest.start]
    ups = [g0] if not any_pose else [sign * float(np.linalg.norm(g0)) * e for e in np.eye(3) for sign in (1.0, -1.0)]
    t = np.arange(0.0, 60.0, 0.5)
    sq = []
    for g in ups:
        y = (_triad_model(truth)[0] @ g)[None, :] + bias_at(truth, t)
        sq.append(np.mean(np.sum((correct(acc, t, y) - g) ** 2, axis=1)))
    return 1e3 * float(np.sqrt(np.mean(sq)))


def gyro_hour_dps(gyr: object, s: Session) -> float:
    x = correct(gyr, s.t_s, s.gyro_radps)
    n = round(60.0 * s.sample_rate_hz)
    k = len(x) // n
    means = x[: k * n].reshape(k, n, 3).mean(axis=1)
    return _DEG * float(np.sqrt(np.mean(np.sum(means**2, axis=1))))


def gyro_model_dps(gyr: object, truth: UnitTruth, hour_s: float = 3600.0) -> float:
    t = np.arange(0.0, hour_s, 10.0)
    m = _triad_model(gyr)[0]
    e = np.linalg.solve(m, (truth.gyro.bias_at(t) - bias_at(gyr, t)).T).T
    return _DEG * float(np.sqrt(np.mean(np.sum(e**2, axis=1))))


# --- part 1: rig time ------------------------------------------------------------------------------

def rig_times(units: list[int], scale: float, max_frames: float) -> list[dict[str, object]]:
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    import bench_sequence

    rows = []
    for name, plan in (("full", default_plan()), ("line", line_rig())):
        for n in units:
            s = min(scale, max_frames / (n * plan.sample_rate_hz))
            original = bench_sequence.default_plan
            bench_sequence.default_plan = lambda p=plan: p  # type: ignore[assignment]
            try:
                r = bench_sequence.run_one(n, s, 1)
            finally:
                bench_sequence.default_plan = original  # type: ignore[assignment]
            rows.append({"plan": name, **r})
            note = " of a fit of the rig recording alone (this runner has no rack recording)" if name == "line" else ""
            print(f"  {name:5s} N={n:2d}: rig {float(r['rig_s']):7.1f} s, per unit {float(r['rig_s']) / n:6.1f} s, "
                  f"{r['outcome']}{note} ({float(r['wall_s']):.0f} s wall)", flush=True)
    return rows


def rig_seconds(plan: RigPlan, n: int, scale: float) -> float:
    """Rig time of one run of ``plan`` with ``n`` units at clock ``scale`` (the plain sequence runner)."""
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    import bench_sequence

    original = bench_sequence.default_plan
    bench_sequence.default_plan = lambda p=plan: p  # type: ignore[assignment]
    try:
        return float(bench_sequence.run_one(n, scale, 1)["rig_s"])  # type: ignore[arg-type]
    finally:
        bench_sequence.default_plan = original  # type: ignore[assignment]


def overhead(scales: list[float]) -> None:
    """Rig time at N=1 of the line's rig part with the rate axes in the order x, y, z (before) and z upside down
    first (after: one tumble less), against the trajectory's own duration; at the given clock scales (a fast
    simulated clock stretches every command round trip and poll by its scale)."""
    from station.physics.trajectory import build_trajectory

    after = line_rig()
    before = replace(after, rate_steps=tuple((a, s_ * 100.0) for a in "xyz" for s_ in (1.0, -1.0)), rate_flip=())
    print("\n| rate axes | trajectory s | " + " | ".join(f"rig s at x{sc:g} (overhead)" for sc in scales) + " |")
    print("|---|---|" + "---|" * len(scales))
    for name, plan in (("x, y, z (before)", before), ("z upside down, x, y (after)", after)):
        traj = build_trajectory(plan).duration_s
        cells = []
        for sc in scales:
            rig = rig_seconds(plan, 1, sc)
            cells.append(f"{rig:.1f} ({rig - traj:+.1f})")
        print(f"| {name} | {traj:.1f} | " + " | ".join(cells) + " |", flush=True)


# --- part 2: accuracy ------------------------------------------------------------------------------

def study_unit(seed: int, rack_s: float, options: FitOptions, rack_orientation: str = "any",
               rack_tilt_deg: float = 3.0, any_tilt_deg: float = 0.0) -> dict[str, dict[str, float]]:
    line = simulate_line(seed, plan=LinePlan(rack_s=rack_s, rig=line_rig(0.0), rack_orientation=rack_orientation),
                         rack_tilt_deg=rack_tilt_deg, any_tilt_deg=any_tilt_deg)
    truth = line.truth
    full = simulate_session(seed + 101, plan=default_plan(), unit=truth).session
    val_a = simulate_session(seed + 202, plan=default_plan(), unit=truth).session
    val_b = simulate_session(seed + 303, plan=replace(default_plan(), rest_s=3600.0, poses=(), rate_steps=()),
                             unit=truth).session
    fits: dict[str, object] = {
        "truth": truth,
        "full": fit_session(full, options),
        "line": fit_joint(line.rack, line.rig, options, rack_orientation=rack_orientation,
                          rack_tilt_tolerance_deg=_tolerance(rack_tilt_deg)),
    }
    fits["line, free offsets"] = fit_joint(line.rack, line.rig, options, rack_orientation=FREE_OFFSETS)
    out: dict[str, dict[str, float]] = {}
    for name, p in fits.items():
        acc, gyr = p.accel, p.gyro  # type: ignore[attr-defined]
        out[name] = {
            "pose": pose_rms_mm(acc, val_a),
            "rate": worst_rate_pct(gyr, val_a),
            "minute": first_minute_mm(acc, val_a),
            "minute_model": minute_model_mm(acc, truth.accel, val_a),
            "minute_any": minute_model_mm(acc, truth.accel, val_a, any_pose=True),
            "gyro_hour": gyro_hour_dps(gyr, val_b),
            "gyro_model": gyro_model_dps(gyr, truth),
        }
        if isinstance(p, ParameterSet):
            out[name]["gyro_bstat_u"] = float(np.max(p.gyro.bias_static_std)) * _DEG
            out[name]["gyro_tc_resolved"] = float(np.isfinite(p.gyro.correlation_time_s).sum())
    return out


class _Truth:
    """A triad's true eq. 1 + eq. 3 parameters, in the names the correction reads."""

    def __init__(self, m: np.ndarray, b_stat: np.ndarray, b_drift: np.ndarray, tc: np.ndarray) -> None:
        self.misalignment, self.bias_static, self.bias_drift, self.correlation_time_s = m, b_stat, b_drift, tc


def _tolerance(rack_tilt_deg: float) -> float:
    """The fit's tilt tolerance for a rack of tilts up to ``rack_tilt_deg`` per component: the plan's 5 deg, or
    what the drawn tilts can reach."""
    return max(5.0, math.sqrt(2.0) * rack_tilt_deg + 0.5)


def study_unit_indep(seed: int, rack_s: float, options: FitOptions, rack_orientation: str = "any",
                     rack_tilt_deg: float = 3.0) -> dict[str, dict[str, float]]:
    """:func:`study_unit` on recordings of the independent generator (``gen_line_indep.py``; its rack is near
    +z up, tilts up to 25 deg per component for ``"any"``, ``rack_tilt_deg`` for ``"+z"``)."""
    import gen_line_indep

    if rack_orientation not in ("any", "+z"):
        raise SystemExit("the independent generator's rack is near +z: --rack-orientation any or +z")
    u = gen_line_indep.generate_unit(seed, rack_s=rack_s, rack_tilt_deg=25.0 if rack_orientation == "any"
                                     else rack_tilt_deg)
    truth = tuple(_Truth(t.m, t.b_stat, t.b_drift, t.tc) for t in (u.unit.accel, u.unit.gyro))
    full = fit_session(u.full, options)
    line = fit_joint(u.rack, u.rig, options, rack_orientation=rack_orientation,
                     rack_tilt_tolerance_deg=_tolerance(rack_tilt_deg))
    rows: list[tuple[str, Any, Any]] = [("truth", truth, None), ("full", (full.accel, full.gyro), full),
                                        ("line", (line.accel, line.gyro), line)]
    if rack_orientation != "any":  # (a rack of any orientation here is tilted up to 25 deg: rarely on a face)
        free = fit_joint(u.rack, u.rig, options, rack_orientation=FREE_OFFSETS)
        rows.append(("line, free offsets", (free.accel, free.gyro), free))
    out: dict[str, dict[str, float]] = {}
    for name, (acc, gyr), p in rows:
        out[name] = {"pose": pose_rms_mm(acc, u.val_full), "rate": worst_rate_pct(gyr, u.val_full),
                     "minute": first_minute_mm(acc, u.val_full),
                     "minute_model": minute_model_mm(acc, truth[0], u.val_full),
                     "minute_any": minute_model_mm(acc, truth[0], u.val_full, any_pose=True),
                     "gyro_hour": gyro_hour_dps(gyr, u.val_hour)}
        if p is not None:
            out[name]["gyro_tc_resolved"] = float(np.isfinite(p.gyro.correlation_time_s).sum())
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--units", type=int, default=30, help="simulated units for the accuracy part")
    ap.add_argument("--seed0", type=int, default=900000, help="first report seed (units use seed0 + 1000 i)")
    ap.add_argument("--rack-s", type=float, default=3600.0, help="rest in the rack from power-on (s)")
    ap.add_argument("--rig-units", type=int, nargs="*", default=[1, 4, 16], help="N for the rig-time part (none: skip)")
    ap.add_argument("--scale", type=float, default=30.0)
    ap.add_argument("--max-frames", type=float, default=12000.0)
    ap.add_argument("--parts", nargs="+", default=["rig", "accuracy", "indep", "predict", "throughput"],
                    choices=["rig", "accuracy", "indep", "predict", "throughput", "overhead"])
    ap.add_argument("--overhead-scales", type=float, nargs="+", default=[30.0, 5.0])
    ap.add_argument("--predict-units", type=int, default=20)
    ap.add_argument("--predict-seed0", type=int, default=910000)
    ap.add_argument("--rack-slots", type=int, default=64)
    ap.add_argument("--line-rig-units", type=int, default=16)
    ap.add_argument("--throughput-rate", type=int, default=10, help="sample rate of the throughput run (Hz)")
    ap.add_argument("--rack-orientation", default="any", help="'any' (the default line) or '+z' (see part 5 above)")
    ap.add_argument("--rack-tilt-deg", type=float, default=3.0, help="largest slot tilt with --rack-orientation +z")
    ap.add_argument("--any-tilt-deg", type=float, default=0.0,
                    help="accuracy part, rack of any orientation: slots tilted up to this (deg) against the face the "
                         "unit lies on (0: level, as the simulated rack)")
    args = ap.parse_args()

    t0 = time.monotonic()
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    if "predict" in args.parts:
        import line_predict

        limits = load_limits()
        seeds = [args.predict_seed0 + 1000 * i for i in range(args.predict_units)]
        rows = line_predict.compare(LinePlan(rack_s=args.rack_s, rig=line_rig(0.0)),
                                    FitOptions(tc_range_s=dict(limits.correlation_time_s)), seeds)
        line_predict.print_table(rows, len(seeds))
    if "throughput" in args.parts:
        import line_throughput

        from station.kernel.line_plan import load_line_plan_file

        lf = load_line_plan_file(None)
        lf = replace(lf, plan=replace(lf.plan, rack_s=args.rack_s))
        run = line_throughput.simulate(lf, rack_slots=args.rack_slots, rig_units=args.line_rig_units,
                                       rate_hz=args.throughput_rate, max_frames=args.max_frames)
        line_throughput.print_table(lf, run, args.throughput_rate)
    if "overhead" in args.parts:
        overhead(args.overhead_scales)
    if args.rig_units and "rig" in args.parts:
        print("rig time (real station code, simulated rig and sensors):", flush=True)
        rows = rig_times(args.rig_units, args.scale, args.max_frames)
        print("\n| plan | " + " | ".join(f"N={n}" for n in args.rig_units) + " |")
        print("|---|" + "---|" * len(args.rig_units))
        for name in ("full", "line"):
            cells = [f"{float(r['rig_s']) / int(r['n']):.0f} s"  # type: ignore[call-overload]
                     for r in rows if r["plan"] == name]
            print(f"| {name} | " + " | ".join(cells) + " |")
        print()

    limits = load_limits()
    options = FitOptions(tc_range_s=dict(limits.correlation_time_s))
    for part, study, label in (("accuracy", study_unit, "station.sim"),
                               ("indep", study_unit_indep, "the independent generator (gen_line_indep.py)")):
        if part not in args.parts:
            continue
        per: dict[str, dict[str, list[float]]] = {}
        for i in range(args.units):
            seed = args.seed0 + 1000 * i
            res = study(seed, args.rack_s, options, args.rack_orientation, args.rack_tilt_deg,
                        **({"any_tilt_deg": args.any_tilt_deg} if part == "accuracy" else {}))
            for name, figs in res.items():
                for k, v in figs.items():
                    per.setdefault(name, {}).setdefault(k, []).append(v)
            print(f"  {part} unit {i + 1}/{args.units} (seed {seed}): pose full {res['full']['pose']:.3f} line "
                  f"{res['line']['pose']:.3f} mm/s^2; gyro hour full {res['full']['gyro_hour']:.4f} line "
                  f"{res['line']['gyro_hour']:.4f} deg/s; first minute full {res['full']['minute']:.3f} line "
                  f"{res['line']['minute']:.3f} mm/s^2", flush=True)
        print(f"\naccuracy on {label}, {args.units} units (seeds {args.seed0} + 1000 i), rack {args.rack_s:.0f} s, "
              f"rack orientation {args.rack_orientation}:\n")
        accuracy_table(per)
    print(f"wall time {time.monotonic() - t0:.0f} s")


def ratio_noise(full: np.ndarray, line: np.ndarray, draws: int = 4000, sizes: tuple[int, ...] = (30, 60, 100)) -> str:
    """How well these units determine the ratio of the median pose RMS (line / full): the ratio, a paired
    bootstrap over the units (90 % interval), the same for other numbers of units (these units' pairs resampled to
    that size), the median per-unit ratio, how often the line is better, and the per-unit log ratio's mean and std."""
    rng = np.random.default_rng(1)
    n = len(full)
    parts = []
    for size in (n, *(s for s in sizes if s != n)):
        idx = rng.integers(0, n, (draws, size))
        r = np.median(line[idx], axis=1) / np.median(full[idx], axis=1)
        lo, hi = np.percentile(r, [5, 95])
        parts.append(f"{size} units {lo:.3f}-{hi:.3f}")
    lr = np.log(line / full)
    sd = float(lr.std(ddof=1)) if n > 1 else math.nan
    return (f"ratio of medians {np.median(line) / np.median(full):.3f}; bootstrap 90 % ({'; '.join(parts)}); "
            f"median per-unit ratio {np.median(line / full):.3f}; line better on {int(np.sum(line < full))} of {n}; "
            f"per-unit log ratio mean {lr.mean():+.3f}, std {sd:.3f}")


def accuracy_table(per: dict[str, dict[str, list[float]]]) -> None:
    def med(name: str, k: str) -> float:
        return float(np.median(per[name][k]))

    def p90(name: str, k: str) -> float:
        return float(np.percentile(per[name][k], 90))

    print("| fit | pose RMS median (mm/s^2) | vs full | worst rate error median / max (%) "
          "| first minute median (mm/s^2) | first minute, fit's part: median / RMS (mm/s^2) "
          "| the same, any of six orientations: median / RMS (mm/s^2) "
          "| gyro bias 1st hour median / p90 (deg/s) | model-only median / p90 (deg/s) | gyro T_c resolved |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for name in [n for n in ("truth", "full", "line", "line, free offsets") if n in per]:
        resolved = (f"{np.mean(per[name]['gyro_tc_resolved']) / 3 * 100:.0f} % of axes"
                    if "gyro_tc_resolved" in per[name] else "-")
        model = (f"{med(name, 'gyro_model'):.5f} / {p90(name, 'gyro_model'):.5f}" if "gyro_model" in per[name]
                 else "-")
        print(f"| {name} | {med(name, 'pose'):.3f} | {med(name, 'pose') / med('full', 'pose'):.2f} | "
              f"{med(name, 'rate'):.4f} / {max(per[name]['rate']):.4f} | {med(name, 'minute'):.3f} | "
              f"{med(name, 'minute_model'):.3f} / {np.sqrt(np.mean(np.square(per[name]['minute_model']))):.3f} | "
              f"{med(name, 'minute_any'):.3f} / {np.sqrt(np.mean(np.square(per[name]['minute_any']))):.3f} | "
              f"{med(name, 'gyro_hour'):.5f} / {p90(name, 'gyro_hour'):.5f} | {model} | {resolved} |")
    print("\npose RMS, line / full: " + ratio_noise(np.array(per["full"]["pose"]), np.array(per["line"]["pose"])))
    g = (med("full", "gyro_hour") / med("line", "gyro_hour"), p90("full", "gyro_hour") / p90("line", "gyro_hour"))
    print(f"\ngyro bias over the first hour, full / line: median {g[0]:.2f}x, p90 {g[1]:.2f}x")


if __name__ == "__main__":
    main()
