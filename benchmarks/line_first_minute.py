"""Why the line's first minute after power-on is worse than the full plan's: the fit's part of the error, taken apart.

Per unit (``station.sim``, the seeds of ``bench_line.py``): the full plan's rig fit and the line's joint fit (1 h
rack + rig part), and the fit's part of the first-minute error (``bench_line.minute_model_mm``: the corrected true
mean output over the first 60 s after a power-on in the validation's orientation, +z up, without any recording's
noise), also with parts of the line's estimate replaced by the truth, with the rack's rest cut into 5 s runs
for its first 300 s (finer blocks of the warm-up), and with the rack's orientation known (its true gravity vector
as the rest's reference, both recordings through the rig fit: what a rack of known slot orientation could
give). Per axis: errors of b_stat and b_drift (estimate - truth)
against their stated stds, their correlation, and the correlation of the bias error at 30 s with the error of
``M g`` in the validation's orientation (how much the two cancel in the corrected output).

    PYTHONPATH=. python benchmarks/line_first_minute.py --units 30 --seed0 3359000
        [--rack-orientation +z --rack-tilt-deg 3 [--no-fine]] [--any-tilt-deg 3] [--pose-hold-s 45] [--indep]

The row "line" has free rack offsets (``rack_orientation="free"``) and the rows with parts from the truth are built
on it; with the default rack of any orientation the fit of ``"any"`` (a rest found on a face tied to the norm of
gravity) is its own row, and ``--any-tilt-deg`` tilts the slots against their face (the simulated rack is level).
"M and b_stat true" leaves the warm-up's shape alone, "b_drift and T_c true" the rig's level at +z alone.

``--rack-orientation +z``: the rack holds every unit +z up, tilted up to ``--rack-tilt-deg``, and the line is
also fitted with the rack's level along gravity tied to its norm (``fit_joint(..., rack_orientation="+z")``).
``--indep``: instead, on the independent generator (``gen_line_indep.py``, its rack +z up with rotation-vector
components uniform in +-``--rack-tilt-deg``): the fit's part at +z per axis for the full plan, the line with free
offsets and the line with the tie.
"""

from __future__ import annotations

import argparse
import itertools
import sys
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import bench_line as bl

import station.fit.joint as joint
from station.fit.calibrate import FitOptions, fit_session
from station.kernel.limits_file import load_limits
from station.kernel.line_plan import LinePlan
from station.kernel.plan import default_plan
from station.session.model import Kind, Session
from station.sim.line_sim import simulate_line
from station.sim.session_sim import simulate_session

_NAMES = ("misalignment", "bias_static", "bias_drift", "correlation_time_s")


class _Mixed:
    """A triad's parameters, some taken from the truth."""

    def __init__(self, fit: Any, truth: Any, from_truth: tuple[str, ...]) -> None:
        for name in _NAMES:
            setattr(self, name, np.asarray(getattr(truth if name in from_truth else fit, name), dtype=float))


def fine_rack_runs(
    rack: Session, offset: int, fine_s: float = 5.0, until_s: float = 300.0
) -> list[tuple[int, int, int]]:
    """The rack's rest in ``fine_s`` runs up to ``until_s``, then runs doubling in length (cf. ``joint._rack_runs``)."""
    runs = []
    for seg in rack.segments_of(Kind.REST, Kind.POSE):
        t = rack.t_s[seg.start:seg.stop]
        bounds = list(np.arange(t[0] + fine_s, min(until_s, t[-1]), fine_s))
        b, length = (bounds[-1] if bounds else float(t[0])), 2.0 * fine_s
        while b + length < t[-1]:
            b += length
            bounds.append(b)
            length *= 2.0
        edges = sorted({0, len(t), *(int(np.searchsorted(t, x)) for x in bounds)})
        runs.extend((seg.index, offset + seg.start + a, offset + seg.start + c) for a, c in itertools.pairwise(edges))
    return runs


def _with_known_rack(rack: Session, rig: Session, gravity: np.ndarray) -> Session:
    """One recording of both, the rack's rest with ``gravity`` (its true specific force) as its reference."""
    n = len(rack)

    def cat(name: str) -> np.ndarray:
        return np.concatenate([getattr(rack, name), getattr(rig, name)])

    return Session(metadata={**rig.metadata}, t_s=cat("t_s"), segment=np.concatenate([rack.segment + 500_000,
                   rig.segment]), kind=cat("kind"), accel_mps2=cat("accel_mps2"), gyro_radps=cat("gyro_radps"),
                   temp_degc=cat("temp_degc"), ref_accel_mps2=np.concatenate([np.tile(gravity, (n, 1)),
                                                                              rig.ref_accel_mps2]),
                   ref_gyro_radps=np.concatenate([np.zeros((n, 3)), rig.ref_gyro_radps]))


