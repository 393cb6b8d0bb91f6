"""A station process killed with SIGKILL mid-run leaves its run UNFINISHED; the next start recovers it.

The child process records a run's start, two steps with their gates, and even a unit's
PASS verdict, then sleeps; it is killed with ``kill -9``. The run must be UNFINISHED
(never PASS), and the next start (:func:`attach_recorder`, as ``station run`` calls it)
must mark it ERROR with a note, and its unit too.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
from pathlib import Path

from sqlalchemy import select

from station.compose import attach_recorder
from station.store import open_database, show_unit
from station.store.models import UNFINISHED, LimitCheck, Run, RunUnit, StepTiming
from station.store.recorder import RECOVERY_NOTE

CHILD = textwrap.dedent(
    """
    import sys, time
    from station.kernel.measurement import Measurement
    from station.sequence.records import Measured, Outcome, RunStarted, StepFinished, StepStarted, UnitFinished
    from station.compose import attach_recorder

    subscribers = []
    rec = attach_recorder(subscribers.append, sys.argv[1], station_name="kill-st", operator="victim")
    run = "killed-run"
    rec(RunStarted(run, "2026-11-21T12:00:00+00:00", 0.0, "kill-st", "rig", ("pty0",), ("rest", "pose +z", "x+")))
    for i, name in enumerate(("rest", "pose +z")):
        rec(StepStarted(run, i, name, "pose", 10.0 * i, 10.0))
        rec(Measured(run, 0, "SNK1", name, Measurement("gravity_ratio", 1.0, "1", 0.95, 1.05, True)))
        rec(StepFinished(run, i, name, 10.0 * i + 10.0, 10.0, True, 1))
    rec(StepStarted(run, 2, "x+", "rate", 20.0, 10.0))
    rec(UnitFinished(run, 0, "SNK1", Outcome.PASS, ""))
    print("READY", flush=True)
    time.sleep(120)
    """
)


def test_kill_9_leaves_unfinished_and_next_start_recovers(tmp_path: Path) -> None:
    url = f"sqlite:///{tmp_path / 'station.sqlite'}"
    child = subprocess.Popen([sys.executable, "-c", CHILD, url], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                             text=True, cwd=tmp_path)
    try:
        line = child.stdout.readline() if child.stdout else ""
        assert line.strip() == "READY", child.stderr.read() if child.stderr else ""
        os.kill(child.pid, signal.SIGKILL)
        assert child.wait(timeout=30) == -signal.SIGKILL
    finally:
        if child.poll() is None:
            child.kill()
            child.wait()
        for f in (child.stdout, child.stderr):
            if f is not None:
                f.close()

    with open_database(url) as db, db.transaction() as s:
        run = s.scalars(select(Run)).one()
        assert (run.run_uid, run.outcome, run.finished_at, run.pid) == ("killed-run", UNFINISHED, None, child.pid)
        steps = s.scalars(select(StepTiming).order_by(StepTiming.step_index)).all()
        assert [(st.name, st.ok) for st in steps] == [("rest", True), ("pose +z", True), ("x+", None)]
        assert len(s.scalars(select(LimitCheck)).all()) == 2
        assert s.scalars(select(RunUnit.outcome)).one() == "PASS"  # the unit's verdict, but in an unfinished run

    subscribers: list[object] = []
    recorder = attach_recorder(subscribers.append, url, station_name="kill-st")  # the next start
    try:
        with recorder.db.transaction() as s:
            run = s.scalars(select(Run)).one()
            assert run.outcome == "ERROR" and run.finished_at is not None
            assert RECOVERY_NOTE in run.message
            unit = s.scalars(select(RunUnit)).one()
            assert unit.outcome == "ERROR" and RECOVERY_NOTE in unit.message
        detail = show_unit(recorder.db, "SNK1")
        assert detail is not None and [r.outcome for r in detail.runs] == ["ERROR"]
        assert detail.attempts == 0  # a station fault is no failed attempt of the unit
    finally:
        recorder.db.close()


REAL_CHILD = textwrap.dedent(
    """
    import sys
    from station.rig import open_rig
    from station.sensor import open_sensor
    from station.sequence import SequenceOptions, SequenceRunner
    from station.kernel.plan import RigPlan
    from station.sim.station_sim import SimStation
    from station.compose import attach_recorder

    scale = 20.0  # slow enough that the parent kills it mid-run
    plan = RigPlan(sample_rate_hz=50.0, rest_s=20.0, pose_hold_s=20.0, rate_steps=(("z", 50.0),), rate_hold_s=20.0)
    with SimStation(1, scale, 5, plan=plan) as sim:
        rig = open_rig(sim.rig_url, sim.clock, **sim.rig_client_options())
        sensors = [open_sensor(u, sim.clock) for u in sim.sensor_urls]
        runner = SequenceRunner(rig, sensors, sim.clock, plan=plan, options=SequenceOptions().for_scale(scale),
                                station="kill-real", sensor_urls=sim.sensor_urls)
        attach_recorder(runner, sys.argv[1], station_name="kill-real")
        runner.run()
    """
)


def test_kill_9_during_a_simulated_sequence(tmp_path: Path) -> None:
    import time

    from station.store.db import make_engine

    url = f"sqlite:///{tmp_path / 'station.sqlite'}"
    child = subprocess.Popen([sys.executable, "-c", REAL_CHILD, url], stdout=subprocess.DEVNULL,
                             stderr=subprocess.PIPE, text=True, cwd=tmp_path)
    engine = make_engine(url)
    finished_steps = 0
    try:
        deadline = time.monotonic() + 60.0  # a guard against a hang, not a timing assertion
        while time.monotonic() < deadline and child.poll() is None:
            time.sleep(0.1)
            try:
                with engine.connect() as conn:
                    finished_steps = len(conn.execute(select(StepTiming.id).where(StepTiming.ok.is_not(None))).all())
            except Exception:  # schema not there yet
                continue
            if finished_steps >= 1:
                break
        assert child.poll() is None, child.stderr.read() if child.stderr else ""
        assert finished_steps >= 1
        os.kill(child.pid, signal.SIGKILL)
        assert child.wait(timeout=30) == -signal.SIGKILL
    finally:
        engine.dispose()
        if child.poll() is None:
            child.kill()
            child.wait()
        if child.stderr is not None:
            child.stderr.close()
    with open_database(url) as db, db.transaction() as s:
        run = s.scalars(select(Run)).one()
        assert run.outcome == UNFINISHED and run.station.name == "kill-real"
        assert [u.outcome for u in run.units] == [UNFINISHED]
    recorder = attach_recorder([].append, url, station_name="kill-real")
    try:
        with recorder.db.transaction() as s:
            run = s.scalars(select(Run)).one()
            assert run.outcome == "ERROR" and RECOVERY_NOTE in run.message
            assert [u.outcome for u in run.units] == ["ERROR"]
    finally:
        recorder.db.close()
