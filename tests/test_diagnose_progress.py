"""Progress of a diagnosis: the stages reach the callback in order (pure layer), and ``station diagnose
--progress`` prints them to stderr while stdout holds only the JSON report."""

from __future__ import annotations

import io
import json
from pathlib import Path

import pytest
from typer.testing import CliRunner

from station.cli import app
from station.commands.progress import stderr_progress, wants_progress
from station.diagnose import diagnose
from station.diagnose.diagnosis_progress import DONE, STAGES, Stage
from station.kernel.plan import RigPlan
from station.physics.effects import Effects
from station.session.csv_v1 import write_session
from station.sim.session_sim import simulate_session

#: ~8 min at 100 Hz with two rate magnitudes (as tests/test_diagnose.py).
PLAN = RigPlan(
    rest_s=120.0,
    pose_hold_s=15.0,
    rate_steps=tuple((a, s * r) for a in "xyz" for r in (50.0, 200.0) for s in (1.0, -1.0)),
    rate_hold_s=6.0,
)


@pytest.fixture(scope="module")
def lever() -> object:
    return simulate_session(5, plan=PLAN, effects=Effects(lever_arm=30.0))


def test_callback_sees_every_stage_once_in_order(lever: object) -> None:
    seen: list[Stage] = []
    d = diagnose(lever.session, progress=seen.append)
    assert [s.name for s in seen] == [*STAGES, DONE]
    assert [s.index for s in seen] == list(range(len(STAGES) + 1))
    assert all(s.total == len(STAGES) for s in seen) and [s.done for s in seen] == [False] * len(STAGES) + [True]
    assert all(s.samples == len(lever.session) for s in seen)
    elapsed = [s.elapsed_s for s in seen]
    assert elapsed == sorted(elapsed) and elapsed[0] >= 0.0
    assert ("lever_arm", "accel") in d.effects  # the callback does not change the diagnosis


def test_cli_progress_goes_to_stderr_and_json_stays_clean(lever: object, tmp_path: Path) -> None:
    path = tmp_path / "lever.csv"
    write_session(lever.session, path)
    result = CliRunner().invoke(app, ["diagnose", str(path), "--json", "--progress"])
    assert result.exit_code == 0, result.output
    report = json.loads(result.stdout)  # stdout is the one JSON object, nothing else
    assert report["format"] == "station-diagnosis/1"
    assert "lever_arm" in [f["effect"] for f in report["findings"]]
    lines = [ln for ln in result.stderr.splitlines() if ln.startswith("diagnosis: ")]
    assert len(lines) == len(STAGES) + 1
    for k, (line, name) in enumerate(zip(lines, STAGES, strict=False)):
        assert f"[{k + 1}/{len(STAGES)}] {name} ({len(lever.session):,} samples" in line
    assert lines[-1].startswith("diagnosis: done in ")


class _Stream(io.StringIO):
    def __init__(self, tty: bool) -> None:
        super().__init__()
        self.tty = tty

    def isatty(self) -> bool:
        return self.tty


def test_progress_is_on_for_a_terminal_unless_told() -> None:
    assert wants_progress(None, _Stream(True)) and not wants_progress(None, _Stream(False))
    assert wants_progress(True, _Stream(False)) and not wants_progress(False, _Stream(True))
    assert stderr_progress(False) is None


def test_no_progress_without_a_terminal(lever: object, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """CliRunner's stderr is not a terminal: without ``--progress`` nothing is printed (the default text report)."""
    from station.commands import diagnose as command

    calls: list[object] = []

    def fake(session: object, *, warmup_tc_s: object = None, progress: object = None,
             drift_class: object = None) -> object:
        calls.append(progress)
        raise command.StationError("stop here")

    monkeypatch.setattr("station.diagnose.report.diagnose", fake)
    path = tmp_path / "lever.csv"
    write_session(lever.session, path)
    result = CliRunner().invoke(app, ["diagnose", str(path)])
    assert result.exit_code == 2 and "stop here" in result.stderr
    assert calls == [None]
