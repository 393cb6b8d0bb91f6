"""The diagnosis on the unit page and in the API, against a temporary SQLite store of real runs.

Unit ``LEVER-1``'s recording is a simulated session (short plan, as in test_diagnose.py)
with a 30 mm lever arm: the API must answer 202 while the background worker computes and
then 200 with ``lever_arm`` at the right magnitude; the result is kept next to the
recording and read back by a second application at once. ``BROKEN-2``'s recording lacks
the -z pose (the fit refuses it), ``GARBAGE-3``'s is not a session and ``CHANGED-4``'s was
modified after its run: each is a readable 422, never a server error.
"""

from __future__ import annotations

import json
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from fastapi.testclient import TestClient

from station.diagnose.residuals import BaseFitNoise
from station.diagnose.results import DiagnosisReport, RerunError
from station.kernel.plan import RigPlan
from station.physics.effects import Effects
from station.sequence.records import Outcome, Record, RunFinished, RunStarted, UnitFinished
from station.session.csv_v1 import write_session
from station.session.model import Kind, Session
from station.sim.session_sim import simulate_session
from station.store import Recorder, open_database
from station.web.app import create_app
from station.web.diagnosis_worker import READY, DiagnosisService, Recording, Result, sidecar_path

#: ~8 min at 100 Hz with two rate magnitudes (as tests/test_diagnose.py): the lever arm is identifiable.
PLAN = RigPlan(
    rest_s=120.0,
    pose_hold_s=15.0,
    rate_steps=tuple((a, s * r) for a in "xyz" for r in (50.0, 200.0) for s in (1.0, -1.0)),
    rate_hold_s=6.0,
)
OLD, NEW = "run-0001", "run-0002"


def _run(run_id: str, at: str, units: list[tuple[str, str | None]]) -> list[Record]:
    """A run of ``units`` [(serial, session path)], all PASS, with nothing but the recordings."""
    done = tuple(UnitFinished(run_id, k, serial, Outcome.PASS, "", path) for k, (serial, path) in enumerate(units))
    return [RunStarted(run_id, at, 0.0, "st1", "sim-rig", tuple(f"pty{k}" for k in range(len(units))), ("rest",)),
            *done, RunFinished(run_id, Outcome.PASS, 600.0, 600.0, 1.0, done)]


def _without_z_down_pose(s: Session) -> Session:
    seg = next(g for g in s.segments_of(Kind.POSE) if s.ref_accel_mps2[g.start][2] < -5.0)
    keep = s.segment != seg.index
    return s.replace(**{n: getattr(s, n)[keep] for n in (
        "t_s", "segment", "kind", "accel_mps2", "gyro_radps", "temp_degc", "ref_accel_mps2", "ref_gyro_radps")})


@pytest.fixture(scope="module")
def store(tmp_path_factory: pytest.TempPathFactory) -> Iterator[dict[str, Any]]:
    tmp = tmp_path_factory.mktemp("webdiag")
    lever = simulate_session(5, plan=PLAN, effects=Effects(lever_arm=30.0))
    paths = {name: tmp / f"{name}.csv" for name in ("lever", "broken", "garbage", "changed")}
    write_session(lever.session, paths["lever"])
    write_session(_without_z_down_pose(simulate_session(6, plan=PLAN).session), paths["broken"])
    paths["garbage"].write_text("this is not a session recording\n", encoding="utf-8")
    paths["changed"].write_text("version one\n", encoding="utf-8")
    db = open_database(f"sqlite:///{tmp / 'station.sqlite'}")
    recorder = Recorder(db)
    for r in (*_run(OLD, "2026-11-20T10:00:00+00:00", [("LEVER-1", str(paths["broken"]))]),
              *_run(NEW, "2026-11-21T10:00:00+00:00", [
                  ("LEVER-1", str(paths["lever"])), ("BROKEN-2", str(paths["broken"])),
                  ("GARBAGE-3", str(paths["garbage"])), ("CHANGED-4", str(paths["changed"])), ("NOREC-5", None)])):
        recorder(r)
    assert recorder.errors == []
    paths["changed"].write_text("version two\n", encoding="utf-8")  # after the run hashed it
    yield {"db": db, "paths": paths, "truth_mm": lever.effect_truth.lever_arm_m * 1e3}
    db.close()


@pytest.fixture(scope="module")
def client(store: dict[str, Any]) -> Iterator[TestClient]:
    with TestClient(create_app(database=store["db"], diagnosis=DiagnosisService())) as c:
        yield c


def _poll(client: TestClient, url: str, limit_s: float = 180.0) -> tuple[list[int], Any]:
    """GET ``url`` until it stops answering 202: every status seen and the last response."""
    codes: list[int] = []
    deadline = time.monotonic() + limit_s
    while True:
        r = client.get(url)
        codes.append(r.status_code)
        if r.status_code != 202 or time.monotonic() > deadline:
            return codes, r
        time.sleep(0.25)


