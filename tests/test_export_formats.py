"""`station export --format kalibr|imu-tk|imu-tk-json|openaxes`: imu_tk's own files read back as imu_tk's loader
reads them, Kalibr moved from `station eeprom kalibr` (kept as an alias that says so), --serial from the store."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
from typer.testing import CliRunner

from station.cli import app
from station.fit.calibrate import fit_session
from station.kernel.parameters import ParameterSet
from station.sequence.records import Outcome
from station.sim.session_sim import simulate_session
from station.store.db import open_database
from station.store.recorder import Recorder
from tests.test_store import synthetic_run

RUN = CliRunner()


def imu_tk_load(path: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """imu_tk's ``CalibratedTriad_::load``: whitespace-separated numbers read with ``>>``; 9 into the misalignment
    matrix (row-major map), 9 into the scale matrix (row-major), 3 into the bias vector."""
    tokens = path.read_text().split()
    assert len(tokens) == 21, tokens
    values = [float(t) for t in tokens]
    return (np.array(values[0:9]).reshape(3, 3), np.array(values[9:18]).reshape(3, 3), np.array(values[18:21]))


def unbias_normalize(t: np.ndarray, k: np.ndarray, b: np.ndarray, raw: np.ndarray) -> np.ndarray:
    """imu_tk's ``unbiasNormalize``: X' = T K (X - B)."""
    return t @ k @ (raw - b)


def _params(tmp_path: Path) -> tuple[ParameterSet, Path]:
    params = fit_session(simulate_session(21).session)
    path = tmp_path / "unit.params.json"
    path.write_text(params.to_json(), encoding="utf-8")
    return params, path


def test_imu_tk_files_read_back_as_imu_tk_loads_them(tmp_path: Path) -> None:
    params, path = _params(tmp_path)
    r = RUN.invoke(app, ["export", str(path), "--format", "imu-tk", "-o", str(tmp_path / "unit")])
    assert r.exit_code == 0, r.output
    acc, gyro = tmp_path / "unit_acc.calib", tmp_path / "unit_gyro.calib"
    assert acc.exists() and gyro.exists()
    rng = np.random.default_rng(5)
    # the exported biases: the set's constant biases (the bias at the end of the recording on an axis whose
    # b_stat the recording cannot determine, as the command says on stderr)
    const = params.constant_bias_values()[0]
    for file, tri in ((acc, const.accel), (gyro, const.gyro)):
        t, k, b = imu_tk_load(file)
        assert np.allclose(np.diag(t), 1.0) and np.allclose(k, np.diag(np.diag(k)))  # imu_tk's T and K shapes
        assert np.allclose(b, tri.bias_static, rtol=0, atol=1e-15)
        for _ in range(5):  # the station's model y = M x + b, inverted by imu_tk's correction
            truth = rng.normal(0.0, 5.0, 3)
            raw = tri.misalignment @ truth + tri.bias_static
            assert np.allclose(unbias_normalize(t, k, b, raw), truth, rtol=0, atol=1e-12)
    # the layout CalibratedTriad::save writes: T rows, blank line, K rows, blank line, B one per line
    blocks = acc.read_text().split("\n\n")
    assert [len(bl.split("\n")) for bl in blocks[:3]] == [3, 3, 3] and len(blocks[0].split("\n")[0].split()) == 3
    r = RUN.invoke(app, ["export", str(path), "--format", "imu-tk"])
    assert r.exit_code == 2 and "give their prefix with -o" in r.output


def test_imu_tk_json_openaxes_and_refusals(tmp_path: Path) -> None:
    _, path = _params(tmp_path)
    r = RUN.invoke(app, ["export", str(path), "--format", "imu-tk-json"])
    assert r.exit_code == 0 and json.loads(r.stdout)["format"] == "station-imutk/1"
    r = RUN.invoke(app, ["export", str(path), "--format", "openaxes"])
    assert r.exit_code == 0 and len(r.stdout.split()) == 24
    r = RUN.invoke(app, ["export", str(path), "--format", "nope"])
    assert r.exit_code == 2 and "kalibr, imu-tk, imu-tk-json, openaxes" in r.output
    r = RUN.invoke(app, ["export", "--format", "kalibr"])
    assert r.exit_code == 2 and "PARAMS.json or --serial" in r.output


def test_kalibr_moved_to_export_and_the_alias_says_so(tmp_path: Path) -> None:
    _, path = _params(tmp_path)
    new = RUN.invoke(app, ["export", str(path), "--format", "kalibr"])
    assert new.exit_code == 0, new.output
    assert "gyroscope_noise_density" in new.stdout and "rostopic:                    /imu0" in new.stdout
    old = CliRunner().invoke(app, ["eeprom", "kalibr", "--params", str(path)])
    assert old.exit_code == 0 and old.stdout == new.stdout
    assert "moved to `station export --format kalibr`" in old.stderr


def test_export_from_the_store_by_serial(tmp_path: Path) -> None:
    params = fit_session(simulate_session(21).session)
    serial = params.serial
    url = f"sqlite:///{tmp_path / 'station.sqlite'}"
    records = synthetic_run("run-1", [serial], [Outcome.PASS], out_dir=tmp_path)
    (tmp_path / f"{serial}_run-1.params.json").write_text(params.to_json())
    with open_database(url) as db:
        rec = Recorder(db)
        for r in records:
            rec(r)
    by_file = tmp_path / "p.json"
    by_file.write_text(params.to_json())
    a = RUN.invoke(app, ["export", "--serial", serial, "--db", url, "--format", "kalibr"])
    b = RUN.invoke(app, ["export", str(by_file), "--format", "kalibr"])
    assert a.exit_code == 0 and a.stdout == b.stdout
    r = RUN.invoke(app, ["export", "--serial", "NOPE", "--db", url, "--format", "kalibr"])
    assert r.exit_code == 2 and "no PASS parameter set of serial 'NOPE'" in r.output
