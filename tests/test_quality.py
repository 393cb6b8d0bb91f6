"""Quality statistics: yield, capability and control charts aggregated by the database, checked
against an independent numpy computation on the same rows; what counts as tested and first pass when runs are
ABORTED, ERROR or UNFINISHED; the incremental index (recorder) against the rebuild (migration); run rules on
known sequences; the API's filters and 422s; the planted drift and lot shift of the synthetic history found.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from datetime import date
from pathlib import Path

import numpy as np
import pytest
from fastapi.testclient import TestClient
from sqlalchemy import select, text
from synthetic_history import DRIFTING, SHIFTED, SHIFTED_LOT, fill

from station.kernel.measurement import Measurement
from station.sequence.records import (
    Measured,
    Outcome,
    Record,
    RunFinished,
    RunStarted,
    StepFinished,
    StepStarted,
    UnitFinished,
)
from station.store import Database, Recorder, RunContext, open_database, recover_unfinished
from station.store.models import QualityResult
from station.store.quality import (
    QualityFilter,
    QualityFilterError,
    ShiftCalendar,
    capabilities,
    control_charts,
    histogram,
    yield_tables,
)
from station.store.quality_index import rebuild
from station.store.spc import c4, capability, control_chart, run_rules
from station.web.app import create_app

UNITS = 2400  # 600 runs over 12 days: ~200 units a day
DAYS = 12


@pytest.fixture(scope="module")
def filled(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Database]:
    path = tmp_path_factory.mktemp("quality") / "q.sqlite"
    with open_database(f"sqlite:///{path}") as db:
        fill(db, UNITS, seed=11, days=DAYS)
        yield db


def _raw(db: Database) -> tuple[list[tuple], list[tuple]]:
    """The records as stored (not the quality tables): results and product-limit values."""
    with db.engine.connect() as c:
        results = c.execute(text(
            "SELECT ru.id, ru.unit_id, ru.outcome, r.started_at, r.id, s.name, r.lot, r.limits_version "
            "FROM run_units ru JOIN runs r ON ru.run_id = r.id JOIN stations s ON r.station_id = s.id "
            "WHERE ru.unit_id IS NOT NULL AND r.outcome <> 'UNFINISHED'")).all()
        values = c.execute(text("SELECT run_unit_id, name, value, low, high FROM limit_checks "
                                "WHERE step = 'limits' AND value IS NOT NULL")).all()
    return results, values


def _independent_yields(results: list[tuple], key: int | None) -> dict[str, tuple[int, int, int]]:
    """(first tested, first pass, final pass) per group, from the rows alone, in numpy/Python."""
    tested = [r for r in results if r[2] in ("PASS", "FAIL", "RETEST")]
    by_unit: dict[int, list[tuple]] = {}
    for r in sorted(tested, key=lambda r: (str(r[3]), r[4])):
        by_unit.setdefault(r[1], []).append(r)
    out: dict[str, list[int]] = {}
    for rows in by_unit.values():
        first, last = rows[0], rows[-1]
        g = "" if key is None else str(first[key])
        acc = out.setdefault(g, [0, 0, 0])
        acc[0] += 1
        acc[1] += first[2] == "PASS"
        acc[2] += last[2] == "PASS"
    return {k: (v[0], v[1], v[2]) for k, v in out.items()}


def test_yield_matches_an_independent_computation(filled: Database) -> None:
    results, _ = _raw(filled)
    tables = yield_tables(filled)
    for by, key in (("total", None), ("station", 5), ("lot", 6)):
        want = _independent_yields(results, key)
        got = {r.group: (r.first_tested, r.first_pass, r.final_pass) for r in tables[by]}
        assert got == want, by
    total = tables["total"][0]
    assert total.units_tested == len({r[1] for r in results if r[2] in ("PASS", "FAIL", "RETEST")})
    assert total.not_tested == sum(r[2] not in ("PASS", "FAIL", "RETEST") for r in results) > 0
    assert total.results == len(results)
    assert 0.95 < total.first_pass_yield < total.final_yield <= 1.0  # type: ignore[operator]
    days = tables["day"]
    assert [r.group for r in days] == sorted(r.group for r in days) and len(days) >= DAYS
    assert sum(r.first_tested for r in days) == total.first_tested


def test_capability_matches_numpy_on_the_same_rows(filled: Database) -> None:
    results, values = _raw(filled)
    info = {r[0]: r for r in results if r[2] in ("PASS", "FAIL", "RETEST")}
    for name in (DRIFTING, SHIFTED, "gyro.M.xy", "fit.accel.residual_rms.y"):
        rows = [(info[v[0]], v[2], v[3], v[4]) for v in values if v[1] == name and v[0] in info]
        x = np.array([r[1] for r in rows])
        groups: dict[tuple, list[float]] = {}
        for r, val, _lo, _hi in rows:
            groups.setdefault((str(r[3])[:10], r[5], r[6], r[7]), []).append(val)
        ss = sum(float(np.sum((np.array(g) - np.mean(g)) ** 2)) for g in groups.values())
        df = sum(len(g) - 1 for g in groups.values())
        sigma_w, sigma_o = math.sqrt(ss / df), float(np.std(x, ddof=1))
        low = None if name.startswith("fit.") else rows[0][2]
        high = rows[0][3]
        mean = float(np.mean(x))
        sides = [high - mean] + ([mean - low] if low is not None else [])
        got = next(c for c in capabilities(filled) if c.name == name)
        assert got.cap.n == len(x)
        assert got.cap.mean == pytest.approx(mean, rel=1e-9, abs=1e-12)
        assert got.cap.sigma_within == pytest.approx(sigma_w, rel=1e-7)
        assert got.cap.sigma_overall == pytest.approx(sigma_o, rel=1e-7)
        assert got.cap.cpk == pytest.approx(min(sides) / (3 * sigma_w), rel=1e-7)
        assert got.cap.ppk == pytest.approx(min(sides) / (3 * sigma_o), rel=1e-7)
        if low is not None:
            assert got.cap.cp == pytest.approx((high - low) / (6 * sigma_w), rel=1e-7)
        else:
            assert got.cap.cp is None and got.one_sided
        assert got.n_above == int(np.sum(x > high))


def test_the_planted_drift_and_lot_shift_are_found(filled: Database) -> None:
    charts = {c.name: c for c in control_charts(filled)}
    drift = charts[DRIFTING].chart
    assert 3 in drift.violations or 2 in drift.violations  # a trend / a run on one side
    assert 1 in drift.violations
    assert drift.points[-1].mean > drift.points[0].mean
    lot = {c.name: c for c in capabilities(filled, QualityFilter(lot=SHIFTED_LOT))}
    assert lot[SHIFTED].cap.cpk is not None and lot[SHIFTED].cap.cpk < 1.33
    other = {c.name: c for c in capabilities(filled, QualityFilter(lot="LOT-02"))}
    assert other[SHIFTED].cap.cpk is not None and other[SHIFTED].cap.cpk > 1.5
    worst = capabilities(filled, QualityFilter(lot=SHIFTED_LOT))[0]
    assert worst.name == SHIFTED  # ranked first (worst Cpk)


def test_histogram_counts_every_value(filled: Database) -> None:
    _, values = _raw(filled)
    h = histogram(filled, DRIFTING, bins=30)
    assert h is not None and sum(h.counts) == h.n == sum(1 for v in values if v[1] == DRIFTING)
    x = np.array([v[2] for v in values if v[1] == DRIFTING])
    want, _ = np.histogram(np.clip(x, h.lo, h.hi), bins=30, range=(h.lo, h.hi))
    assert np.abs(np.array(h.counts) - want).sum() <= 2  # bin edges: float rounding may move a value


def test_filters_narrow_the_statistics(filled: Database) -> None:
    f = QualityFilter(date_from=date(2026, 9, 3), date_to=date(2026, 9, 4), station="EOL-2")
    t = yield_tables(filled, f)
    assert [r.group for r in t["station"]] == ["EOL-2"]
    assert {r.group for r in t["day"]} <= {"2026-09-03", "2026-09-04"}
    assert yield_tables(filled, QualityFilter(station="nope"))["total"][0].results == 0
    with pytest.raises(QualityFilterError):
        QualityFilter(date_from=date(2026, 9, 5), date_to=date(2026, 9, 4))


def test_shift_calendar() -> None:
    cal = ShiftCalendar.parse("early=05:30, late=13:30, night=21:30")
    assert [cal.of(m) for m in (0, 330, 800, 810, 1290, 1439)] == ["night", "early", "early", "late", "night",
                                                                   "night"]
    for bad in ("A=25:00", "A", "B=14:00,A=06:00", "A=06:00,A=07:00", "", "A=06:10"):
        with pytest.raises(QualityFilterError):
            ShiftCalendar.parse(bad)


# --- what counts: records through the recorder ---------------------------------------------------------------

def _run(run_id: str, at: str, units: list[tuple[str, Outcome, float | None]], outcome: Outcome,
         *, finish: bool = True, station: str = "st1") -> list[Record]:
    recs: list[Record] = [RunStarted(run_id, at, 0.0, station, "rig", tuple(f"p{k}" for k in range(len(units))),
                                     ("s0",)),
                          StepStarted(run_id, 0, "s0", "rest", 0.0, 1.0)]
    recs.append(StepFinished(run_id, 0, "s0", 1.0, 1.0, True, len(units)))
    done = []
    for k, (serial, out, value) in enumerate(units):
        if value is not None:
            recs.append(Measured(run_id, k, serial, "limits",
                                 Measurement("accel.bias_static.x", value, "m/s^2", -0.1, 0.1, abs(value) <= 0.1)))
        u = UnitFinished(run_id, k, serial, out, "", None, None)
        recs.append(u)
        done.append(u)
    if finish:
        recs.append(RunFinished(run_id, outcome, 2.0, 2.0, 0.1, tuple(done)))
    return recs


@pytest.fixture
def db(tmp_path: Path) -> Iterator[Database]:
    with open_database(f"sqlite:///{tmp_path / 's.sqlite'}") as database:
        yield database


def _feed(db: Database, recs: list[Record], lot: str = "") -> Recorder:
    rec = Recorder(db, RunContext(limits_version="L 1", lot=lot))
    for r in recs:
        rec(r)
    return rec


def test_aborted_error_and_unfinished_runs_do_not_count_as_first_pass(db: Database) -> None:
    P, F, A, E = Outcome.PASS, Outcome.FAIL, Outcome.ABORTED, Outcome.ERROR
    _feed(db, _run("r1", "2026-11-20T07:00:00+00:00", [("U1", A, None), ("U2", E, None)], A))
    _feed(db, _run("r2", "2026-11-20T08:00:00+00:00", [("U1", F, 0.2), ("U2", P, 0.01)], F), lot="L-1")
    _feed(db, _run("r3", "2026-11-20T09:00:00+00:00", [("U1", P, 0.02), ("U3", P, 0.03)], P), lot="L-1")
    _feed(db, _run("r4", "2026-11-20T15:00:00+00:00", [("U3", P, 0.04)], P, finish=False))  # process died
    assert recover_unfinished(db) == ["r4"]  # -> ERROR, not tested
    with db.transaction() as s:
        rows = {(r.unit_id, r.run_unit_id): (r.outcome, r.tested, r.attempt, r.final_outcome, r.latest)
                for r in s.scalars(select(QualityResult))}
    assert sorted(v for v in rows.values()) == sorted([
        ("ABORTED", False, 0, "PASS", False), ("ERROR", False, 0, "PASS", False),
        ("FAIL", True, 1, "PASS", False), ("PASS", True, 1, "PASS", True),
        ("PASS", True, 2, "PASS", True), ("PASS", True, 1, "PASS", False), ("ERROR", False, 0, "PASS", True)])
    t = yield_tables(db)
    total = t["total"][0]
    assert (total.results, total.not_tested, total.tested, total.units_tested) == (7, 3, 4, 3)
    assert (total.first_tested, total.first_pass, total.final_pass, total.retests) == (3, 2, 3, 1)
    assert total.first_pass_yield == pytest.approx(2 / 3) and total.final_yield == 1.0
    assert {r.group: r.first_tested for r in t["shift"]} == {"A": 3, "B": 0}  # A 06:00-14:00 UTC, B 14:00-22:00
    assert {r.group: r.not_tested for r in t["shift"]} == {"A": 2, "B": 1}  # r4 (15:00, recovered) not tested
    assert {r.group for r in t["lot"]} == {"", "L-1"}
    caps = capabilities(db)
    assert [c.name for c in caps] == ["accel.bias_static.x"] and caps[0].cap.n == 4 and caps[0].n_above == 1
    assert caps[0].cap.mean == pytest.approx((0.2 + 0.01 + 0.02 + 0.03) / 4)


def test_recorder_index_equals_the_rebuild(db: Database) -> None:
    P, F, R = Outcome.PASS, Outcome.FAIL, Outcome.RETEST
    _feed(db, _run("a", "2026-11-20T23:30:00+00:00", [("X1", P, 0.01), ("X2", F, 0.5)], F), lot="L-A")
    _feed(db, _run("b", "2026-11-21T01:00:00+00:00", [("X2", R, 0.09), ("X3", P, -0.02)], R), lot="L-A")
    _feed(db, _run("c", "2026-11-21T06:10:00+00:00", [("X2", P, 0.03)], P), lot="L-B")

    def snapshot() -> tuple[list[tuple], list[tuple], list[tuple], list[tuple]]:
        with db.engine.connect() as c:
            return (c.execute(text("SELECT day, quarter, station_id, lot, limits_version, results, not_tested, "
                                   "tested, first_tested, first_pass, final_pass, retests FROM quality_yield "
                                   "WHERE results > 0 OR final_pass <> 0 ORDER BY 1, 2, 3, 4")).all(),
                    c.execute(text("SELECT run_unit_id, unit_id, lot, day, minute, outcome, tested, attempt, "
                                   "final_outcome, latest FROM quality_results ORDER BY run_unit_id")).all(),
                    c.execute(text("SELECT q.run_unit_id, p.name, v.day, v.value FROM quality_values v "
                                   "JOIN quality_results q ON q.id = v.result_id JOIN quality_parameters p "
                                   "ON p.id = v.param_id ORDER BY 1, 2")).all(),
                    c.execute(text("SELECT p.name, day, station_id, lot, limits_version, n, vmin, vmax, low, high, "
                                   "n_below, n_above, s1 + n * p.ref, ROUND(s2, 12) FROM quality_daily d "
                                   "JOIN quality_parameters p ON p.id = d.param_id ORDER BY 1, 2, 3, 4")).all())

    yields_before, *incremental = snapshot()
    with db.engine.begin() as conn:
        rebuild(conn)
    yields_after, *rebuilt = snapshot()
    assert yields_before == yields_after
    # per quarter hour: results, not tested, tested, first tested, first pass, final pass, retests; X2 failed
    # first at 23:30, its final pass (06:10 the next day) is counted where it was first tested
    assert [r[5:] for r in yields_after] == [(2, 0, 2, 2, 1, 2, 0), (2, 0, 2, 1, 1, 1, 1), (1, 0, 1, 0, 0, 0, 1)]
    assert incremental[0] == rebuilt[0] and incremental[1] == rebuilt[1]
    for a, b in zip(incremental[2], rebuilt[2], strict=True):  # the sums are about a different ref: compare means
        assert a[:12] == b[:12] and a[12] == pytest.approx(b[12], abs=1e-12)
    assert [r[3:5] for r in incremental[0]] == [("2026-11-20", 1410), ("2026-11-20", 1410), ("2026-11-21", 60),
                                               ("2026-11-21", 60), ("2026-11-21", 370)]


# --- run rules -------------------------------------------------------------------------------------------------

def test_run_rules_on_known_sequences() -> None:
    assert run_rules([0.1, -3.5, 0.2]) == [set(), {1}, set()]
    rising = [-1.0 + 0.3 * i for i in range(6)]
    assert 3 in run_rules(rising)[5] and all(3 not in f for f in run_rules(rising)[:5])
    assert 2 in run_rules([0.2] * 9)[8] and 2 not in run_rules([0.2] * 8 + [-0.1])[8]
    assert 5 in run_rules([2.5, 0.0, 2.2])[2] and 5 not in run_rules([2.5, 0.0, -2.2])[2]
    assert 6 in run_rules([1.5, 1.2, 0.0, 1.1, 1.3])[4]
    alternating = [(-1) ** i * 0.5 for i in range(14)]
    assert 4 in run_rules(alternating)[13]
    assert 7 in run_rules([0.1] * 7 + [-0.1] * 8)[14]
    assert 8 in run_rules([1.5, -1.5] * 4)[7]
    assert run_rules([None, 4.0]) == [set(), {1}]


def test_capability_and_chart_from_sums_match_numpy() -> None:
    rng = np.random.default_rng(3)
    groups = [rng.normal(10.0 + 0.01 * i, 0.5, 20 + i) for i in range(8)]
    ref = 9.0
    n = [len(g) for g in groups]
    s1 = [float(np.sum(g - ref)) for g in groups]
    s2 = [float(np.sum((g - ref) ** 2)) for g in groups]
    within_ss = sum(float(np.sum((g - g.mean()) ** 2)) for g in groups)
    cap = capability(sum(n), sum(s1), sum(s2), within_ss, sum(k - 1 for k in n), ref, 8.0, 13.0)
    allx = np.concatenate(groups)
    sw = math.sqrt(within_ss / sum(k - 1 for k in n))
    assert cap.mean == pytest.approx(allx.mean(), rel=1e-12)
    assert cap.sigma_overall == pytest.approx(allx.std(ddof=1), rel=1e-10)
    assert cap.cpk == pytest.approx(min(13.0 - allx.mean(), allx.mean() - 8.0) / (3 * sw), rel=1e-10)
    ch = control_chart([f"d{i}" for i in range(8)], n, s1, s2, ref)
    assert ch.center == pytest.approx(allx.mean(), rel=1e-12)
    for p, g in zip(ch.points, groups, strict=True):
        assert p.mean == pytest.approx(g.mean(), rel=1e-12) and p.s == pytest.approx(g.std(ddof=1), rel=1e-9)
        assert p.ucl - ch.center == pytest.approx(3 * sw / math.sqrt(len(g)), rel=1e-9)
    assert c4(2) == pytest.approx(math.sqrt(2 / math.pi), rel=1e-12)


# --- the API -----------------------------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def client(filled: Database) -> Iterator[TestClient]:
    with TestClient(create_app(database=filled)) as c:
        yield c


def test_quality_api_and_page(client: TestClient) -> None:
    y = client.get("/api/quality/yield", params={"by": "lot", "shifts": "A=06:00,B=18:00"})
    assert y.status_code == 200 and y.json()["shifts"] == "A=06:00,B=18:00"
    assert SHIFTED_LOT in {r["group"] for r in y.json()["rows"]} and "Tested" in y.json()["definitions"]
    s = client.get("/api/quality/yield", params={"by": "shift", "shifts": "A=06:00,B=18:00"}).json()
    assert [r["group"] for r in s["rows"]] == ["A", "B"]
    caps = client.get("/api/quality/capability", params={"lot": SHIFTED_LOT}).json()
    assert caps[0]["name"] == SHIFTED and caps[0]["cpk"] < 1.33
    charts = client.get("/api/quality/control-charts", params={"name": DRIFTING}).json()
    assert [c["name"] for c in charts["charts"]] == [DRIFTING] and charts["charts"][0]["violations"]
    assert len(charts["rules"]) == 8
    h = client.get(f"/api/quality/histogram/{DRIFTING}", params={"bins": 20}).json()
    assert len(h["counts"]) == 20 and sum(h["counts"]) == h["n"]
    for bad in ({"date_from": "2026-02-30"}, {"date_from": "2026-09-05", "date_to": "2026-09-01"},
                {"shifts": "A=6"}, {"by": "week"}):
        assert client.get("/api/quality/yield", params=bad).status_code == 422, bad
        if "by" not in bad:
            assert client.get("/quality", params=bad).status_code == 422, bad
    page = client.get("/quality", params={"lot": SHIFTED_LOT})
    assert page.status_code == 200 and f'data-param="{SHIFTED}"' in page.text and "Definitions" in page.text
    csv_text = client.get("/quality/yield.csv", params={"by": "station"}).text.splitlines()
    assert csv_text[0].startswith("group,results,not_tested") and len(csv_text) == 5
    cap_csv = client.get("/quality/capability.csv").text.splitlines()
    assert cap_csv[0].startswith("name,label,unit") and len(cap_csv) == 1 + len(client.get(
        "/api/quality/capability").json())
    svg = client.get(f"/quality/histogram/{DRIFTING}.svg")
    assert svg.status_code == 200 and svg.text.startswith("<svg") and "USL" in svg.text
    assert client.get("/quality/histogram/nope.svg").status_code == 404
    assert client.get(f"/quality/control/{DRIFTING}.svg").text.count("<circle") >= DAYS


def test_unit_list_search_and_cursor_pages(client: TestClient) -> None:
    seen: list[str] = []
    params: dict[str, str | int] = {"q": "imu-00001", "limit": 4}
    while True:
        r = client.get("/api/units", params=params)
        assert r.status_code == 200
        seen += [u["serial"] for u in r.json()]
        if "X-Next-Cursor" not in r.headers:
            assert "Link" not in r.headers
            break
        assert 'rel="next"' in r.headers["Link"]
        params = {**params, "cursor": r.headers["X-Next-Cursor"]}
    assert seen == [f"IMU-{i:07d}" for i in range(100, 200)]  # 'IMU-00001' + two digits, in 25 pages
    one = client.get("/api/units", params={"q": "IMU-0000042"}).json()
    assert [u["serial"] for u in one] == ["IMU-0000042"] and one[0]["last_started_at"].endswith("+00:00")
    fails = client.get("/api/units", params={"outcome": "FAIL", "limit": 1000}).json()
    assert fails and all(u["last_outcome"] == "FAIL" for u in fails)
    for bad in ({"outcome": "BOGUS"}, {"cursor": "%%%"}, {"limit": 0}):
        assert client.get("/api/units", params=bad).status_code == 422, bad
    page = client.get("/units", params={"q": "IMU-000004", "limit": 5})
    assert page.status_code == 200 and "IMU-0000040" in page.text and 'id="next"' in page.text
    runs, cursor, pages = [], None, 0
    while pages < 3:
        r = client.get("/api/runs", params={"limit": 50, **({"cursor": cursor} if cursor else {})})
        runs += [x["run_id"] for x in r.json()]
        cursor, pages = r.headers.get("X-Next-Cursor"), pages + 1
    starts = [x["started_at"] for x in client.get("/api/runs", params={"limit": 150}).json()]
    assert runs == [x["run_id"] for x in client.get("/api/runs", params={"limit": 150}).json()]
    assert starts == sorted(starts, reverse=True) and all(t.endswith("+00:00") for t in starts)
    assert client.get("/api/runs", params={"cursor": "bm9wZQ"}).status_code == 422
    unit = client.get("/api/units/IMU-0000042").json()  # ISO 8601 with the UTC offset everywhere
    assert all(r["started_at"].endswith("+00:00") and r["finished_at"].endswith("+00:00") for r in unit["runs"])


def test_an_old_database_gets_its_statistics_on_migration(db: Database) -> None:
    P, F = Outcome.PASS, Outcome.FAIL
    _feed(db, _run("a", "2026-11-20T09:00:00+00:00", [("M1", F, 0.3), ("M2", P, 0.02)], F))
    _feed(db, _run("b", "2026-11-20T10:00:00+00:00", [("M1", P, 0.01)], P))
    before = yield_tables(db), capabilities(db)
    from station.store.db import downgrade, upgrade

    downgrade(db.engine, "0002")  # a database of the previous version: no quality tables, no lot
    with db.engine.connect() as c:
        assert "quality_results" not in {r[0] for r in c.execute(text("SELECT name FROM sqlite_master"))}
    upgrade(db.engine)
    after = yield_tables(db), capabilities(db)
    assert after[0] == before[0] and after[0]["total"][0].first_pass == 1
    assert [(c.name, c.cap.n, c.cap.mean) for c in after[1]] == [(c.name, c.cap.n, pytest.approx(c.cap.mean))
                                                                  for c in before[1]]


def test_status_shows_the_rig_only_while_a_run_holds_it(db: Database) -> None:
    from station.sequence.records import RigReading
    from station.web.state import LiveStatus

    live = LiveStatus(db)
    recs = _run("live", "2026-11-20T07:00:00+00:00", [("S1", Outcome.ABORTED, None)], Outcome.ABORTED)
    live(recs[0])
    live(RigReading("live", 1.0, 0.0, 0.0, 10.0, -18.7, "MOVING", 0))
    assert live.status(with_store=False).rig_state is not None  # running: the rig's last reading
    for r in recs[1:]:
        live(r)
    st = live.status(with_store=False)
    assert st.state == "idle" and st.rig_state is None and st.outcome == "ABORTED"