def test_lever_arm_goes_pending_then_ready(client: TestClient, store: dict[str, Any]) -> None:
    lever = store["paths"]["lever"]
    assert not sidecar_path(lever).exists()
    codes, r = _poll(client, "/api/units/LEVER-1/diagnosis")
    assert codes[0] == 202 and codes[-1] == 200, codes
    body = r.json()
    assert body["status"] == READY and body["run_id"] == NEW and body["serial"] == "LEVER-1"
    report = body["report"]
    assert report["format"] == "station-diagnosis/1"
    finding = next(f for f in report["findings"] if f["effect"] == "lever_arm")
    assert finding["sensor"] == "accel" and finding["parameters"]["unit"] == "mm"
    value, std = np.array(finding["parameters"]["value"]), np.array(finding["parameters"]["std"])
    assert np.all(np.abs(value - store["truth_mm"]) < 5 * std + 1.0), (value, store["truth_mm"])
    assert abs(finding["parameters"]["length_mm"] - 30.0) < 2.0
    assert max(finding["fit"]["after"]["block_rms"]) < 0.2 * max(finding["fit"]["before"]["block_rms"])
    # computed once: asked again, answered from memory; persisted next to the recording
    again = client.get("/api/units/LEVER-1/diagnosis", params={"run_id": NEW})
    assert again.status_code == 200 and again.json()["report"] == report
    saved = json.loads(sidecar_path(lever).read_text(encoding="utf-8"))
    assert saved["status"] == READY and saved["report"] == report
    assert "accel lever_arm" in [c["title"] for c in saved["curves"]]
    # a second server on the same store reads it back at once (no 202)
    with TestClient(create_app(database=store["db"], diagnosis=DiagnosisService())) as other:
        r2 = other.get("/api/units/LEVER-1/diagnosis")
        assert r2.status_code == 200 and r2.json()["report"] == report
        svg = other.get("/units/LEVER-1/diagnosis.svg")
        assert svg.status_code == 200 and "lever_arm" in svg.text
    # a kept report of another format is not read back into the types (it would be computed again)
    rec = Recording(NEW, lever, saved["session_sha256"])
    assert DiagnosisService().peek(rec) is not None
    other_format = {**saved, "report": {**saved["report"], "format": "station-diagnosis/0"}}
    sidecar_path(lever).write_text(json.dumps(other_format), encoding="utf-8")
    assert DiagnosisService().peek(rec) is None
    sidecar_path(lever).write_text(json.dumps(saved), encoding="utf-8")


def test_svg_figure(client: TestClient) -> None:
    _poll(client, "/api/units/LEVER-1/diagnosis")
    r = client.get("/units/LEVER-1/diagnosis.svg")
    assert r.status_code == 200 and r.headers["content-type"].startswith("image/svg+xml")
    assert r.text.lstrip().startswith("<?xml") and "<path" in r.text
    assert "accel lever_arm: before" in r.text and "accel lever_arm: after" in r.text
    assert client.get("/units/NO-SUCH-UNIT/diagnosis.svg").status_code == 404
    assert client.get("/units/NOREC-5/diagnosis.svg").status_code == 404


def test_unit_page_has_the_section(client: TestClient) -> None:
    page = client.get("/units/LEVER-1")
    assert page.status_code == 200
    text = page.text
    assert 'id="diagnosis"' in text and 'id="diagnosis-run"' in text and 'id="diagnosis-figure"' in text
    assert f'<option value="{NEW}">' in text and f'<option value="{OLD}">' in text  # one per run with a recording
    assert f'data-diagnose="{OLD}"' in text
    assert "/api/units/' + encodeURIComponent(serial) + '/diagnosis" in text
    none = client.get("/units/NOREC-5")
    assert none.status_code == 200 and "No session recording to diagnose" in none.text


def test_unknown_unit_run_or_recording_is_404(client: TestClient) -> None:
    r = client.get("/api/units/NO-SUCH-UNIT/diagnosis")
    assert r.status_code == 404 and "NO-SUCH-UNIT" in r.json()["detail"]
    r = client.get("/api/units/NOREC-5/diagnosis")
    assert r.status_code == 404 and "no session recording" in r.json()["detail"]
    assert client.get("/api/units/LEVER-1/diagnosis", params={"run_id": "nope"}).status_code == 404


