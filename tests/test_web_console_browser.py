"""The operator's whole flow in real headless Chromium against ``station serve`` and a simulated line.

``station sim`` serves a simulated rig (Modbus/TCP) and two units (ptys, calibration firmware) on a fast clock;
``station serve --rig ... --sensor ...`` runs the station with the operator console. The browser, with the
keyboard only (typed text and key presses as a barcode reader sends them): signs in, scans the lot, scans an
unknown serial and a scrapped one (both refused on the spot), scans the two units' serials, starts, confirms
the load and close-the-lid prompts, watches the progress, aborts the run, starts again, lets it finish, confirms
the unload prompt (each nest with its verdict) and sees the verdict per nest in plain words. The database then
holds both runs with the operator, the lot and the scanned serials.

Screenshots at 1920 and 800 px wide go to ``/tmp/operator-console-*.png``. Never downloads a browser: skipped
when ``/usr/bin/chromium`` or Playwright is missing.
"""

from __future__ import annotations

import os
import re
import signal
import socket
import subprocess
import sys
import time
import urllib.request
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest

CHROMIUM = Path("/usr/bin/chromium")
if not CHROMIUM.is_file():
    pytest.skip(f"{CHROMIUM} not installed (apt-get install chromium)", allow_module_level=True)
sync_api = pytest.importorskip("playwright.sync_api", reason="Playwright's Python package is not installed")

from sqlalchemy import select  # noqa: E402

from station.sequence.records import Outcome, RunFinished, RunStarted, UnitFinished  # noqa: E402
from station.store import Recorder, open_database  # noqa: E402
from station.store.models import Run, RunUnit, Unit  # noqa: E402
from station.store.recorder import record_disposition  # noqa: E402
from tests.browser_wait import wait_for  # noqa: E402

pytestmark = pytest.mark.integration

STATION = str(Path(sys.executable).with_name("station"))
CHROMIUM_ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
                 "--disable-component-update", "--disable-sync", "--no-first-run"]
SCALE = 60.0
TOKEN = "line-token-not-for-pages"
SHOTS = Path("/tmp")


@dataclass
class Line:
    url: str
    db_url: str
    serials: list[str]


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _stop(proc: subprocess.Popen[str]) -> None:
    if proc.poll() is None:
        proc.send_signal(signal.SIGTERM)
        try:
            proc.wait(30)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(10)


@pytest.fixture
def line(tmp_path: Path) -> Iterator[Line]:
    env = {**os.environ, "STATION_LOCK_DIR": str(tmp_path / "locks"), "STATION_TOKEN": TOKEN}
    db_url = f"sqlite:///{tmp_path / 'line.sqlite'}"
    with open_database(db_url) as db:  # a unit tested and scrapped earlier
        rec = Recorder(db)
        rec(RunStarted("old-1", "2026-11-20T10:00:00+00:00", 0.0, "line1", "rig", ("pty0",), ("rest",)))
        u = UnitFinished("old-1", 0, "SIM-SCRAPPED", Outcome.FAIL, "out of limits")
        rec(u)
        rec(RunFinished("old-1", Outcome.FAIL, 1.0, 1.0, 1.0, (u,)))
        record_disposition(db, "SIM-SCRAPPED", "scrap", operator="qa", note="dropped on the floor")
    sim_log = open(tmp_path / "sim.log", "w")  # noqa: SIM115 - a file, not a pipe nobody drains
    sim = subprocess.Popen([STATION, "sim", "--units", "2", "--scale", f"{SCALE:g}", "--seed", "11"],
                           stdout=subprocess.PIPE, stderr=sim_log, text=True, env=env)
    serve = None
    try:
        rig, sensors, serials = "", [], []
        assert sim.stdout is not None
        while True:
            text = sim.stdout.readline()
            if text.startswith("rig: "):
                rig = text.split()[1]
            elif m := re.match(r"sensor \d+: (\S+) \(serial (\S+)\)", text):
                sensors.append(m.group(1))
                serials.append(m.group(2))
            elif text.startswith("Ctrl-C") or not text:
                break
        assert rig and len(sensors) == 2, (tmp_path / "sim.log").read_text()
        port = _free_port()
        args = [STATION, "serve", "--port", str(port), "--rig", rig, "--scale", f"{SCALE:g}", "--db", db_url,
                "--out", str(tmp_path / "runs"), "--station", "line1"]
        for s in sensors:
            args += ["--sensor", s]
        serve = subprocess.Popen(args, stdout=subprocess.DEVNULL, stderr=open(tmp_path / "serve.log", "w"),  # noqa: SIM115
                                 text=True, env=env)
        url = f"http://127.0.0.1:{port}"
        deadline = time.monotonic() + 60
        while True:
            try:
                urllib.request.urlopen(url + "/api/status", timeout=2).read()
                break
            except OSError:
                assert serve.poll() is None, (tmp_path / "serve.log").read_text()
                assert time.monotonic() < deadline, "station serve did not answer"
                time.sleep(0.2)
        yield Line(url, db_url, serials)
    finally:
        if serve is not None:
            _stop(serve)
            print((tmp_path / "serve.log").read_text()[-3000:])
        _stop(sim)
        sim_log.close()
        print((tmp_path / "sim.log").read_text()[-2000:])


