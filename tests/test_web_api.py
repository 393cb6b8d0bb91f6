"""The web application against a temporary SQLite store: every endpoint, auth, 404s, live status, fuzz.

The store is filled by the store's :class:`~station.store.Recorder` from records built
here: a real unit (simulated session, fitted parameter set, real limit checks against
the default limits file) that passes, and two synthetic units (one FAIL, one ERROR).
"""

from __future__ import annotations

import asyncio
import json
import math
from collections.abc import Iterator
from dataclasses import replace
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import pytest
from fastapi.testclient import TestClient

from station.eeprom.image import decode_image
from station.fit.calibrate import fit_session
from station.kernel.found_terms import found_terms
from station.kernel.limits import table1_limits
from station.kernel.limits_file import load_limits
from station.kernel.measurement import Measurement, Verdict
from station.kernel.parameters import ParameterSet
from station.sequence.limits import check_limits, conformance
from station.sequence.records import (
    Measured,
    Outcome,
    Record,
    RunFinished,
    RunStarted,
    StepFinished,
    StepStarted,
    UnitFinished,
    worst,
)
from station.session.csv_v1 import write_session
from station.sim.session_sim import simulate_session
from station.store import Recorder, open_database
from station.store.quality import ShiftCalendar
from station.store.queries import show_unit
from station.web.app import create_app
from station.web.listing import is_marginal, latest_checks
from station.web.state import LiveStatus, shift_start, shift_stats

TOKEN = "s3cret-token"
RUN1, RUN2 = "run-0001", "run-0002"


# what the station's conformance records for 0.095 +- 2 * 0.001 in [-0.1, 0.1] with a 5 % marginal band
MARGINAL_CHECK = conformance("accel.bias_static.y", 0.095, 0.001, (-0.1, 0.1), "m/s^2",
                             replace(table1_limits(), rule="guard-band", k_sigma=2.0, marginal_fraction=0.05))
assert MARGINAL_CHECK is not None and MARGINAL_CHECK.verdict == Verdict.MARGINAL


def run_records(run_id: str, at: str, units: list[tuple[str, Outcome, list[Measured], str | None, str | None]],
                *, station: str = "st1") -> list[Record]:
    """A two-step run: each unit ``(serial, outcome, limit measurements, session path, params path)``."""
    recs: list[Record] = [RunStarted(run_id, at, 0.0, station, "sim-rig", tuple(f"pty{k}" for k in range(len(units))),
                                     ("rest", "pose +z"))]
    for i, (name, hold) in enumerate((("rest", 300.0), ("pose +z", 30.0))):
        t0 = 0.0 if i == 0 else 305.0
        recs.append(StepStarted(run_id, i, name, "rest" if i == 0 else "pose", t0, hold))
        for k, (serial, *_rest) in enumerate(units):
            recs.append(Measured(run_id, k, serial, name, Measurement("gravity_ratio", 1.0, "1", 0.95, 1.05, True)))
        recs.append(StepFinished(run_id, i, name, t0 + hold + 5.0, hold + 5.0, True, len(units)))
    finished = []
    for k, (serial, outcome, measurements, session_path, params_path) in enumerate(units):
        recs.extend(m for m in measurements if m.slot == k)
        u = UnitFinished(run_id, k, serial, outcome, "" if outcome == Outcome.PASS else f"{outcome.value.lower()}",
                         session_path, params_path)
        recs.append(u)
        finished.append(u)
    recs.append(RunFinished(run_id, worst(u.outcome for u in finished), 340.0, 340.0, 1.0, tuple(finished)))
    return recs


@pytest.fixture(scope="module")
def store(tmp_path_factory: pytest.TempPathFactory) -> Iterator[dict[str, Any]]:
    tmp = tmp_path_factory.mktemp("web")
    sim = simulate_session(21)
    params = fit_session(sim.session)
    session_path, params_path = tmp / "unit.csv", tmp / "unit.params.json"
    write_session(sim.session, session_path)
    params_path.write_text(params.to_json(), encoding="utf-8")
    checks = check_limits(params, load_limits().product)
    good = [Measured(RUN2, 0, params.serial, "limits", c)
            for c in checks]
    bad = [Measured(RUN1, 0, "BAD-1", "limits",
                    Measurement("accel.bias_static.x", 0.5, "m/s^2", -0.1, 0.1, False, 0.01)),
           Measured(RUN1, 0, "BAD-1", "limits",
                    MARGINAL_CHECK)]
    url = f"sqlite:///{tmp / 'station.sqlite'}"
    db = open_database(url)
    recorder = Recorder(db)
    for r in run_records(RUN1, "2026-11-20T10:00:00+00:00",
                         [("BAD-1", Outcome.FAIL, bad, None, None), ("ERR-2", Outcome.ERROR, [], None, None)]):
        recorder(r)
    for r in run_records(RUN2, "2026-11-21T10:00:00+00:00",
                         [(params.serial, Outcome.PASS, good, str(session_path), str(params_path))],
                         station="st2"):
        recorder(r)
    assert recorder.errors == []
    yield {"url": url, "db": db, "params": params, "checks": checks}
    db.close()


