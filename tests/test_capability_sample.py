"""Capability only from a minimum sample, with the confidence interval of Cpk.

The interval (Bissell's approximation) is checked against known truth: normal values drawn with a known Cpk,
the interval from each sample must cover it in about 95 % of the samples. The quality page says "too few
units" instead of Cp/Cpk/Pp/Ppk below 25 values and flags no parameter for such a Cpk.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from fastapi.testclient import TestClient
from synthetic_history import fill

from station.store import open_database
from station.store.spc import MIN_CAPABILITY_N, cpk_interval
from station.web.app import create_app


def test_cpk_interval_values() -> None:
    lo, hi = cpk_interval(1.33, 50)  # type: ignore[misc]
    half = 1.959964 * math.sqrt(1 / 450 + 1.33**2 / 98)
    assert (lo, hi) == (pytest.approx(1.33 - half, abs=1e-6), pytest.approx(1.33 + half, abs=1e-6))
    assert cpk_interval(None, 50) is None and cpk_interval(1.0, 1) is None
    wide, narrow = cpk_interval(1.33, 25), cpk_interval(1.33, 1000)
    assert wide is not None and narrow is not None and wide[1] - wide[0] > 5 * (narrow[1] - narrow[0])


@pytest.mark.parametrize(("n", "true_cpk"), [(25, 1.0), (50, 1.33), (200, 1.67)])
def test_cpk_interval_covers_the_true_cpk_95_percent_of_the_time(n: int, true_cpk: float) -> None:
    rng = np.random.default_rng(7)
    low, high, sigma = -1.0, 1.0, 1.0
    mean = high - 3.0 * true_cpk * sigma  # the upper side is the nearer one
    low = min(low, mean - 3.0 * true_cpk * sigma - 1.0)
    reps, covered = 4000, 0
    for _ in range(reps):
        x = rng.normal(mean, sigma, n)
        m, s = x.mean(), x.std(ddof=1)
        cpk = min(high - m, m - low) / (3 * s)
        ci = cpk_interval(cpk, n)
        assert ci is not None
        covered += ci[0] <= true_cpk <= ci[1]
    assert 0.93 <= covered / reps <= 0.97, covered / reps


def test_the_quality_page_says_too_few_units(tmp_path: Path) -> None:
    db = open_database(f"sqlite:///{tmp_path / 'few.sqlite'}")
    try:
        fill(db, 12, seed=3, days=2, stations=1, lots=1)
        client = TestClient(create_app(database=db))
        caps = client.get("/api/quality/capability").json()
        assert caps and all(c["n"] < MIN_CAPABILITY_N and c["enough"] is False for c in caps)
        page = client.get("/quality").text
        assert page.count("too few units (n = ") == len(caps)
        assert 'id="flag-count">0<' in page or all(c["rules"] for c in caps)
        assert 'class="num cpk' not in page  # no Cpk cell, red or not, from a handful of units
    finally:
        db.close()
