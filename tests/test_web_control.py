"""Starting and aborting runs through the API on a simulated station (real Modbus rig, sensor on a pty).

The station runs on the virtual clock: its watchdog and heartbeat live in simulated time, so host load cannot
trip the rig's watchdog (as 0.3 wall s at 200x once did), and the run is held at one virtual instant while
the test looks at the live status and aborts it."""

from __future__ import annotations

import threading
import time
from dataclasses import replace
from pathlib import Path

from fastapi.testclient import TestClient

from station.compose import Station, StationConfig
from station.kernel.limits import table1_limits
from station.kernel.limits_file import load_limits
from station.kernel.plan import RigPlan
from station.kernel.virtual_clock import VirtualClock
from station.sequence import Outcome, Record, RigReading, SequenceOptions
from station.sim.station_sim import SimStation
from station.web.app import create_app
from station.web.control import StationControl
from station.web.state import LiveStatus

PLAN = RigPlan(sample_rate_hz=50.0, rest_s=60.0, pose_hold_s=4.0,
               rate_steps=(("x", 100.0), ("y", 100.0), ("z", 100.0)), rate_hold_s=3.0)
AUTH = {"Authorization": "Bearer s3cret"}


class HoldAtFirstReading:
    """A subscriber that, once armed, holds the run thread at the first rig reading (the rig is held then)
    until released; time stands still meanwhile (the run owns the virtual clock)."""

    def __init__(self) -> None:
        self.armed = False
        self.reached = threading.Event()
        self.release = threading.Event()

    def __call__(self, record: Record) -> None:
        if self.armed and isinstance(record, RigReading) and not self.reached.is_set():
            self.reached.set()
            self.release.wait(60.0)


def test_start_conflict_abort_through_the_api(tmp_path: Path) -> None:
    with SimStation(1, 1.0, 8, plan=PLAN, clock=VirtualClock()) as sim:
        config = StationConfig(sim.rig_url, tuple(sim.sensor_urls), station_id="web",
                               db_url=f"sqlite:///{tmp_path / 'st.sqlite'}", out_dir=None, plan=PLAN,
                               rig_options=sim.rig_client_options())
        station = Station(config, clock=sim.clock, limits=replace(load_limits(), product=table1_limits()),
                          options=SequenceOptions())
        assert station.recorder is not None
        live = LiveStatus(station.recorder.db)
        station.subscribe(live)
        hold = HoldAtFirstReading()
        station.subscribe(hold)  # after the live status: it has the reading when the run is held
        control = StationControl(station.run, on_error=live.set_fault)
        live.on_start, live.on_abort = control.start, control.abort
        client = TestClient(create_app(database=station.recorder.db, token="s3cret", live=live))

        assert client.post("/api/runs").status_code == 401
        r = client.post("/api/runs", headers=AUTH)
        assert r.status_code == 202, r.text
        first = r.json()["run_id"]
        assert client.post("/api/runs", headers=AUTH).status_code == 409  # one run at a time
        assert client.post(f"/api/runs/{first}/abort").status_code == 401
        result = control.wait(120)
        assert result is not None and result.run_id == first and result.outcome == Outcome.PASS
        assert client.post(f"/api/runs/{first}/abort", headers=AUTH).status_code == 404  # not running any more
        # the rig's readings reached the live status (and the page's JSON), the store ignores them
        readings = [r for r in result.records if isinstance(r, RigReading)]
        assert readings and all(abs(r.roll_deg) <= 360 and "REMOTE" in r.status for r in readings)
        assert client.get("/api/status").json()["rig_state"] is None  # idle: the rig is not held, nothing shown

        hold.armed = True
        second = client.post("/api/runs", headers=AUTH).json()["run_id"]
        assert hold.reached.wait(60.0)
        rig_state, deadline = None, time.monotonic() + 30.0
        while rig_state is None and time.monotonic() < deadline:  # while the run holds the rig: its readings
            status = client.get("/api/status").json()
            rig_state = status["rig_state"] if status["state"] == "running" else None
            time.sleep(0.05)
        assert rig_state is not None and set(rig_state) >= {"roll_deg", "pitch_deg", "yaw_deg", "rate_dps", "status"}
        assert client.post(f"/api/runs/{second}/abort", headers=AUTH).status_code == 202
        hold.release.set()
        result = control.wait(120)
        assert result is not None and result.run_id == second and result.outcome == Outcome.ABORTED
        assert result.rig_at_rest

        runs = {r["run_id"]: r for r in client.get("/api/runs").json()}
        assert runs[first]["outcome"] == "PASS" and runs[second]["outcome"] == "ABORTED"
