"""Starting and aborting runs through the API on a simulated station (real Modbus rig, sensor on a pty)."""

from __future__ import annotations

import time
from dataclasses import replace
from pathlib import Path

from fastapi.testclient import TestClient

from station.compose import Station, StationConfig
from station.kernel.limits import table1_limits
from station.kernel.limits_file import load_limits
from station.kernel.plan import RigPlan
from station.sequence import Outcome, RigReading, SequenceOptions
from station.sim.station_sim import SimStation
from station.web.app import create_app
from station.web.control import StationControl
from station.web.state import LiveStatus

SCALE = 60.0  # the rig watchdog is at most 60 rig s: 1 wall s at 60x (0.3 s at 200x tripped under load)
PLAN = RigPlan(sample_rate_hz=50.0, rest_s=60.0, pose_hold_s=4.0,
               rate_steps=(("x", 100.0), ("y", 100.0), ("z", 100.0)), rate_hold_s=3.0)
AUTH = {"Authorization": "Bearer s3cret"}


def test_start_conflict_abort_through_the_api(tmp_path: Path) -> None:
    with SimStation(1, SCALE, 8, plan=PLAN) as sim:
        config = StationConfig(sim.rig_url, tuple(sim.sensor_urls), station_id="web",
                               db_url=f"sqlite:///{tmp_path / 'st.sqlite'}", out_dir=None, plan=PLAN,
                               rig_options=sim.rig_client_options())
        station = Station(config, clock=sim.clock, limits=replace(load_limits(), product=table1_limits()),
                          options=SequenceOptions())
        assert station.recorder is not None
        live = LiveStatus(station.recorder.db)
        station.subscribe(live)
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

        second = client.post("/api/runs", headers=AUTH).json()["run_id"]
        rig_state, deadline = None, time.monotonic() + 30.0
        while rig_state is None and time.monotonic() < deadline:  # while the run holds the rig: its readings
            status = client.get("/api/status").json()
            rig_state = status["rig_state"] if status["state"] == "running" else None
            time.sleep(0.05)
        assert rig_state is not None and set(rig_state) >= {"roll_deg", "pitch_deg", "yaw_deg", "rate_dps", "status"}
        assert client.post(f"/api/runs/{second}/abort", headers=AUTH).status_code == 202
        result = control.wait(120)
        assert result is not None and result.run_id == second and result.outcome == Outcome.ABORTED
        assert result.rig_at_rest

        runs = {r["run_id"]: r for r in client.get("/api/runs").json()}
        assert runs[first]["outcome"] == "PASS" and runs[second]["outcome"] == "ABORTED"