@pytest.mark.parametrize(("serial", "run_id", "words"), [
    ("BROKEN-2", None, ("FitError", "missing pose")),
    ("LEVER-1", OLD, ("FitError", "missing pose")),  # the same broken file in the unit's older run
    ("GARBAGE-3", None, ("Error",)),
    ("CHANGED-4", None, ("has changed since run", NEW)),
])
def test_a_bad_recording_is_a_readable_error(client: TestClient, serial: str, run_id: str | None,
                                             words: tuple[str, ...]) -> None:
    params = {"run_id": run_id} if run_id else {}
    codes, r = _poll(client, f"/api/units/{serial}/diagnosis?" + "&".join(f"{k}={v}" for k, v in params.items()))
    assert codes[-1] == 422, codes
    body = r.json()
    assert body["status"] == "error" and body["serial"] == serial
    for w in words:
        assert w in body["detail"], body["detail"]
    svg = client.get(f"/units/{serial}/diagnosis.svg", params=params)
    assert svg.status_code == 422 and "no diagnosis" in svg.text


def test_openapi_documents_the_endpoint(client: TestClient) -> None:
    op = client.get("/openapi.json").json()["paths"]["/api/units/{serial}/diagnosis"]["get"]
    assert op["tags"] == ["units"] and {"200", "202", "404", "422"} <= set(op["responses"])
    assert [p["name"] for p in op["parameters"]] == ["serial", "run_id"]


def _odd_report() -> DiagnosisReport:
    """A report without entries whose base-fit noise holds a NaN."""
    nan = float("nan")
    return DiagnosisReport(serial="LEVER-1", findings=(), rejected=(), inseparable=(), unexplained=(), location={},
                           warmup_tc_range_s=None, base_fit=BaseFitNoise([nan, 0.0, 0.0], [0.0] * 3, [0.0] * 3,
                                                                         [0.0] * 3),
                           rerun=RerunError("no motion"))


def test_busy_queue_and_strict_json(store: dict[str, Any]) -> None:
    release = threading.Event()

    def slow(rec: Recording) -> Result:
        release.wait(30.0)
        return Result(READY, report=_odd_report(), elapsed_s=0.0)

    service = DiagnosisService(max_queued=1, persist=False, compute=slow)
    try:
        with TestClient(create_app(database=store["db"], diagnosis=service)) as c:
            assert c.get("/api/units/LEVER-1/diagnosis").status_code == 202
            assert c.get("/api/units/LEVER-1/diagnosis").status_code == 202  # queued once
            busy = c.get("/api/units/GARBAGE-3/diagnosis")  # a second recording: beyond max_queued
            assert busy.status_code == 503 and busy.json()["status"] == "busy" and "Retry-After" in busy.headers
            release.set()
            codes, r = _poll(c, "/api/units/LEVER-1/diagnosis")
            expected = json.loads(json.dumps(_odd_report().to_json()).replace("NaN", "null"))
            assert expected["base_fit"]["accel_residual_rms_mps2"] == [None, 0.0, 0.0]
            assert codes[-1] == 200 and r.json()["report"] == expected  # strict JSON
    finally:
        release.set()


def _wait_ready(service: DiagnosisService, rec: Recording, limit_s: float = 180.0) -> Result:
    deadline = time.monotonic() + limit_s
    while (result := service.get(rec)).status not in (READY, "error"):
        assert time.monotonic() < deadline, "the diagnosis did not finish"
        time.sleep(0.1)
    return result


def test_service_diagnoses_with_the_limits_tc_range(tmp_path: Path) -> None:
    """The service's T_c range (the station's limits file, as create_app sets it) reaches the diagnosis: a gyro
    temperature bias the recording alone cannot tell from the warm-up is named with it. A result persisted with
    another range is not taken for this one's."""
    from station.kernel.limits_file import load_limits
    from station.store.recorder import sha256_file

    path = tmp_path / "temp.csv"
    write_session(simulate_session(14, plan=PLAN, effects=Effects(temperature_bias=2e-3)).session, path)
    rec = Recording("run-x", path, sha256_file(path)[0])
    with_range = DiagnosisService(nice=0, warmup_tc_s=load_limits().correlation_time_s)
    alone = DiagnosisService(nice=0)
    try:
        found = _wait_ready(with_range, rec)
        assert found.report is not None and found.report.effects == [("temperature_bias", "gyro")]
        saved = json.loads(sidecar_path(path).read_text(encoding="utf-8"))
        assert saved["settings"] == {"warmup_tc_range_s": {"accel": [50.0, 167.0], "gyro": [1030.0, 3760.0]}}
        assert alone.peek(rec) is None  # persisted with another range: computed again
        again = _wait_ready(alone, rec).report
        assert again is not None and again.findings == ()
        assert DiagnosisService(warmup_tc_s=load_limits().correlation_time_s).peek(rec) is None
    finally:
        with_range.stop()
        alone.stop()