@pytest.fixture(scope="module")
def client(store: dict[str, Any]) -> Iterator[TestClient]:
    live = LiveStatus(store["db"], now=lambda: datetime(2026, 11, 21, 12, 0, tzinfo=UTC))
    live.on_start = lambda options: "started-1"
    live.on_abort = lambda run_id: run_id == "running-1"
    with TestClient(create_app(database=store["db"], token=TOKEN, live=live)) as c:
        yield c


def test_units_list_and_filters(client: TestClient, store: dict[str, Any]) -> None:
    serial = store["params"].serial
    rows = client.get("/api/units").json()
    assert {r["serial"]: r["last_outcome"] for r in rows} == {"BAD-1": "FAIL", "ERR-2": "ERROR", serial: "PASS"}
    assert [r["serial"] for r in client.get("/api/units", params={"outcome": "PASS"}).json()] == [serial]
    assert {r["serial"] for r in client.get("/api/units", params={"station": "st1"}).json()} == {"BAD-1", "ERR-2"}
    day = client.get("/api/units", params={"date_from": "2026-11-21", "date_to": "2026-11-21"}).json()
    assert [r["serial"] for r in day] == [serial]
    assert client.get("/api/units", params={"date_to": "2026-11-19"}).json() == []
    assert client.get("/api/units", params={"date_from": "not-a-date"}).status_code == 422


def test_unit_detail_and_404(client: TestClient, store: dict[str, Any]) -> None:
    params: ParameterSet = store["params"]
    d = client.get(f"/api/units/{params.serial}").json()
    assert d["serial"] == params.serial and d["latest_params_run_id"] == RUN2
    assert d["runs"][0]["outcome"] == "PASS" and d["runs"][0]["station"] == "st2"
    back = ParameterSet.from_dict(d["latest_params"])
    assert back.accel.bias_static.tolist() == params.accel.bias_static.tolist()
    assert len(d["checks"]) == len(store["checks"])
    first = d["checks"][0]
    assert first["name"] == store["checks"][0].name and math.isclose(first["value"], store["checks"][0].value)
    r = client.get("/api/units/NO-SUCH-UNIT")
    assert r.status_code == 404 and "NO-SUCH-UNIT" in r.json()["detail"]


def test_eeprom_download(client: TestClient, store: dict[str, Any]) -> None:
    params: ParameterSet = store["params"]
    r = client.get(f"/api/units/{params.serial}/eeprom.bin")
    assert r.status_code == 200 and r.headers["content-type"] == "application/octet-stream"
    assert f'filename="{params.serial}.eeprom.bin"' in r.headers["content-disposition"]
    img = decode_image(r.content)
    assert img.serial == params.serial and img.station_id == "st2"
    assert img.calibration_time == datetime(2026, 11, 21, 10, 0, tzinfo=UTC)
    assert img.accel.bias_static == pytest.approx(params.accel.bias_static.tolist(), rel=1e-6)
    assert client.get(f"/api/units/{params.serial}/eeprom.bin").content == r.content  # deterministic
    assert client.get("/api/units/BAD-1/eeprom.bin").status_code == 404  # never passed
    assert client.get("/api/units/NO-SUCH-UNIT/eeprom.bin").status_code == 404


def test_runs(client: TestClient, store: dict[str, Any]) -> None:
    runs = client.get("/api/runs").json()
    assert [r["run_id"] for r in runs] == [RUN2, RUN1]
    assert runs[1]["outcome"] == "ERROR" and [u["serial"] for u in runs[1]["units"]] == ["BAD-1", "ERR-2"]
    assert [r["run_id"] for r in client.get("/api/runs", params={"limit": 1}).json()] == [RUN2]
    assert [r["run_id"] for r in client.get("/api/runs", params={"outcome": "PASS"}).json()] == [RUN2]
    assert client.get("/api/runs", params={"limit": 0}).status_code == 422