@pytest.fixture
def browser() -> Iterator[object]:
    with sync_api.sync_playwright() as pw:
        b = pw.chromium.launch(executable_path=str(CHROMIUM), args=CHROMIUM_ARGS, headless=True)
        try:
            yield b
        finally:
            b.close()


def _scan(page: object, text: str) -> None:
    """What a barcode reader does: type the characters, press Enter."""
    page.keyboard.type(text, delay=5)  # type: ignore[attr-defined]
    page.keyboard.press("Enter")  # type: ignore[attr-defined]


def _focused(page: object) -> str:
    return str(page.evaluate("document.activeElement && document.activeElement.id"))  # type: ignore[attr-defined]


def _answer_prompt(page: object, kind: str, timeout_ms: int = 60_000) -> str:
    """Wait for the prompt ``kind``, check the confirm button has the focus, press Enter; the prompt's text."""
    wait_for(page,
        f"document.getElementById('prompt').classList.contains('open') && "
        f"document.getElementById('prompt-kind').textContent === '{kind}' && "
        f"document.activeElement.id === 'prompt-confirm'", timeout=timeout_ms)
    text = str(page.text_content("#prompt-text"))  # type: ignore[attr-defined]
    page.keyboard.press("Enter")  # type: ignore[attr-defined]
    wait_for(page,
        f"!document.getElementById('prompt').classList.contains('open') || "
        f"document.getElementById('prompt-kind').textContent !== '{kind}'", timeout=30_000)
    return text


def _tab_to(page: object, element_id: str, limit: int = 60) -> None:
    for _ in range(limit):
        if _focused(page) == element_id:
            return
        page.keyboard.press("Tab")  # type: ignore[attr-defined]
    raise AssertionError(f"Tab never reached #{element_id}")


