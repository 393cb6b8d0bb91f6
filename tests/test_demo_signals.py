"""``station demo`` keeps the promise of its help: SIGTERM and SIGHUP abort the run as Ctrl-C does.

The demo runs in its own process; once its prompts are confirmed and the rig's power-on rest is under way the
test sends the signal: the process exits 130 (ABORTED), the run is recorded ABORTED with the signal's name, the
rig at rest, and no unit is left UNFINISHED.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from sqlalchemy import select

from station.store.db import open_database
from station.store.models import Run, RunUnit

pytestmark = pytest.mark.integration

STATION = str(Path(sys.executable).with_name("station"))


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGHUP])
def test_demo_aborts_on_a_signal(tmp_path: Path, sig: signal.Signals) -> None:
    db_url = f"sqlite:///{tmp_path / 'demo.sqlite'}"
    env = {**os.environ, "STATION_LOCK_DIR": str(tmp_path / "locks")}
    proc = subprocess.Popen([STATION, "demo", "--rig-only", "--units", "2", "--scale", "30", "--seed", "2",
                             "--db", db_url, "--out", str(tmp_path / "out")],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    try:
        assert proc.stdout is not None
        seen = []
        for line in proc.stdout:  # the console is not a terminal: one line per prompt and answer
            seen.append(line)
            if "confirmed by the demo" in line and any("CLOSE-LID" in s for s in seen):
                break
        assert any("LOAD" in s and "nests 1-2" in s for s in seen), seen
        time.sleep(1.0)  # inside the 300 s power-on rest (10 s of wall time at x30)
        proc.send_signal(sig)
        out, err = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 130, "".join(seen) + out[-2000:] + err[-2000:]
    assert "Traceback" not in err
    with open_database(db_url) as db, db.transaction() as s:
        run = s.scalars(select(Run)).one()
        outcomes = s.scalars(select(RunUnit.outcome).where(RunUnit.run_id == run.id)).all()
    assert run.outcome == "ABORTED" and run.message == f"aborted by {sig.name}" and run.rig_at_rest
    assert outcomes == ["ABORTED", "ABORTED"]
