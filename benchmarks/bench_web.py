"""Status page and API latency under concurrent clients while a simulated 4-unit calibration runs.

One process holds the whole station: the simulated rig (Modbus/TCP) and sensors (ptys),
the sequence runner with the store's recorder and the live status as subscribers, and
uvicorn serving the web app on 127.0.0.1 (in a thread). While the sequence runs,
``--clients`` HTTP clients request ``/``, ``/api/status``, ``/api/units`` and
``/api/runs`` in a loop, and ``--sse`` clients hold ``/events`` open (the clients run
in a separate process). Reported: p50 and p99 latency per endpoint (ms), requests per
second, SSE events received, and the capture's frame accounting from the run's link
gates (``dropped_fraction`` per step and unit: lost frames = fraction x expected
frames), which must be zero.

    /work/venv/bin/python benchmarks/bench_web.py [--units 4] [--scale 30] [--clients 16] [--sse 8] [--short]
"""

from __future__ import annotations

import argparse
import asyncio
import io
import math
import multiprocessing as mp
import tempfile
import time
from pathlib import Path
from typing import Any

import httpx
import numpy as np
from rich.console import Console

from station.kernel.plan import RigPlan, default_plan
from station.sequence.records import Measured, Record, StepStarted
from station.sim.demo import run_demo
from station.store import Recorder, open_database
from station.web.app import create_app
from station.web.serve import ServerThread
from station.web.state import LiveStatus

ENDPOINTS = ("/", "/api/status", "/api/units", "/api/runs?limit=20")


class LinkTally:
    """Record subscriber: expected and lost frames from the ``dropped_fraction`` link gates."""

    def __init__(self, rate_hz: float) -> None:
        self.rate_hz = rate_hz
        self.hold_s: dict[str, float] = {}
        self.windows = 0
        self.lost = 0.0
        self.expected = 0.0

    def __call__(self, r: Record) -> None:
        if isinstance(r, StepStarted):
            self.hold_s[r.name] = r.hold_s
        elif isinstance(r, Measured) and r.measurement.name == "dropped_fraction":
            n = self.hold_s.get(r.step, 0.0) * self.rate_hz
            self.windows += 1
            self.expected += n
            self.lost += r.measurement.value * n


def _load_process(base: str, clients: int, sse: int, stop: Any, ready: Any, out: Any) -> None:
    """The load generator, in its own process (its CPU use must not count against the server's GIL)."""
    ready.set()
    lat: dict[str, list[float]] = {p: [] for p in ENDPOINTS}
    events = [0] * sse
    errors: list[str] = []
    asyncio.run(_load(base, clients, sse, stop, lat, events, errors))
    out.send((lat, events, errors))
    out.close()