def indep_axes(seed0: int, units: int, tilt_deg: float, opts: FitOptions) -> None:
    """The fit's part of the first-minute error at +z per axis on the independent generator (see the docstring)."""
    import gen_line_indep

    res: dict[str, list[np.ndarray]] = {}
    t = np.arange(0.0, 60.0, 0.5)
    for i in range(units):
        seed = seed0 + 1000 * i
        u = gen_line_indep.generate_unit(seed, rack_tilt_deg=tilt_deg)
        truth = bl._Truth(u.unit.accel.m, u.unit.accel.b_stat, u.unit.accel.b_drift, u.unit.accel.tc)
        fits = {"full": fit_session(u.full, opts).accel,
                "line, free offsets": joint.fit_joint(u.rack, u.rig, opts, rack_orientation=joint.FREE_OFFSETS).accel,
                "line, tied": joint.fit_joint(u.rack, u.rig, opts, rack_orientation="+z",
                                              rack_tilt_tolerance_deg=bl._tolerance(tilt_deg)).accel}
        g = u.val_full.ref_accel_mps2[u.val_full.segments_of(Kind.REST)[0].start]
        y = (truth.misalignment @ g)[None, :] + bl.bias_at(truth, t)
        for label, p in fits.items():
            res.setdefault(label, []).append(1e3 * np.sqrt(np.mean((bl.correct(p, t, y) - g) ** 2, axis=0)))
        print(f"  unit {i + 1}/{units} (seed {seed})", flush=True)
    print(f"\nindependent generator, {units} units (seeds {seed0} + 1000 i), rack +z up within +-{tilt_deg:g} deg "
          "per rotation-vector component:\n")
    print("| fit | fit's part at +z, norm: median (mm/s^2) | per axis x / y / z, RMS (mm/s^2) |")
    print("|---|---|---|")
    for label, v in res.items():
        a = np.array(v)
        print(f"| {label} | {np.median(np.linalg.norm(a, axis=1)):.3f} | "
              f"{' / '.join(f'{x:.3f}' for x in np.sqrt(np.mean(a**2, axis=0)))} |")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--units", type=int, default=30)
    ap.add_argument("--seed0", type=int, default=3359000)
    ap.add_argument("--rack-orientation", default="any",
                    help="how the simulated rack holds its units: 'any' (one of six poses at random, level) or a pose "
                         "such as '+z' (that pose, tilted up to --rack-tilt-deg); the line is also fitted with the "
                         "rack's level tied to gravity's norm then")
    ap.add_argument("--rack-tilt-deg", type=float, default=3.0)
    ap.add_argument("--any-tilt-deg", type=float, default=0.0,
                    help="with --rack-orientation any: slots tilted up to this (deg) against the face the unit lies on")
    ap.add_argument("--pose-hold-s", type=float, default=25.0, help="the line's rig poses' hold (s; the line's: 25)")
    ap.add_argument("--no-fine", action="store_true", help="skip the rack-in-5-s-runs variant")
    ap.add_argument("--indep", action="store_true", help="per-axis figures on the independent generator instead")
    args = ap.parse_args()
    limits = load_limits()
    opts = FitOptions(tc_range_s=dict(limits.correlation_time_s))
    if args.indep:
        indep_axes(args.seed0, args.units, args.rack_tilt_deg, opts)
        return
    fig: dict[str, list[float]] = {}
    ax: dict[str, list[np.ndarray]] = {}
    t30 = np.array([30.0])
    for i in range(args.units):
        seed = args.seed0 + 1000 * i
        rig = replace(bl.line_rig(0.0), pose_hold_s=args.pose_hold_s)
        line = simulate_line(seed, plan=LinePlan(rack_s=3600.0, rig=rig, rack_orientation=args.rack_orientation),
                             rack_tilt_deg=args.rack_tilt_deg, any_tilt_deg=args.any_tilt_deg)
        truth = line.truth.accel
        full_s = simulate_session(seed + 101, plan=default_plan(), unit=line.truth).session
        val = simulate_session(seed + 202, plan=default_plan(), unit=line.truth).session
        fits = {"full": fit_session(full_s, opts).accel,
                "line": joint.fit_joint(line.rack, line.rig, opts, rack_orientation=joint.FREE_OFFSETS).accel}
        if args.rack_orientation == "any":
            fits["line, the face found up, its level tied to gravity's norm (the default 'any')"] = \
                joint.fit_joint(line.rack, line.rig, opts).accel
        else:
            fits["line, rack level along gravity tied to its norm"] = joint.fit_joint(
                line.rack, line.rig, opts, rack_orientation=args.rack_orientation,
                rack_tilt_tolerance_deg=max(5.0, args.rack_tilt_deg)).accel
        if not args.no_fine:
            original = joint._rack_runs
            joint._rack_runs = fine_rack_runs  # type: ignore[assignment]
            try:
                fits["line, rack in 5 s runs for 300 s"] = joint.fit_joint(
                    line.rack, line.rig, opts, rack_orientation=joint.FREE_OFFSETS).accel
            finally:
                joint._rack_runs = original  # type: ignore[assignment]
        # what a rack of known orientation would give: its rest with the true gravity vector as a reference, both
        # recordings through the rig fit (its own blocks, no rack offsets): an upper bound of that remedy's effect
        fits["line, rack orientation known (rig fit over both)"] = fit_session(
            _with_known_rack(line.rack, line.rig, line.rack_specific_force()), opts).accel
        rows: dict[str, Any] = dict(fits)
        for label, names in (("line, b_drift and T_c true", ("bias_drift", "correlation_time_s")),
                             ("line, b_drift true", ("bias_drift",)), ("line, T_c true", ("correlation_time_s",)),
                             ("line, M true", ("misalignment",)), ("line, b_stat true", ("bias_static",)),
                             ("line, M and b_stat true (the warm-up's shape alone)",
                              ("misalignment", "bias_static"))):
            rows[label] = _Mixed(fits["line"], truth, names)
        rows["full, M and b_stat true (the warm-up's shape alone)"] = _Mixed(fits["full"], truth,
                                                                           ("misalignment", "bias_static"))
        g = val.ref_accel_mps2[val.segments_of(Kind.REST)[0].start]
        for label, p in rows.items():
            fig.setdefault(label, []).append(bl.minute_model_mm(p, truth, val))
            y = (truth.misalignment @ g)[None, :] + truth.bias_at(np.arange(0.0, 60.0, 0.5))
            e = bl.correct(p, np.arange(0.0, 60.0, 0.5), y) - g
            ax.setdefault("per-axis:" + label, []).append(1e3 * np.sqrt(np.mean(e**2, axis=0)))
            fig.setdefault(label + " (any of six orientations)", []).append(
                bl.minute_model_mm(p, truth, val, any_pose=True))
        for label in ("full", "line"):
            p = fits[label]
            for key, v in (("b", p.bias_static - truth.bias_static), ("d", p.bias_drift - truth.bias_drift),
                           ("sb", p.bias_static_std), ("sd", p.bias_drift_std),
                           ("e30", (bl.bias_at(p, t30) - truth.bias_at(t30))[0]),
                           ("mg", (p.misalignment - truth.misalignment) @ g),
                           ("tc", (p.correlation_time_s - truth.correlation_time_s) / truth.correlation_time_s)):
                ax.setdefault(f"{label}:{key}", []).append(np.asarray(v, dtype=float))
        print(f"  unit {i + 1}/{args.units} (seed {seed})", flush=True)
    print(f"\nthe fit's part of the first-minute error, {args.units} units (seeds {args.seed0} + 1000 i):\n")
    print("| fit | validation's orientation (+z): median / RMS (mm/s^2) | any of six orientations: median / RMS "
          "| at +z per axis x / y / z, RMS (mm/s^2) |")
    print("|---|---|---|---|")
    for label in [k for k in fig if not k.endswith("orientations)")]:
        a, b = np.array(fig[label]), np.array(fig[label + " (any of six orientations)"])
        per_axis = np.sqrt(np.mean(np.square(ax["per-axis:" + label]), axis=0))
        print(f"| {label} | {np.median(a):.3f} / {np.sqrt(np.mean(a**2)):.3f} | "
              f"{np.median(b):.3f} / {np.sqrt(np.mean(b**2)):.3f} | {' / '.join(f'{v:.3f}' for v in per_axis)} |")
    print("\n| fit | b_stat error RMS / stated (mm/s^2) | b_drift error RMS / stated | corr(b_stat, b_drift errors) "
          "| corr(bias error at 30 s, M g error) x / y / z | T_c relative error RMS (resolved axes) |")
    print("|---|---|---|---|---|---|")
    for label in ("full", "line"):
        def arr(key: str, lab: str = label) -> np.ndarray:
            return np.array(ax[f"{lab}:{key}"]) * (1e3 if key != "tc" else 1.0)

        b, d, e30, mg, tc = arr("b"), arr("d"), arr("e30"), arr("mg"), arr("tc")
        rms = lambda x: float(np.sqrt(np.nanmean(np.square(x))))  # noqa: E731
        corr = [float(np.corrcoef(e30[:, k], mg[:, k])[0, 1]) for k in range(3)]
        ok = np.isfinite(d.ravel())
        print(f"| {label} | {rms(b):.3f} / {rms(arr('sb')):.3f} | {rms(d):.3f} / {rms(arr('sd')):.3f} | "
              f"{np.corrcoef(b.ravel()[ok], d.ravel()[ok])[0, 1]:+.2f} | {' / '.join(f'{c:+.2f}' for c in corr)} | "
              f"{rms(tc):.3f} ({int(np.isfinite(tc).sum())} of {tc.size}) |")


if __name__ == "__main__":
    main()
