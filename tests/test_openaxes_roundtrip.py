"""The round trip on the real OpenAXES recording: the rig-free fit, ``station export --format imu-tk`` and
``--format openaxes``, the files read back as imu_tk and OpenAXES read them: the same corrected still means as the
parameter set in memory (to the files' rounding), and the readers refuse what those tools could not read.
Skipped where the recording is absent ($STATION_REAL overrides ../shared/real)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from realdata import OPENAXES_LOG, real_path
from typer.testing import CliRunner

from station.cli import app
from station.fit.export_readback import read_imu_tk_calib, read_openaxes_list
from station.fit.rigfree_fit import RigFreeOptions, fit_rig_free
from station.kernel.errors import FormatError
from station.kernel.parameters import ParameterSet
from station.session.model import Kind
from station.session.multipos_import import import_openaxes

LOG = real_path(OPENAXES_LOG)
pytestmark = pytest.mark.real(OPENAXES_LOG)
G_TK = 9.81744


@pytest.fixture(scope="module")
def exported(tmp_path_factory: pytest.TempPathFactory) -> dict:
    tmp = tmp_path_factory.mktemp("oa")
    session = import_openaxes(LOG, accel="bmi160", gravity_mps2=G_TK)
    params = fit_rig_free(session, RigFreeOptions(cv_folds=0))
    path = tmp / "bmi160.params.json"
    path.write_text(params.to_json(), encoding="utf-8")
    runner = CliRunner()
    r1 = runner.invoke(app, ["export", str(path), "--format", "imu-tk", "-o", str(tmp / "bmi160")])
    r2 = runner.invoke(app, ["export", str(path), "--format", "openaxes", "-o", str(tmp / "bmi160.txt")])
    assert r1.exit_code == 0 and r2.exit_code == 0, r1.output + r2.output
    still = session.segments_of(Kind.REST, Kind.POSE)
    acc = np.array([session.accel_mps2[s.start:s.stop].mean(axis=0) for s in still])
    gyr = np.array([session.gyro_radps[s.start:s.stop].mean(axis=0) for s in still])
    return {"tmp": tmp, "params": ParameterSet.from_json(path.read_text(encoding="utf-8")), "acc": acc, "gyr": gyr}


def test_exported_files_reproduce_the_in_memory_score(exported: dict) -> None:
    tmp: Path = exported["tmp"]
    acc, gyr = exported["acc"], exported["gyr"]
    p, notes = exported["params"].constant_bias_values()
    assert any("accel z" in n for n in notes)  # the BMI160's b_stat z is not determined: the end bias is exported
    a_mem = (acc - p.accel.bias_static) @ np.linalg.inv(p.accel.misalignment).T
    w_mem = (gyr - p.gyro.bias_static) @ np.linalg.inv(p.gyro.misalignment).T
    tk_a, tk_g = read_imu_tk_calib(tmp / "bmi160_acc.calib"), read_imu_tk_calib(tmp / "bmi160_gyro.calib")
    assert np.allclose(np.diag(tk_a.t), 1.0) and np.count_nonzero(tk_a.k - np.diag(np.diag(tk_a.k))) == 0
    # imu_tk's files carry 17 significant digits: the same corrected means to double rounding
    assert np.max(np.abs(tk_a.correct(acc) - a_mem)) < 1e-12
    assert np.max(np.abs(tk_g.correct(gyr) - w_mem)) < 1e-14
    # OpenAXES's list carries 8: the same gravity norm to a few 1e-8 m/s^2
    oa = read_openaxes_list((tmp / "bmi160.txt").read_text(encoding="ascii"))
    norm_mem = np.linalg.norm(a_mem, axis=1)
    assert np.max(np.abs(np.linalg.norm(oa.correct_accel(acc), axis=1) - norm_mem)) < 2e-7
    assert np.max(np.abs(oa.correct_gyro(gyr) - w_mem)) < 1e-9
    # and the score itself is a calibration: far below the raw norm error (hundreds of mm/s^2)
    rms = float(np.sqrt(np.mean((norm_mem - G_TK) ** 2)))
    raw = float(np.sqrt(np.mean((np.linalg.norm(acc, axis=1) - G_TK) ** 2)))
    assert rms < 0.05 * raw


def test_readers_refuse_what_the_tools_could_not_read(tmp_path: Path) -> None:
    bad = tmp_path / "x.calib"
    bad.write_text("1 0 0\n0 1 0\n0 0 1\n\n1 0 0\n0 1 0\n0 0 1\n\n0\n0\n", encoding="ascii")  # 20 numbers
    with pytest.raises(FormatError, match="21 numbers"):
        read_imu_tk_calib(bad)
    with pytest.raises(FormatError, match="24 or 36"):
        read_openaxes_list("1 2 3")
    # a published 36-number list: two accelerometers and the gyro, column-major
    lst = read_openaxes_list(" ".join(str(float(v)) for v in range(36)))
    assert lst.accel_tk[1][0, 1] == 15.0 and lst.accel_bias_after[1].tolist() == [21.0, 22.0, 23.0]
    assert lst.gyro_m[2, 0] == 26.0 and lst.gyro_bias.tolist() == [33.0, 34.0, 35.0]
