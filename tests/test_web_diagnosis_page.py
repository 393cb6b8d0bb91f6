"""The diagnosis page (``/units/{serial}/diagnosis``) and the typed summary of the API's answer, against real
diagnoses of two recordings in a temporary SQLite store.

``LEVER-1``: the station's simulator with a planted 30 mm lever arm: the page and ``summary`` name
``lever_arm`` on the accelerometer with its value per axis in mm, the uncertainties, the confidence, and
every inseparable pair with the rig step the report gives. ``WOBBLE-2``: the independent generator's rate
table whose spin axis wobbles by 0.2 deg (physics outside the library): no finding, and the unexplained
structure located on the accelerometer in the rate segments, periodic at the spin frequency.
"""

from __future__ import annotations

import html
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from fastapi.testclient import TestClient

sys.path.insert(0, str(Path(__file__).resolve().parent))

import indepgen

from station.diagnose.residuals import BaseFitNoise
from station.diagnose.results import (
    DiagnosisReport,
    Finding,
    OutlierEvidence,
    ReportFormatError,
    RerunError,
    load_report,
)
from station.kernel.plan import RigPlan
from station.physics.effects import Effects
from station.sequence.records import Outcome, RunFinished, RunStarted, UnitFinished
from station.session.csv_v1 import write_session
from station.sim.session_sim import simulate_session
from station.store import Recorder, open_database
from station.web.app import create_app
from station.web.diagnosis_worker import DiagnosisService
from station.web.models import DiagnosisReady, DiagnosisSummary

#: ~8 min at 100 Hz with two rate magnitudes (as tests/test_web_diagnosis.py).
PLAN = RigPlan(
    rest_s=120.0,
    pose_hold_s=15.0,
    rate_steps=tuple((a, s * r) for a in "xyz" for r in (50.0, 200.0) for s in (1.0, -1.0)),
    rate_hold_s=6.0,
)
RUN = "run-0001"


@pytest.fixture(scope="module")
def store(tmp_path_factory: pytest.TempPathFactory) -> Iterator[dict[str, Any]]:
    tmp = tmp_path_factory.mktemp("webdiagpage")
    lever = simulate_session(5, plan=PLAN, effects=Effects(lever_arm=30.0))
    paths = {"lever": tmp / "lever.csv", "wobble": tmp / "wobble.csv"}
    write_session(lever.session, paths["lever"])
    write_session(indepgen.generate(3, {"wobble": 0.2}).session, paths["wobble"])
    db = open_database(f"sqlite:///{tmp / 'station.sqlite'}")
    recorder = Recorder(db)
    done = (UnitFinished(RUN, 0, "LEVER-1", Outcome.PASS, "", str(paths["lever"])),
            UnitFinished(RUN, 1, "WOBBLE-2", Outcome.PASS, "", str(paths["wobble"])))
    for r in (RunStarted(RUN, "2026-11-21T10:00:00+00:00", 0.0, "st1", "sim-rig", ("pty0", "pty1"), ("rest",)),
              *done, RunFinished(RUN, Outcome.PASS, 600.0, 600.0, 1.0, done)):
        recorder(r)
    assert recorder.errors == []
    yield {"db": db, "truth_mm": lever.effect_truth.lever_arm_m * 1e3}
    db.close()


@pytest.fixture(scope="module")
def client(store: dict[str, Any]) -> Iterator[TestClient]:
    with TestClient(create_app(database=store["db"], diagnosis=DiagnosisService(persist=False))) as c:
        yield c


def _ready(client: TestClient, serial: str, limit_s: float = 300.0) -> dict[str, Any]:
    """The page answers 202 (reloading itself) until the diagnosis is ready; then the API's answer."""
    deadline = time.monotonic() + limit_s
    while (page := client.get(f"/units/{serial}/diagnosis")).status_code == 202:
        assert 'http-equiv="refresh"' in page.text and 'data-state="pending"' in page.text
        assert time.monotonic() < deadline, "the diagnosis did not finish"
        time.sleep(0.25)
    assert page.status_code == 200, page.text[:500]
    r = client.get(f"/api/units/{serial}/diagnosis")
    assert r.status_code == 200
    return r.json()


def _row(page: str, table: str, **attrs: str) -> str:
    """The HTML of the first row of table ``table`` carrying ``attrs`` as data- attributes."""
    start = page.index(f'<table id="{table}">')
    body = page[start:page.index("</table>", start)]
    for row in body.split("<tr")[2:]:
        if all(f'data-{k}="{v}"' in row for k, v in attrs.items()):
            return html.unescape(row)
    raise AssertionError(f"no row {attrs} in table {table}")


