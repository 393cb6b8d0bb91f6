"""The diagnosis on physics outside its library (``benchmarks/gen_outside.py``): is it located, not named?

Per recording: the planted kind, the findings named, and every ``unexplained`` entry (sensor, axes, segment
kinds, covariate). Per kind: ``right`` = an ``unexplained`` entry at one of the kind's sensors and segment
kinds (``gen_outside.LOCATION``) and no finding; ``cov`` = right, and every such entry's covariate text names
what the kind follows (``gen_outside.COVARIATE``; on a null: an unexplained entry that says no covariate);
``s+cov`` = an ``unexplained`` entry at one of the kind's sensors in any segment kind whose covariate names what the
kind follows, and no finding (located and described where the recording shows it, which for some kinds is not
where ``LOCATION`` says it acts); ``unexpl`` = any ``unexplained``; ``named`` = recordings with
a finding (each a false finding: none of these kinds is in the library); ``held-out`` = median over the
recordings of the empirical model's held-out improvement (best located axis at the kind's sensors).
Nulls (``none``, ``ar1_noise``):
``named`` counts false findings; an ``unexplained`` on a null is listed with its covariate.

Seeds: development used 0-999 (``--base 0``) and, for the kinds added later (``gen_outside.OUTSIDE_NEW``),
1000-1100; report seeds were drawn after the method was settled (90000 for the first round, 120000 for the second;
the seed of a recording is ``base + i * len(KINDS) + index of its kind``, so adding kinds changed the mapping).

The kinds of ``gen_outside.UNANTICIPATED`` are not in the default list (kept out of development, run only as the
final check): ``--kinds alpha_sign_bias,g_scale,temp_misalign,rate_deadband``; their seeds are
``base + i * len(UNANTICIPATED) + index`` on their own random streams. Their first run (report seeds 175000) made
``g_scale`` and ``temp_misalign`` development kinds of the fourth round (development seeds 176000-176160, the other
kinds 177000-177200; its report seeds 178000 and 178500, drawn after).

``--generator sealed`` runs the sealed generator (``benchmarks/gen_sealed.py``: its kinds and nulls, its
``LOCATION`` and ``COVARIATE``), kept out of every locator development: run once, at the end, as the final check.
Its seeds are ``base + i * len(gen_sealed.KINDS) + index``. ``--generator sealed2`` runs the second sealed generator
(``benchmarks/gen_sealed2.py``) the same way, seeds ``base + i * len(gen_sealed2.KINDS) + index``; ``--generator
sealed3`` the third (``benchmarks/gen_sealed3.py``), seeds ``base + i * len(gen_sealed3.KINDS) + index``.

Run: ``python benchmarks/bench_diagnose_outside.py [--base 50000] [--per 4] [--kinds telegraph,...]
[--generator outside|sealed|sealed2|sealed3]``
"""

from __future__ import annotations

import argparse
import sys
import time
from collections import Counter
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))

import gen_outside
import gen_sealed
import gen_sealed2
import gen_sealed3

from station.diagnose import diagnose
from station.kernel.errors import StationError
from station.kernel.limits_file import DEFAULT_LIMITS_PATH, load_limits


def warmup_tc() -> dict[str, tuple[float, float]] | None:
    try:
        return dict(load_limits(DEFAULT_LIMITS_PATH).correlation_time_s)
    except Exception:
        return None


#: The generator whose recordings are diagnosed (``--generator``); its LOCATION, COVARIATE and NULLS are used.
GEN: Any = gen_outside


def axis_label(axis: int) -> str:
    """The planted axis's letter; ``all`` for a kind on every axis (gen_sealed2's ``axis`` -1)."""
    return "xyz"[axis] if axis >= 0 else "all"


def right_place(kind: str, unexplained: list[dict]) -> bool:
    if kind not in GEN.LOCATION:
        return False
    sensors, kinds = GEN.LOCATION[kind]
    return any(u["sensor"] in sensors and set(u["segment_kinds"]) & kinds for u in unexplained)


def covariate_right(kind: str, unexplained: list[dict]) -> bool:
    """Whether every unexplained entry at the kind's place names its covariate (a null's: none, or noise colour)."""
    words = GEN.COVARIATE[kind]
    loc = GEN.LOCATION.get(kind)
    mine = [u for u in unexplained if loc is None or (u["sensor"] in loc[0] and set(u["segment_kinds"]) & loc[1])]
    if loc is not None:  # a "none" text lists the dictionary: it names no covariate
        return bool(mine) and all(not u["covariate"].startswith("none") and any(w in u["covariate"] for w in words)
                                  for u in mine)
    return bool(mine) and all(any(w in u["covariate"] for w in words) for u in mine)