def test_writes_need_the_token(client: TestClient, store: dict[str, Any]) -> None:
    for path in ("/api/runs", "/api/runs/running-1/abort"):
        assert client.post(path).status_code == 401
        r = client.post(path, headers={"Authorization": "Bearer wrong"})
        assert r.status_code == 401 and r.headers["www-authenticate"] == "Bearer"
    auth = {"Authorization": f"Bearer {TOKEN}"}
    assert client.post("/api/runs", headers=auth, json={}).json() == {"run_id": "started-1"}
    r = client.post("/api/runs/running-1/abort", headers=auth)
    assert r.status_code == 202 and r.json()["state"] == "aborting"
    assert client.post("/api/runs/other/abort", headers=auth).status_code == 404
    # no token configured on the station: read-only, every write answers 401, even with some token
    with TestClient(create_app(database=store["db"])) as ro:
        assert ro.post("/api/runs", headers=auth).status_code == 401
        assert ro.post("/api/runs/running-1/abort", headers=auth).status_code == 401
        assert ro.get("/api/runs").status_code == 200


def test_live_status_follows_records(store: dict[str, Any]) -> None:
    live = LiveStatus(store["db"], now=lambda: datetime(2026, 11, 21, 12, 0, tzinfo=UTC))
    s = live.snapshot()
    assert s["state"] == "idle" and s["slots"] == [] and s["remaining_s"] is None
    assert s["shift"]["units_tested"] == 1 and s["shift"]["first_pass_yield"] == 1.0
    assert [r["run_id"] for r in s["recent_runs"]] == [RUN2, RUN1]
    recs = run_records("live-1", "2026-11-21T11:00:00+00:00",
                       [("A-1", Outcome.PASS, [], None, None), ("B-2", Outcome.FAIL, [], None, None)])
    live(recs[0])
    live(recs[1])  # StepStarted rest, hold 300 s, 2 steps
    s = live.snapshot(with_store=False)
    assert s["state"] == "running" and s["step"]["name"] == "rest" and s["steps_total"] == 2
    assert s["remaining_s"] == pytest.approx(300.0 + 300.0)  # current hold + one more step at the same estimate
    for r in recs[2:5]:  # two measurements and StepFinished (305 s)
        live(r)
    s = live.snapshot(with_store=False)
    # the next step is a pose (kind not seen yet): the last hold (300 s) plus the mean overhead (305 - 300 s)
    assert s["progress"] == pytest.approx(0.5) and s["remaining_s"] == pytest.approx(305.0)
    live(recs[5])  # StepStarted pose +z, hold 30 s
    assert live.snapshot(with_store=False)["remaining_s"] == pytest.approx(30.0)
    assert [t["serial"] for t in s["slots"]] == ["A-1", "B-2"]
    assert live.version == 6
    for r in recs[6:]:
        live(r)
    s = live.snapshot(with_store=False)
    assert live.version == len(recs)  # one change per record
    assert s["state"] == "idle" and s["outcome"] == "FAIL" and s["progress"] == 1.0
    assert [(t["serial"], t["verdict"]) for t in s["slots"]] == [("A-1", "PASS"), ("B-2", "FAIL")]
    live.set_fault("rig not at rest")
    assert live.snapshot(with_store=False)["state"] == "fault"


def test_wait_change_is_woken_from_another_thread() -> None:
    live = LiveStatus()

    async def scenario() -> tuple[int, int]:
        v0 = live.version
        loop = asyncio.get_running_loop()
        loop.call_later(0.05, lambda: loop.run_in_executor(None, live.set_fault, "x"))
        woke = await live.wait_change(v0, 10.0)
        timed_out = await live.wait_change(woke, 0.01)
        return woke, timed_out

    woke, timed_out = asyncio.run(scenario())
    assert woke == 1 and timed_out == 1


