"""The quality, unit list, unit and status pages in real headless Chromium (Debian's ``chromium``, Playwright),
on a synthetic production history (:func:`synthetic_history.fill`) with a drifting parameter and a
shifted lot planted: the quality page must flag the drift by a run rule and show the shifted lot's Cpk below
1.33; the pages must fit an 800 px wide window without sideways scrolling. Screenshots at 1920 and 800 px are
saved under pytest's tmp dir (their paths are printed).

Never downloads a browser: skipped when ``/usr/bin/chromium`` or Playwright is missing.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest

CHROMIUM = Path("/usr/bin/chromium")
if not CHROMIUM.is_file():
    pytest.skip(f"{CHROMIUM} not installed (apt-get install chromium)", allow_module_level=True)
sync_api = pytest.importorskip("playwright.sync_api", reason="Playwright's Python package is not installed")

from synthetic_history import DRIFTING, SHIFTED, SHIFTED_LOT, fill  # noqa: E402

from station.store import Database, open_database  # noqa: E402
from station.web.app import create_app  # noqa: E402
from station.web.serve import ServerThread  # noqa: E402

CHROMIUM_ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
                 "--disable-component-update", "--disable-sync", "--no-first-run"]


@pytest.fixture(scope="module")
def server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[str]:
    path = tmp_path_factory.mktemp("qb") / "q.sqlite"
    db: Database = open_database(f"sqlite:///{path}")
    fill(db, 3000, seed=21, days=14)
    srv = ServerThread(create_app(database=db))
    try:
        yield srv.url
    finally:
        srv.stop()
        db.close()


@pytest.fixture(scope="module")
def browser() -> Iterator[object]:
    with sync_api.sync_playwright() as pw:
        b = pw.chromium.launch(executable_path=str(CHROMIUM), args=CHROMIUM_ARGS, headless=True)
        try:
            yield b
        finally:
            b.close()


def _fits(page: object, width: int) -> None:
    overflow = page.evaluate("() => document.documentElement.scrollWidth")  # type: ignore[attr-defined]
    assert overflow <= width, f"the page is {overflow} px wide in a {width} px window"


def test_quality_page_flags_the_drift_and_the_shifted_lot(server: str, browser: object, tmp_path: Path) -> None:
    shots = []
    for width in (1920, 800):
        page = browser.new_page(viewport={"width": width, "height": 1080})  # type: ignore[attr-defined]
        page.goto(f"{server}/quality")
        row = page.locator(f'#capability tr[data-param="{DRIFTING}"]')
        rules = row.locator("td.rules").text_content() or ""
        assert {"2", "3"} & set(rules.replace(" ", "").split(",")), rules  # a run or a trend
        figure = page.locator(f'#flagged figure[data-param="{DRIFTING}"]')
        assert "run rules" in (figure.locator("figcaption").text_content() or "")
        assert figure.locator("svg circle[fill='#c62828']").count() >= 1  # points completing a rule, in red
        _fits(page, width)
        shot = tmp_path / f"quality-{width}.png"
        page.screenshot(path=str(shot))
        shots.append(shot)
        page.goto(f"{server}/quality?lot={SHIFTED_LOT}")
        cell = page.locator(f'#capability tr[data-param="{SHIFTED}"] td.cpk')
        assert float(cell.text_content() or "nan") < 1.33 and "bad" in (cell.get_attribute("class") or "")
        first = page.locator("#capability tr[data-param]").first.get_attribute("data-param")
        assert first == SHIFTED  # ranked worst
        img = page.locator(f'#flagged figure[data-param="{SHIFTED}"] img')
        img.scroll_into_view_if_needed()
        page.wait_for_function("(el) => el.complete && el.naturalWidth > 0", arg=img.element_handle())
        _fits(page, width)
        shot = tmp_path / f"quality-lot-{width}.png"
        page.screenshot(path=str(shot), full_page=False)
        shots.append(shot)
        page.close()
    print("\nscreenshots: " + " ".join(map(str, shots)))


def test_unit_list_unit_page_and_status_fit(server: str, browser: object, tmp_path: Path) -> None:
    shots = []
    for width in (1920, 800):
        page = browser.new_page(viewport={"width": width, "height": 1080})  # type: ignore[attr-defined]
        page.goto(f"{server}/units?q=IMU-000012")
        serials = page.locator("#units td a").all_text_contents()
        assert serials[:3] == ["IMU-0000120", "IMU-0000121", "IMU-0000122"]
        _fits(page, width)
        page.locator("#units td a").first.click()
        page.wait_for_selector("#verdict")
        assert page.text_content("#verdict") in ("PASS", "FAIL", "RETEST")
        assert "accelerometer" in (page.text_content("#checks") or "")
        _fits(page, width)
        shot = tmp_path / f"unit-{width}.png"
        page.screenshot(path=str(shot))
        shots.append(shot)
        page.goto(f"{server}/")
        page.wait_for_function("document.getElementById('conn').textContent === 'live'")
        assert page.locator("#rigline").is_hidden()  # idle: no rig state from an old run
        _fits(page, width)
        shot = tmp_path / f"status-{width}.png"
        page.screenshot(path=str(shot))
        shots.append(shot)
        page.close()
    print("\nscreenshots: " + " ".join(map(str, shots)))
