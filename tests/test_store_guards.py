"""Databases that cannot keep records, locked databases and full disks: refused in one line, exit 2.

The locked database is held by a real second connection (``BEGIN EXCLUSIVE``); the full disk is a small
tmpfs mounted for the test (root only: elsewhere that test is skipped with its reason).
"""

from __future__ import annotations

import contextlib
import os
import sqlite3
import subprocess
import uuid
from collections.abc import Iterator
from pathlib import Path

import pytest
from typer.testing import CliRunner

from station.cli import app
from station.store.db import open_database
from station.store.opening import DatabaseFull, DatabaseLocked, DatabaseRefused, StoreError
from station.store.recorder import record_disposition, record_eeprom_write


@pytest.mark.parametrize("url", ["sqlite:///:memory:", "sqlite://"])
def test_a_database_that_keeps_nothing_is_refused_for_writing(url: str) -> None:
    with pytest.raises(DatabaseRefused, match="keeps no records"):
        open_database(url)
    with open_database(url, for_writing=False) as db:  # reading one is harmless (and finds nothing)
        assert db.url == url


def test_station_run_refuses_an_in_memory_database(tmp_path: Path) -> None:
    res = CliRunner().invoke(app, ["run", "--rig", "modbus-tcp://127.0.0.1:1", "--sensor", "serial:///dev/null",
                                   "--db", "sqlite:///:memory:"])
    assert res.exit_code == 2, res.output
    assert "keeps no records" in res.output and "Traceback" not in res.output


@pytest.fixture
def locked(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[str]:
    url = f"sqlite:///{tmp_path / 's.sqlite'}"
    with open_database(url) as db:
        record_eeprom_write(db, "U1", "0" * 64, attempts=1, read_back_ok=True)
    holder = sqlite3.connect(tmp_path / "s.sqlite", isolation_level=None)
    holder.execute("BEGIN EXCLUSIVE")
    monkeypatch.setenv("STATION_DB_LOCK_TIMEOUT_S", "0.3")
    try:
        yield url
    finally:
        holder.execute("ROLLBACK")
        holder.close()


def test_a_locked_database_is_waited_for_then_refused(locked: str) -> None:
    with open_database(locked) as db, pytest.raises(DatabaseLocked, match=r"locked by another process: waited 0.3 s"):
        record_disposition(db, "U1", "retest", operator="ann", note="why")


def test_a_locked_database_is_one_line_exit_2_in_the_cli(locked: str) -> None:
    res = CliRunner().invoke(app, ["units", "disposition", "U1", "retest", "--operator", "ann", "--reason", "x",
                                   "--db", locked])
    assert res.exit_code == 2, res.output
    lines = [ln for ln in res.output.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("error: the station database") and "waited 0.3 s" in lines[0]


@pytest.fixture
def full_disk(tmp_path: Path) -> Iterator[Path]:
    mnt = tmp_path / f"full-{uuid.uuid4().hex[:6]}"
    mnt.mkdir()
    if os.geteuid() != 0 or subprocess.run(["mount", "-t", "tmpfs", "-o", "size=2m", "tmpfs", str(mnt)],
                                          capture_output=True).returncode != 0:
        pytest.skip("a full disk needs a small tmpfs: mounting one needs root")
    try:
        yield mnt
    finally:
        subprocess.run(["umount", "-l", str(mnt)], check=False)


def test_a_full_disk_is_named_as_such(full_disk: Path) -> None:
    url = f"sqlite:///{full_disk / 's.sqlite'}"
    with open_database(url) as db:
        filler = full_disk / "filler"
        with contextlib.suppress(OSError), filler.open("wb") as f:
            while True:
                f.write(b"\0" * 4096)
                f.flush()
        with pytest.raises(DatabaseFull, match="is full"):
            for k in range(200):
                record_eeprom_write(db, f"U{k}", "0" * 64, attempts=1, read_back_ok=True, image=b"\1" * 4096)
    try:  # the next command: the file is fine, only the disk is full; never "corrupt"
        open_database(url).close()
    except StoreError as exc:
        assert isinstance(exc, DatabaseFull) and "corrupt" not in str(exc)
