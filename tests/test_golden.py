"""The golden unit: registration from repeated runs, the check, the shift gate, and the trend chart."""

from __future__ import annotations

from collections.abc import Iterator
from datetime import UTC, datetime
from pathlib import Path

import numpy as np
import pytest

from station.kernel.errors import FormatError, StationError, UnsupportedVersionError
from station.kernel.golden import check_golden, golden_from_json, golden_trends, register_golden
from station.store.db import Database, open_database
from station.store.golden_records import (
    golden_checks,
    golden_gate,
    golden_units,
    record_golden_check,
    save_golden,
    shift_start,
)
from station.store.quality import ShiftCalendar
from station.store.spc import run_rules


def _runs(n: int, sigma: float = 1e-3, seed: int = 0) -> list[dict[str, tuple[float, str, float | None, float | None]]]:
    rng = np.random.default_rng(seed)
    return [{"accel.bias_static.x": (0.02 + rng.normal(0, sigma), "m/s^2", -0.17, 0.026),
             "gyro.M.xz": (0.0002 + rng.normal(0, 1e-6), "1", -0.001, 0.001)} for _ in range(n)]


def test_registration_needs_ten_runs_and_takes_the_larger_allowance() -> None:
    with pytest.raises(StationError, match="at least 10 runs"):
        register_golden("G1", "", _runs(9))
    g = register_golden("G1", "2026-11-28T06:00:00+00:00", _runs(12))
    assert g.rule is not None
    assert (g.rule.false_stop_rate, g.rule.runs, g.rule.parameters) == (0.0027, 12, 2)
    # k = t_11^-1(1 - 0.0027 / 4) * sqrt(1 + 1/12); t_11^-1(0.999325) = 4.256905 (scipy.stats.t.ppf)
    assert g.rule.k == pytest.approx(4.256905 * (13 / 12) ** 0.5, rel=1e-5)
    bias = g.reference("accel.bias_static.x")
    assert bias is not None and bias.runs == 12
    assert bias.value == pytest.approx(0.02, abs=2e-3)
    assert bias.allowed == pytest.approx(max(g.rule.k * bias.repeatability, 0.1 * 0.196))
    m = g.reference("gyro.M.xz")
    assert m is not None and m.allowed == pytest.approx(0.1 * 0.002)  # the limit fraction dominates
    assert g.to_json()["format"] == "station-golden/2"
    assert golden_from_json(g.to_json()) == g
    with pytest.raises(UnsupportedVersionError):
        golden_from_json({**g.to_json(), "format": "station-golden/0"})
    with pytest.raises(UnsupportedVersionError):
        golden_from_json({**g.to_json(), "format": "station-golden/3"})


def test_a_version_1_registration_still_loads_with_its_stored_allowances() -> None:
    v1 = {"format": "station-golden/1", "serial": "G0", "registered_at": "2026-11-01T06:00:00+00:00",
          "references": [{"parameter": "accel.bias_static.x", "unit": "m/s^2", "value": 0.02, "allowed": 0.0196,
                          "repeatability": 0.001, "runs": 5}]}
    g = golden_from_json(v1)
    assert g.rule is None
    ref = g.reference("accel.bias_static.x")
    assert ref is not None and ref.allowed == 0.0196 and ref.runs == 5
    assert check_golden(g, {"accel.bias_static.x": 0.02 + 0.019}).passed
    assert not check_golden(g, {"accel.bias_static.x": 0.02 + 0.0197}).passed
    assert g.to_json() == {**v1, "rule": None}  # saved again as what it is
    with pytest.raises(FormatError):
        golden_from_json({**v1, "format": "station-golden/2"})  # a /2 file must carry its rule


def test_check_passes_within_and_fails_outside_or_missing() -> None:
    g = register_golden("G1", "", _runs(10))
    ref = {r.parameter: r.value for r in g.references}
    assert check_golden(g, ref).passed
    off = dict(ref, **{"accel.bias_static.x": ref["accel.bias_static.x"] + 0.03})
    bad = check_golden(g, off)
    assert not bad.passed and [d.parameter for d in bad.failed] == ["accel.bias_static.x"]
    assert "off by +0.03" in bad.describe()
    missing = check_golden(g, {"gyro.M.xz": ref["gyro.M.xz"]})
    assert not missing.passed and "not measured" in missing.describe()


@pytest.fixture
def db(tmp_path: Path) -> Iterator[Database]:
    with open_database(f"sqlite:///{tmp_path / 'g.sqlite'}") as database:
        yield database


def test_shift_start_follows_the_calendar() -> None:
    cal = ShiftCalendar.parse("A=06:00,B=14:00,C=22:00")
    assert shift_start(datetime(2026, 11, 28, 7, 30, tzinfo=UTC), cal) == datetime(2026, 11, 28, 6, 0, tzinfo=UTC)
    assert shift_start(datetime(2026, 11, 28, 23, 0, tzinfo=UTC), cal) == datetime(2026, 11, 28, 22, 0, tzinfo=UTC)
    # after midnight: still last night's shift C
    assert shift_start(datetime(2026, 11, 28, 2, 0, tzinfo=UTC), cal) == datetime(2026, 11, 27, 22, 0, tzinfo=UTC)


