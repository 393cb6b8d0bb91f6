"""A Gage R&R study and a nest calibration on the simulated station, end to end through the records.

The simulated rig's two nests carry known mounting errors; the reference unit run in both gives their
relative rotation, and a small crossed study shows the nests' share of the gyro cross-axis terms before
and after the calibration. A short plan keeps it to ~16 runs of two units on the in-process fakes.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from station.cli import app
from station.commands.msa import study_report
from station.commands.nest_cal import estimate_from_records
from station.kernel.plan import RigPlan
from station.sim.msa_study import StudyDesign, run_nest_calibration, run_study

pytestmark = [pytest.mark.slow, pytest.mark.integration]

PLAN = RigPlan(rest_s=120.0, pose_hold_s=15.0, rate_hold_s=6.0)
ERRORS = [(0.3, 0.0, 0.0), (0.0, -0.3, 0.1)]  # deg, sensor -> nest, per nest


@pytest.fixture(scope="module")
def study(tmp_path_factory: pytest.TempPathFactory) -> tuple[str, Path]:
    tmp = tmp_path_factory.mktemp("msa")
    db = f"sqlite:///{tmp / 'msa.sqlite'}"
    design = StudyDesign(3, 2, 2, seed=5)
    sid = "msa-test"  # its own rig (lock and nest-calibration key)
    run_study(design, db, "before", scale=120.0, plan=PLAN, nest_errors_deg=ERRORS, out_dir=tmp / "out",
              station_id=sid)
    serial, _, _ = run_nest_calibration(2, db, seed=5, scale=120.0, plan=PLAN, nest_errors_deg=ERRORS,
                                        out_dir=tmp / "out", station_id=sid)
    estimate_from_records(db, f"fake-rig://{sid}", serial)  # relative: the datum is the mean nest
    run_study(design, db, "after", scale=120.0, plan=PLAN, nest_errors_deg=ERRORS, out_dir=tmp / "out",
              station_id=sid)
    return db, tmp


def test_nest_calibration_finds_the_relative_tilts(study: tuple[str, Path]) -> None:
    db, _ = study
    runner = CliRunner()
    out = runner.invoke(app, ["nest-cal", "show", "--json", "--db", db])
    assert out.exit_code == 0, out.output
    (cal,) = json.loads(out.output)
    truth = np.array(ERRORS) - np.mean(ERRORS, axis=0)  # the datum is the mean nest
    assert np.allclose(np.array(cal["rotations_deg"]), truth, atol=0.01)
    assert max(cal["agreement_deg"]) < 0.01


def test_nest_errors_show_as_reproducibility_and_are_calibrated_out(study: tuple[str, Path]) -> None:
    db, _ = study
    before = {p.parameter: p for p in study_report(db, lot="before").parameters}
    after = {p.parameter: p for p in study_report(db, lot="after").parameters}
    # a 0.3 deg tilt is 5.2e-3 in M's cross-axis terms: the nests differ by that much before, not after
    for name in ("gyro.M.xz", "gyro.M.yz", "accel.M.yz"):
        b, a = before[name].study, after[name].study
        assert b is not None and a is not None
        assert b.reproducibility.std > 1e-3, name
        assert a.reproducibility.std < 2e-4, name
        assert a.grr.std < b.grr.std / 5, name


def test_msa_report_command(study: tuple[str, Path]) -> None:
    db, tmp = study
    runner = CliRunner()
    out = runner.invoke(app, ["msa", "report", "--lot", "after", "--json", "--csv", str(tmp / "s.csv"), "--db", db])
    assert out.exit_code == 0, out.output
    data = json.loads(out.output)
    assert data["format"] == "station-msa/1"
    assert len(data["parts"]) == 3 and data["appraisers"] == ["nest 1", "nest 2"]
    names = {p["parameter"] for p in data["parameters"]}
    assert "gyro.M.xz" in names and not any(n.startswith("fit.") for n in names)
    assert (tmp / "s.csv").read_text().startswith("format,parameter")
    refused = runner.invoke(app, ["msa", "report", "--db", db])
    assert refused.exit_code == 2 and "choose the study's runs" in refused.output


def test_msa_page_and_api(study: tuple[str, Path]) -> None:
    from fastapi.testclient import TestClient

    from station.web.app import create_app

    db, _ = study
    with TestClient(create_app(db)) as client:
        api = client.get("/api/msa", params={"lot": "before"})
        assert api.status_code == 200
        body = api.json()
        assert body["format"] == "station-msa/1" and body["appraisers"] == ["nest 1", "nest 2"]
        gyro_xz = next(p for p in body["parameters"] if p["parameter"] == "gyro.M.xz")
        av = next(c for c in gyro_xz["components"] if c["name"] == "reproducibility")
        assert av["std"] > 1e-3  # the nests' tilt, in SI
        assert client.get("/api/msa", params={"lot": "no-such-lot"}).status_code == 404
        page = client.get("/msa", params={"lot": "before", "parameter": "gyro.M.xz"})
        assert page.status_code == 200 and "gyro.M.xz" in page.text and "unacceptable" in page.text
        for kind in ("components", "ranges", "parts"):
            svg = client.get(f"/msa/plots/{kind}.svg", params={"lot": "before", "parameter": "gyro.M.xz"})
            assert svg.status_code == 200 and svg.text.startswith("<svg")
        assert client.get("/msa").status_code == 200


def test_a_repeated_study_run_gives_the_same_bytes(tmp_path: Path) -> None:
    """The study's runs are on the virtual clock: the same parts with the same noise give the same parameter
    files, so the study's repeatability is the units' noise, not the host's thread scheduling."""
    from station.sim.msa_study import SimRig

    def one(tag: str) -> dict[str, bytes]:
        out = tmp_path / tag
        rig = SimRig("msa-repeat", f"sqlite:///{tmp_path / (tag + '.sqlite')}", 120.0, PLAN, ERRORS, None, out)
        result = rig.run(5, [0, 1], 3, "repeat", nest_calibration=False)
        assert len(result.units) == 2 and all(u.params is not None for u in result.units)
        files = {p.name.split("_")[0]: p.read_bytes() for p in sorted(out.rglob("*.params.json"))}  # by serial
        assert len(files) == 2
        return files

    assert one("a") == one("b")
