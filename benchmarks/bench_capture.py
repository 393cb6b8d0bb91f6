"""Concurrent capture: N simulated sensors at R Hz each, captured by N serial clients over real ptys.

The sensors run in a child process (their own interpreter, like separate devices),
the clients in this process, so each side's CPU use is measured on its own
(process time / wall time; 100 % = one core). A frame counts as lost when the
sensor produced it and the client did not receive it, or when the client's
sequence/timestamp accounting shows a gap.

    /work/venv/bin/python benchmarks/bench_capture.py [--sensors 16] [--rate 1000] [--duration 60] [--scale 1.0]

``--duration`` is simulated seconds; at ``--scale s`` the run takes duration / s wall seconds.
"""

from __future__ import annotations

import argparse
import multiprocessing as mp
import os
import sys
import time
from multiprocessing.connection import Connection

import numpy as np

from station.kernel.clock import SimClock
from station.sensor.client import SampleBlock, SerialSensor, open_sensor
from station.sim.sensor_peer import SimulatedSensor


class BenchSource:
    """Cheap deterministic physics: gravity on z, small sines (m/s^2, rad/s, degC)."""

    def __init__(self, k: int) -> None:
        self.f = 0.1 + 0.01 * k

    def power_on(self) -> None:
        pass

    def render(self, t_s: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        s = np.sin(2 * np.pi * self.f * t_s)
        accel = np.empty((t_s.size, 3))
        accel[:, 0] = 0.1 * s
        accel[:, 1] = 0.0
        accel[:, 2] = 9.80665
        gyro = np.zeros((t_s.size, 3))
        gyro[:, 2] = 0.02 * s
        return accel, gyro, 25.0 + 0.001 * t_s


def serve(conn: Connection, n: int, scale: float) -> None:
    """Child process: run the simulated sensors until told to stop, then report."""
    clock = SimClock(scale=scale)
    sims = [SimulatedSensor(BenchSource(k), clock, serial=f"BENCH-{k:03d}", seed=k) for k in range(n)]
    conn.send([s.url for s in sims])
    conn.recv()
    cpu0, wall0 = time.process_time(), time.monotonic()
    conn.recv()
    cpu1, wall1 = time.process_time(), time.monotonic()
    stats = [s.stats() for s in sims]
    conn.send((cpu1 - cpu0, wall1 - wall0, [(st.sample_frames, st.frames_dropped, st.tx_overruns) for st in stats]))
    for s in sims:
        s.close()


class Tally:
    """Per-client continuity check over successive drains."""

    def __init__(self) -> None:
        self.received = 0
        self.seq_breaks = 0
        self.time_breaks = 0
        self.last_seq: int | None = None
        self.last_t_us: int | None = None

    def add(self, block: SampleBlock, period_us: int) -> None:
        if not len(block):
            return
        seq = block.seq.astype(np.int64)
        t_us = np.round(block.t_s * 1e6).astype(np.int64)
        if self.last_seq is not None:
            seq = np.concatenate([[self.last_seq], seq])
            t_us = np.concatenate([[self.last_t_us], t_us])
        self.seq_breaks += int(np.count_nonzero(np.diff(seq) % 65536 != 1))
        self.time_breaks += int(np.count_nonzero(np.diff(t_us) != period_us))
        self.received += len(block)
        self.last_seq, self.last_t_us = int(seq[-1]), int(t_us[-1])


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sensors", type=int, default=16)
    ap.add_argument("--rate", type=int, default=1000, help="Hz per sensor")
    ap.add_argument("--duration", type=float, default=60.0, help="simulated seconds")
    ap.add_argument("--scale", type=float, default=1.0, help="SimClock scale (1.0 = real time)")
    args = ap.parse_args()

    ctx = mp.get_context("spawn")
    parent, child = ctx.Pipe()
    proc = ctx.Process(target=serve, args=(child, args.sensors, args.scale), daemon=True)
    proc.start()
    urls = parent.recv()
    clock = SimClock(scale=args.scale)
    clients: list[SerialSensor] = [open_sensor(u, clock) for u in urls]
    for c in clients:
        c.identify()
    period_us = 1_000_000 // args.rate
    tallies = [Tally() for _ in clients]

    parent.send("start")
    cpu0, wall0 = time.process_time(), time.monotonic()
    for c in clients:
        c.start_stream(args.rate)
    t_end = clock.now() + args.duration
    while (left := t_end - clock.now()) > 0:
        clock.sleep(min(left, 0.5 * args.scale))  # drain about every 0.5 s wall, like a capture writer
        for c, tally in zip(clients, tallies, strict=True):
            tally.add(c.drain(), period_us)
    for c, tally in zip(clients, tallies, strict=True):
        c.stop_stream()
        tally.add(c.drain(), period_us)
    cpu1, wall1 = time.process_time(), time.monotonic()
    parent.send("stop")
    sim_cpu, sim_wall, sim_stats = parent.recv()
    link = [c.stats() for c in clients]
    for c in clients:
        c.close()
    proc.join(timeout=10)

    print(
        f"# bench_capture: {args.sensors} sensors x {args.rate} Hz, {args.duration:g} simulated s, "
        f"SimClock scale {args.scale:g}, {os.cpu_count()} CPUs, Python {sys.version.split()[0]}"
    )
    print()
    print(
        "| sensor | produced | received | lost (sensor-client) | parser gaps | lost_frames | crc_errors "
        "| seq/time breaks | retries |"
    )
    print("|---|---|---|---|---|---|---|---|---|")
    total_lost = 0
    for k, (tally, st, (produced, dropped, overruns)) in enumerate(zip(tallies, link, sim_stats, strict=True)):
        lost = produced - tally.received
        total_lost += max(lost, 0) + st.lost_frames + dropped + overruns
        print(
            f"| {k:2d} | {produced} | {tally.received} | {lost} | {st.gaps} | {st.lost_frames} | {st.crc_errors} "
            f"| {tally.seq_breaks}/{tally.time_breaks} | {st.retries} |"
        )
    produced_all = sum(s[0] for s in sim_stats)
    received_all = sum(t.received for t in tallies)
    print()
    print("| process | CPU time (s) | wall (s) | CPU / wall | frames/s (wall) |")
    print("|---|---|---|---|---|")
    print(
        f"| sensors ({args.sensors} sims) | {sim_cpu:.2f} | {sim_wall:.2f} | {sim_cpu / sim_wall:.1%} "
        f"| {produced_all / sim_wall:.0f} |"
    )
    print(
        f"| station ({args.sensors} clients) | {cpu1 - cpu0:.2f} | {wall1 - wall0:.2f} "
        f"| {(cpu1 - cpu0) / (wall1 - wall0):.1%} | {received_all / (wall1 - wall0):.0f} |"
    )
    print()
    verdict = "OK" if total_lost == 0 and all(t.seq_breaks == 0 and t.time_breaks == 0 for t in tallies) else "LOSS"
    print(f"frames produced {produced_all}, received {received_all}, lost {total_lost}: {verdict}")
    return 0 if verdict == "OK" else 1


if __name__ == "__main__":
    raise SystemExit(main())