def test_lever_arm_finding_with_values_uncertainties_units_and_confidence(client: TestClient,
                                                                         store: dict[str, Any]) -> None:
    body = _ready(client, "LEVER-1")
    DiagnosisReady.model_validate(body)
    summary = DiagnosisSummary.model_validate(body["summary"])
    assert summary == DiagnosisSummary.of(load_report(body["report"]))
    lever = next(f for f in summary.findings if f.effect == "lever_arm")
    assert lever.sensor == "accel" and lever.axes == ["x", "y", "z"] and lever.confidence == "high"
    main = next(p for p in lever.parameters if p.name == "lever_arm")
    assert main.unit == "mm"
    value, std = np.array(main.value), np.array(main.std)
    assert value.shape == (3,) and np.all(std > 0) and np.all(std < 5.0)
    assert np.all(np.abs(value - store["truth_mm"]) < 5 * std + 1.0), (value, store["truth_mm"])
    length = next(p for p in lever.parameters if p.name == "length_mm")
    assert abs(length.value - 30.0) < 2.0 and length.unit == "mm"
    assert lever.quasi_gain_chi2 > lever.threshold_chi2 > 0
    assert summary.unexplained == []
    page = client.get("/units/LEVER-1/diagnosis").text
    row = _row(page, "findings", effect="lever_arm", sensor="accel")
    for k, (v, s) in enumerate(zip(value, std, strict=True)):
        assert f"{'xyz'[k]}: {v:.4g} ± {s:.4g}" in row
    assert " mm" in row and 'class="conf-high">high' in row and "length_mm: " in row
    assert 'id="no-unexplained"' in page
    # every inseparable pair and every rejection of the report is on the page, with its rig step
    for item in summary.inseparable:
        assert " / ".join(item.effects) in html.unescape(page) and item.rig_step in html.unescape(page)
    assert len(summary.rejected) == len(body["report"]["rejected"]) > 0
    for r in summary.rejected:
        assert r.reason in html.unescape(_row(page, "rejected", effect=html.escape(r.effect), sensor=r.sensor))
    sized = [r for r in summary.rejected if r.detectable_from is not None]
    assert sized and all(r.reason == "no significant improvement" and r.detectable_from.unit for r in sized)


def test_outside_physics_is_unexplained_with_its_location(client: TestClient) -> None:
    body = _ready(client, "WOBBLE-2")
    summary = DiagnosisSummary.model_validate(body["summary"])
    assert summary.findings == []
    accel = [u for u in summary.unexplained if u.sensor == "accel"]
    assert accel, summary.unexplained
    u = accel[0]
    assert "rate" in u.segment_kinds and "spin frequency" in u.covariate and u.unit == "m/s^2"
    assert u.amplitude is not None and len(u.amplitude) == 3 and max(u.amplitude) > 0.005  # ~0.2 deg of g
    page = client.get("/units/WOBBLE-2/diagnosis").text
    assert 'id="no-findings"' in page and "unexplained (below)" in page
    row = _row(page, "unexplained", sensor="accel")
    assert "spin frequency" in row and "rate" in row and "m/s^2" in row


def test_page_of_unknown_unit_or_run_is_404(client: TestClient) -> None:
    assert client.get("/units/NO-SUCH-UNIT/diagnosis").status_code == 404
    assert client.get("/units/LEVER-1/diagnosis", params={"run_id": "nope"}).status_code == 404


def test_summary_models_are_described_in_openapi(client: TestClient) -> None:
    schemas = client.get("/openapi.json").json()["components"]["schemas"]
    for name in ("DiagnosisSummary", "FindingSummary", "UnexplainedSummary", "InseparableSummary",
                 "RejectionSummary", "ParameterValue"):
        props = schemas[name]["properties"]
        assert props and all(p.get("description") for p in props.values()), name
    assert "summary" in schemas["DiagnosisReady"]["properties"]


def test_summary_of_no_report_or_an_odd_one() -> None:
    """No report gives empty lists; non-finite numbers become null; a report of another format or a malformed one
    is refused by the loader."""
    assert DiagnosisSummary.of(None) == DiagnosisSummary(findings=[], unexplained=[], inseparable=[], rejected=[])
    finding = Finding("time_offset", "gyro", ("x",), {"value": [float("nan")], "std": [0.1], "unit": "ms"},
                      OutlierEvidence(0, 3, 1e-5, 1.0))
    report = DiagnosisReport(serial="X", findings=(finding,), rejected=(), inseparable=(), unexplained=(),
                             location={}, warmup_tc_range_s=None, base_fit=BaseFitNoise([0.0] * 3, [0.0] * 3,
                                                                                        [0.0] * 3, [0.0] * 3),
                             rerun=RerunError("none"))
    s = DiagnosisSummary.of(report)
    assert s.findings[0].parameters[0].value == [None] and s.findings[0].parameters[0].std == [0.1]
    assert s.findings[0].confidence is None and s.findings[0].bic_gain is None
    assert DiagnosisSummary.of(load_report(report.to_json())) == s
    with pytest.raises(ReportFormatError, match="station-diagnosis/1"):
        load_report({**report.to_json(), "format": "station-diagnosis/3"})
    with pytest.raises(ReportFormatError, match="malformed"):
        load_report({"format": "station-diagnosis/1", "findings": []})
