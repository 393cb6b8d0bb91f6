"""The operator console's API: sign-in, scans checked on the spot, starts with scanned serials, prompt answers.

No browser and no hardware: the store holds a scrapped unit and one over its failed attempts; the live status's
start hook records what it was given; a :class:`ConsoleOperator` waits in a thread as the runner's would.
"""

from __future__ import annotations

import threading
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from fastapi.testclient import TestClient

from station.sequence.prompts import close_lid_prompt
from station.sequence.records import Outcome, PromptAnswered, PromptShown, RunFinished, RunStarted, UnitFinished
from station.store import Recorder, open_database
from station.store.recorder import record_disposition
from station.web.app import create_app
from station.web.console import ConsoleOperator
from station.web.state import LiveStatus

TOKEN = "console-s3cret"


def _run(recorder: Recorder, run_id: str, serial: str, outcome: Outcome) -> None:
    recorder(RunStarted(run_id, "2026-11-21T10:00:00+00:00", 0.0, "st", "rig", ("pty0",), ("rest",)))
    u = UnitFinished(run_id, 0, serial, outcome, "" if outcome == Outcome.PASS else "out of limits")
    recorder(u)
    recorder(RunFinished(run_id, outcome, 10.0, 10.0, 1.0, (u,)))


@pytest.fixture
def setup(tmp_path: Path) -> Iterator[dict[str, Any]]:
    db = open_database(f"sqlite:///{tmp_path / 'console.sqlite'}")
    recorder = Recorder(db)
    _run(recorder, "r1", "SCRAP-0001", Outcome.FAIL)
    record_disposition(db, "SCRAP-0001", "scrap", operator="qa", note="cracked housing")
    for k in range(3):
        _run(recorder, f"f{k}", "TIRED-0001", Outcome.FAIL)
    _run(recorder, "p1", "GOOD-0001", Outcome.PASS)
    live = LiveStatus(db)
    live.nests = 2
    started: list[dict[str, Any]] = []
    live.on_start = lambda options: started.append(options) or "run-42"
    live.on_abort = lambda run_id: run_id == "run-42"
    prompter = ConsoleOperator()
    app = create_app(database=db, token=TOKEN, live=live, prompter=prompter, session_key="k" * 32)
    with TestClient(app) as client:
        yield {"client": client, "live": live, "started": started, "prompter": prompter, "app": app}
    db.close()


def test_sign_in_and_the_writes_it_allows(setup: dict[str, Any]) -> None:
    c: TestClient = setup["client"]
    assert c.post("/api/runs", json={}).status_code == 401
    assert c.post("/api/operator/scan", json={"serial": "NEW-0001", "nest": 1}).status_code == 401
    assert c.get("/api/operator/session").json() == {"signed_in": False, "name": "", "role": ""}
    r = c.post("/api/operator/session", json={"name": " alice ", "role": "technician"})
    assert r.status_code == 200 and r.json() == {"signed_in": True, "name": "alice", "role": "technician"}
    cookie = r.headers["set-cookie"]
    assert "station_operator=" in cookie and "samesite=strict" in cookie.lower() and "httponly" in cookie.lower()
    assert c.post("/api/operator/session", json={"name": "bob", "role": "boss"}).status_code == 422
    r = c.post("/api/runs", json={"lot": "LOT-7", "serials": {"1": "NEW-0001", "2": "GOOD-0001"},
                                  "operator": "mallory"})
    assert r.status_code == 202 and r.json() == {"run_id": "run-42"}
    # the signed-in operator's own name is recorded, whatever the body says
    assert setup["started"] == [{"operator": "alice", "lot": "LOT-7", "serials": {1: "NEW-0001", 2: "GOOD-0001"}}]
    assert c.post("/api/runs/run-42/abort").status_code == 202
    # a page of another site cannot write in the operator's name
    assert c.post("/api/runs/run-42/abort", headers={"Origin": "http://evil.example"}).status_code == 403
    c.delete("/api/operator/session")
    assert c.post("/api/runs/run-42/abort").status_code == 401
    # the bearer token still works without anyone signed in
    assert c.post("/api/runs/run-42/abort", headers={"Authorization": f"Bearer {TOKEN}"}).status_code == 202