def sensor_and_covariate(kind: str, unexplained: list[dict]) -> bool:
    """An ``unexplained`` entry at one of the kind's sensors, in any segment kind, whose covariate text names what
    the kind follows (not "none"): located and described, wherever the recording shows it."""
    loc = GEN.LOCATION.get(kind)
    if loc is None:
        return False
    words = GEN.COVARIATE[kind]
    return any(u["sensor"] in loc[0] and not u["covariate"].startswith("none")
               and any(w in u["covariate"] for w in words) for u in unexplained)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--base", type=int, default=50_000, help="first seed (development used 0-999)")
    ap.add_argument("--per", type=int, default=4, help="recordings per kind")
    ap.add_argument("--kinds", default=None, help="comma-separated kinds (default: the generator's KINDS)")
    ap.add_argument("--generator", choices=("outside", "sealed", "sealed2", "sealed3"), default="outside",
                    help="gen_outside (default), or the sealed gen_sealed / gen_sealed2 / gen_sealed3 (the final "
                         "check only)")
    args = ap.parse_args()
    global GEN
    GEN = {"sealed": gen_sealed, "sealed2": gen_sealed2, "sealed3": gen_sealed3}.get(args.generator, gen_outside)
    tc = warmup_tc()
    kinds = [k for k in (args.kinds or ",".join(GEN.KINDS)).split(",") if k]
    stats: dict[str, Counter] = {}
    times: list[float] = []
    improvements: dict[str, list[float]] = {}
    seed = args.base
    for i in range(args.per):
        for kind in kinds:
            order: tuple[str, ...]
            if GEN is not gen_outside:
                order = GEN.KINDS
            else:
                order = gen_outside.KINDS if kind in gen_outside.KINDS else gen_outside.UNANTICIPATED
            s = seed + i * len(order) + order.index(kind)
            rec = GEN.generate(s, kind)
            t0 = time.process_time()
            try:
                rep = diagnose(rec.session, warmup_tc_s=tc).report.to_json()
            except StationError as exc:  # the fit refuses the recording (e.g. a saturated axis): its own column
                dt = time.process_time() - t0
                st = stats.setdefault(kind, Counter())
                st["n"] += 1
                st["refused"] += 1
                print(f"  {kind:16s} seed {s}: {rec.plan.rate_hz:4.0f} Hz {rec.session.duration_s:4.0f} s "
                      f"axis {axis_label(rec.axis)} refused: {exc} ({dt:.1f} s)", flush=True)
                continue
            dt = time.process_time() - t0
            times.append(dt)
            named = sorted({f"{f['effect']}:{f['sensor']}" for f in rep["findings"]})
            un = rep["unexplained"]
            st = stats.setdefault(kind, Counter())
            st["n"] += 1
            st["named"] += bool(named)
            st["unexpl"] += bool(un)
            ok = right_place(kind, un) and not named
            st["right"] += ok
            st["cov"] += covariate_right(kind, un) and (ok or kind in GEN.NULLS)
            st["anywhere"] += sensor_and_covariate(kind, un) and not named
            loc = GEN.LOCATION.get(kind)
            emp = [e["heldout_improvement"] for u in un for e in u.get("empirical", [])
                   if loc is None or u["sensor"] in loc[0]]
            if emp:
                improvements.setdefault(kind, []).append(max(emp))
            where = "; ".join(f"{u['sensor']} {''.join(u['axes'])} {'/'.join(u['segment_kinds'])}: "
                              f"{u['covariate'][:60]}" for u in un) or "-"
            flag = "RIGHT" if ok else ("" if kind in GEN.NULLS else "miss")
            flag += f" held-out {max(emp):.2f}" if emp else ""
            print(f"  {kind:16s} seed {s}: {rec.plan.rate_hz:4.0f} Hz {rec.session.duration_s:4.0f} s "
                  f"axis {axis_label(rec.axis)} named {named or '-'} | unexplained {where} {flag} ({dt:.1f} s)",
                  flush=True)
    print()
    print(f"outside-library generator (benchmarks/{GEN.__name__}.py), seeds from {args.base}, {args.per} per kind")
    print(f"{'kind':16s} {'n':>3s} {'right':>6s} {'cov':>4s} {'s+cov':>6s} {'unexpl':>7s} {'named':>6s} "
          f"{'refused':>8s} {'held-out':>9s}   where it acts")
    tot_n = tot_r = tot_refused = null_n = null_named = 0
    for kind, st in stats.items():
        loc = GEN.LOCATION.get(kind)
        where = (f"{'/'.join(sorted(loc[0]))} in {'/'.join(sorted(loc[1]))}" if loc else "null (no physics)")
        imp = improvements.get(kind)
        held = f"{sorted(imp)[len(imp) // 2]:.2f}" if imp else "-"
        print(f"{kind:16s} {st['n']:3d} {st['right'] if loc else '-':>6} {st['cov']:4d} "
              f"{st['anywhere'] if loc else '-':>6} {st['unexpl']:7d} "
              f"{st['named']:6d} {st['refused']:8d} {held:>9s}   {where}")
        if loc:
            tot_n += st["n"]
            tot_r += st["right"]
            tot_refused += st["refused"]
        else:
            null_n += st["n"]
            null_named += st["named"]
    if tot_n:
        print(f"outside kinds unexplained at the right place with no finding: {tot_r}/{tot_n} "
              f"({100.0 * tot_r / tot_n:.0f} %); refused by the fit's input checks (not counted right): "
              f"{tot_refused}")
    if null_n:
        print(f"nulls with a (false) finding: {null_named}/{null_n}")
    if times:
        times.sort()
        print(f"diagnosis CPU time: median {times[len(times) // 2]:.1f} s, max {times[-1]:.1f} s")


if __name__ == "__main__":
    main()
