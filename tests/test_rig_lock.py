"""One run per rig: the lock file on this host and the lock row for stations on several hosts."""

from __future__ import annotations

import os
import subprocess
import sys
from datetime import UTC, datetime
from pathlib import Path

import pytest
from sqlalchemy import select

from station.rig_lock import RigBusy, RigLock, rig_key
from station.store.db import open_database
from station.store.models import RigLock as LockRow

URL = "modbus-tcp://127.0.0.1:5020?unit=1"


def test_the_url_names_the_rig_not_its_options() -> None:
    assert rig_key(URL) == rig_key("MODBUS-TCP://127.0.0.1:5020?timeout=2") == "modbus-tcp://127.0.0.1:5020"
    assert rig_key("modbus-rtu:///dev/ttyUSB0?baud=19200") == "modbus-rtu:///dev/ttyUSB0"
    assert rig_key(URL) != rig_key("modbus-tcp://127.0.0.1:5021")


def test_a_second_holder_in_another_process_is_refused_with_who_and_since(tmp_path: Path) -> None:
    with RigLock(URL, "line1", directory=tmp_path):
        code = (f"import sys; sys.path.insert(0, {str(Path(__file__).resolve().parents[1])!r})\n"
                "from pathlib import Path\nfrom station.rig_lock import RigBusy, RigLock\n"
                f"try:\n    RigLock({URL!r}, 'line2', directory=Path({str(tmp_path)!r})).acquire()\n"
                "except RigBusy as exc:\n    print(exc)\n    sys.exit(3)\n")
        other = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
        assert other.returncode == 3, other.stderr
        assert f"in use by station line1 (host {os.uname().nodename}, pid {os.getpid()}) since" in other.stdout
    # released: the other process may take it now
    again = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert again.returncode == 0, again.stdout + again.stderr


def test_the_database_row_holds_the_rig_across_hosts(tmp_path: Path) -> None:
    url = f"sqlite:///{tmp_path / 'line.sqlite'}"
    with open_database(url) as db:
        with RigLock(URL, "line1", db, directory=tmp_path / "a"):
            with db.transaction() as s:
                row = s.scalars(select(LockRow)).one()
                assert (row.rig_url, row.station, row.pid) == (rig_key(URL), "line1", os.getpid())
            # another host (its own lock directory) sees the row and is refused
            with pytest.raises(RigBusy, match="in use by station line1"):
                RigLock(URL, "line2", db, directory=tmp_path / "b").acquire()
        with db.transaction() as s:
            assert s.scalars(select(LockRow)).all() == []  # released


def test_a_row_left_by_a_dead_process_on_this_host_is_taken_over(tmp_path: Path) -> None:
    url = f"sqlite:///{tmp_path / 'line.sqlite'}"
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True)
    with open_database(url) as db:
        with db.transaction() as s:
            s.add(LockRow(rig_url=rig_key(URL), station="crashed", host=os.uname().nodename,
                          pid=int(dead.stdout), since=datetime.now(UTC)))
        with RigLock(URL, "line1", db, directory=tmp_path), db.transaction() as s:
            assert s.scalars(select(LockRow.station)).one() == "line1"
        with db.transaction() as s:  # a live holder on another host is not taken over
            s.add(LockRow(rig_url=rig_key(URL), station="remote", host="other-host", pid=1, since=datetime.now(UTC)))
        with pytest.raises(RigBusy, match="station remote \\(host other-host"):
            RigLock(URL, "line1", db, directory=tmp_path).acquire()
