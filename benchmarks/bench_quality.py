"""Quality analytics at factory scale: page and endpoint latency on a synthetic production history.

Fills a fresh database with ``--units`` synthetic units and their runs (:func:`synthetic_history.fill`:
several stations and lots, retests, station faults, a drifting parameter and a shifted lot), serves the web
app with uvicorn on 127.0.0.1 (a thread) and times sequential HTTP requests (one client, ``--requests`` per
endpoint after two warm-ups, serials and searches drawn from a seeded RNG): the quality page, the population
statistics endpoint, the unit list with a search, a unit page, and a few more. Prints p50/p95/max (ms) per
endpoint. SQLite always; PostgreSQL with ``--postgres`` (a throwaway cluster from Debian's ``initdb``, run as
the ``postgres`` user when root) or ``--postgres-url URL`` (a server whose user may create databases).
``--growth`` also runs 10,000 units first, to show how the times grow.

    .venv/bin/python benchmarks/bench_quality.py --units 100000 [--postgres] [--growth] [--requests 30]
"""

from __future__ import annotations

import argparse
import contextlib
import sys
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path

import httpx
import numpy as np

from station.store import open_database
from station.web.app import create_app
from station.web.serve import ServerThread

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

from pgcluster import ClusterStartError, PostgresUnavailable, fresh_database, throwaway_cluster
from synthetic_history import DRIFTING, SHIFTED_LOT, fill


def endpoints(units: int, rng: np.random.Generator) -> dict[str, list[str]]:
    """Per endpoint name, the URLs to request (drawn so that no two requests are the same where possible)."""
    serials = [f"IMU-{int(i):07d}" for i in rng.integers(0, units, 64)]
    return {
        "quality page": ["/quality"],
        "quality page, lot filter": [f"/quality?lot={SHIFTED_LOT}"],
        "population statistics (JSON)": ["/api/quality/capability"],
        "yield by day (JSON)": ["/api/quality/yield?by=day"],
        "histogram SVG": [f"/quality/histogram/{DRIFTING}.svg"],
        "unit list, search (page)": [f"/units?q={s[:-2]}" for s in serials],
        "unit list, search (JSON)": [f"/api/units?q={s[4:-1]}&limit=50" for s in serials],
        "unit page": [f"/units/{s}" for s in serials],
    }


def measure(base: str, urls: dict[str, list[str]], n: int) -> dict[str, tuple[float, float, float]]:
    out = {}
    with httpx.Client(base_url=base, timeout=120.0) as client:
        for name, variants in urls.items():
            for k in range(2):
                client.get(variants[k % len(variants)]).raise_for_status()
            times = []
            for k in range(n):
                t0 = time.perf_counter()
                r = client.get(variants[(k + 2) % len(variants)])
                times.append((time.perf_counter() - t0) * 1e3)
                r.raise_for_status()
            a = np.array(times)
            out[name] = (float(np.percentile(a, 50)), float(np.percentile(a, 95)), float(a.max()))
    return out


def run_one(url: str, backend: str, units: int, n: int) -> list[tuple[str, int, str, float, float, float]]:
    with open_database(url) as db:
        t0 = time.perf_counter()
        summary = fill(db, units, seed=7)
        fill_s = time.perf_counter() - t0
        print(f"# {backend}: filled {summary.units} units, {summary.runs} runs, {summary.results} results, "
              f"{summary.checks} limit checks in {fill_s:.1f} s", flush=True)
        server = ServerThread(create_app(database=db))
        try:
            res = measure(server.url, endpoints(units, np.random.default_rng(3)), n)
        finally:
            server.stop()
    return [(backend, units, name, *v) for name, v in res.items()]


@contextlib.contextmanager
def throwaway_bench_cluster() -> Iterator[str]:
    """A temporary PostgreSQL cluster sized for the benchmark (``tests/pgcluster.py``); exits with the reason
    when none can be run."""
    try:
        with throwaway_cluster(server_options="-c fsync=off -c shared_buffers=512MB -c work_mem=64MB",
                               prefix="station-bench-pg-") as server:
            yield server
    except (PostgresUnavailable, ClusterStartError) as exc:
        raise SystemExit(f"{exc}; or give --postgres-url") from None


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--units", type=int, default=100_000)
    ap.add_argument("--requests", type=int, default=30, help="timed requests per endpoint")
    ap.add_argument("--growth", action="store_true", help="also run 10,000 units first")
    ap.add_argument("--postgres", action="store_true", help="also on a throwaway PostgreSQL cluster")
    ap.add_argument("--postgres-url", help="also on this PostgreSQL server (its user may create databases)")
    ap.add_argument("--no-sqlite", action="store_true", help="PostgreSQL only")
    args = ap.parse_args()
    sizes = ([10_000] if args.growth and args.units != 10_000 else []) + [args.units]
    rows: list[tuple[str, int, str, float, float, float]] = []
    if not args.no_sqlite:
        for n in sizes:
            with tempfile.TemporaryDirectory(prefix="station-bench-") as tmp:
                rows += run_one(f"sqlite:///{tmp}/q.sqlite", "sqlite", n, args.requests)
    if args.postgres or args.postgres_url:
        with (contextlib.nullcontext(args.postgres_url) if args.postgres_url else throwaway_bench_cluster()) as server:
            for n in sizes:
                with fresh_database(server, prefix="station_bench_") as url:
                    rows += run_one(url, "postgresql", n, args.requests)
    print(f"\n{'backend':<11} {'units':>7}  {'endpoint':<30} {'p50 ms':>8} {'p95 ms':>8} {'max ms':>8}  target")
    for backend, n, name, p50, p95, mx in rows:
        print(f"{backend:<11} {n:>7}  {name:<30} {p50:>8.1f} {p95:>8.1f} {mx:>8.1f}  "
              f"{'ok' if p95 < 500 else 'MISSED'} (p95 < 500)")


if __name__ == "__main__":
    main()
