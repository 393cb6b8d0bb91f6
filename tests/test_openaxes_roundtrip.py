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
from station.fit.export import left_out_notes
from station.fit.export_readback import read_imu_tk_calib, read_openaxes_list
from station.fit.rigfree_fit import RigFreeOptions, fit_rig_free
from station.kernel.errors import FormatError
from station.kernel.parameters import ParameterSet
from station.session.model import Kind
from station.session.multipos_import import import_openaxes

LOG = real_path(OPENAXES_LOG)
pytestmark = pytest.mark.real(OPENAXES_LOG)
G_TK = 9.81744


PUBLISHED_BMI160_ACCEL = np.array([0.95418, 0, 0, 0.0031573, 0.96061, 0, 0.009235, 0.00049713, 0.9501,
                                   -0.033224, 0.080497, 0.01579])


@pytest.fixture(scope="module")
def exported(tmp_path_factory: pytest.TempPathFactory) -> dict:
    """Per fit (the default with eq. 3's drift, imu_tk's model without it): the set and its exported files."""
    tmp = tmp_path_factory.mktemp("oa")
    session = import_openaxes(LOG, accel="bmi160", gravity_mps2=G_TK)
    runner = CliRunner()
    out: dict = {}
    for name, drift in (("drift", True), ("nodrift", False)):
        params = fit_rig_free(session, RigFreeOptions(cv_folds=0, accel_drift=drift))
        path = tmp / f"{name}.params.json"
        path.write_text(params.to_json(), encoding="utf-8")
        r1 = runner.invoke(app, ["export", str(path), "--format", "imu-tk", "-o", str(tmp / name)])
        r2 = runner.invoke(app, ["export", str(path), "--format", "openaxes", "-o", str(tmp / f"{name}.txt")])
        assert r1.exit_code == 0 and r2.exit_code == 0, r1.output + r2.output
        out[name] = ParameterSet.from_json(path.read_text(encoding="utf-8"))
    still = session.segments_of(Kind.REST, Kind.POSE)
    acc = np.array([session.accel_mps2[s.start:s.stop].mean(axis=0) for s in still])
    gyr = np.array([session.gyro_radps[s.start:s.stop].mean(axis=0) for s in still])
    return {"tmp": tmp, "acc": acc, "gyr": gyr, **out}


def _norm_rms(a: np.ndarray) -> float:
    return float(np.sqrt(np.mean((np.linalg.norm(a, axis=1) - G_TK) ** 2)))


@pytest.mark.parametrize("name", ["drift", "nodrift"])
def test_exported_files_reproduce_the_in_memory_score(exported: dict, name: str) -> None:
    tmp: Path = exported["tmp"]
    acc, gyr = exported["acc"], exported["gyr"]
    drift_note = [n for n in left_out_notes(exported[name]) if n.startswith("accel") and "warm-up drift" in n]
    assert bool(drift_note) == (name == "drift")  # the export says it leaves the warm-up out
    p, notes = exported[name].constant_bias_values()
    # the default fit cannot determine the BMI160's b_stat z (T_c ~ the record): the end bias is exported instead
    assert any("accel z" in n for n in notes) == (name == "drift")
    a_mem = (acc - p.accel.bias_static) @ np.linalg.inv(p.accel.misalignment).T
    w_mem = (gyr - p.gyro.bias_static) @ np.linalg.inv(p.gyro.misalignment).T
    tk_a, tk_g = read_imu_tk_calib(tmp / f"{name}_acc.calib"), read_imu_tk_calib(tmp / f"{name}_gyro.calib")
    assert np.allclose(np.diag(tk_a.t), 1.0) and np.count_nonzero(tk_a.k - np.diag(np.diag(tk_a.k))) == 0
    # imu_tk's files carry 17 significant digits: the same corrected means to double rounding
    assert np.max(np.abs(tk_a.correct(acc) - a_mem)) < 1e-12
    assert np.max(np.abs(tk_g.correct(gyr) - w_mem)) < 1e-14
    # OpenAXES's list carries 8: the same gravity norm to a few 1e-8 m/s^2
    oa = read_openaxes_list((tmp / f"{name}.txt").read_text(encoding="ascii"))
    norm_mem = np.linalg.norm(a_mem, axis=1)
    assert np.max(np.abs(np.linalg.norm(oa.correct_accel(acc), axis=1) - norm_mem)) < 2e-7
    assert np.max(np.abs(oa.correct_gyro(gyr) - w_mem)) < 1e-9
    assert _norm_rms(a_mem) < 0.1 * _norm_rms(acc)  # a calibration: raw is ~460 mm/s^2 off


def test_imu_tk_model_export_no_worse_than_published(exported: dict) -> None:
    """``station fit --no-accel-drift`` exported and read back as OpenAXES reads it: its gravity-norm RMS on the
    recording's still intervals is no worse than the published coefficients' (same model, same data; 0.01 mm/s^2
    allowed for the list's rounding)."""
    acc = exported["acc"]
    ours = read_openaxes_list((exported["tmp"] / "nodrift.txt").read_text(encoding="ascii")).correct_accel(acc)
    pub = PUBLISHED_BMI160_ACCEL
    published = acc @ pub[:9].reshape(3, 3, order="F").T - pub[9:]
    assert abs(_norm_rms(published) - 8.07e-3) < 0.01e-3  # the README's figure for the published coefficients
    assert _norm_rms(ours) <= _norm_rms(published) + 1e-5


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
