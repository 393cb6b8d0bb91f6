"""``station fit --no-accel-drift``: imu_tk's model (no accelerometer warm-up drift) for a rig-free fit, refused for a
rig recording."""

from __future__ import annotations

from pathlib import Path

from typer.testing import CliRunner

from station.cli import app
from station.kernel.parameters import ParameterSet
from station.session.csv_v1 import write_session
from station.sim.handheld import simulate_handheld
from station.sim.session_sim import simulate_session
from tests.test_diagnose_rigfree import _session


def test_no_accel_drift_is_refused_for_a_rig_recording(tmp_path: Path) -> None:
    path = tmp_path / "rig.csv"
    write_session(simulate_session(5).session, path)
    r = CliRunner().invoke(app, ["fit", str(path), "--no-accel-drift"])
    assert r.exit_code == 2 and "--no-accel-drift is for the rig-free fit" in r.output


def test_no_accel_drift_fits_without_the_drift(tmp_path: Path) -> None:
    path = tmp_path / "hand.csv"
    write_session(_session(simulate_handheld(7)), path)
    runner = CliRunner()
    with_drift = runner.invoke(app, ["fit", str(path), "--json"])
    without = runner.invoke(app, ["fit", str(path), "--json", "--no-accel-drift"])
    assert with_drift.exit_code in (0, 3) and without.exit_code in (0, 3), with_drift.output + without.output
    p = ParameterSet.from_json(without.stdout)
    assert p.quality.rig_free is not None
    assert not any(p.accel.bias_drift)  # imu_tk's model: one constant bias
    assert any(ParameterSet.from_json(with_drift.stdout).accel.bias_drift)  # the default fits the warm-up
