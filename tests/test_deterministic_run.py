"""A simulated run on the virtual clock repeats bit for bit, also under CPU load.

Two units on the simulated Modbus rig and ptys run a short plan twice, each time on a fresh
:class:`~station.kernel.virtual_clock.VirtualClock`; the second run competes with two busy processes
started (and stopped) by the test. The session CSVs and parameter JSONs must be the same bytes; the only
line allowed to differ is the CSV's ``# run_id:`` metadata (a fresh id per run). On a scaled ``SimClock``
the same comparison fails: capture windows and rig command times follow thread timing there.
"""

from __future__ import annotations

import subprocess
import sys
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

import pytest

from station.kernel.clock import Clock
from station.kernel.plan import RigPlan
from station.kernel.virtual_clock import VirtualClock, acting
from station.rig import open_rig
from station.sensor import open_sensor
from station.sequence import Outcome, SequenceOptions, SequenceRunner
from station.sim.station_sim import SimStation

pytestmark = pytest.mark.integration

SEED = 11
PLAN = RigPlan(
    sample_rate_hz=50.0,
    rest_s=200.0,
    pose_hold_s=8.0,
    rate_steps=(("x", 100.0), ("y", -100.0), ("z", 100.0)),
    rate_hold_s=4.0,
)


@contextmanager
def cpu_load(processes: int = 2) -> Iterator[None]:
    """Busy processes competing for the CPU while the block runs."""
    procs = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(processes)]
    try:
        yield
    finally:
        for p in procs:
            p.kill()
        for p in procs:
            p.wait()


def run_once(out_dir: Path, clock: Clock) -> dict[str, bytes]:
    """One run of two simulated units on ``clock``; its files by serial and suffix, the run id line removed.

    The test's thread is an actor of a virtual clock from the start: time does not pass while it sets up."""
    with acting(clock, name="test"), SimStation(2, clock.scale, SEED, plan=PLAN, clock=clock) as sim:
        rig = open_rig(sim.rig_url, sim.clock, **sim.rig_client_options())
        sensors = [open_sensor(url, sim.clock) for url in sim.sensor_urls]
        try:
            result = SequenceRunner(
                rig, sensors, sim.clock, plan=PLAN, options=SequenceOptions().for_scale(clock.scale), out_dir=out_dir,
                station="pytest", rig_name="sim", sensor_urls=sim.sensor_urls,
            ).run()
        finally:
            for s in sensors:
                s.close()
            rig.close()
    assert result.outcome not in (Outcome.ERROR, Outcome.ABORTED), result.message
    files: dict[str, bytes] = {}
    for u in result.units:
        assert u.session_path is not None and u.params_path is not None, (u.outcome, u.message)
        lines = u.session_path.read_bytes().splitlines(keepends=True)
        files[f"{u.serial}.csv"] = b"".join(line for line in lines if not line.startswith(b"# run_id:"))
        files[f"{u.serial}.params.json"] = u.params_path.read_bytes()
    return files


def runs_repeat(tmp_path: Path, make_clock: Callable[[], Clock]) -> tuple[dict[str, bytes], dict[str, bytes]]:
    first = run_once(tmp_path / "quiet", make_clock())
    with cpu_load():
        second = run_once(tmp_path / "loaded", make_clock())
    return first, second


def test_virtual_clock_run_repeats_bit_for_bit_under_load(tmp_path: Path) -> None:
    first, second = runs_repeat(tmp_path, VirtualClock)
    assert sorted(first) == sorted(second) and len(first) == 4
    for name in first:
        assert len(first[name]) > 1000
        assert first[name] == second[name], f"{name} differs between the quiet and the loaded run"


# --- the line demo: rack (relay board, ptys), powered transfer, rig role, joint fit ------------------------

LINE_SEED = 13


def line_demo_once(tmp_path: Path, name: str, clock: Clock) -> dict[str, bytes]:
    """One run of ``station demo`` (the line; 2 units, 120 s in the rack) on ``clock``: its parameter JSONs,
    session CSVs without the run id line and the rack recordings stored in its database, by serial."""
    import gzip
    import io

    from rich.console import Console
    from sqlalchemy import select

    from station.sim.demo import run_line_demo
    from station.store.db import open_database
    from station.store.models import RackRecording

    db_url = f"sqlite:///{tmp_path / (name + '.sqlite')}"
    result = run_line_demo(2, 120.0, LINE_SEED, console=Console(file=io.StringIO(), width=140),
                           out_dir=tmp_path / name, db_url=db_url, clock=clock)
    files: dict[str, bytes] = {}
    for u in result.units:
        # a unit out of limits (FAIL) is a result too; a station fault or an abort is not
        assert u.outcome in (Outcome.PASS, Outcome.FAIL), (u.serial, u.outcome, u.message)
        assert u.session_path is not None and u.params_path is not None, (u.serial, u.outcome, u.message)
        lines = u.session_path.read_bytes().splitlines(keepends=True)
        files[f"{u.serial}.csv"] = b"".join(line for line in lines if not line.startswith(b"# run_id:"))
        files[f"{u.serial}.params.json"] = u.params_path.read_bytes()
    with open_database(db_url) as db, db.transaction() as s:
        for rec in s.scalars(select(RackRecording)).all():
            files[f"{rec.serial}.rack.csv"] = gzip.decompress(rec.data)
    return files


def test_line_demo_repeats_bit_for_bit_under_load(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The line demo on the virtual clock: the second run under two busy processes gives the same bytes."""
    monkeypatch.setenv("STATION_LOCK_DIR", str(tmp_path / "locks"))
    first = line_demo_once(tmp_path, "quiet", VirtualClock())
    with cpu_load():
        second = line_demo_once(tmp_path, "loaded", VirtualClock())
    assert sorted(first) == sorted(second) and len(first) == 6
    for name in first:
        assert len(first[name]) > 1000
        assert first[name] == second[name], f"{name} differs between the quiet and the loaded run"
