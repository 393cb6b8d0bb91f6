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
from collections.abc import Callable
from pathlib import Path

import pytest
from sqlalchemy import select

from station.store.db import open_database
from station.store.models import Run, RunUnit

pytestmark = pytest.mark.integration

STATION = str(Path(sys.executable).with_name("station"))


def signalled_demo(tmp_path: Path, args: list[str], ready: Callable[[list[str]], bool], sig: signal.Signals,
                   delay_s: float) -> tuple[int, list[str], str, str]:
    """Run ``station demo ARGS`` (database and output in ``tmp_path``), send ``sig`` ``delay_s`` after the line
    for which ``ready(lines so far)`` holds; return the exit code, the lines read until then, the rest of stdout
    and stderr."""
    db_url = f"sqlite:///{tmp_path / 'demo.sqlite'}"
    env = {**os.environ, "STATION_LOCK_DIR": str(tmp_path / "locks")}
    proc = subprocess.Popen([STATION, "demo", *args, "--db", db_url, "--out", str(tmp_path / "out")],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    try:
        assert proc.stdout is not None
        seen: list[str] = []
        for line in proc.stdout:  # the console is not a terminal: one line per prompt and answer
            seen.append(line)
            if ready(seen):
                break
        time.sleep(delay_s)
        proc.send_signal(sig)
        out, err = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
    return proc.returncode, seen, out, err


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGHUP])
def test_demo_aborts_on_a_signal(tmp_path: Path, sig: signal.Signals) -> None:
    # inside the 300 s power-on rest (10 s of wall time at x30)
    code, seen, out, err = signalled_demo(
        tmp_path, ["--rig-only", "--units", "2", "--scale", "30", "--seed", "2"],
        lambda seen: "confirmed by the demo" in seen[-1] and any("CLOSE-LID" in s for s in seen), sig, 1.0)
    assert any("LOAD" in s and "nests 1-2" in s for s in seen), seen
    assert code == 130, "".join(seen) + out[-2000:] + err[-2000:]
    assert "Traceback" not in err
    with open_database(f"sqlite:///{tmp_path / 'demo.sqlite'}") as db, db.transaction() as s:
        run = s.scalars(select(Run)).one()
        outcomes = s.scalars(select(RunUnit.outcome).where(RunUnit.run_id == run.id)).all()
    assert run.outcome == "ABORTED" and run.message == f"aborted by {sig.name}" and run.rig_at_rest
    assert outcomes == ["ABORTED", "ABORTED"]


def _joined(lines: list[str]) -> str:
    """The console's lines as one text (it wraps at 80 columns when not a terminal)."""
    return " ".join(line.strip() for line in lines)


def test_line_demo_aborts_during_the_soak(tmp_path: Path) -> None:
    """The line demo on the virtual clock, SIGTERM while the rack's loggers wait on the clock: the process exits
    130 (it must not join the loggers while it holds virtual time, which would hang it for good)."""
    # the soak starts after this line: 3600 s of rack time, many seconds of wall time
    code, seen, out, err = signalled_demo(
        tmp_path, ["--units", "2", "--rack-s", "3600", "--seed", "2"], lambda seen: "from power-on" in _joined(seen),
        signal.SIGTERM, 0.5)
    assert "virtual clock" in _joined(seen), seen
    assert code == 130, "".join(seen) + out[-2000:] + err[-2000:]
    assert "Traceback" not in err
    assert "aborted before the run started" in err
