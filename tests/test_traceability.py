"""Traceability: dispositions in the unit lists, no image for a scrapped unit, the lot as a CLI option, the limits
file shown with its content hash (an edited file with the same name and version shows another hash)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest
from fastapi.testclient import TestClient
from typer.testing import CliRunner

from station.cli import app
from station.fit.calibrate import fit_session
from station.kernel.errors import StationError
from station.sequence.records import Outcome
from station.sim.session_sim import simulate_session
from station.store.db import open_database
from station.store.recorder import Recorder, RunContext, record_disposition
from station.web.app import create_app
from tests.test_store import synthetic_run

RUN = CliRunner()
HASH = "ab12cd34ef56" + "0" * 52


@pytest.fixture()
def scrapped_store(tmp_path: Path) -> dict[str, Any]:
    """Two passed units, the first scrapped afterwards."""
    params = fit_session(simulate_session(21).session)
    serial = params.serial
    url = f"sqlite:///{tmp_path / 'station.sqlite'}"
    records = synthetic_run("run-1", [serial, "OTHER-2"], [Outcome.PASS, Outcome.PASS], out_dir=tmp_path)
    (tmp_path / f"{serial}_run-1.params.json").write_text(params.to_json())
    with open_database(url) as db:
        rec = Recorder(db, RunContext(limits_version="table1-default 2.0.0", limits_hash=HASH, lot="LOT-9"))
        for r in records:
            rec(r)
        record_disposition(db, serial, "scrap", operator="qa", note="cracked housing")
    params_path = tmp_path / "p.json"
    params_path.write_text(params.to_json())
    return {"url": url, "serial": serial, "params_path": params_path, "tmp": tmp_path}


def test_units_list_shows_the_scrap(scrapped_store: dict[str, Any]) -> None:
    s = scrapped_store
    out = RUN.invoke(app, ["units", "list", "--db", s["url"]])
    assert out.exit_code == 0, out.output
    line = next(ln for ln in out.output.splitlines() if ln.startswith(s["serial"]))
    assert "SCRAPPED" in line
    other = next(ln for ln in out.output.splitlines() if ln.startswith("OTHER-2"))
    assert "SCRAPPED" not in other
    listed = {u["serial"]: u["disposition"] for u in json.loads(RUN.invoke(app, ["units", "list", "--json", "--db",
                                                                                 s["url"]]).output)}
    assert listed == {s["serial"]: "scrap", "OTHER-2": ""}
    shown = RUN.invoke(app, ["units", "show", s["serial"], "--db", s["url"]]).output
    assert "SCRAPPED" in shown and "lot LOT-9" in shown
    assert "limits table1-default 2.0.0, sha256 ab12cd34ef56" in shown  # the hash, not only name and version


def test_unit_list_page_and_api_show_the_disposition(scrapped_store: dict[str, Any]) -> None:
    s = scrapped_store
    with open_database(s["url"]) as db, TestClient(create_app(database=db)) as c:
        rows = {u["serial"]: u["disposition"] for u in c.get("/api/units").json()}
        assert rows == {s["serial"]: "scrap", "OTHER-2": None}
        page = c.get("/units").text
        row = page[page.index(f">{s['serial']}<"):]
        assert "SCRAPPED" in row[:row.index("</tr>")]
        unit = c.get(f"/units/{s['serial']}").text
        assert "SCRAPPED" in unit and "table1-default 2.0.0, sha256 ab12cd34ef56" in unit
        runs = c.get(f"/api/units/{s['serial']}").json()["runs"]
        assert runs[0]["lot"] == "LOT-9" and runs[0]["limits_hash"] == HASH


def test_no_image_for_a_scrapped_unit(scrapped_store: dict[str, Any]) -> None:
    s = scrapped_store
    image = s["tmp"] / "x.bin"
    out = RUN.invoke(app, ["eeprom", "image", s["serial"], "-o", str(image), "--db", s["url"]])
    assert out.exit_code == 2 and "was scrapped" in out.output and not image.exists()
    out = RUN.invoke(app, ["eeprom", "image", s["serial"], "--params", str(s["params_path"]), "-o", str(image),
                           "--db", s["url"]])
    assert out.exit_code == 2 and "was scrapped" in out.output and not image.exists()
    # refused before any sensor is opened: this port does not exist, and the refusal names the scrap
    out = RUN.invoke(app, ["eeprom", "write", s["serial"], "--sensor", "serial:///dev/no-such-port", "--db",
                           s["url"]])
    assert out.exit_code == 2 and "was scrapped" in out.output
    # with --params and no store to consult (no such database) there is no record of the scrap: imaged
    other = s["tmp"] / "y.bin"
    params_serial = json.loads(s["params_path"].read_text())["serial"]
    assert params_serial == s["serial"]
    out = RUN.invoke(app, ["eeprom", "image", s["serial"], "--params", str(s["params_path"]), "-o", str(other),
                           "--db", f"sqlite:///{s['tmp'] / 'absent.sqlite'}"])
    assert out.exit_code == 0 and other.exists()


def test_lot_is_a_cli_option(monkeypatch: pytest.MonkeyPatch) -> None:
    import station.compose
    import station.sim.demo

    seen: dict[str, Any] = {}

    def station_stub(cfg: Any, **_: Any) -> Any:
        seen["run"] = cfg.lot
        raise StationError("stub: stop before any hardware")

    monkeypatch.setattr(station.compose, "Station", station_stub)
    out = RUN.invoke(app, ["run", "--rig", "fake-rig://1", "--sensor", "fake-sensor://1", "--lot", "LOT-42"])
    assert out.exit_code == 2 and seen["run"] == "LOT-42"

    def demo_stub(*_: Any, **kw: Any) -> Any:
        seen["demo"] = kw["lot"]
        raise StationError("stub")

    monkeypatch.setattr(station.sim.demo, "run_demo", demo_stub)
    out = RUN.invoke(app, ["demo", "--rig-only", "--lot", "LOT-43"])
    assert out.exit_code == 2 and seen["demo"] == "LOT-43"

    def line_stub(*_: Any, **kw: Any) -> Any:
        seen["line"] = kw["lot"]
        raise StationError("stub")

    monkeypatch.setattr(station.sim.demo, "run_line_demo", line_stub)
    out = RUN.invoke(app, ["demo", "--lot", "LOT-44"])
    assert out.exit_code == 2 and seen["line"] == "LOT-44"


def test_a_unit_scrapped_during_its_run_is_not_provisioned() -> None:
    """The retest gate is asked again before the image is written: a unit scrapped while it was measured
    gets no image (REFUSED), the others are provisioned."""
    from station.compose import Station, StationConfig
    from station.kernel.plan import default_plan
    from station.sim.fakes import FakeStation

    plan = default_plan()  # the production plan: the simulated units pass it
    asked: dict[str, int] = {}

    with FakeStation(2, 200.0, 0, plan=plan) as sim:
        scrapped = sim.units[0].truth.serial

        def admit(serial: str, run_id: str) -> str | None:
            asked[serial] = asked.get(serial, 0) + 1
            return f"{serial} was scrapped" if serial == scrapped and asked[serial] > 1 else None

        config = StationConfig(sim.rig_url, tuple(sim.sensor_urls), station_id="pytest", record=False, out_dir=None,
                               plan=plan, rig_options=sim.rig_client_options(), provision=True)
        station = Station(config, clock=sim.clock, admit=admit)
        result = station.run()
    by_serial = {u.serial: u for u in result.units}
    assert by_serial[scrapped].outcome == Outcome.REFUSED and "was scrapped" in by_serial[scrapped].message
    assert station.provisioner is not None and scrapped not in station.provisioner.records
    other = next(s for s in by_serial if s != scrapped)
    assert asked == {scrapped: 2, other: 2}  # at admission and again before provisioning
    assert other in station.provisioner.records  # the other unit's image was written (its verification is its own)
