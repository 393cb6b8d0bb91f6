"""Inputs checked against physics before the fit, and the goodness-of-fit verdict after it."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest
from realdata import IMUCAL_FERRARIS, IMUCAL_SECTIONS, real_path
from typer.testing import CliRunner

from station.cli import app
from station.fit import calibrate
from station.fit.calibrate import fit_session
from station.fit.goodness import EXIT_GOODNESS
from station.kernel.errors import FitError, SessionFormatError
from station.session import parse_session, write_session
from station.session.csv_v1 import format_session
from station.session.imucal_import import import_imucal_ferraris
from station.session.model import Kind, Session
from station.sim.session_sim import simulate_session

REAL = real_path("imucal")
needs_real = pytest.mark.real(IMUCAL_FERRARIS, IMUCAL_SECTIONS)


@pytest.fixture(scope="module")
def good() -> Session:
    return simulate_session(77).session


def _pose(s: Session, axis: int, sign: float) -> int:
    return next(seg for seg in s.segments_of(Kind.POSE) if sign * s.ref_accel_mps2[seg.start, axis] > 5.0).start


def _segment(s: Session, start: int) -> slice:
    return next(seg.slice for seg in s.segments() if seg.start == start)


def test_pose_reference_of_two_g_is_refused(good: Session) -> None:
    ref = good.ref_accel_mps2.copy()
    sl = _segment(good, _pose(good, 2, -1.0))
    ref[sl] *= 2.0
    with pytest.raises(FitError, match=r"pose segment \d+: reference .* has norm 19.6.*not the recording's gravity"):
        fit_session(good.replace(ref_accel_mps2=ref))


def test_pose_reference_pointing_the_wrong_way_is_refused(good: Session) -> None:
    ref = good.ref_accel_mps2.copy()
    sl = _segment(good, _pose(good, 0, 1.0))
    ref[sl] *= -1.0
    with pytest.raises(FitError, match=r"pose segment \d+: the accelerometer measures .* 1[78]\d deg away"):
        fit_session(good.replace(ref_accel_mps2=ref))


def test_rate_step_reference_flipped_is_refused(good: Session) -> None:
    ref = good.ref_gyro_radps.copy()
    seg = good.segments_of(Kind.RATE)[0]
    ref[seg.slice] *= -1.0
    with pytest.raises(FitError, match=rf"rate segment {seg.index}: the gyroscope measures"):
        fit_session(good.replace(ref_gyro_radps=ref))


def test_sample_rate_contradicted_by_the_time_column(good: Session) -> None:
    with pytest.raises(FitError, match=r"sample_rate_hz 1000 Hz contradicts the time column.*100 Hz"):
        fit_session(good.replace(metadata={**good.metadata, "sample_rate_hz": "1000"}))


def test_huge_value_and_temperature_are_refused_by_range(good: Session) -> None:
    acc = good.accel_mps2.copy()
    acc[3000, 0] = 1e30
    with pytest.raises(FitError, match=r"accel x is 1e\+30 m/s\^2 at sample 3000.*beyond any MEMS"):
        fit_session(good.replace(accel_mps2=acc))
    temp = good.temp_degc.copy()
    temp[10] = 1e300
    with pytest.raises(FitError, match=r"temperature 1e\+300 degC at sample 10"):
        fit_session(good.replace(temp_degc=temp))


def test_gap_inside_a_segment_is_refused_without_warnings(good: Session) -> None:
    t = good.t_s.copy()
    t[40000:] += 1e5
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(FitError, match=r"time jumps by 100000 s at sample 40000 .* inside segment"):
            fit_session(good.replace(t_s=t))


def test_angles_on_missing_segment_or_on_a_pose_are_refused(good: Session) -> None:
    with pytest.raises(FitError, match=r"angle\.999: the recording has no segment 999"):
        fit_session(good.replace(angles_deg={999: (90.0, 0.0, 0.0)}))
    pose = good.segments_of(Kind.POSE)[0].index
    with pytest.raises(FitError, match=rf"angle\.{pose}: segment {pose} is pose, not a move"):
        fit_session(good.replace(angles_deg={pose: (90.0, 0.0, 0.0)}))


@pytest.mark.parametrize("value", ["abc", "500", "nan", "-91"])
def test_latitude_is_checked_by_the_reader(good: Session, value: str) -> None:
    text = format_session(good.replace(metadata={**good.metadata, "latitude_deg": value}))
    with pytest.raises(SessionFormatError, match="metadata latitude_deg"):
        parse_session(text)


def test_numerical_failure_names_what_was_fitted(good: Session, monkeypatch: pytest.MonkeyPatch) -> None:
    def broken(*args: object, **kwargs: object) -> None:
        raise np.linalg.LinAlgError("SVD did not converge")

    monkeypatch.setattr(calibrate, "fit_axis", broken)
    with pytest.raises(FitError, match=r"accelerometer fit \(rest and poses\): numerical failure \(SVD did not"):
        fit_session(good)


def test_good_recording_passes_goodness_of_fit(good: Session) -> None:
    verdict = fit_session(good).quality.goodness_of_fit.to_dict()
    assert verdict["format"] == "station-goodness/1"
    assert verdict["passed"] and verdict["failed"] == []
    kinds = {(t["triad"], t["kind"]) for t in verdict["tests"]}
    assert {("accel", "pose"), ("gyro", "rate"), ("gyro", "pose")} <= kinds


@pytest.mark.parametrize(("axis", "offset"), [(0, 0.05), (1, 0.01)])
def test_pose_mean_off_its_reference_fails_goodness_of_fit(good: Session, tmp_path: Path, axis: int,
                                                           offset: float) -> None:
    # the x-up pose, off along x or across it (y); a pose mean has ~0.3 mm/s^2 of white noise
    acc = good.accel_mps2.copy()
    acc[_segment(good, _pose(good, 0, 1.0)), axis] += offset
    bad = good.replace(accel_mps2=acc)
    verdict = fit_session(bad).quality.goodness_of_fit.to_dict()
    assert not verdict["passed"] and "accel pose" in verdict["failed"]
    path = tmp_path / f"off{axis}.csv"
    write_session(bad, path)
    result = CliRunner().invoke(app, ["fit", str(path), "--json"])
    assert result.exit_code == EXIT_GOODNESS
    assert result.stderr.count("\n") == 1 and "goodness-of-fit" in result.stderr and "accel pose" in result.stderr
    assert '"goodness_of_fit"' in result.stdout


def test_rate_step_off_its_command_fails_goodness_of_fit(good: Session) -> None:
    gyr = good.gyro_radps.copy()
    seg = good.segments_of(Kind.RATE)[3]
    gyr[seg.slice] *= 1.01
    verdict = fit_session(good.replace(gyro_radps=gyr)).quality.goodness_of_fit.to_dict()
    assert not verdict["passed"] and "gyro rate" in verdict["failed"]
    worst = [t for t in verdict["tests"] if not t["passed"]]
    assert any(t["worst_segment"] == seg.index for t in worst)


@needs_real
def test_real_ferraris_passes_and_turns_not_about_one_axis_are_refused() -> None:
    s = import_imucal_ferraris(REAL / "example_ferraris_session.csv", REAL / "example_ferraris_session_list.json")
    assert fit_session(s).quality.passed
    index = min(s.angles_deg)
    sel = np.flatnonzero(s.segment == index)
    gyr = s.gyro_radps.copy()
    half = len(sel) // 2
    gyr[sel[:half], 1] += np.radians(60.0)  # a wobble about y, there and back: the net turn is unchanged
    gyr[sel[half:2 * half], 1] -= np.radians(60.0)
    with pytest.raises(FitError, match=rf"angle\.{index}: move segment {index} is not a rotation about one fixed"):
        fit_session(s.replace(gyro_radps=gyr))


@needs_real
@pytest.mark.parametrize(("a", "b", "fragment"), [
    ("x_p", "x_a", "deg away from the reference"),
    ("x_rot", "y_rot", "from the stated rotation"),
])
def test_imucal_swapped_labels_are_refused(tmp_path: Path, a: str, b: str, fragment: str) -> None:
    import json

    d = json.loads((REAL / "example_ferraris_session_list.json").read_text())
    d[a], d[b] = d[b], d[a]
    sections = tmp_path / "s.json"
    sections.write_text(json.dumps(d))
    out = tmp_path / "o.csv"
    result = CliRunner().invoke(app, ["import", "imucal", str(REAL / "example_ferraris_session.csv"),
                                      "--segments", str(sections), "-o", str(out)])
    assert result.exit_code == 2 and fragment in result.stderr and result.stderr.count("\n") == 1
    assert not out.exists()


@needs_real
def test_imucal_single_section_is_refused_in_one_line(tmp_path: Path) -> None:
    import json

    sections = tmp_path / "s.json"
    sections.write_text(json.dumps({"x_p": {"start": 1, "end": 1271}}))
    out = tmp_path / "o.csv"
    runner = CliRunner()
    result = runner.invoke(app, ["import", "imucal", str(REAL / "example_ferraris_session.csv"),
                                 "--segments", str(sections), "-o", str(out)])
    assert result.exit_code == 0
    result = runner.invoke(app, ["fit", str(out)])
    assert result.exit_code == 2 and result.stderr.startswith("error: ") and result.stderr.count("\n") == 1


def test_the_sequence_retests_a_recording_that_contradicts_its_fit(good: Session) -> None:
    """The station's limits treat a failed goodness of fit as a FAIL of the recording (RETEST, no attempt
    counted), not of the unit, even when every limit passes."""
    from station.kernel.limits import table1_limits
    from station.sequence.limits import check_limits
    from station.sequence.records import Outcome
    from station.sequence.runner import recording_verdict, unit_verdict

    params = fit_session(good)
    assert recording_verdict(params) is None
    acc = good.accel_mps2.copy()
    acc[_segment(good, _pose(good, 0, 1.0)), 0] += 0.05
    bad = fit_session(good.replace(accel_mps2=acc))
    lim = table1_limits()
    assert unit_verdict(check_limits(bad, lim), lim)[0] == Outcome.PASS  # the limits alone would pass it
    verdict = recording_verdict(bad)
    assert verdict is not None and verdict[0] == Outcome.RETEST and "accel pose" in verdict[1]


def test_a_gap_the_station_captured_is_its_own_fault_and_any_other_refusal_the_units(good: Session) -> None:
    """A gap inside a segment is a TimeBaseError; in a run that captured it the unit ends ERROR (the link or the
    station did not keep up, and the retest policy does not count it), while a refusal of what the unit measured
    is the unit's FAIL."""
    from station.kernel.errors import TimeBaseError
    from station.sequence import Outcome
    from station.sequence.runner import refusal_outcome

    t = good.t_s.copy()
    t[40000:] += 34.8
    with pytest.raises(TimeBaseError) as gap:
        fit_session(good.replace(t_s=t))
    assert refusal_outcome(gap.value)[0] == Outcome.ERROR
    assert "capture fault (station, not the unit)" in refusal_outcome(gap.value)[1]
    acc = good.accel_mps2.copy()
    acc[3000, 0] = 1e30
    with pytest.raises(FitError) as range_error:
        fit_session(good.replace(accel_mps2=acc))
    assert not isinstance(range_error.value, TimeBaseError)
    assert refusal_outcome(range_error.value) == (Outcome.FAIL, f"fit refused the recording: {range_error.value}")