def test_signing_in_from_another_computer_needs_the_token_which_no_page_shows(setup: dict[str, Any]) -> None:
    remote = TestClient(setup["app"], client=("10.1.2.3", 40000))
    assert remote.post("/api/operator/session", json={"name": "eve"}).status_code == 401
    assert remote.post("/api/operator/session", json={"name": "eve", "token": "guess"}).status_code == 401
    page = remote.get("/operator").text
    assert TOKEN not in page and 'id="op-token"' in page and 'type="password"' in page
    assert remote.post("/api/operator/session", json={"name": "eve", "token": TOKEN}).status_code == 200
    page = remote.get("/operator").text
    assert TOKEN not in page and 'id="who-name">eve<' in page
    for path in ("/", "/units", "/quality", "/operator"):
        assert TOKEN not in setup["client"].get(path).text


@pytest.mark.parametrize(("serial", "nest", "others", "accepted", "message"), [
    ("NEW-0001", 1, {}, True, "new unit: first test"),
    ("  GOOD-0001 \r", 2, {}, True, "tested 1 time(s) before, last PASS"),
    ("hello world!", 1, {}, False, "not a serial number of this line: 'hello world!'"),
    ("", 1, {}, False, "nothing scanned"),
    ("NEW-0001", 2, {"1": "NEW-0001"}, False, "NEW-0001 is already scanned into nest 1"),
    ("SCRAP-0001", 1, {}, False, "SCRAP-0001 was scrapped on "),
    ("TIRED-0001", 1, {}, False, "TIRED-0001 has failed 3 attempt(s), the limit is 3: a disposition is needed"),
    ("NEW-0002", 3, {}, False, "the fixture has nests 1 to 2"),
])
def test_a_scan_is_checked_on_the_spot(setup: dict[str, Any], serial: str, nest: int, others: dict[str, str],
                                       accepted: bool, message: str) -> None:
    c: TestClient = setup["client"]
    c.post("/api/operator/session", json={"name": "alice"})
    r = c.post("/api/operator/scan", json={"serial": serial, "nest": nest, "scanned": others})
    assert r.status_code == 200
    body = r.json()
    assert body["accepted"] is accepted and body["message"].startswith(message), body
    assert body["serial"] == serial.strip()


def test_a_start_with_a_refused_serial_is_refused(setup: dict[str, Any]) -> None:
    c: TestClient = setup["client"]
    auth = {"Authorization": f"Bearer {TOKEN}"}
    r = c.post("/api/runs", json={"serials": {"1": "SCRAP-0001"}}, headers=auth)
    assert r.status_code == 422 and "nest 1: SCRAP-0001 was scrapped" in r.json()["detail"]
    assert c.post("/api/runs", json={"serials": {"3": "NEW-0001"}}, headers=auth).status_code == 422
    assert c.post("/api/runs", json={"lot": "no spaces"}, headers=auth).status_code == 422
    assert setup["started"] == []


def test_a_prompt_is_answered_from_the_console(setup: dict[str, Any]) -> None:
    c: TestClient = setup["client"]
    live: LiveStatus = setup["live"]
    prompter: ConsoleOperator = setup["prompter"]
    live(RunStarted("run-42", "2026-11-21T10:00:00+00:00", 0.0, "st", "rig", ("a", "b"), ("rest",), (300.0,)))
    prompt = close_lid_prompt(timeout_s=30.0)
    live(PromptShown("run-42", "run-42/p1", prompt.kind.value, prompt.text, (), prompt.timeout_s))
    status = c.get("/api/status").json()
    assert status["prompt"]["prompt_id"] == "run-42/p1" and status["prompt"]["kind"] == "close-lid"
    assert [s["state"] for s in status["slots"]] == ["reading serial…", "reading serial…"]
    got: list[tuple[str, str]] = []
    waiter = threading.Thread(target=lambda: got.append(prompter.ask("run-42/p1", prompt, threading.Event())))
    waiter.start()
    assert c.post("/api/prompts/run-42/p1", json={"answer": "confirmed"}).status_code == 401
    c.post("/api/operator/session", json={"name": "alice"})
    assert c.post("/api/prompts/run-42/p9", json={"answer": "confirmed"}).status_code == 404
    assert c.post("/api/prompts/run-42/p1", json={"answer": "maybe"}).status_code == 422
    r = c.post("/api/prompts/run-42/p1", json={"answer": "confirmed"})
    assert r.status_code == 202, r.text
    waiter.join(10.0)
    assert got == [("confirmed", "alice")]
    live(PromptAnswered("run-42", "run-42/p1", "confirmed", "alice", 0.5))
    assert c.get("/api/status").json()["prompt"] is None
    assert c.post("/api/prompts/run-42/p1", json={"answer": "confirmed"}).status_code == 404  # closed


