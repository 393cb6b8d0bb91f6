"""Diagnosis time and peak memory against the number of samples.

One recording per size and case from the station's simulator (``simulate_session``, seed 3). A case is the
effect planted (``--cases``): by default a 30 mm lever arm (the whole chain runs: base fit, selection, simulator
re-run, compensation check) and a 3 ms time offset (its findings on both sensors also run the compensation's two
calibration fits with the time offset estimated, and the delay's refinement); ``--cases library`` plants each
library effect of the station's simulator alone at 4x its concealed magnitude (``bench_diagnose.CONCEALED``), to
find the slowest. The 9e4 rows are the 15-minute 100 Hz case (target < 5 s); the other sizes keep the same
15-minute plan and raise the sample rate until the recording holds the wanted number of rows (up to 4.9 M rows),
so the rows show how the per-sample parts grow (the block problem has the same blocks at every rate).

``--code DIR[,DIR...]``: the checkouts to time (each child runs with that directory first on ``PYTHONPATH``), in
turn on the same recording (before/after comparisons on a shared machine: the runs alternate, so load drifts hit
both alike); one CPU column per checkout.

Every measurement runs ``station.diagnose.diagnose`` in a fresh subprocess (``--repeats`` of them per
size, median shown), which loads the recording from an ``.npz`` and reports:

- ``time s``: wall time of ``diagnose`` alone; ``CPU s``: its process CPU time (steadier on a busy machine);
- ``RSS loaded MB``: resident memory after loading the recording (the session's arrays, numpy, scipy);
- ``peak RSS MB``: ``ru_maxrss`` of the subprocess at the end (the diagnosis's peak; loading is below it);
- ``tracemalloc MB`` (with ``--tracemalloc``): the peak of memory allocated during ``diagnose`` (numpy
  arrays included), from one more run with ``tracemalloc`` on (its time is not used).

Run: ``python benchmarks/bench_diagnose_scale.py [--sizes 9e4,1e6,4.9e6] [--repeats 3] [--tracemalloc]
[--cases lever_arm=30,time_offset=3 | library] [--code DIR,DIR]``
(``nice`` it on a shared machine; about 40 min with the defaults on the shared 2-core machine at load 6-8;
``--sizes 9e4`` alone takes about a minute).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

FIELDS = ("t_s", "segment", "kind", "accel_mps2", "gyro_radps", "temp_degc", "ref_accel_mps2", "ref_gyro_radps")
BASE_RATE_HZ = 100.0
PLAN_S = 900.0


def _make(rows: float, path: Path, case: str = "lever_arm=30") -> tuple[int, float, float]:
    """Simulate the recording with about ``rows`` samples and the effect ``case`` (``NAME=VALUE``) into ``path``:
    (rows, rate Hz, duration s)."""
    from station.physics.effects import Effects
    from station.sim.session_sim import default_plan, simulate_session

    plan = default_plan()
    short = simulate_session(3, plan=dataclasses.replace(plan, rest_s=0.0)).session
    # the rest stretched so that the plan lasts 15 minutes
    plan = dataclasses.replace(plan, rest_s=PLAN_S - (short.t_s[-1] - short.t_s[0]))
    rate = rows / PLAN_S if rows > 1.05 * PLAN_S * BASE_RATE_HZ else BASE_RATE_HZ
    plan = dataclasses.replace(plan, sample_rate_hz=float(np.round(rate, 1)))
    s = simulate_session(3, plan=plan, effects=Effects.parse([case])).session
    np.savez(path, **{f: getattr(s, f) for f in FIELDS},
             metadata=json.dumps(dict(s.metadata)), angles=json.dumps({str(k): v for k, v in s.angles_deg.items()}))
    return len(s), plan.sample_rate_hz, float(s.t_s[-1] - s.t_s[0])


def _measure(path: str, trace: bool) -> None:
    """Child process: load, diagnose once, print one JSON line."""
    import resource
    import tracemalloc

    from station.diagnose import diagnose
    from station.session.model import Session

    with np.load(path) as z:
        s = Session(metadata=json.loads(str(z["metadata"])),
                    angles_deg={int(k): v for k, v in json.loads(str(z["angles"])).items()},
                    **{f: z[f] for f in FIELDS})
    rss_loaded = _rss_now_mb()
    if trace:
        tracemalloc.start()
    t0, c0 = time.perf_counter(), time.process_time()
    d = diagnose(s)
    dt, cpu = time.perf_counter() - t0, time.process_time() - c0
    peak = tracemalloc.get_traced_memory()[1] / 2**20 if trace else None
    maxrss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024  # Linux: KiB
    print(json.dumps({"time_s": dt, "cpu_s": cpu, "rss_loaded_mb": rss_loaded, "maxrss_mb": maxrss, "traced_mb": peak,
                      "findings": sorted(f"{f['effect']}:{f['sensor']}" for f in d.to_json()["findings"])}))


def _rss_now_mb() -> float:
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20


def _child(path: Path, trace: bool, code: str | None = None) -> dict:
    env = dict(os.environ)
    if code:
        env["PYTHONPATH"] = os.pathsep.join([code, *filter(None, [env.get("PYTHONPATH")])])
    out = subprocess.run([sys.executable, __file__, "--child", str(path)] + (["--trace"] if trace else []),
                         capture_output=True, text=True, check=True, env=env)
    return json.loads(out.stdout.strip().splitlines()[-1])


def _cases(spec: str) -> list[str]:
    """The ``--cases`` items: ``NAME=VALUE`` effects, or ``library`` for each simulated library effect."""
    if spec != "library":
        return [c for c in spec.split(",") if c]
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from bench_diagnose import CONCEALED

    return [f"{name}={4.0 * value:g}" for name, value in CONCEALED.items()]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", default="9e4,3e5,1e6,2.5e6,4.9e6",
                    help="comma-separated sample counts (90 000 and fewer: the 15-min plan at 100 Hz)")
    ap.add_argument("--repeats", type=int, default=3, help="timed subprocesses per size (median)")
    ap.add_argument("--tracemalloc", action="store_true", help="one more run per size with tracemalloc on")
    ap.add_argument("--cases", default="lever_arm=30,time_offset=3",
                    help="effects planted, one recording each (NAME=VALUE, comma-separated), or 'library'")
    ap.add_argument("--code", default="", help="checkouts to time, comma-separated (default: this one)")
    ap.add_argument("--child", help=argparse.SUPPRESS)
    ap.add_argument("--trace", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        _measure(args.child, args.trace)
        return
    sizes = [float(x) for x in args.sizes.split(",")]
    codes: list[str | None] = [c for c in args.code.split(",") if c] or [None]
    cpu_heads = " ".join(f"{'CPU s' if c is None else 'CPU s ' + Path(c).name:>14s}" for c in codes)
    print(f"{'case':24s} {'rows':>9s} {'rate Hz':>8s} {'min':>5s} {'time s':>8s} {cpu_heads} {'RSS loaded MB':>14s} "
          f"{'peak RSS MB':>12s} {'tracemalloc MB':>15s}  findings")
    with tempfile.TemporaryDirectory() as tmp:
        for k, rows in enumerate(sizes):
            for case in _cases(args.cases):
                path = Path(tmp) / f"rec{k}.npz"
                n, rate, dur = _make(rows, path, case)
                runs: dict[str | None, list[dict]] = {c: [] for c in codes}
                for _ in range(args.repeats):  # alternating between the checkouts
                    for c in codes:
                        runs[c].append(_child(path, False, c))
                first = runs[codes[0]]
                traced = None if not args.tracemalloc else _child(path, True, codes[0])["traced_mb"]
                med = {key: float(np.median([r[key] for r in first]))
                       for key in ("time_s", "rss_loaded_mb", "maxrss_mb")}
                cpus = " ".join(f"{float(np.median([r['cpu_s'] for r in runs[c]])):14.2f}" for c in codes)
                tm = "-" if traced is None else f"{traced:.0f}"
                print(f"{case:24s} {n:9d} {rate:8.1f} {dur / 60:5.1f} {med['time_s']:8.2f} {cpus} "
                      f"{med['rss_loaded_mb']:14.0f} "
                      f"{med['maxrss_mb']:12.0f} {tm:>15s}  {','.join(first[0]['findings']) or '-'}", flush=True)
                path.unlink()
    print(f"median of {args.repeats} subprocess(es) per size and case"
          + (", alternating between the checkouts" if len(codes) > 1 else "")
          + ("; tracemalloc: one more run per size" if args.tracemalloc else "")
          + f"; time s, RSS: the first checkout; load average at the end {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
