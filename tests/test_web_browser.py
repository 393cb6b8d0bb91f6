"""The status and unit pages in real headless Chromium (Debian's ``chromium``, driven by Playwright).

uvicorn serves the app in a thread on 127.0.0.1 (free port); a short simulated run (two
units, real Modbus/TCP rig server and pty sensors on a fast clock) feeds the store's
recorder and the live status while the browser watches the status page: it must see
the steps go by through server-sent events, without reloading, and end with the
runner's verdicts. Then the unit page must show its plots and its diagnosis. Screenshots of both pages
are saved under pytest's tmp dir (their paths are printed).

Never downloads a browser: skipped when ``/usr/bin/chromium`` or Playwright is missing.
"""

from __future__ import annotations

import io
import threading
from collections.abc import Iterator
from pathlib import Path

import pytest

CHROMIUM = Path("/usr/bin/chromium")
if not CHROMIUM.is_file():
    pytest.skip(f"{CHROMIUM} not installed (apt-get install chromium)", allow_module_level=True)
sync_api = pytest.importorskip("playwright.sync_api", reason="Playwright's Python package is not installed")

from rich.console import Console  # noqa: E402

from station.kernel.plan import RigPlan  # noqa: E402
from station.sequence.records import Outcome  # noqa: E402
from station.sim.demo import run_demo  # noqa: E402
from station.store import Recorder, open_database  # noqa: E402
from station.web.app import create_app  # noqa: E402
from station.web.serve import ServerThread  # noqa: E402
from station.web.state import LiveStatus  # noqa: E402
from tests.browser_wait import wait_for  # noqa: E402

CHROMIUM_ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
                 "--disable-component-update", "--disable-sync", "--no-first-run"]
PLAN = RigPlan(sample_rate_hz=50.0, rest_s=120.0, pose_hold_s=5.0,
               rate_steps=(("x", 100.0), ("y", 100.0), ("z", 100.0)), rate_hold_s=4.0)
SCALE = 40.0


@pytest.fixture
def browser() -> Iterator[object]:
    with sync_api.sync_playwright() as pw:
        b = pw.chromium.launch(executable_path=str(CHROMIUM), args=CHROMIUM_ARGS, headless=True)
        try:
            yield b
        finally:
            b.close()


