"""The core commands end to end: simulate -> fit --json -> correct, through files."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
from typer.testing import CliRunner

from station.cli import app
from station.kernel.parameters import ParameterSet
from station.session import read_session
from station.session.model import Kind


def test_simulate_fit_correct(tmp_path: Path) -> None:
    runner = CliRunner()
    a, b = tmp_path / "a.csv", tmp_path / "b.csv"
    for out in (a, b):
        r = runner.invoke(app, ["simulate", "-o", str(out), "--seed", "5"])
        assert r.exit_code == 0, r.output
    assert a.read_bytes() == b.read_bytes()  # a seed goes in, the same bytes come out

    r = runner.invoke(app, ["fit", str(a), "--json"])
    assert r.exit_code == 0, r.output
    doc = json.loads(r.stdout)
    assert doc["format"] == "station-params/2"
    params = ParameterSet.from_dict(doc)
    assert ParameterSet.from_json(params.to_json()).to_json() == params.to_json()

    p_path, c_path = tmp_path / "p.json", tmp_path / "c.csv"
    p_path.write_text(r.stdout)
    r = runner.invoke(app, ["correct", str(a), "--params", str(p_path), "-o", str(c_path)])
    assert r.exit_code == 0, r.output
    corrected = read_session(c_path)
    # corrected poses read the rig's gravity reference
    for seg in corrected.segments_of(Kind.POSE):
        sl = slice(seg.start + 40, seg.stop)
        err = corrected.accel_mps2[sl].mean(axis=0) - corrected.ref_accel_mps2[seg.start]
        assert np.abs(err).max() < 0.003


def test_fit_prints_table(tmp_path: Path) -> None:
    runner = CliRunner()
    path = tmp_path / "s.csv"
    assert runner.invoke(app, ["simulate", "-o", str(path), "--seed", "9"]).exit_code == 0
    r = runner.invoke(app, ["fit", str(path)])
    assert r.exit_code == 0, r.output
    assert "accelerometer" in r.output and "gyroscope" in r.output and "T_c" in r.output


def test_unknown_params_version_is_refused(tmp_path: Path) -> None:
    runner = CliRunner()
    s, p = tmp_path / "s.csv", tmp_path / "p.json"
    assert runner.invoke(app, ["simulate", "-o", str(s), "--seed", "3"]).exit_code == 0
    p.write_text(json.dumps({"format": "station-params/99"}))
    r = runner.invoke(app, ["correct", str(s), "--params", str(p), "-o", str(tmp_path / "c.csv")])
    assert r.exit_code != 0
    assert "station-params/99" in r.output
