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
