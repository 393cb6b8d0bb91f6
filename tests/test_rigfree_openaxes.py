"""The rig-free fit on the real OpenAXES hand-held recording (shared/real/openaxes, read-only).

Published reference (shared/real/README.md): OpenAXES's imu_tk-based script's 36 coefficients, accel
``calibrated = T K raw - b`` fitted to 9.81744 m/s^2, gyro ``calibrated = M (raw - b)`` integrated with a fixed
0.01 s step. Skipped with the reason where the recording is absent ($STATION_REAL overrides ../shared/real).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from realdata import OPENAXES_LOG, real_path

from station.fit.export import openaxes_coefficients
from station.fit.multipos import direction_errors_deg
from station.fit.rigfree_fit import RigFreeOptions, fit_rig_free, is_rig_free
from station.kernel.parameters import ParameterSet
from station.session.model import Kind, Session
from station.session.multipos_import import import_openaxes

LOG = real_path(OPENAXES_LOG)
pytestmark = pytest.mark.real(OPENAXES_LOG)

G_TK = 9.81744
PUBLISHED = np.array([
    0.96276, 0, 0, 0.0015751, 0.96732, 0, -0.00018891, 0.000859, 0.97079, 0.064447, 0.011034, 0.034253,
    0.95418, 0, 0, 0.0031573, 0.96061, 0, 0.009235, 0.00049713, 0.9501, -0.033224, 0.080497, 0.01579,
    0.97288, 0.0076747, -0.0063582, -0.011829, 1.0062, -0.00033403, 0.010087, 0.00029571, 1.0068,
    -0.00020494, 0.00063007, -0.00036962,
])


@pytest.fixture(scope="module")
def sessions() -> dict[str, Session]:
    return {a: import_openaxes(LOG, accel=a, gravity_mps2=G_TK) for a in ("adxl355", "bmi160")}


@pytest.fixture(scope="module")
def fits(sessions: dict[str, Session]) -> dict[str, ParameterSet]:
    return {
        "adxl355": fit_rig_free(sessions["adxl355"]),  # the default, with the cross-validation
        "bmi160": fit_rig_free(sessions["bmi160"], RigFreeOptions(cv_folds=0)),
        # imu_tk's model: no accelerometer drift, the gyro's reads integrated as they come (stale reads included)
        "adxl355 tk": fit_rig_free(sessions["adxl355"], RigFreeOptions(cv_folds=0, accel_drift=False,
                                                                       read_timing=False)),
        "bmi160 tk": fit_rig_free(sessions["bmi160"], RigFreeOptions(cv_folds=0, accel_drift=False,
                                                                     read_timing=False)),
    }


def test_import_finds_the_initial_still_and_the_faces(sessions: dict[str, Session]) -> None:
    s = sessions["adxl355"]
    assert is_rig_free(s)
    assert s.sample_rate_hz == pytest.approx(100.054, abs=0.01)
    rest = s.segments_of(Kind.REST)
    assert len(rest) == 1 and 38 < s.t_s[rest[0].stop - 1] < 42  # ~40 s still after --reset
    assert 30 <= len(s.segments_of(Kind.POSE)) <= 45  # ~38 faces, then random faces
    assert s.gravity_mps2 == G_TK


def test_gravity_norm_at_least_as_good_as_published(fits: dict[str, ParameterSet]) -> None:
    # targets: ADXL355 <= 3.0 mm/s^2, BMI160 <= 8.0 mm/s^2 on the poses fitted
    assert fits["adxl355"].quality.rig_free["accel_norm_rms_mps2"] <= 3.0e-3
    assert fits["bmi160"].quality.rig_free["accel_norm_rms_mps2"] <= 8.0e-3


def test_imu_tk_model_reproduces_the_published_coefficients(fits: dict[str, ParameterSet]) -> None:
    values, stds = openaxes_coefficients([fits["adxl355 tk"], fits["bmi160 tk"]])
    scale = np.ones(36)
    scale[24:33] = fits["bmi160 tk"].sample_period_s / 0.01  # the published gyro integrates with a fixed 0.01 s step
    values, stds = values * scale, stds * scale
    structural = stds == 0  # the zeros below the diagonal of T K
    assert np.all(values[structural] == 0) and np.all(PUBLISHED[structural] == 0)
    z = (values - PUBLISHED)[~structural] / stds[~structural]
    # the published gyro bias is the initial still's raw mean, ours b_stat of eq. (3): x differs by 2.5 sigma
    assert np.all(np.abs(z) <= 3.0), np.round(z, 2)


def _published_direction_errors(s: Session, still: list) -> np.ndarray:
    """The published BMI160 calibration's gravity-direction error (deg) after each move between the stills."""
    means = np.array([s.accel_mps2[a.start:a.stop].mean(axis=0) for a in still])
    a_pub, b_pub = PUBLISHED[12:21].reshape(3, 3, order="F"), PUBLISHED[21:24]
    m_pub, bw_pub = PUBLISHED[24:33].reshape(3, 3, order="F"), PUBLISHED[33:36]
    u = means @ a_pub.T - b_pub
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    moves = [s.gyro_radps[still[i].stop - 1:still[i + 1].start + 1] - bw_pub for i in range(len(still) - 1)]
    return direction_errors_deg(m_pub, moves, 0.01, u[:-1], u[1:])


