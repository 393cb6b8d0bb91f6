"""One run per rig: an advisory lock that the rig URL names, on this host and in the station database.

:class:`RigLock` is held for a whole run. On this host it is an exclusive ``flock`` on a lock file named
after the rig URL (scheme, host, port or device; query parameters do not name another rig), in
``$STATION_LOCK_DIR`` or the system's temporary directory; the kernel drops it when the process dies,
even by ``kill -9``. For stations on several hosts sharing one database it is also a row of the
``rig_locks`` table (unique per rig URL), deleted at release; a row left by a process that is gone from
this host is taken over. A second run on a held rig is refused before it touches anything, with who
holds the rig and since when (:class:`RigBusy`).
"""

from __future__ import annotations

import contextlib
import fcntl
import hashlib
import json
import os
import socket
import tempfile
from datetime import UTC, datetime
from pathlib import Path
from types import TracebackType
from typing import TYPE_CHECKING

from station.kernel.errors import StationBusy
from station.kernel.urls import split_url

if TYPE_CHECKING:
    from station.store.db import Database


class RigBusy(StationBusy):
    """The rig is held by another run (who and since when in the message)."""


def rig_key(url: str) -> str:
    """The rig a URL names: scheme, host and port or device, without query parameters (lower-case host)."""
    parts = split_url(url, "rig")
    netloc = (parts.hostname or "") + (f":{parts.port}" if parts.port else "")
    return f"{parts.scheme.lower()}://{netloc}{parts.path}"


def lock_dir() -> Path:
    return Path(os.environ.get("STATION_LOCK_DIR") or Path(tempfile.gettempdir()) / "station-locks")


class RigLock:
    """Hold ``rig_url`` for one run (context manager).

    Args:
        rig_url: the rig's URL.
        station: the station id, recorded as the holder.
        db: the station database for the lock row (None: this host only).
        directory: where lock files go (default :func:`lock_dir`).
    """

    def __init__(self, rig_url: str, station: str, db: Database | None = None, directory: Path | None = None) -> None:
        self.key = rig_key(rig_url)
        self.station = station
        self.db = db
        self.path = (directory or lock_dir()) / f"rig-{hashlib.sha256(self.key.encode()).hexdigest()[:20]}.lock"
        self.host = socket.gethostname()
        self.pid = os.getpid()
        self._fd: int | None = None
        self._row = False

    def _holder(self) -> str:
        try:
            info = json.loads(self.path.read_text() or "{}")
        except (OSError, ValueError):
            info = {}
        return (f"station {info.get('station', '?')} (host {info.get('host', '?')}, pid {info.get('pid', '?')}) "
                f"since {info.get('since', '?')}")

    def acquire(self) -> RigLock:
        """Take the lock or raise :class:`RigBusy` naming the holder; nothing else is touched."""
        self.path.parent.mkdir(parents=True, exist_ok=True)
        fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o666)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            os.close(fd)
            raise RigBusy(f"rig {self.key} is in use by {self._holder()}: one run per rig") from None
        since = datetime.now(UTC)
        os.ftruncate(fd, 0)
        os.write(fd, json.dumps({"rig": self.key, "station": self.station, "host": self.host, "pid": self.pid,
                                 "since": since.isoformat()}).encode())
        self._fd = fd
        try:
            if self.db is not None:
                self._take_row(since)
        except BaseException:
            self.release()
            raise
        return self

    def _take_row(self, since: datetime) -> None:
        from sqlalchemy import delete, select
        from sqlalchemy.exc import IntegrityError

        from station.store.models import RigLock as Row
        from station.store.recorder import process_alive

        assert self.db is not None
        for _ in range(2):
            try:
                with self.db.transaction() as s:
                    s.add(Row(rig_url=self.key, station=self.station, host=self.host, pid=self.pid, since=since))
                self._row = True
                return
            except IntegrityError:
                with self.db.transaction() as s:
                    row = s.scalar(select(Row).where(Row.rig_url == self.key))
                    if row is None:
                        continue
                    if row.host == self.host and not process_alive(row.pid):  # left by a dead process
                        s.execute(delete(Row).where(Row.id == row.id))
                        continue
                    raise RigBusy(f"rig {self.key} is in use by station {row.station} (host {row.host}, pid {row.pid}) "
                                  f"since {row.since.isoformat()}: one run per rig") from None
        raise RigBusy(f"rig {self.key}: could not take its lock row")

    def release(self) -> None:
        """Give the rig back (the row, then the file lock); safe to call twice."""
        if self._row and self.db is not None:
            from sqlalchemy import delete

            from station.store.models import RigLock as Row

            with contextlib.suppress(Exception), self.db.transaction() as s:
                s.execute(delete(Row).where(Row.rig_url == self.key, Row.host == self.host, Row.pid == self.pid))
            self._row = False
        if self._fd is not None:
            with contextlib.suppress(OSError):
                os.ftruncate(self._fd, 0)
                fcntl.flock(self._fd, fcntl.LOCK_UN)
            os.close(self._fd)
            self._fd = None

    def __enter__(self) -> RigLock:
        return self.acquire()

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.release()


__all__ = ["RigBusy", "RigLock", "lock_dir", "rig_key"]
