"""The population page's cost: ``GET /population`` and every histogram image it shows, on a synthetic history.

A database is filled with ``--units`` synthetic units (:func:`station.store.synthetic.fill`, 14 days, seed 21),
then the page and each image it references are fetched in turn through the application (Starlette's test client,
no network, one client). Reported: the page's time, the images' total time and count, and the whole (s of wall
time). Run it with another checkout first on ``PYTHONPATH`` to compare two versions on the same data.

    PYTHONPATH=. python benchmarks/bench_population.py [--units 3000]
"""

from __future__ import annotations

import argparse
import re
import tempfile
import time
from pathlib import Path

from fastapi.testclient import TestClient
from synthetic_history import fill

from station.store import open_database
from station.web.app import create_app


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--units", type=int, default=3000)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        db = open_database(f"sqlite:///{Path(tmp) / 'pop.sqlite'}")
        fill(db, args.units, seed=21, days=14)
        client = TestClient(create_app(database=db))
        t0 = time.perf_counter()
        page = client.get("/population")
        t_page = time.perf_counter() - t0
        srcs = re.findall(r'src="([^"]+\.svg)"', page.text)
        t1 = time.perf_counter()
        for src in srcs:
            r = client.get(src.replace("&amp;", "&"))
            assert r.status_code == 200, (src, r.status_code)
        t_img = time.perf_counter() - t1
        db.close()
    print(f"| units | page (s) | images | images (s) | total (s) |\n| --- | --- | --- | --- | --- |\n"
          f"| {args.units} | {t_page:.2f} | {len(srcs)} | {t_img:.2f} | {t_page + t_img:.2f} |")


if __name__ == "__main__":
    main()
