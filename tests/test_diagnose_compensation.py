"""The diagnosis says which of its findings the station's calibration compensates (issue 18, item 4)."""

from __future__ import annotations

import pytest

from station.diagnose.report import diagnose
from station.physics.effects import Effects
from station.sim.session_sim import simulate_session

PRIOR = {"accel": (50.0, 167.0), "gyro": (1030.0, 3760.0)}


@pytest.mark.parametrize(("effects", "name", "compensated", "note"), [
    (Effects(g_sensitivity=0.05), "g_sensitivity", True, "gyro.g_sensitivity"),
    (Effects(scale_nonlinearity=0.002), "scale_nonlinearity", True, "gyro.scale_nonlinearity"),
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
