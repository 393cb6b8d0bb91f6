"""The one display convention (station/kernel/display.py): units per quantity, one "±", local time with the zone."""

from __future__ import annotations

import math
import time
from datetime import UTC, datetime

import pytest

from station.kernel.display import (
    PM,
    display_for,
    display_of_check,
    format_number,
    format_value,
    limits_identity,
    local_time,
)
from station.kernel.measurement import Measurement


def test_quantities_and_their_units() -> None:
    cases = {  # (stored name, SI unit) -> (display unit, SI value, shown value)
        ("accel.bias_static.x", "m/s^2"): ("mg", 9.80665e-3, 1.0),
        ("gyro.bias_static.y", "rad/s"): ("deg/s", math.pi, 180.0),
        ("accel.M.xx", "1"): ("ppm", 1.000125, 125.0),  # a scale factor shown as its error
        ("gyro.M.zx", "1"): ("ppm", -0.00094, -940.0),  # cross-axis
        ("fit.accel.M_std.xy", "1"): ("ppm", 3.4e-5, 34.0),
        ("accel.correlation_time_s.x", "s"): ("s", 93.0, 93.0),
        ("time_offset_s", "s"): ("ms", 0.0123, 12.3),
        ("accel.temp_bias_coeff.x", "m/s^2/K"): ("mg/K", 9.80665e-4, 0.1),
        ("gyro.temp_scale_coeff.z", "1/K"): ("ppm/K", 2e-5, 20.0),
        ("rest.sample_fraction", "1"): ("%", 0.995, 99.5),
        ("gravity_ratio", "1"): ("%", 1.01, 101.0),
        ("fit.goodness_of_fit.failed_tests", "1"): ("", 2.0, 2.0),
    }
    for (name, si), (unit, value, shown) in cases.items():
        d = display_of_check(name, si)
        assert d.unit == unit, name
        assert d.value(value) == pytest.approx(shown, rel=1e-12), name
    assert display_of_check("accel.M.xx", "1").spread(5.2e-5) == pytest.approx(52.0)  # no offset on a spread


def test_one_plus_minus_and_digits_from_the_uncertainty() -> None:
    assert format_value(-11.7312, 0.1023, "mg") == f"-11.73 {PM} 0.10 mg"
    assert format_value(10820.4, 104.1, "ppm") == f"10820 {PM} 104 ppm"
    assert format_value(2.64712, 0.0551, "deg/s") == f"2.647 {PM} 0.055 deg/s"
    assert format_value(0.0123456) == "0.01235"
    assert format_value(math.nan, 1.0, "mg") == "—" and format_value(None) == "—"
    assert format_number(0.0) == "0"
    # the example: "1.01082 +- 5.2e-05 1 outside [0.998, 1.005]"
    m = Measurement("accel.M.xx", 1.01082, "1", 0.998, 1.005, False, 5.2e-05, k=2.0)
    assert m.describe() == f"accel.M.xx (scale-factor error) = 10820 {PM} 104 ppm outside [-2000, 5000] ppm"
    assert "+-" not in Measurement("gyro.bias_static.x", 0.04619, "rad/s", -0.0127, 0.0478, True, 4.8e-4,
                                   k=2.0).describe()


def test_local_time_with_the_zone(monkeypatch: pytest.MonkeyPatch) -> None:
    when = datetime(2026, 11, 27, 6, 6, 15, 302880, tzinfo=UTC)
    try:
        monkeypatch.setenv("TZ", "Europe/Berlin")
        time.tzset()
        assert local_time(when) == "2026-11-27 07:06:15 CET (UTC+01:00)"
        assert local_time("2026-11-27T06:06:15.302880+00:00") == "2026-11-27 07:06:15 CET (UTC+01:00)"
        assert local_time(datetime(2026, 7, 1, 12, 0)) == "2026-07-01 14:00:00 CEST (UTC+02:00)"  # naive = UTC
        monkeypatch.setenv("TZ", "UTC")
        time.tzset()
        assert local_time(when) == "2026-11-27 06:06:15 UTC+00:00"
    finally:
        monkeypatch.undo()
        time.tzset()
    assert local_time(None) == "—"


def test_limits_identity_names_the_hash() -> None:
    h = "9f10cb38a666d97ad445f5a160bc666de983dea4e379dbe71f92af91e737d64c"
    assert limits_identity("table1-default 2.0.0", h) == "table1-default 2.0.0, sha256 9f10cb38a666"
    assert limits_identity("table1-default 2.0.0", h, short=False).endswith(h)
    assert limits_identity("table1-default 2.0.0", "") == "table1-default 2.0.0, sha256 unknown"
    assert display_for("acceleration").unit == "mg"
