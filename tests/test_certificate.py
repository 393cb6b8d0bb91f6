"""The calibration certificate: PDF text (pypdf) and HTML against the database's values, CLI and API, refusals."""

from __future__ import annotations

import hashlib
import io
import math
import re
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from fastapi.testclient import TestClient
from pypdf import PdfReader
from sqlalchemy import text
from typer.testing import CliRunner

from station.cli import app
from station.fit.calibrate import fit_session
from station.kernel.limits_file import load_limits
from station.kernel.measurement import Measurement
from station.kernel.parameters import ParameterSet
from station.sequence.limits import check_limits
from station.sequence.records import Measured, Outcome
from station.session.csv_v1 import write_session
from station.sim.session_sim import simulate_session
from station.store import Recorder, open_database
from station.store.certificate import unit_certificate
from station.web.app import create_app
from tests.test_web_api import run_records

RUN = "run-cert-1"
MG = 9.80665e-3


@pytest.fixture(scope="module")
def store(tmp_path_factory: pytest.TempPathFactory) -> Iterator[dict[str, Any]]:
    tmp = tmp_path_factory.mktemp("cert")
    sim = simulate_session(21)
    params = fit_session(sim.session)
    session_path, params_path = tmp / "unit.csv", tmp / "unit.params.json"
    write_session(sim.session, session_path)
    params_path.write_text(params.to_json(), encoding="utf-8")
    limits = load_limits()
    measured = [Measured(RUN, 0, params.serial, "limits", c) for c in check_limits(params, limits.product)]
    measured.append(Measured(RUN, 0, params.serial, "verify",
                             Measurement.at_most_abs("verify.pose.accel_error", 0.00137, 0.05, "m/s^2")))
    url = f"sqlite:///{tmp / 'station.sqlite'}"
    db = open_database(url)
    from station.store.recorder import RunContext

    recorder = Recorder(db, RunContext(operator="alice", lot="LOT-7", limits_version=f"{limits.name} {limits.version}",
                                       limits_hash=limits.sha256, software_version="station 0.1.0"))
    for r in run_records(RUN, "2026-11-21T10:00:00+00:00",
                         [(params.serial, Outcome.PASS, measured, str(session_path), str(params_path))],
                         station="st2"):
        recorder(r)
    assert recorder.errors == []
    yield {"url": url, "db": db, "params": params, "limits": limits, "tmp": tmp}
    db.close()


@pytest.fixture(scope="module")
def client(store: dict[str, Any]) -> Iterator[TestClient]:
    with TestClient(create_app(database=store["db"])) as c:
        yield c


def _pdf_text(data: bytes) -> str:
    reader = PdfReader(io.BytesIO(data))
    return re.sub(r"\s+", " ", " ".join(page.extract_text() for page in reader.pages))


def _stored(db: Any, serial: str) -> tuple[str, str]:
    with db.engine.connect() as c:
        row = c.execute(text("SELECT p.sha256, p.params_json FROM parameter_sets p JOIN units u ON p.unit_id = u.id "
                             "WHERE u.serial = :s"), {"s": serial}).one()
    return row[0], row[1]


def _expected_rows(params: ParameterSet) -> dict[str, str]:
    """Each parameter as the certificate must state it, computed here from the database's parameter set:
    value ± 2u, biases in mg and deg/s, M as ppm (diagonal: M_ii - 1), U to two significant digits."""

    def pm(v: float, u: float, unit: str) -> str:
        big_u = 2.0 * u
        d = max(0, 1 - math.floor(math.log10(big_u)))
        return f"{v:.{d}f} ± {big_u:.{d}f} {unit}"

    out: dict[str, str] = {}
    for key, scale, unit in (("accel", 1.0 / MG, "mg"), ("gyro", 180.0 / math.pi, "deg/s")):
        t = getattr(params, key)
        for i, a in enumerate("xyz"):
            out[f"{key}.bias_static.{a}"] = pm(t.bias_static[i] * scale, t.bias_static_std[i] * scale, unit)
            for j, b in enumerate("xyz"):
                v = (t.misalignment[i, j] - (1.0 if i == j else 0.0)) * 1e6
                out[f"{key}.M.{a}{b}"] = pm(v, t.misalignment_std[i, j] * 1e6, "ppm")
    return out


def test_the_pdf_states_the_database_values(client: TestClient, store: dict[str, Any]) -> None:
    params: ParameterSet = store["params"]
    r = client.get(f"/units/{params.serial}/certificate.pdf")
    assert r.status_code == 200 and r.headers["content-type"] == "application/pdf"
    assert r.content.startswith(b"%PDF-")
    body = _pdf_text(r.content)
    sha, params_json = _stored(store["db"], params.serial)
    stored = ParameterSet.from_json(params_json)
    assert stored.to_json() == params.to_json()  # the database holds the fitted set
    assert sha == hashlib.sha256(params_json.encode("utf-8")).hexdigest()
    assert params.serial in body and "verdict PASS" in body
    assert sha in body  # the checksum of the stored parameter set
    assert store["limits"].sha256 in body and "table1-default 2.0.0" in body
    assert "ISO 14253-1 guard bands" in body and "k = 2" in body
    assert "alice" in body and "LOT-7" in body and "st2" in body and "sim-rig" in body
    rows = _expected_rows(stored)
    assert len(rows) == 24
    for name, shown in rows.items():
        assert shown in body, (name, shown)
    # one value by hand: the accelerometer's x bias in mg, to the digit its expanded uncertainty allows
    b, u = stored.accel.bias_static[0] / MG, 2 * stored.accel.bias_static_std[0] / MG
    found = re.search(r"static bias b_stat x (-?\d+\.\d+) ± (\d+\.\d+) mg", body)
    assert found is not None
    assert abs(float(found.group(1)) - b) <= 0.5 * 10 ** -len(found.group(1).split(".")[1])
    assert abs(float(found.group(2)) - u) <= 0.5 * 10 ** -len(found.group(2).split(".")[1])
    assert "verify.pose.accel_error" in body and "0.1397 mg" in body  # 0.00137 m/s^2 in mg
    assert "+-" not in body


