"""Bad input to the fit: a one-line reason and a non-zero exit, never a silently wrong result."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from station.cli import app
from station.fit.calibrate import fit_session
from station.kernel.errors import FitError
from station.session import write_session
from station.session.model import Kind, Session
from station.sim.session_sim import simulate_session


@pytest.fixture(scope="module")
def good() -> Session:
    return simulate_session(77).session


def _drop_segment(s: Session, index: int) -> Session:
    keep = s.segment != index
    return s.replace(
        t_s=s.t_s[keep], segment=s.segment[keep], kind=s.kind[keep], accel_mps2=s.accel_mps2[keep],
        gyro_radps=s.gyro_radps[keep], temp_degc=s.temp_degc[keep], ref_accel_mps2=s.ref_accel_mps2[keep],
        ref_gyro_radps=s.ref_gyro_radps[keep],
    )


def _first(s: Session, kind: Kind, up_axis: int | None = None, sign: float = 1.0) -> int:
    for seg in s.segments_of(kind):
        ref = s.ref_accel_mps2[seg.start]
        if up_axis is None or sign * ref[up_axis] > 5.0:
            return seg.index
    raise AssertionError("no such segment")


def test_missing_pose(good: Session) -> None:
    idx = _first(good, Kind.POSE, up_axis=2, sign=-1.0)
    # the rest segment also has +z up; removing the -z pose leaves z only one way
    with pytest.raises(FitError, match="missing pose: no settled pose with z pointing down"):
        fit_session(_drop_segment(good, idx))


def test_too_few_samples_in_a_pose(good: Session) -> None:
    idx = _first(good, Kind.POSE)
    seg = next(s for s in good.segments() if s.index == idx)
    keep = np.ones(len(good), dtype=bool)
    keep[seg.start + 10:seg.stop] = False
    s = good.replace(**{n: getattr(good, n)[keep] for n in (
        "t_s", "segment", "kind", "accel_mps2", "gyro_radps", "temp_degc", "ref_accel_mps2", "ref_gyro_radps")})
    with pytest.raises(FitError, match=f"pose segment {idx} has 10 samples"):
        fit_session(s)


def test_nan_in_data(good: Session) -> None:
    acc = good.accel_mps2.copy()
    acc[1234, 1] = np.nan
    with pytest.raises(FitError, match="accel y is NaN or infinite at sample 1234"):
        fit_session(good.replace(accel_mps2=acc))


def test_non_increasing_time(good: Session) -> None:
    t = good.t_s.copy()
    t[500] = t[499]
    with pytest.raises(FitError, match="time does not increase at sample 500"):
        fit_session(good.replace(t_s=t))


def test_dead_axis(good: Session) -> None:
    gyr = good.gyro_radps.copy()
    gyr[:, 2] = 0.0
    with pytest.raises(FitError, match=r"gyro z is constant .* \(dead axis\)"):
        fit_session(good.replace(gyro_radps=gyr))


def test_saturated_axis(good: Session) -> None:
    acc = good.accel_mps2.copy()
    idx = _first(good, Kind.POSE, up_axis=0, sign=1.0)
    sel = good.segment == idx
    acc[:, 0] = np.minimum(acc[:, 0], 9.0)  # clips the +x pose at 9 m/s^2
    assert np.all(acc[sel, 0] == 9.0)
    with pytest.raises(FitError, match="accel x is saturated"):
        fit_session(good.replace(accel_mps2=acc))


def test_no_rate_steps_and_no_angles(good: Session) -> None:
    s = good
    for seg in good.segments_of(Kind.RATE):
        s = _drop_segment(s, seg.index)
    with pytest.raises(FitError, match="no rate step and no known-angle rotation"):
        fit_session(s)


def test_cli_reports_one_line_and_exits_nonzero(good: Session, tmp_path: Path) -> None:
    acc = good.accel_mps2.copy()
    acc[:, 0] = np.minimum(acc[:, 0], 9.0)
    path = tmp_path / "clipped.csv"
    write_session(good.replace(accel_mps2=acc), path)
    result = CliRunner().invoke(app, ["fit", str(path)])
    assert result.exit_code != 0
    lines = [ln for ln in result.output.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("error: accel x is saturated"), result.output