def test_shift_stats(store: dict[str, Any]) -> None:
    assert shift_start(datetime(2026, 11, 21, 5, 0, tzinfo=UTC)) == (datetime(2026, 11, 20, 22, 0, tzinfo=UTC), "C")
    assert shift_start(datetime(2026, 11, 21, 13, 59, tzinfo=UTC)) == (datetime(2026, 11, 21, 6, 0, tzinfo=UTC), "A")
    night = ShiftCalendar.parse("day=07:30,night=19:30")
    assert shift_start(datetime(2026, 11, 21, 7, 0, tzinfo=UTC), night) == (datetime(2026, 11, 20, 19, 30,
                                                                                      tzinfo=UTC), "night")
    st = shift_stats(store["db"], datetime(2026, 11, 21, 12, 0, tzinfo=UTC))  # 6 h into the shift, one PASS unit
    assert (st.units_tested, st.first_pass_units, st.first_pass_yield) == (1, 1, 1.0)
    # units per hour over the last hour, not since the shift's start: the unit (10:00) is 2 h old at 12:00
    assert (st.units_per_hour, st.units_in_window, st.rate_window_s) == (0.0, 0, 3600.0)
    soon = shift_stats(store["db"], datetime(2026, 11, 21, 10, 30, tzinfo=UTC))
    assert (soon.units_per_hour, soon.units_in_window) == (1.0, 1)
    prev = shift_stats(store["db"], datetime(2026, 11, 20, 12, 0, tzinfo=UTC))  # a FAIL and an ERROR
    # the ERROR result is not tested: it is no unit tested and uses up no first pass
    assert (prev.results, prev.not_tested, prev.units_tested, prev.first_pass_units, prev.first_pass_yield) == \
        (2, 1, 1, 1, 0.0)
    assert is_marginal(0.095, -0.1, 0.1, 0.1) and not is_marginal(0.0, -0.1, 0.1, 0.1)
    assert not is_marginal(0.2, -0.1, 0.1, 0.1)


def test_status_page_and_events(client: TestClient) -> None:
    r = client.get("/")
    assert r.status_code == 200 and "EventSource('/events')" in r.text and RUN2 in r.text
    s = client.get("/api/status").json()
    assert s["state"] == "idle" and s["shift"]["units_tested"] == 1


def test_events_stream_sends_status(tmp_path: Path) -> None:
    # the app's SSE generator, driven directly (TestClient cannot stop an endless stream)
    live = LiveStatus()
    app = create_app(f"sqlite:///{tmp_path / 'empty.sqlite'}", live=live)
    route = next(r for r in app.routes if getattr(r, "path", "") == "/events")

    class FakeRequest:
        async def is_disconnected(self) -> bool:
            return False

    async def first_events() -> list[str]:
        response = await route.endpoint(FakeRequest())  # type: ignore[attr-defined]
        it = response.body_iterator
        out = [await it.__anext__(), await it.__anext__()]
        live.set_fault("rig fault")
        out.append(await it.__anext__())
        await it.aclose()
        return out

    retry, first, second = asyncio.run(first_events())
    assert retry == "retry: 1000\n\n"
    assert first.startswith("id: 0\nevent: status\ndata: ") and '"state": "idle"' in first
    assert '"recent_runs": []' in first
    assert second.startswith("id: 1\n") and '"state": "fault"' in second and "rig fault" in second


def test_unit_page_plots_and_population(client: TestClient, store: dict[str, Any]) -> None:
    serial = store["params"].serial
    page = client.get(f"/units/{serial}")
    assert page.status_code == 200
    for name in ("raw_corrected", "drift", "acf", "allan", "residuals"):
        assert f'id="plot-{name}"' in page.text
        svg = client.get(f"/units/{serial}/plots/{name}.svg")
        assert svg.status_code == 200 and svg.headers["content-type"].startswith("image/svg+xml")
        assert svg.text.lstrip().startswith("<?xml") and "<path" in svg.text
    assert client.get(f"/units/{serial}/plots/nope.svg").status_code == 404
    bad = client.get("/units/BAD-1")
    assert 'class="fail"' in bad.text and 'class="marginal"' in bad.text  # 0.5 out, 0.095 within 5 % of 0.1
    assert "No session recording" in bad.text
    assert client.get("/units/NO-SUCH-UNIT").status_code == 404
    hostile = client.get("/units/%3Cscript%3Ealert(1)")
    assert hostile.status_code == 404 and "<script>alert" not in hostile.text and "&lt;script&gt;" in hostile.text
    pop = client.get("/population")  # the quality page's histograms, counted by the database
    assert pop.status_code == 200 and "/quality/histogram/accel.bias_static.x.svg" in pop.text
    old = client.get("/population/plots/accel.bias_static.x.svg", follow_redirects=False)
    assert old.status_code == 308 and old.headers["location"] == "/quality/histogram/accel.bias_static.x.svg"
    h = client.get("/population/plots/accel.bias_static.x.svg")
    assert h.status_code == 200 and "n=2" in h.text  # BAD-1 and the real unit
    assert client.get("/population/plots/nope.svg").status_code == 404


