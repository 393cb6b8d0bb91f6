"""The production run across processes: `station sim` serves a simulated rig and units, `station run` calibrates.

Every PASS unit's image is written, read back and its corrected output verified on the rig; the image
recorded in the database, the API's download and `station eeprom image` are the same bytes. A second
run on a held rig is refused before it touches anything while the first PASSes, and SIGTERM aborts a run
with the rig brought to rest and the run recorded ABORTED with the signal's name.
"""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest
from fastapi.testclient import TestClient
from sqlalchemy import select

from station.eeprom.image import decode_image, image_sha256
from station.store.db import open_database
from station.store.models import EepromWrite, Run, RunUnit, Unit
from station.web.app import create_app

pytestmark = pytest.mark.integration

STATION = str(Path(sys.executable).with_name("station"))


@dataclass
class Sim:
    proc: subprocess.Popen[str]
    rig: str
    sensors: list[str]
    clock: str

    def run_args(self, tmp: Path, db: str, *extra: str) -> list[str]:
        args = [STATION, "run", "--rig", self.rig, "--clock", self.clock, "--db", db, "--out", str(tmp / "runs"),
                "--station", "line1", "--operator", "ci", "--yes"]
        for s in self.sensors:
            args += ["--sensor", s]
        return args + list(extra)


