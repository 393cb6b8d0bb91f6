"""Fill a station database with a synthetic production history (:func:`synthetic_history.fill`).

    .venv/bin/python benchmarks/gen_quality.py --db sqlite:///quality.sqlite --units 100000 [--days 30] [--seed 1]

The database must have no runs yet (a new SQLite file, or an empty PostgreSQL database). Then
``station serve --db URL`` (or ``create_app``) shows it on ``/quality``.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from station.store import open_database

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))  # the generator is test data, not the station

from synthetic_history import fill


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--db", required=True, help="database URL (sqlite:///FILE or postgresql+psycopg://...)")
    ap.add_argument("--units", type=int, default=10_000)
    ap.add_argument("--days", type=int, default=30)
    ap.add_argument("--stations", type=int, default=4)
    ap.add_argument("--lots", type=int, default=10)
    ap.add_argument("--seed", type=int, default=1)
    a = ap.parse_args()
    with open_database(a.db) as db:
        s = fill(db, a.units, seed=a.seed, days=a.days, stations=a.stations, lots=a.lots)
    print(f"{s.units} units, {s.runs} runs, {s.results} results, {s.checks} limit checks in {s.seconds:.1f} s")


if __name__ == "__main__":
    main()