def test_the_html_states_the_same(client: TestClient, store: dict[str, Any]) -> None:
    params: ParameterSet = store["params"]
    r = client.get(f"/units/{params.serial}/certificate.html")
    assert r.status_code == 200 and r.headers["content-type"].startswith("text/html")
    sha, params_json = _stored(store["db"], params.serial)
    assert sha in r.text and store["limits"].sha256 in r.text and ">PASS<" in r.text
    for name, shown in _expected_rows(ParameterSet.from_json(params_json)).items():
        assert shown in r.text.replace("&lt;", "<"), (name, shown)
    assert "2026-11-21 10:00:00" in r.text or "2026-11-21" in r.text  # local time of the run's start
    page = client.get(f"/units/{params.serial}")
    assert f"/units/{params.serial}/certificate.pdf" in page.text  # linked from the unit page


def test_cli_writes_the_same_certificate(store: dict[str, Any], client: TestClient) -> None:
    params: ParameterSet = store["params"]
    out_pdf = store["tmp"] / "cert.pdf"
    res = CliRunner().invoke(app, ["units", "certificate", params.serial, "--run", RUN, "-o", str(out_pdf),
                                   "--db", store["url"]])
    assert res.exit_code == 0, res.output
    api = _pdf_text(client.get(f"/units/{params.serial}/certificate.pdf", params={"run": RUN}).content)
    cli = _pdf_text(out_pdf.read_bytes())
    strip = re.compile(r"Issued .*")  # the issue time differs
    assert strip.sub("", cli) == strip.sub("", api)
    out_html = store["tmp"] / "cert.html"
    res = CliRunner().invoke(app, ["units", "certificate", params.serial, "-o", str(out_html), "--db", store["url"]])
    assert res.exit_code == 0 and "<h1>Calibration certificate</h1>" in out_html.read_text()
    res = CliRunner().invoke(app, ["units", "certificate", "NOPE", "-o", str(out_pdf), "--db", store["url"]])
    assert res.exit_code == 2 and "no unit with serial 'NOPE'" in res.output
    res = CliRunner().invoke(app, ["units", "certificate", params.serial, "--run", "other", "-o", str(out_pdf),
                                   "--db", store["url"]])
    assert res.exit_code == 2 and "run 'other'" in res.output


def test_unknown_unit_and_run_answer_404(client: TestClient, store: dict[str, Any]) -> None:
    assert client.get("/units/NOPE/certificate.pdf").status_code == 404
    assert client.get(f"/units/{store['params'].serial}/certificate.pdf", params={"run": "x"}).status_code == 404


def test_an_altered_record_gets_no_certificate(tmp_path: Path, store: dict[str, Any]) -> None:
    import sqlite3

    copy = tmp_path / "copy.sqlite"
    with sqlite3.connect(store["url"].removeprefix("sqlite:///")) as src, sqlite3.connect(copy) as dst:
        src.backup(dst)  # the store's WAL included
    url = f"sqlite:///{copy}"
    with open_database(url) as db:
        with db.engine.begin() as c:
            c.execute(text("UPDATE parameter_sets SET params_json = replace(params_json, '\"serial\"', "
                           "' \"serial\"')"))
        with pytest.raises(Exception, match="does not match its recorded SHA-256"):
            unit_certificate(db, store["params"].serial)
        with TestClient(create_app(database=db)) as c:
            assert c.get(f"/units/{store['params'].serial}/certificate.pdf").status_code == 409
    res = CliRunner().invoke(app, ["units", "certificate", store["params"].serial, "-o", str(tmp_path / "x.pdf"),
                                   "--db", url])
    assert res.exit_code == 2 and "record was altered" in res.output


def test_quality_page_and_csv_in_the_display_convention(client: TestClient, store: dict[str, Any]) -> None:
    """The capability CSV and table give the certificate's units (ppm, mg, deg/s); the API stays SI."""
    import csv

    params: ParameterSet = store["params"]
    rows = {r["name"]: r for r in csv.DictReader(io.StringIO(client.get("/quality/capability.csv").text))}
    m = rows["accel.M.xx"]
    assert m["unit"] == "ppm" and float(m["mean"]) == pytest.approx((params.accel.misalignment[0, 0] - 1) * 1e6)
    b = rows["gyro.bias_static.y"]
    assert b["unit"] == "deg/s" and float(b["mean"]) == pytest.approx(math.degrees(params.gyro.bias_static[1]))
    a = rows["accel.bias_static.z"]
    assert a["unit"] == "mg" and float(a["mean"]) == pytest.approx(params.accel.bias_static[2] / MG)
    api = {c["name"]: c for c in client.get("/api/quality/capability").json()}
    assert api["accel.M.xx"]["unit"] == "1" and api["accel.M.xx"]["mean"] == pytest.approx(
        params.accel.misalignment[0, 0])
    page = client.get("/quality").text
    assert f"table1-default 2.0.0, sha256 {store['limits'].sha256[:12]}" in page  # the limits filter names the hash
    hist = client.get("/quality/histogram/accel.bias_static.z.svg").text
    assert "accel.bias_static.z (mg)" in hist
    chart = client.get("/quality/control/gyro.M.xx.svg").text
    assert "gyro.M.xx (ppm) daily mean" in chart
