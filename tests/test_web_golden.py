"""The golden unit's individuals chart on ``/quality`` and in ``/api/quality/golden`` (no browser).

A golden unit is registered with known references; eight checks scatter within a third of a sigma, the ninth
is 5 registered sigmas off on ``accel.bias_static.x`` (outside its allowed deviation too): Nelson's rule 1
(a point beyond 3 sigma) must fire at check 9 and nowhere else, and the page must show that chart flagged.
"""

from __future__ import annotations

import re
from collections.abc import Iterator
from datetime import UTC, datetime, timedelta
from pathlib import Path

import pytest
from fastapi.testclient import TestClient

from station.kernel.golden import GoldenReference, GoldenUnit, check_golden
from station.store.db import open_database
from station.store.golden_records import record_golden_check, save_golden
from station.web.app import create_app

SIGMA = 1e-3  # m/s^2, the registered repeatability of accel.bias_static.x
G1 = GoldenUnit("G1", "2026-11-01T06:00:00+00:00", (
    GoldenReference("accel.bias_static.x", "m/s^2", 0.02, 4 * SIGMA, SIGMA, 5),
    GoldenReference("gyro.M.xz", "1", 2e-4, 2e-4, 1e-6, 5),
))
IN_CONTROL = [0.3, -0.2, 0.1, -0.4, 0.2, -0.1, 0.3, -0.3]  # sigmas: no run rule completes on these


@pytest.fixture(scope="module")
def client(tmp_path_factory: pytest.TempPathFactory) -> Iterator[TestClient]:
    url = f"sqlite:///{tmp_path_factory.mktemp('golden-web') / 'g.sqlite'}"
    t0 = datetime(2026, 11, 2, 6, 5, tzinfo=UTC)
    with open_database(url) as db:
        save_golden(db, G1)
        for k, z in enumerate([*IN_CONTROL, 5.0]):
            measured = {"accel.bias_static.x": 0.02 + z * SIGMA, "gyro.M.xz": 2e-4 + 0.1 * z * 1e-6}
            record_golden_check(db, check_golden(G1, measured), station="st1", version=1, run_uid=None, slot=None,
                                checked_at=t0 + timedelta(hours=8 * k))
        # another station's check: not on st1's chart
        record_golden_check(db, check_golden(G1, {"accel.bias_static.x": 0.02, "gyro.M.xz": 2e-4}), station="st2",
                            version=1, run_uid=None, slot=None, checked_at=t0 + timedelta(days=5))
    with TestClient(create_app(url)) as c:
        yield c


def test_api_answers_every_check_and_where_the_rule_fired(client: TestClient) -> None:
    r = client.get("/api/quality/golden", params={"station": "st1"})
    assert r.status_code == 200, r.text
    body = r.json()
    assert {x["number"] for x in body["rules"]} == set(range(1, 9))
    (unit,) = body["units"]
    assert unit["serial"] == "G1" and unit["version"] == 1
    assert [c["passed"] for c in unit["checks"]] == [True] * 8 + [False]
    assert {c["station"] for c in unit["checks"]} == {"st1"}
    charts = {p["parameter"]: p for p in unit["parameters"]}
    acc = charts["accel.bias_static.x"]
    assert acc["reference"] == 0.02 and acc["repeatability"] == SIGMA and acc["allowed"] == 4 * SIGMA
    assert acc["deviation"] == pytest.approx([z * SIGMA for z in [*IN_CONTROL, 5.0]])
    assert acc["z"] == pytest.approx([*IN_CONTROL, 5.0])
    assert acc["first_signal"] == 8 and 1 in acc["rules"][8] and not any(acc["rules"][:8])
    gyro = charts["gyro.M.xz"]
    assert gyro["first_signal"] is None and gyro["z"][8] == pytest.approx(0.5)
    everything = client.get("/api/quality/golden").json()["units"][0]
    assert len(everything["checks"]) == 10  # without a station filter st2's check is on the chart too


def test_quality_page_shows_the_flagged_golden_chart(client: TestClient) -> None:
    r = client.get("/quality", params={"station": "st1"})
    assert r.status_code == 200, r.text
    html = r.text
    section = html[html.index('id="golden"'):]
    assert 'data-golden="G1"' in section and "9 checks" in section and "FAILED" in section
    flagged = section[section.index('class="grid2 golden-flagged"'):section.index("<details>")]
    assert 'data-golden-param="accel.bias_static.x"' in flagged
    assert 'data-golden-param="gyro.M.xz"' not in flagged  # in control, its last check within bounds
    assert "first signal at check 9" in flagged and "rules 1" in flagged
    svg = flagged[flagged.index("<svg"):flagged.index("</svg>")]
    assert len(re.findall(r'class="signal"', svg)) == 1 and len(re.findall(r'class="point"', svg)) == 8
    # the deviation drawn in the display convention: 5 sigma = 5 mm/s^2 = 0.5099 mg
    assert "0.5099 mg" in svg
    img = client.get("/quality/golden/G1/gyro.M.xz.svg", params={"station": "st1"})
    assert img.status_code == 200 and img.headers["content-type"].startswith("image/svg+xml")
    assert "in control" in img.text and 'class="signal"' not in img.text
    assert client.get("/quality/golden/G1/nothing.svg").status_code == 404
    assert client.get("/quality/golden/NOPE/gyro.M.xz.svg").status_code == 404


def test_quality_page_without_a_golden_unit(tmp_path: Path) -> None:
    url = f"sqlite:///{tmp_path / 'none.sqlite'}"
    with open_database(url):
        pass
    with TestClient(create_app(url)) as c:
        html = c.get("/quality").text
    assert "no golden unit is registered" in html