async def _load(base: str, clients: int, sse: int, stop: Any,
                lat: dict[str, list[float]], events: list[int], errors: list[str]) -> None:
    limits = httpx.Limits(max_connections=clients + sse + 4, keepalive_expiry=2.0)  # server closes idle at 5 s
    async with httpx.AsyncClient(base_url=base, timeout=30.0, limits=limits) as client:

        async def worker(k: int) -> None:
            i = k
            while not stop.is_set():
                path = ENDPOINTS[i % len(ENDPOINTS)]
                i += 1
                t0 = time.perf_counter()
                try:
                    r = await client.get(path)
                    if r.status_code != 200:
                        errors.append(f"{path}: {r.status_code}")
                except httpx.HTTPError as exc:
                    errors.append(f"{path}: {exc!r}")
                    continue
                lat[path].append(time.perf_counter() - t0)

        async def listener(k: int) -> None:
            try:
                async with client.stream("GET", "/events", timeout=None) as r:
                    async for line in r.aiter_lines():
                        if line.startswith("event: status"):
                            events[k] += 1
                        if stop.is_set():
                            break
            except httpx.HTTPError as exc:
                errors.append(f"/events: {exc!r}")

        tasks = [asyncio.create_task(worker(k)) for k in range(clients)]
        tasks += [asyncio.create_task(listener(k)) for k in range(sse)]
        while not stop.is_set():
            await asyncio.sleep(0.1)
        await asyncio.wait(tasks, timeout=10.0)
        for t in tasks:
            t.cancel()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--units", type=int, default=4)
    ap.add_argument("--scale", type=float, default=30.0, help="simulated seconds per wall second")
    ap.add_argument("--clients", type=int, default=16, help="concurrent HTTP clients")
    ap.add_argument("--sse", type=int, default=8, help="concurrent /events listeners")
    ap.add_argument("--idle-s", type=float, default=5.0, help="seconds of the same load on the idle station first")
    ap.add_argument("--short", action="store_true", help="a 2-minute rest and short steps instead of the default plan")
    args = ap.parse_args()
    plan = (RigPlan(sample_rate_hz=100.0, rest_s=120.0, pose_hold_s=10.0,
                    rate_steps=tuple((a, s * 100.0) for a in "xyz" for s in (1.0, -1.0)), rate_hold_s=6.0)
            if args.short else default_plan())

    with tempfile.TemporaryDirectory() as tmp:
        db = open_database(f"sqlite:///{Path(tmp) / 'station.sqlite'}")
        live = LiveStatus(db)
        server = ServerThread(create_app(database=db, live=live), log_level="error")
        base = server.url
        tally = LinkTally(plan.sample_rate_hz)
        holder: dict[str, Any] = {}

        def calibrate() -> None:
            holder["run"] = run_demo(args.units, args.scale, seed=1, out_dir=Path(tmp) / "out", plan=plan,
                                     provision=False, console=Console(file=io.StringIO()),
                                     subscribers=[Recorder(db), live, tally])

        idle = _measure(base, args.clients, args.sse, lambda: time.sleep(args.idle_s))
        busy = _measure(base, args.clients, args.sse, calibrate)
        server.stop()
        db.close()

    result = holder["run"]
    print(f"{args.units} unit(s), clock x{args.scale:g}, {'short' if args.short else 'default'} plan: "
          f"run {result.outcome.value} in {busy[0]:.1f} s wall; {args.clients} HTTP clients, {args.sse} SSE listeners")
    print(f"{'phase':<8}{'endpoint':<22}{'requests':>9}{'req/s':>8}{'p50 ms':>9}{'p99 ms':>9}{'max ms':>9}")
    for phase, (wall, lat, events, errors) in (("idle", idle), ("run", busy)):
        for path, xs in lat.items():
            if xs:
                a = np.array(xs) * 1e3
                print(f"{phase:<8}{path:<22}{len(a):>9}{len(a) / wall:>8.1f}{np.percentile(a, 50):>9.1f}"
                      f"{np.percentile(a, 99):>9.1f}{a.max():>9.1f}")
        print(f"{phase:<8}SSE events per listener: min {min(events, default=0)}, max {max(events, default=0)}; "
              f"errors: {len(errors)}" + (f" (first: {errors[0]})" if errors else ""))
    lost = round(tally.lost) if math.isfinite(tally.lost) else -1
    print(f"capture: {tally.windows} link-gate windows, {tally.expected:.0f} frames expected, "
          f"{lost} lost{'' if lost == 0 else '  <-- FRAMES LOST'}; "
          f"unit outcomes: {', '.join(f'{u.serial} {u.outcome.value}' for u in result.units)}")


def _measure(base: str, clients: int, sse: int, during: Any) -> tuple[float, dict[str, list[float]], list[int],
                                                                       list[str]]:
    """Run the load process while ``during()`` runs: (wall s, latencies per endpoint (s), SSE events, errors)."""
    ctx = mp.get_context("spawn")
    stop, ready = ctx.Event(), ctx.Event()
    receive, send = ctx.Pipe(duplex=False)
    loader = ctx.Process(target=_load_process, args=(base, clients, sse, stop, ready, send))
    loader.start()
    ready.wait(60.0)
    time.sleep(0.5)  # the clients connect
    t0 = time.monotonic()
    during()
    wall = time.monotonic() - t0
    stop.set()
    lat, events, errors = receive.recv()
    loader.join(30.0)
    return wall, lat, events, errors


if __name__ == "__main__":
    main()