def test_status_page_follows_a_run_and_unit_page_shows_plots(tmp_path: Path, browser: object) -> None:
    db = open_database(f"sqlite:///{tmp_path / 'station.sqlite'}")
    live = LiveStatus(db)
    server = ServerThread(create_app(database=db, live=live))
    try:
        page = browser.new_page(viewport={"width": 1280, "height": 900})  # type: ignore[attr-defined]
        page.goto(server.url + "/")
        wait_for(page, "document.getElementById('conn').textContent === 'live'")
        assert page.text_content("#state") == "idle"
        # record every step name and state the page shows, and mark the document to prove it never reloads
        page.evaluate("""() => {
            window.__marker = 'same page'; window.__seen = [];
            const text = id => document.getElementById(id).textContent;
            const note = () => window.__seen.push(text('state') + '|' + text('step') + '|' + text('remaining'));
            new MutationObserver(note).observe(document.querySelector('main'),
                                               {childList: true, subtree: true, characterData: true});
        }""")
        result: dict[str, object] = {}

        def run() -> None:
            result["run"] = run_demo(2, SCALE, seed=5, out_dir=tmp_path / "out", plan=PLAN, provision=False,
                                     console=Console(file=io.StringIO()),
                                     subscribers=[Recorder(db), live])

        worker = threading.Thread(target=run)
        worker.start()
        wait_for(page, "document.getElementById('state').textContent === 'running'", timeout=60_000)
        wait_for(page, "window.__seen.some(s => s.startsWith('running|pose'))", timeout=60_000)
        mid = tmp_path / "status-running.png"
        page.screenshot(path=str(mid), full_page=True)
        worker.join(180.0)
        assert not worker.is_alive()
        res = result["run"]
        wait_for(page, "document.getElementById('state').textContent === 'idle'", timeout=30_000)
        wait_for(page, "document.querySelectorAll('#recent tbody tr').length === 1", timeout=30_000)
        final = tmp_path / "status-final.png"
        page.screenshot(path=str(final), full_page=True)
        print(f"\nscreenshots: {mid} {final}")

        assert page.evaluate("window.__marker") == "same page"  # live updates, no reload
        seen = page.evaluate("window.__seen")
        steps = {s.split("|")[1] for s in seen if s.startswith("running|")}
        assert {"rest", "pose +z", "pose -z"} <= steps, steps
        remaining = [s.split("|")[2] for s in seen if s.startswith("running|pose")]
        assert all(" min " in r for r in remaining), remaining  # a time remaining while the poses run
        assert page.evaluate("document.getElementById('bar').style.width") == "100%"
        verdicts = {page.get_attribute(f"#slot-{u.slot}", "data-verdict") for u in res.units}  # type: ignore[attr-defined]
        expected = {u.outcome.value for u in res.units}  # type: ignore[attr-defined]
        assert verdicts == expected
        for u in res.units:  # type: ignore[attr-defined]
            tile = page.text_content(f"#slot-{u.slot}")
            assert u.serial in tile and u.outcome.value in tile
        assert res.outcome.value in page.text_content("#recent")  # type: ignore[attr-defined]

        fitted = [u for u in res.units if u.params is not None]  # type: ignore[attr-defined]
        assert fitted, "no unit was fitted"
        serial = fitted[0].serial
        page.goto(f"{server.url}/units/{serial}")
        for name in ("raw_corrected", "drift", "acf", "allan", "residuals"):
            wait_for(page,
                f"(() => {{ const i = document.getElementById('plot-{name}'); "
                f"return i && i.complete && i.naturalWidth > 300; }})()", timeout=60_000)
        assert page.locator("#checks tr").count() > 10
        # the diagnosis section: computed in the background, the page polls until it renders
        wait_for(page, "document.getElementById('diagnosis-status').dataset.state === 'ready'",
                               timeout=120_000)
        wait_for(page, "(() => { const i = document.getElementById('diagnosis-figure'); "
                               "return !i.hidden && i.complete && i.naturalWidth > 300; })()", timeout=60_000)
        assert page.locator("#diagnosis-findings tr").count() > 1 or page.locator("#diagnosis .diag-none").count() == 1
        unit_png = tmp_path / "unit.png"
        page.screenshot(path=str(unit_png), full_page=True)
        assert unit_png.stat().st_size > 10_000
        page.goto(f"{server.url}/population")
        wait_for(page, "[...document.querySelectorAll('.grid img')].every(i => i.complete && "
                               "i.naturalWidth > 100) && document.querySelectorAll('.grid img').length > 20",
                               timeout=60_000)
        population_png = tmp_path / "population.png"
        page.screenshot(path=str(population_png), full_page=True)
        print(f"screenshots: {unit_png} {population_png}")
        assert any(u.outcome in (Outcome.PASS, Outcome.FAIL) for u in res.units)  # type: ignore[attr-defined]

        # the connection drops (server restart) and returns: the page reconnects and shows the new state
        page.goto(server.url + "/")
        wait_for(page, "document.getElementById('conn').textContent === 'live'")
        server.stop()
        wait_for(page, "document.getElementById('conn').className === 'lost'", timeout=30_000)
        server = ServerThread(create_app(database=db, live=live), port=server.port)
        live.set_fault("rig lost power")
        wait_for(page, "document.getElementById('state').textContent === 'fault'", timeout=30_000)
        assert "rig lost power" in page.text_content("#message")
        assert page.text_content("#conn") == "live"
        page.goto("about:blank")  # close the event stream before the server stops
    finally:
        server.stop()
        db.close()
