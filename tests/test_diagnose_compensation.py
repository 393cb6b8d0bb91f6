"""The diagnosis says which of its findings the station's calibration compensates."""

from __future__ import annotations

import pytest

from station.diagnose.report import diagnose
from station.physics.effects import Effects
from station.sim.session_sim import simulate_session

PRIOR = {"accel": (50.0, 167.0), "gyro": (1030.0, 3760.0)}


@pytest.mark.parametrize(("effects", "name", "compensated", "note"), [
    (Effects(g_sensitivity=0.05), "g_sensitivity", True, "gyro.g_sensitivity"),
    (Effects(scale_nonlinearity=0.002), "scale_nonlinearity", True, "gyro.scale_cubic"),
    (Effects(time_offset=3.0), "time_offset", True, "time_offset_s"),
    (Effects(scale_asymmetry=0.002), "scale_asymmetry", False, "no parameter"),
])
def test_each_finding_says_whether_the_calibration_compensates_it(
    effects: Effects, name: str, compensated: bool, note: str
) -> None:
    report = diagnose(simulate_session(310, effects=effects).session, warmup_tc_s=PRIOR).to_json()
    found = [f for f in report["findings"] if f["effect"] == name and f["sensor"] == "gyro"]
    assert found, [f["effect"] for f in report["findings"]]
    cal = found[0]["calibration"]
    assert cal["compensated"] is compensated and note in cal["note"], cal
    # only the finding's own sensor's fields count: the gyro finding names no accelerometer field
    assert "accel." not in cal["note"]


def test_each_finding_shows_the_held_out_error_with_and_without_its_compensation() -> None:
    """A time offset: the corrected rate on held-out segments is far better with the fitted offset than without it;
    the typed entry survives the JSON round trip."""
    from station.diagnose.results import load_report

    diagnosis = diagnose(simulate_session(311, effects=Effects(time_offset=4.0)).session, warmup_tc_s=PRIOR)
    gyro = [f for f in diagnosis.report.findings if f.effect == "time_offset" and f.sensor == "gyro"]
    assert gyro and gyro[0].calibration is not None
    gain = gyro[0].calibration.gain
    assert gain is not None and gain.applied and gain.unit == "deg/s" and gain.held_out[0] > 0 and gain.held_out[1] > 0
    assert gain.error_with < gain.error_without / 5.0, gain
    doc = diagnosis.report.to_json()
    back = load_report(doc)
    assert back.to_json() == doc
    entry = next(f for f in doc["findings"] if f["effect"] == "time_offset" and f["sensor"] == "gyro")
    assert entry["calibration"]["held_out"]["error_with"] == gain.error_with


def test_a_finding_without_parameters_has_the_same_error_both_ways() -> None:
    from station.diagnose.compensation_gain import gains
    from station.fit.calibrate import FitOptions

    session = simulate_session(312, effects=Effects(scale_asymmetry=0.002)).session
    (gain,) = gains(session, [("scale_asymmetry", "gyro")], ["scale_asymmetry"], FitOptions(tc_range_s=PRIOR))
    assert not gain.applied and gain.error_with == gain.error_without > 0