@pytest.fixture
def sim(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[Sim]:
    env = {**os.environ, "STATION_LOCK_DIR": str(tmp_path / "locks")}
    # the simulator serves its virtual clock and the runs join it: no machine load can make a sensor skip samples
    proc = subprocess.Popen([STATION, "sim", "--units", "2", "--seed", "3", "--clock", "virtual"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    rig, clock, sensors = "", "", []
    assert proc.stdout is not None
    deadline = time.monotonic() + 30
    while time.monotonic() < deadline:
        line = proc.stdout.readline()
        if line.startswith("rig: "):
            rig = line.split()[1]
        elif line.startswith("clock: "):
            clock = line.split()[1]
        elif m := re.match(r"sensor \d+: (\S+)", line):
            sensors.append(m.group(1))
        elif line.startswith("Ctrl-C") or not line:
            break
    assert rig and clock and len(sensors) == 2, proc.stderr.read() if proc.poll() is not None else "no URLs"
    monkeypatch.setenv("STATION_LOCK_DIR", str(tmp_path / "locks"))  # restored after the test
    try:
        yield Sim(proc, rig, sensors, clock)
    finally:
        proc.send_signal(signal.SIGTERM)
        try:
            proc.wait(15)
        except subprocess.TimeoutExpired:
            proc.kill()


def _wait_until_the_rig_is_held(proc: subprocess.Popen[str], locks: Path, timeout: float = 240.0) -> None:
    """Until some process holds a rig lock file in ``locks`` (a non-blocking flock on it fails): the run has begun.

    Waiting for the event rather than a fixed time keeps the test right on a loaded machine."""
    import fcntl

    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        assert proc.poll() is None, "the run ended before it held the rig"
        for path in locks.glob("rig-*.lock"):
            fd = os.open(path, os.O_RDWR)
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
                fcntl.flock(fd, fcntl.LOCK_UN)
            except BlockingIOError:
                return
            finally:
                os.close(fd)
        time.sleep(0.05)
    raise AssertionError(f"no rig lock held in {locks} after {timeout} s")


def _run(args: list[str], **kw: object) -> subprocess.CompletedProcess[str]:
    return subprocess.run(args, capture_output=True, text=True, timeout=300, env=os.environ.copy(), **kw)  # type: ignore[call-overload]


def test_every_pass_unit_is_written_read_back_verified_and_its_image_is_one(sim: Sim, tmp_path: Path) -> None:
    db_url = f"sqlite:///{tmp_path / 'line.sqlite'}"
    done = _run(sim.run_args(tmp_path, db_url))
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
    with open_database(db_url) as db, db.transaction() as s:
        rows = s.execute(select(Unit.serial, RunUnit.outcome, EepromWrite).join(RunUnit, RunUnit.unit_id == Unit.id)
                         .join(EepromWrite, EepromWrite.run_unit_id == RunUnit.id)).all()
        run = s.scalars(select(Run)).one()
        assert run.operator == "ci" and run.outcome == "PASS"
    assert len(rows) == 2
    client = TestClient(create_app(db_url))
    for serial, outcome, write in rows:
        assert outcome == "PASS"
        assert (write.written, write.read_back_ok, write.verified_on_rig, write.verified) == (True, True, True, True)
        assert write.image is not None and image_sha256(write.image) == write.image_sha256
        img = decode_image(write.image)
        assert img.serial == serial and img.station_id == "line1"
        assert img.calibration_time == run.started_at.replace(tzinfo=img.calibration_time.tzinfo)  # the run's start
        api = client.get(f"/api/units/{serial}/eeprom.bin")
        assert api.status_code == 200 and api.content == write.image
        out = tmp_path / f"{serial}.bin"
        cli = _run([STATION, "eeprom", "image", serial, "-o", str(out), "--db", db_url])
        assert cli.returncode == 0, cli.stderr
        assert out.read_bytes() == write.image


def test_a_second_run_on_a_held_rig_is_refused_and_the_first_passes(sim: Sim, tmp_path: Path) -> None:
    db_url = f"sqlite:///{tmp_path / 'line.sqlite'}"
    first = subprocess.Popen(sim.run_args(tmp_path, db_url), stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                             text=True, env=os.environ.copy())
    try:
        _wait_until_the_rig_is_held(first, tmp_path / "locks")
        second = _run(sim.run_args(tmp_path / "second", f"sqlite:///{tmp_path / 'other.sqlite'}"))
        assert second.returncode == 2
        assert "in use by station line1" in second.stderr and "since" in second.stderr
        assert "Traceback" not in second.stderr
        out, err = first.communicate(timeout=300)
    finally:
        if first.poll() is None:
            first.kill()
    assert first.returncode == 0, out[-3000:] + err[-3000:]
    with open_database(f"sqlite:///{tmp_path / 'other.sqlite'}") as other, other.transaction() as s:
        assert s.scalars(select(Run)).all() == []  # refused before anything was recorded or moved


def test_sigterm_aborts_with_the_rig_at_rest(sim: Sim, tmp_path: Path) -> None:
    db_url = f"sqlite:///{tmp_path / 'line.sqlite'}"
    proc = subprocess.Popen(sim.run_args(tmp_path, db_url), stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, env=os.environ.copy())
    try:
        _wait_until_the_rig_is_held(proc, tmp_path / "locks")
        time.sleep(1.0)  # mid-run: the rig is held, and the whole run takes tens of seconds of wall time
        proc.send_signal(signal.SIGTERM)
        out, err = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 130, out[-2000:] + err[-2000:]
    assert "Traceback" not in err
    with open_database(db_url) as db, db.transaction() as s:
        run = s.scalars(select(Run)).one()
        assert (run.outcome, run.rig_at_rest) == ("ABORTED", True)
        assert "SIGTERM" in run.message
        assert s.scalars(select(EepromWrite)).all() == []  # nothing written to an aborted unit


def test_a_run_started_through_the_api_provisions_and_serves_the_same_image(tmp_path: Path,
                                                                            monkeypatch: pytest.MonkeyPatch) -> None:
    """`POST /api/runs` on the station `station serve` builds: written, read back, verified, one image."""
    from dataclasses import replace

    from typer.testing import CliRunner

    from station.cli import app
    from station.compose import Station, StationConfig
    from station.kernel.limits import table1_limits
    from station.kernel.limits_file import load_limits
    from station.kernel.plan import RigPlan
    from station.kernel.virtual_clock import VirtualClock
    from station.sequence import Outcome
    from station.sim.firmware import install_firmware
    from station.sim.station_sim import SimStation
    from station.web.control import StationControl
    from station.web.state import LiveStatus

    plan = RigPlan(sample_rate_hz=50.0, rest_s=60.0, pose_hold_s=4.0,
                   rate_steps=(("x", 100.0), ("y", 100.0), ("z", 100.0)), rate_hold_s=3.0)
    db_url = f"sqlite:///{tmp_path / 'api.sqlite'}"
    monkeypatch.setenv("STATION_LOCK_DIR", str(tmp_path / "locks"))
    with SimStation(1, 1.0, 8, plan=plan, clock=VirtualClock()) as sim:  # discrete events: no load can hurry it
        for unit in sim.units:
            install_firmware(unit.sensor, sim.clock)
        config = StationConfig(sim.rig_url, tuple(sim.sensor_urls), station_id="api", db_url=db_url,
                               out_dir=None, plan=plan, provision=True, rig_options=sim.rig_client_options())
        station = Station(config, clock=sim.clock, limits=replace(load_limits(), product=table1_limits()))
        assert station.recorder is not None
        live = LiveStatus(station.recorder.db)
        station.subscribe(live)
        control = StationControl(station.run, on_error=live.set_fault)
        live.on_start, live.on_abort = control.start, control.abort
        client = TestClient(create_app(database=station.recorder.db, token="t0k", live=live))
        r = client.post("/api/runs", headers={"Authorization": "Bearer t0k"}, json={"operator": "eve"})
        assert r.status_code == 202, r.text
        result = control.wait(180)
        serial = sim.units[0].truth.serial
    assert result is not None and result.outcome == Outcome.PASS, result and result.units[0].message
    with open_database(db_url) as db, db.transaction() as s:
        write = s.scalars(select(EepromWrite)).one()
        assert s.scalars(select(Run)).one().operator == "eve"
    assert (write.written, write.read_back_ok, write.verified_on_rig) == (True, True, True)
    assert write.image is not None and decode_image(write.image).station_id == "api"
    assert client.get(f"/api/units/{serial}/eeprom.bin").content == write.image
    out = tmp_path / "cli.bin"
    done = CliRunner().invoke(app, ["eeprom", "image", serial, "-o", str(out), "--db", db_url])
    assert done.exit_code == 0, done.output
    assert out.read_bytes() == write.image