def test_the_operator_flow_with_the_keyboard_only(line: Line, browser: object) -> None:
    page = browser.new_page(viewport={"width": 1920, "height": 1080})  # type: ignore[attr-defined]
    page.goto(line.url + "/operator")
    assert TOKEN not in page.content()
    assert _focused(page) == "op-name"
    _scan(page, "alice")  # a badge: the name, Enter (the role stays 'operator')
    page.wait_for_selector("#who-name")
    assert page.text_content("#who-name") == "alice" and TOKEN not in page.content()
    wait_for(page, "document.getElementById('conn').textContent === 'live'")
    assert _focused(page) == "lot"
    assert page.locator(".nest").count() == 2

    _scan(page, "LOT-2026-11")
    assert _focused(page) == "serial-1"
    _scan(page, "hello world!")  # not a serial of this line: refused, the field keeps the focus
    wait_for(page, "document.getElementById('scan-msg').textContent.startsWith('Refused')")
    assert "not a serial number of this line" in page.text_content("#scan-msg")
    assert _focused(page) == "serial-1"
    _scan(page, "SIM-SCRAPPED")  # the field's text is selected: the next scan replaces it
    wait_for(page, "document.getElementById('scan-msg').textContent.includes('scrapped')")
    assert page.get_attribute("#serial-1", "class") == "serial refused"
    _scan(page, line.serials[0])
    wait_for(page, "document.getElementById('serial-1').className === 'serial ok'")
    assert page.input_value("#serial-1") == line.serials[0] and _focused(page) == "serial-2"
    _scan(page, line.serials[0])  # the same unit again, into nest 2
    wait_for(page, "document.getElementById('scan-msg').textContent.includes('already scanned into nest 1')")
    _scan(page, line.serials[1])
    wait_for(page, "document.activeElement.id === 'start' && !document.getElementById('start').disabled")

    # run 1: start, confirm the prompts, watch it go, abort it
    page.keyboard.press("Enter")
    load = _answer_prompt(page, "load")
    assert load == "Load the units into nests 1-2 and plug in their cables."
    lid = _answer_prompt(page, "close lid")
    assert lid.startswith("Close the lid")
    wait_for(page, "document.getElementById('step').textContent === 'rest' && "
                           "document.getElementById('bar-1').style.width !== ''", timeout=60_000)
    remaining = page.text_content("#remaining")
    basis = page.text_content("#basis")
    assert " min " in remaining and basis.startswith("estimated from the plan's capture times"), (remaining, basis)
    minutes = int(remaining.split(" min ")[0].split()[-1])
    assert 10 <= minutes <= 20, remaining  # the default plan: about 15 min of rig time, not 125
    shot = SHOTS / "operator-console-1920-running.png"
    page.screenshot(path=str(shot), full_page=True)
    _tab_to(page, "abort")
    page.keyboard.press("Enter")
    wait_for(page, "document.body.dataset.state === 'idle' && "
                           "document.getElementById('nest-1').dataset.verdict === 'ABORTED'", timeout=60_000)
    for n in (1, 2):
        assert page.text_content(f"#reason-{n}").startswith("Not tested: the run was stopped (aborted by the operator)")
    assert page.locator("#prompt.open").count() == 0  # no unload prompt after an abort

    # run 2: the same units (still scanned), to the end
    wait_for(page, "!document.getElementById('start').disabled")
    _tab_to(page, "start")
    page.keyboard.press("Enter")
    _answer_prompt(page, "load")
    _answer_prompt(page, "close lid")
    wait_for(page, "document.getElementById('step').textContent.startsWith('pose')", timeout=60_000)
    unload = _answer_prompt_later(page, line)
    assert unload.startswith("Open the lid and unload nest 1: ") and "nest 2: " in unload
    wait_for(page, "document.body.dataset.state === 'idle' && "
                           "document.getElementById('serial-1').value === '' && "
                           "document.activeElement.id === 'serial-1'", timeout=30_000)
    verdicts = [page.get_attribute(f"#nest-{n}", "data-verdict") for n in (1, 2)]
    assert all(v in {"PASS", "FAIL", "RETEST"} for v in verdicts), verdicts
    for n, v in zip((1, 2), verdicts, strict=True):
        assert f"nest {n}: {v}" in unload
        reason = page.text_content(f"#reason-{n}")
        assert reason.startswith({"PASS": "Good unit", "FAIL": "Bad unit", "RETEST": "Not decided"}[v]), reason
    page.screenshot(path=str(SHOTS / "operator-console-1920-done.png"), full_page=True)
    page.set_viewport_size({"width": 800, "height": 1000})
    narrow = SHOTS / "operator-console-800-done.png"
    page.screenshot(path=str(narrow), full_page=True)
    assert page.evaluate("document.documentElement.scrollWidth") <= 800  # nothing cut off or scrolled sideways
    page.goto("about:blank")

    with open_database(line.db_url) as db, db.transaction() as s:
        runs = s.scalars(select(Run).where(Run.run_uid != "old-1").order_by(Run.id)).all()
        assert len(runs) == 2
        assert (runs[0].outcome, runs[0].operator, runs[0].lot) == ("ABORTED", "alice", "LOT-2026-11")
        assert (runs[1].operator, runs[1].lot) == ("alice", "LOT-2026-11")
        assert runs[1].outcome in {"PASS", "FAIL", "RETEST"}
        tested = s.execute(select(RunUnit.slot, Unit.serial, RunUnit.outcome).join(Unit, RunUnit.unit_id == Unit.id)
                           .where(RunUnit.run_id == runs[1].id).order_by(RunUnit.slot)).all()
    assert [(slot, serial) for slot, serial, _ in tested] == [(0, line.serials[0]), (1, line.serials[1])]
    assert [o for *_, o in tested] == verdicts
    print(f"\nscreenshots: {shot} {SHOTS / 'operator-console-1920-done.png'} {narrow}")


def _answer_prompt_later(page: object, line: Line) -> str:
    """The unload prompt comes after the fits, the EEPROM writes and the verification: wait long, take a
    screenshot of it at 1920 px, confirm."""
    wait_for(page,
        "document.getElementById('prompt-kind').textContent === 'unload' && "
        "document.getElementById('prompt').classList.contains('open')", timeout=300_000)
    page.screenshot(path=str(SHOTS / "operator-console-1920-unload.png"), full_page=True)  # type: ignore[attr-defined]
    return _answer_prompt(page, "unload")
