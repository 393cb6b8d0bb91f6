"""Magnitudes of the named library effects against the truth, on the independent generator (``tests/indepgen.py``).

Per library effect with per-axis (or per-element, or scalar) parameters, ``--per`` recordings of that effect alone;
for every finding of it (per sensor): the stated value and standard uncertainty (the finding's ``parameters``, in
SI: ``Finding.theta`` and ``theta_std``) against the generator's drawn truth (``Recording.truth``). A recording's
finding is *covered* when every parameter is within 3 of its stated uncertainties of the truth
(``|value - truth| <= 3 std``); the table gives the share, the largest ``|z|`` seen and the median, and the same
share for the value re-fitted under the final model (``evidence.retest``). Not covered here: ``outliers`` (a rate,
not a drawn parameter) and ``pose_tilt`` (per pose, drawn per visit's axis).

Seeds: development used 0-999 (and 200000-203999 for the walk's restricted likelihood and the spread in the stated
std, 205000-206999 for the walk's profile-likelihood size); report seeds start at ``--base`` (140000+, then
210000-212999, then 215000-216999). Per finding the line shows z per parameter
and, for a scalar effect, the value, stated std and truth (SI).

Run: ``python benchmarks/bench_diagnose_magnitudes.py [--base 10000] [--per 10] [--effects lever_arm,...]``
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
sys.path.insert(0, str(Path(__file__).resolve().parent))

import indepgen
from bench_diagnose_indep import SINGLE, warmup_tc

from station.diagnose import diagnose
from station.diagnose.effect_registry import unit_factor

#: Effects whose truth the generator records in the candidate's form, and their magnitudes (indepgen units).
EFFECTS = {**{k: v for k, v in SINGLE.items() if k not in ("outliers", "pose_tilt")}, "time_offset": 5.0}


def zscores(rec: indepgen.Recording, findings: list
            ) -> list[tuple[str, np.ndarray, np.ndarray | None, np.ndarray, np.ndarray, np.ndarray]]:
    """Per finding with a recorded truth: (sensor, z of the stated value, z of the final model's value or None,
    value, stated std, truth (SI))."""
    out = []
    for f in findings:
        truth = rec.truth.get(f"{f.effect} {f.sensor}")
        if truth is None or f.theta is None or f.theta_std is None:
            continue
        t = np.asarray(truth, dtype=float).ravel()
        v = np.asarray(f.theta, dtype=float).ravel()
        s = np.asarray(f.theta_std, dtype=float).ravel()
        if v.shape != t.shape:
            continue
        z = (v - t) / np.where(s > 0, s, np.nan)
        zf = None
        rt = getattr(f.evidence, "retest", None)
        if rt is not None and "value" in rt.final_model:
            vf = np.asarray(rt.final_model["value"], dtype=float).ravel() / unit_factor(f.effect, f.sensor)[0]
            if vf.shape == t.shape:
                zf = (vf - t) / np.where(s > 0, s, np.nan)
        out.append((f.sensor, z, zf, v, s, t))
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--base", type=int, default=10_000, help="first seed (development used 0-999)")
    ap.add_argument("--per", type=int, default=10, help="recordings per effect")
    ap.add_argument("--effects", default=",".join(EFFECTS))
    args = ap.parse_args()
    tc = warmup_tc()
    rows: dict[str, list[tuple[float, float | None]]] = {}
    named: dict[str, int] = {}
    seed = args.base
    times = []
    names = [e for e in args.effects.split(",") if e]
    for i in range(args.per):  # round-robin over the effects: a run cut short still covers each of them
        for name in names:
            seed = args.base + i * len(names) + names.index(name)
            rec = indepgen.generate(seed, {name: EFFECTS[name]})
            t0 = time.process_time()
            rep = diagnose(rec.session, warmup_tc_s=tc).report
            times.append(time.process_time() - t0)
            mine = [f for f in rep.findings if f.effect == name]
            named[name] = named.get(name, 0) + bool(mine)
            for sensor, z, zf, v, s, t in zscores(rec, mine):
                zmax = float(np.nanmax(np.abs(z)))
                zfmax = None if zf is None else float(np.nanmax(np.abs(zf)))
                rows.setdefault(name, []).append((zmax, zfmax))
                print(f"  {name:24s} seed {seed} {sensor}: max |z| stated {zmax:6.2f}"
                      f"{'' if zfmax is None else f', final model {zfmax:6.2f}'}  z {np.round(z, 2).tolist()}"
                      + (f"  value {v[0]:.4g} std {s[0]:.3g} truth {t[0]:.4g}" if len(t) == 1 else ""),
                      flush=True)
    print()
    print(f"magnitudes on the independent generator, seeds {args.base}-{args.base + args.per * len(names) - 1}, "
          f"{args.per} per effect")
    print(f"{'effect':24s} {'named':>6s} {'findings':>8s} {'<=3 std':>8s} {'share':>6s} {'median|z|':>9s} "
          f"{'max|z|':>7s} {'final<=3':>8s}")
    tot = cov = 0
    for name in EFFECTS:
        r = rows.get(name, [])
        if name not in named:
            continue
        ok = sum(z <= 3.0 for z, _ in r)
        okf = sum(zf is not None and zf <= 3.0 for _, zf in r)
        tot += len(r)
        cov += ok
        zs = sorted(z for z, _ in r)
        med = f"{zs[len(zs) // 2]:.2f}" if zs else "-"
        mx = f"{zs[-1]:.1f}" if zs else "-"
        share = f"{100.0 * ok / len(r):.0f} %" if r else "-"
        print(f"{name:24s} {named[name]:3d}/{args.per:<2d} {len(r):8d} {ok:8d} {share:>6s} {med:>9s} {mx:>7s} {okf:8d}")
    if tot:
        print(f"all: {cov}/{tot} findings within 3 stated uncertainties ({100.0 * cov / tot:.0f} %)")
    if times:
        print(f"diagnosis CPU time: median {sorted(times)[len(times) // 2]:.1f} s")


if __name__ == "__main__":
    main()
