"""Cost and effect of the simulator re-run in ``station.diagnose`` on 15-minute 100 Hz recordings.

For a clean recording and recordings with clearly visible effects: the wall time of the whole
:func:`station.diagnose.diagnose` and of the re-run alone (:func:`station.diagnose.rerun.rerun` on the
same base fit and findings, best of ``--repeat``, wall and CPU time: the CPU time is what the
re-run costs on a machine shared with other work), and the worst-axis block chi^2 of recording minus
simulation for the base and the extended model (1 = white noise).

Run: ``/work/venv/bin/python benchmarks/bench_diagnose_rerun.py [--repeat 3]``
"""

from __future__ import annotations

import argparse
import time

from threadpoolctl import threadpool_limits

from station.diagnose import diagnose
from station.diagnose.rerun import rerun
from station.kernel.plan import RigPlan
from station.physics.effects import Effects
from station.sim.session_sim import simulate_session

CASES = (
    ("none", ""),
    ("lever arm + temperature scale", "lever_arm=30,temperature_scale=300"),
    ("g-sensitivity + time offset", "g_sensitivity=0.05,time_offset=3"),
)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    plan = RigPlan(sample_rate_hz=100.0, rest_s=RigPlan().rest_s + 60.0)  # the default plan stretched to 15 min
    print(f"{'effects':32s} {'samples':>8s} {'sim.':>4s} {'diagnose s':>10s} {'rerun s':>8s} {'cpu s':>6s} "
          f"{'accel chi2 base->ext':>22s} {'gyro chi2 base->ext':>22s}")
    for label, effects in CASES:
        session = simulate_session(1, plan=plan, effects=Effects.parse(effects)).session
        t0 = time.perf_counter()
        d = diagnose(session)
        total = time.perf_counter() - t0
        assert d.rerun is not None
        fitted = list(d.rerun.extended.effects)
        best, cpu = float("inf"), float("inf")
        for _ in range(args.repeat):
            with threadpool_limits(limits=1, user_api="blas"):
                t0, c0 = time.perf_counter(), time.process_time()
                rerun(d.baseline, fitted)
                best = min(best, time.perf_counter() - t0)
                cpu = min(cpu, time.process_time() - c0)
        rr = d.to_json()["rerun"]
        cols = []
        for sensor in ("accel", "gyro"):
            b, e = max(rr["base"][sensor]["chi2"]), max(rr["extended"][sensor]["chi2"])
            cols.append(f"{b:10.3g} -> {e:8.3g}")
        print(f"{label:32s} {len(session):8d} {len(fitted):4d} {total:10.2f} {best:8.3f} {cpu:6.3f} "
              f"{cols[0]:>22s} {cols[1]:>22s}", flush=True)


if __name__ == "__main__":
    main()