def test_the_shift_gate(db: Database) -> None:
    cal = ShiftCalendar.parse("A=06:00,B=14:00,C=22:00")
    clock = [datetime(2026, 11, 28, 7, 0, tzinfo=UTC)]
    admit = golden_gate(db, "st1", cal, now=lambda: clock[0])
    assert "no golden unit is registered" in (admit("P1", "r") or "")
    g = register_golden("G1", "", _runs(10))
    save_golden(db, g)
    assert golden_units(db)["G1"][0] == 1
    assert admit("G1", "r") is None  # a golden unit is always admitted
    assert "no golden-unit run on station st1 in this shift" in (admit("P1", "r") or "")
    ref = {r.parameter: r.value for r in g.references}
    record_golden_check(db, check_golden(g, ref), station="st1", version=1, run_uid=None, slot=None,
                        checked_at=datetime(2026, 11, 28, 6, 5, tzinfo=UTC))
    assert admit("P1", "r") is None
    # another station's golden run does not count for st1's gate
    assert golden_gate(db, "st2", cal, now=lambda: clock[0])("P1", "r") is not None
    clock[0] = datetime(2026, 11, 28, 14, 1, tzinfo=UTC)  # the next shift: a golden run first again
    assert "in this shift" in (admit("P1", "r") or "")
    bad = dict(ref, **{"accel.bias_static.x": ref["accel.bias_static.x"] + 1.0})
    record_golden_check(db, check_golden(g, bad), station="st1", version=1, run_uid=None, slot=None,
                        checked_at=datetime(2026, 11, 28, 14, 2, tzinfo=UTC))
    assert "production is stopped" in (admit("P1", "r") or "")
    inner_calls: list[str] = []
    record_golden_check(db, check_golden(g, ref), station="st1", version=1, run_uid=None, slot=None,
                        checked_at=datetime(2026, 11, 28, 14, 3, tzinfo=UTC))
    gated = golden_gate(db, "st1", cal, inner=lambda s, r: inner_calls.append(s) or "retest policy",
                        now=lambda: clock[0])
    assert gated("P1", "r") == "retest policy" and inner_calls == ["P1"]  # the retest policy still applies
    assert [c.passed for c in golden_checks(db, station="st1")] == [True, False, True]


def test_trend_rules_fire_on_a_drift_not_on_noise() -> None:
    g = register_golden("G1", "", _runs(10, sigma=1e-3, seed=4))
    sigma = g.reference("accel.bias_static.x").repeatability  # type: ignore[union-attr]
    rng = np.random.default_rng(9)
    steady = [{"accel.bias_static.x": float(rng.normal(0, sigma))} for _ in range(12)]
    drift = [{"accel.bias_static.x": float(0.6 * sigma * k + rng.normal(0, sigma))} for k in range(12)]
    (t_steady, _) = golden_trends(g, steady, run_rules)
    (t_drift, _) = golden_trends(g, drift, run_rules)
    assert t_steady.first_signal is None
    assert t_drift.first_signal is not None and t_drift.first_signal <= 8


def test_the_commands_state_the_rule_and_the_charts_dof(tmp_path: Path) -> None:
    from typer.testing import CliRunner

    from station.cli import app

    url = f"sqlite:///{tmp_path / 'c.sqlite'}"
    with open_database(url) as database:
        save_golden(database, register_golden("G2", "2026-11-28T06:00:00+00:00", _runs(12)))
    res = CliRunner().invoke(app, ["golden", "list", "--db", url])
    assert res.exit_code == 0, res.output
    assert "false-stop rate 0.27 % per check over 2 parameters, n = 12 runs (11 dof)" in res.output
    res = CliRunner().invoke(app, ["golden", "chart", "G2", "--db", url])
    assert res.exit_code == 0, res.output
    assert "registered from 12 runs (11 degrees of freedom" in res.output
    res = CliRunner().invoke(app, ["golden", "register", "P9", "--db", url])
    assert res.exit_code != 0 and "at least 10 runs" in res.output


def test_register_says_how_sensitive_the_check_is(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from typer.testing import CliRunner

    import station.store.golden_records as records
    from station.cli import app

    url = f"sqlite:///{tmp_path / 'r.sqlite'}"
    with open_database(url):
        pass
    monkeypatch.setattr(records, "unit_runs", lambda *_: _runs(12))
    res = CliRunner().invoke(app, ["golden", "register", "G3", "--db", url, "--false-stop-rate", "0.01"])
    assert res.exit_code == 0, res.output
    # k = t_11^-1(1 - 0.01 / 4) sqrt(13/12) = 3.4966 * 1.0408 (scipy.stats.t.ppf(0.9975, 11) = 3.49661)
    assert "false-stop rate 1 % per check over 2 parameters, n = 12 runs (11 dof): allowed max(3.64 s" in res.output
    assert "catches a shift of one parameter of 3.64 sigma with 50 %" in res.output
    assert "20 runs or more" in res.output
