"""The web application's hardening: security headers, serials with any printable character, every status code
in the OpenAPI document, a locked database answered 503 in one line."""

from __future__ import annotations

import inspect
import re
import sqlite3
from collections.abc import Iterator
from pathlib import Path
from urllib.parse import quote

import pytest
from fastapi.routing import APIRoute
from fastapi.testclient import TestClient

from station.kernel.measurement import Measurement
from station.sequence.records import (
    Measured,
    Outcome,
    RunFinished,
    RunStarted,
    StepFinished,
    StepStarted,
    UnitFinished,
)
from station.store import Recorder, open_database
from station.web.app import ROUTERS, create_app
from station.web.security import CONTENT_SECURITY_POLICY

ODD = ["A/B 1", "x?y#z", "100%", "dot/../dot", "tab\u00e9-\u6e2c", "end/", "a/plots/b"]


def _fill(url: str, serials: list[str]) -> None:
    run = "run-odd"
    with open_database(url) as db:
        rec = Recorder(db)
        rec(RunStarted(run, "2026-11-21T10:00:00+00:00", 0.0, "st1", "rig", tuple(f"p{k}" for k in range(len(serials))),
                       ("rest",)))
        rec(StepStarted(run, 0, "rest", "rest", 0.0, 10.0))
        for k, serial in enumerate(serials):
            rec(Measured(run, k, serial, "rest", Measurement("gravity_ratio", 1.0, "1", 0.95, 1.05, True)))
        rec(StepFinished(run, 0, "rest", 10.0, 10.0, True, len(serials)))
        done = tuple(UnitFinished(run, k, s, Outcome.FAIL, "fail", None, None) for k, s in enumerate(serials))
        for u in done:
            rec(u)
        rec(RunFinished(run, Outcome.FAIL, 20.0, 20.0, 1.0, done))


@pytest.fixture
def client(tmp_path: Path) -> Iterator[tuple[TestClient, str]]:
    url = f"sqlite:///{tmp_path / 's.sqlite'}"
    _fill(url, ODD)
    with TestClient(create_app(url, token="t")) as c:
        yield c, url


def test_pages_carry_security_headers(client: tuple[TestClient, str]) -> None:
    c, _ = client
    for path in ("/", "/units", "/population", "/quality", f"/units/{quote(ODD[0], safe='')}"):
        r = c.get(path)
        assert r.status_code == 200, path
        assert r.headers["content-security-policy"] == CONTENT_SECURITY_POLICY
        assert r.headers["x-frame-options"] == "DENY" and r.headers["x-content-type-options"] == "nosniff"
    api = c.get("/api/units")
    assert api.headers["x-content-type-options"] == "nosniff" and "content-security-policy" not in api.headers
    assert c.get("/units/no-such-unit").headers["x-frame-options"] == "DENY"  # a 404 page too


@pytest.mark.parametrize("serial", ODD)
def test_any_printable_serial_is_reachable(client: tuple[TestClient, str], serial: str) -> None:
    c, _ = client
    enc = quote(serial, safe="")
    page = c.get(f"/units/{enc}")
    assert page.status_code == 200 and "unknown unit" not in page.text
    record = c.get(f"/api/units/{enc}")
    assert record.status_code == 200 and record.json()["serial"] == serial
    eeprom = c.get(f"/api/units/{enc}/eeprom.bin")  # a FAIL unit: no image, and the answer names the serial
    assert eeprom.status_code == 404 and eeprom.json()["detail"] == f"no passed parameter set for unit {serial}"
    diag = c.get(f"/api/units/{enc}/diagnosis")
    assert diag.status_code == 404 and serial in diag.json()["detail"]
    plot = c.get(f"/units/{enc}/plots/residuals.svg")
    assert plot.status_code in (200, 404) and "unknown unit" not in plot.text
    listed = {u["serial"] for u in c.get("/api/units").json()}
    assert serial in listed
    # the unit list links to the page by the encoded serial, and the link leads there
    hrefs = re.findall(r'href="(/units/[^"]+)"', c.get("/units").text)
    assert any(c.get(h.replace("&amp;", "&")).status_code == 200 and serial in c.get(h).text for h in hrefs)


def _codes(route: APIRoute) -> set[int]:
    """The status codes an endpoint's own code can answer (HTTPException, status_code=, _json(..., N))."""
    src = inspect.getsource(route.endpoint)
    codes = {int(c) for c in re.findall(r"HTTPException\((\d{3})", src)}
    codes |= {int(c) for c in re.findall(r"status_code=(\d{3})", src)}
    codes |= {int(c) for c in re.findall(r"_json\([^)]*?, (\d{3})", src)}
    if "unit_or_404" in src or "recording_of" in src:
        codes.add(404)
    if route.dependencies:
        codes.add(401)
    return codes | {503}


def test_openapi_lists_every_status_code_an_endpoint_returns(client: tuple[TestClient, str]) -> None:
    c, _ = client
    doc = c.get("/openapi.json").json()
    checked = 0
    for router in ROUTERS:
        for route in router.routes:
            if not isinstance(route, APIRoute) or not route.include_in_schema:
                continue
            for method in route.methods:
                documented = {int(k) for k in doc["paths"][route.path_format][method.lower()]["responses"]}
                assert _codes(route) <= documented, (method, route.path_format, _codes(route) - documented)
                checked += 1
    assert checked >= 12
    assert "503" in doc["paths"]["/api/runs"]["post"]["responses"]


def test_post_runs_without_a_rig_answers_the_documented_503(client: tuple[TestClient, str]) -> None:
    c, _ = client
    r = c.post("/api/runs", headers={"Authorization": "Bearer t"})
    assert r.status_code == 503 and r.json() == {"detail": "this station cannot start runs from the API"}


def test_a_locked_database_is_503_in_one_line(client: tuple[TestClient, str], monkeypatch: pytest.MonkeyPatch,
                                              tmp_path: Path) -> None:
    """The store held locked past the stated wait (a real second connection holding BEGIN EXCLUSIVE): the write
    gives DatabaseLocked, and any answer that meets it is a documented 503 with one line, not a 500."""
    from station.store.opening import DatabaseLocked
    from station.store.recorder import record_disposition
    from station.web import lookup

    c, _ = client
    monkeypatch.setenv("STATION_DB_LOCK_TIMEOUT_S", "0.2")
    url = f"sqlite:///{tmp_path / 'locked.sqlite'}"
    _fill(url, ["U1"])
    holder = sqlite3.connect(tmp_path / "locked.sqlite", isolation_level=None)
    holder.execute("BEGIN EXCLUSIVE")
    try:
        with open_database(url) as db, pytest.raises(DatabaseLocked, match=r"waited 0\.2 s") as info:
            record_disposition(db, "U1", "retest", operator="a", note="b")
    finally:
        holder.execute("ROLLBACK")
        holder.close()

    def locked(*_args: object) -> None:
        raise info.value

    monkeypatch.setattr(lookup, "show_unit", locked)
    r = c.get(f"/api/units/{quote(ODD[0], safe='')}")
    assert r.status_code == 503 and r.json() == {"detail": str(info.value)}
    assert "\n" not in r.json()["detail"]