def test_gyro_direction_error_as_published_on_the_same_moves(sessions: dict[str, Session],
                                                             fits: dict[str, ParameterSet]) -> None:
    s = sessions["bmi160"]
    still = s.segments_of(Kind.REST, Kind.POSE)
    published = float(np.sqrt(np.mean(_published_direction_errors(s, still) ** 2)))
    ours = fits["bmi160"].quality.rig_free["gyro_direction_rms_deg"]
    assert published == pytest.approx(0.96, abs=0.005)  # a review's independent re-computation: 0.96 deg
    assert ours <= 0.1  # issue target 0.96 deg: the moves integrated on the gyro's own samples (stale reads out)
    tk = fits["bmi160 tk"].quality.rig_free["gyro_direction_rms_deg"]
    assert tk <= 1.02 * published  # imu_tk's model on the reads as they come: the published figure


def test_gyro_direction_error_not_worse_than_published(sessions: dict[str, Session],
                                                       fits: dict[str, ParameterSet]) -> None:
    # The still detector must keep the 2.4 s pose at ~145 s (its minimum length once applied to the run the
    # 1 s window had eroded to 1.4 s, merging two moves into one): with it, the published calibration's
    # direction RMS on our moves is the 0.96 deg (0.974 without it).
    s = sessions["bmi160"]
    still = s.segments_of(Kind.REST, Kind.POSE)
    assert any(144.0 <= s.t_s[p.start] <= 146.5 and s.t_s[p.stop - 1] - s.t_s[p.start] >= 1.0 for p in still)
    e_pub = _published_direction_errors(s, still)
    e_ours = np.array(fits["bmi160"].quality.rig_free["gyro_direction_error_deg"])
    assert len(e_ours) == len(e_pub) == 38
    # The station's RMS over the same 38 moves against the published calibration's, with the standard error of
    # the paired difference (bootstrap over the moves): the published per-move errors of ~1 deg are the gyro's
    # stale reads (station.fit.readtiming); integrated on the sensor's samples the station is better by far.
    def rms(e: np.ndarray) -> np.ndarray:
        return np.sqrt(np.mean(e**2, axis=-1))

    idx = np.random.default_rng(0).integers(0, len(e_pub), size=(4000, len(e_pub)))
    se = float(np.std(rms(e_ours[idx]) - rms(e_pub[idx])))
    assert 0.02 < se < 0.2
    assert rms(e_ours) <= rms(e_pub) - 5.0 * se, (rms(e_ours), rms(e_pub), se)


def test_stale_gyro_reads_found_on_the_openaxes_logger(fits: dict[str, ParameterSet]) -> None:
    # the BMI160's ODR beats against the logger's reads: each axis repeats a sample once per ~130 reads, y about
    # 1.8 reads after x and z 1.8 after y (read axis by axis over I2C); found from exact repeats alone
    for name in ("adxl355", "bmi160"):
        t = fits[name].quality.rig_free["read_timing"]
        assert t["selected"], t["reason"]
        assert t["period_reads"] == pytest.approx(130.30, abs=0.05) and t["period_reads_std"] < 0.02
        assert np.allclose(np.diff(t["offsets_reads"]), 1.8, atol=0.2)
        assert t["p_value"] < 1e-12 and t["on_grid"] >= 0.5 * t["candidates"]
        assert fits[name + " tk"].quality.rig_free["read_timing"]["selected"] is False


def test_cross_validation_is_reported(fits: dict[str, ParameterSet]) -> None:
    q = fits["adxl355"].quality.rig_free
    cv = q["cross_validation"]
    assert cv["folds"] == 5 and len(cv["accel_norm_error_mps2"]) == q["still_segments"] - 1
    assert q["accel_norm_rms_mps2"] < cv["accel_norm_rms_mps2"] < 2 * q["accel_norm_rms_mps2"]
    assert q["gyro_direction_rms_deg"] < cv["gyro_direction_rms_deg"] < 2 * q["gyro_direction_rms_deg"]


def test_command_line_import_with_gravity_from_latitude(tmp_path: Path) -> None:
    from typer.testing import CliRunner

    from station.cli import app
    from station.session import read_session

    out = tmp_path / "s.csv"
    r = CliRunner().invoke(app, ["import", "openaxes", str(LOG), "--accel", "bmi160", "--latitude", "52.3759",
                                 "--height", "55", "-o", str(out)])
    assert r.exit_code == 0, r.output
    s = read_session(out)
    assert s.gravity_mps2 == pytest.approx(9.81263, abs=1e-5) and s.metadata["latitude_deg"] == "52.3759"
    assert s.metadata["source_accel"] == "bmi160" and is_rig_free(s)
    r = CliRunner().invoke(app, ["import", "openaxes", str(LOG), "--gravity", "9.81", "--latitude", "52",
                                 "-o", str(tmp_path / "t.csv")])
    assert r.exit_code == 2 and "not both" in r.stderr