def test_openapi_lists_the_api(client: TestClient) -> None:
    doc = client.get("/openapi.json").json()
    paths = doc["paths"]
    for p in ("/api/units", "/api/units/{serial}", "/api/units/{serial}/eeprom.bin", "/api/runs", "/api/status",
              "/api/runs/{run_id}/abort"):
        assert p in paths
    assert "post" in paths["/api/runs"] and "401" in paths["/api/runs"]["post"]["responses"]
    assert "/" not in paths and "/events" not in paths


def test_typed_answers_lose_nothing(client: TestClient, store: dict[str, Any]) -> None:
    """The response models pass on every field the store and the live status have (nothing dropped on the way)."""
    for serial in (store["params"].serial, "BAD-1", "ERR-2"):
        detail = show_unit(store["db"], serial)
        assert detail is not None
        expected = {**detail.to_dict(), "checks": [c.model_dump() for c in latest_checks(store["db"], serial)]}
        params = detail.latest_params()
        if params is not None:  # what the API adds: the found terms' summary, and a /2 set's /3 fields at 0
            lp = expected["latest_params"]
            lp["found_terms"] = found_terms(params).to_dict()
            lp.setdefault("time_offset_std_s", 0.0)
            for tri in ("accel", "gyro"):
                for name in ("scale_quadratic", "scale_quadratic_std", "scale_cubic", "scale_cubic_std"):
                    lp[tri].setdefault(name, [0.0, 0.0, 0.0])
        assert client.get(f"/api/units/{serial}").json() == json.loads(json.dumps(expected))
    check = client.get("/api/units/BAD-1").json()["checks"][0]
    assert check == {"name": "accel.bias_static.x", "value": 0.5, "std": 0.01, "low": -0.1, "high": 0.1,
                     "unit": "m/s^2", "passed": False, "verdict": "FAIL", "k": None}
    live: LiveStatus = client.app.state.live  # type: ignore[attr-defined]
    assert client.get("/api/status").json() == json.loads(json.dumps(live.snapshot()))


def test_schemathesis_finds_no_server_error(client: TestClient) -> None:
    schemathesis = pytest.importorskip("schemathesis")
    from hypothesis import HealthCheck, given, settings

    schema = schemathesis.openapi.from_asgi("/openapi.json", client.app)
    failures: list[str] = []
    calls = 0
    codes: dict[int, int] = {}
    for op in schema.get_all_operations():
        operation = op.ok()

        @settings(max_examples=15, deadline=None, database=None,
                  suppress_health_check=list(HealthCheck))
        @given(case=operation.as_strategy())
        def check(case: Any) -> None:
            for headers in ({}, {"Authorization": f"Bearer {TOKEN}"}):  # writes: rejected, then authorized
                response = case.call(headers=headers)
                codes[response.status_code] = codes.get(response.status_code, 0) + 1
                if response.status_code >= 500:
                    failures.append(f"{case.method} {case.formatted_path} -> {response.status_code}")

        check()
        calls += 1
    print(f"schemathesis: {calls} operations, responses by status: {dict(sorted(codes.items()))}")
    assert calls >= 7 and failures == []
    assert codes.get(200, 0) > 0 and codes.get(401, 0) > 0 and codes.get(202, 0) > 0


def test_every_outcome_the_station_records_is_served(tmp_path: Path) -> None:
    """REFUSED and RETEST units (and a far date filter) answer 200 with typed bodies, not 500."""
    from tests.test_store import synthetic_run

    url = f"sqlite:///{tmp_path / 'outcomes.sqlite'}"
    with open_database(url) as db:
        rec = Recorder(db)
        for k, outcome in enumerate(Outcome):
            for r in synthetic_run(f"run-{k}", [f"U-{outcome.value}"], [outcome]):
                rec(r)
    client = TestClient(create_app(url))
    units = client.get("/api/units")
    assert units.status_code == 200
    assert {u["last_outcome"] for u in units.json()} == {o.value for o in Outcome}
    assert client.get("/api/runs").status_code == 200
    for outcome in Outcome:
        assert client.get(f"/api/units/U-{outcome.value}").status_code == 200
        assert client.get(f"/api/units?outcome={outcome.value}").json()[0]["serial"] == f"U-{outcome.value}"
    assert client.get("/api/units?date_to=9999-12-31").status_code == 200
