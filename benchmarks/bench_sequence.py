"""Cycle time of the default calibration sequence per unit, and units per hour, for N units on one rig.

For each N the whole station runs in this process on a simulated clock: a simulated
rig (Modbus/TCP on 127.0.0.1) and N simulated sensors on ptys, driven by the real
station client code through the default sequence (300 s rest, six 30 s poses, 18
rate steps of 12 s at 100 Hz). Reported per N:

* rig time: station clock seconds from start until the rig is confirmed at rest
  (what the sequence takes on a real rig, plus polling latencies that grow with the
  clock scale);
* post: wall seconds for the fits, limit checks and saving (they run at wall speed on a
  real station too);
* cycle/unit = (rig time + post) / N, and units/h = 3600 / cycle/unit (loading and
  unloading the fixture not included);
* wall time, CPU use of this process (station and simulated peers together; 100 % = one
  core) and the outcome.

The clock scale is chosen per N so that the simulated sensors produce at most
``--max-frames`` frames per wall second in total (default 12000).

    /work/venv/bin/python benchmarks/bench_sequence.py [--units 1 4 16] [--scale 30] [--max-frames 12000]
"""

from __future__ import annotations

import argparse
import logging
import time

from station.kernel.plan import default_plan
from station.rig import open_rig
from station.sensor import open_sensor
from station.sequence import SequenceOptions, SequenceRunner
from station.sequence.records import Outcome
from station.sim.station_sim import SimStation


def run_one(n: int, scale: float, seed: int) -> dict[str, object]:
    plan = default_plan()
    wall0, cpu0 = time.monotonic(), time.process_time()
    with SimStation(n, scale, seed, plan=plan) as sim:
        rig = open_rig(sim.rig_url, sim.clock, **sim.rig_client_options())
        sensors = [open_sensor(url, sim.clock) for url in sim.sensor_urls]
        try:
            result = SequenceRunner(
                rig, sensors, sim.clock, plan=plan, options=SequenceOptions().for_scale(scale), station="bench",
            ).run()
        finally:
            for s in sensors:
                s.close()
            rig.close()
    wall, cpu = time.monotonic() - wall0, time.process_time() - cpu0
    counts = {o: sum(u.outcome == o for u in result.units) for o in Outcome}
    return {
        "n": n,
        "scale": scale,
        "rig_s": result.sequence_s,
        "post_s": result.post_wall_s,
        "cycle_s": result.cycle_time_per_unit_s,
        "per_hour": 3600.0 / result.cycle_time_per_unit_s,
        "wall_s": wall,
        "cpu": cpu / wall,
        "outcome": " ".join(f"{c}x{o.value}" for o, c in counts.items() if c),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    ap.add_argument("--units", type=int, nargs="+", default=[1, 4, 16])
    ap.add_argument("--scale", type=float, default=30.0, help="largest clock scale (sim s per wall s)")
    ap.add_argument("--max-frames", type=float, default=12000.0, help="frames per wall second, all sensors")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    logging.basicConfig(level=logging.ERROR)
    rate = default_plan().sample_rate_hz
    rows = []
    for n in args.units:
        scale = min(args.scale, args.max_frames / (n * rate))
        rows.append(run_one(n, scale, args.seed))
        r = rows[-1]
        print(f"N={n}: done in {r['wall_s']:.0f} s wall", flush=True)
    print()
    print(f"{'N':>3} {'scale':>6} {'rig time s':>10} {'post s':>7} {'cycle/unit s':>12} {'units/h':>8} "
          f"{'wall s':>7} {'CPU %':>6}  outcome")
    for r in rows:
        print(f"{r['n']:>3} {r['scale']:>6.1f} {r['rig_s']:>10.1f} {r['post_s']:>7.1f} {r['cycle_s']:>12.1f} "
              f"{r['per_hour']:>8.1f} {r['wall_s']:>7.1f} {100 * r['cpu']:>6.0f}  {r['outcome']}")


if __name__ == "__main__":
    main()