def test_the_console_operator_times_out_and_gives_up_on_abort() -> None:
    op = ConsoleOperator()
    assert op.ask("r/p1", close_lid_prompt(timeout_s=0.05), threading.Event()) == ("timeout", "")
    cancel = threading.Event()
    cancel.set()
    assert op.ask("r/p2", close_lid_prompt(), cancel) == ("cancelled", "")
    assert not op.answer("r/p1", "confirmed", "late")  # closed prompts take no answer


def test_every_page_links_the_console(setup: dict[str, Any]) -> None:
    c: TestClient = setup["client"]
    for path in ("/", "/units", "/quality", "/operator", "/units/GOOD-0001"):
        r = c.get(path)
        assert r.status_code == 200 and '<a href="/operator">operator</a>' in r.text, path


def test_time_remaining_comes_from_the_plan() -> None:
    from station.sequence.records import StepFinished, StepStarted

    live = LiveStatus()
    live(RunStarted("r", "2026-11-21T10:00:00+00:00", 0.0, "st", "rig", ("a",), ("rest", "pose +z", "pose -z"),
                    (300.0, 30.0, 30.0)))
    s = live.status(with_store=False)
    assert s.remaining_s == pytest.approx(360.0) and "rig motion not measured yet" in s.remaining_basis
    assert s.slots[0].state == "reading serial…" and s.slots[0].serial == ""
    live(StepStarted("r", 0, "rest", "rest", 0.0, 300.0))
    s = live.status(with_store=False)
    # the plan's holds, not the current step's 300 s for every step to come (which said 900 s)
    assert s.remaining_s == pytest.approx(360.0) and s.slots[0].state == "measuring"
    live(StepFinished("r", 0, "rest", 310.0, 310.0, True, 1))
    s = live.status(with_store=False)
    assert s.remaining_s == pytest.approx(30.0 + 30.0 + 2 * 10.0)
    assert s.remaining_basis == ("estimated from the plan's capture times + rig motion 10 s per step (mean of 1 "
                                 "finished step(s))")
    live(StepStarted("r", 1, "pose +z", "pose", 310.0, 30.0))
    live(StepFinished("r", 1, "pose +z", 345.0, 35.0, True, 1))
    live(StepStarted("r", 2, "pose -z", "pose", 345.0, 30.0))
    live(StepFinished("r", 2, "pose -z", 380.0, 35.0, True, 1))
    s = live.status(with_store=False)
    assert s.remaining_s == 0.0 and s.remaining_basis.endswith("writing the units are not estimated")


def test_the_verdict_in_plain_words() -> None:
    from station.kernel.measurement import Measurement
    from station.sequence.records import Measured

    live = LiveStatus()
    live(RunStarted("r", "2026-11-21T10:00:00+00:00", 0.0, "st", "rig", ("a", "b"), ("rest",), (300.0,)))
    live(Measured("r", 0, "A-1", "limits", Measurement("gyro.bias_static.x", 0.01, "rad/s", -0.00873, 0.00873,
                                                       False)))
    live(UnitFinished("r", 0, "A-1", Outcome.FAIL, "out of limits (t1): gyro.bias_static.x = 0.01 rad/s outside ..."))
    live(UnitFinished("r", 1, "B-2", Outcome.ERROR, "step 'rest': SerialTimeout: no answer"))
    s = live.status(with_store=False)
    assert s.slots[0].reason == ("Bad unit: gyroscope static bias x is 0.573 °/s, allowed −0.5002 to 0.5002 °/s. "
                                 "Put it in the reject bin.")
    assert s.slots[1].reason.startswith("Not the unit's fault: the station had a problem (step 'rest': SerialTimeout")


def test_an_inconclusive_check_in_plain_words() -> None:
    from station.kernel.measurement import Measurement
    from station.web.verdicts import Missed, plain_reason

    m = Measurement("accel.bias_static.z", -0.1694, "m/s^2", -0.17, 0.026, False, 0.00044, inconclusive=True, k=2.0)
    assert plain_reason("FAIL", "inconclusive ...", (Missed.of(m),)) == (
        "Bad unit: accelerometer static bias z is −0.1694 m/s², too close to its limits (−0.17 to 0.026 m/s²) to be "
        "sure. Put it in the reject bin.")
