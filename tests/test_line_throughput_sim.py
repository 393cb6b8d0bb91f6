"""The line throughput simulation (benchmarks/line_throughput.py) on the virtual clock: the same seed gives the same
units, outcomes and simulated times when the second run competes with a busy process; a unit that loses power on
the way to the rig is refused with the reason, the others of its batch go on. Real peers: relay board and rig on
Modbus/TCP (127.0.0.1), sensors on ptys; 3 units at 10 Hz, 300 s in the rack, two rig batches."""

from __future__ import annotations

import importlib
import sys
from dataclasses import replace
from pathlib import Path
from types import ModuleType

import pytest

from station.kernel.line_plan import load_line_plan_file
from tests.test_deterministic_run import cpu_load


def _module() -> ModuleType:
    """The benchmark module, imported as ``bench_line.py`` imports it (its folder on the path)."""
    folder = str(Path(__file__).resolve().parents[1] / "benchmarks")
    if folder not in sys.path:
        sys.path.insert(0, folder)
    return importlib.import_module("line_throughput")


def test_the_throughput_run_repeats_under_load_and_refuses_an_interrupted_unit(
        monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    monkeypatch.setenv("STATION_LOCK_DIR", str(tmp_path / "locks"))
    lt = _module()
    lf = load_line_plan_file(None)
    lf = replace(lf, plan=replace(lf.plan, rack_s=300.0))

    def once() -> tuple[tuple[object, ...], tuple[tuple[float, ...], ...], float]:
        run = lt.simulate(lf, rack_slots=3, rig_units=2, rate_hz=10, seed=41, interrupt=[2])
        times = tuple((b.sequence_s, b.verify_s, b.wait_s, b.start_s, b.end_s) for b in run.batches)
        return run.units, times, run.soak_s

    first = once()
    with cpu_load(1):
        second = once()
    assert first == second
    units, times, _ = first
    assert len(times) == 2 and [u.batch for u in units] == [1, 1, 2]
    assert all(u.recorded for u in units)
    cut = units[2]
    assert cut.interrupted and cut.outcome == "REFUSED" and "power-on counter changed" in cut.message
    assert cut.decision.startswith("full") and not cut.written
    for u in units[:2]:  # powered all the way: the line plan, fitted over both recordings
        assert not u.interrupted and u.decision == "line" and u.outcome != "REFUSED"
        assert u.written == u.verified == (u.outcome == "PASS")
