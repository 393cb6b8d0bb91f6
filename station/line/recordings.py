"""The rack's recordings in the line's database: written by the rack role, found by serial by the rig role.

A recording is the unit's rest as a session CSV (:mod:`station.session.csv_v1`), gzip-compressed
(``codec = 'csv-v1+gzip'``, mtime 0: the same recording gives the same bytes) into the
``rack_recordings`` table, with the SHA-256 and size of the uncompressed CSV as the run's own session
recordings have. Reading checks the codec and the SHA-256: a recording that does not match is
refused (:class:`RackRecordingError`), never fitted.
"""

from __future__ import annotations

import gzip
import hashlib
import threading
from collections.abc import Callable
from dataclasses import dataclass
from datetime import UTC, datetime
from typing import Protocol

from sqlalchemy import select
from sqlalchemy.orm import Session as DbSession

from station.kernel.errors import StationError
from station.session.csv_v1 import format_session, parse_session
from station.session.model import Session
from station.store.models import RackRecording

#: the only codec this version writes and reads
CODEC = "csv-v1+gzip"


class RackRecordingError(StationError):
    """A rack recording that is missing, of an unknown codec, or whose bytes do not match their SHA-256."""


@dataclass(frozen=True, eq=False)
class StoredRackRecording:
    """A rack recording read back: the session, its SHA-256 and row id."""

    id: int
    session: Session
    sha256: str
    slot: int
    station: str


def _int_or_none(text: str | None) -> int | None:
    try:
        return int(str(text)) if text not in (None, "") else None
    except ValueError:
        return None


def _float_or_none(text: str | None) -> float | None:
    try:
        return float(str(text)) if text not in (None, "") else None
    except ValueError:
        return None


def save_rack_recording(db: DbSession, session: Session, *, station: str, slot: int) -> str:
    """Add ``session`` (a rack rest) to the database session ``db``; returns the CSV's SHA-256 (the caller commits)."""
    csv = format_session(session).encode("utf-8")
    sha = hashlib.sha256(csv).hexdigest()
    db.add(RackRecording(
        serial=session.serial, station=station, slot=int(slot),
        boot_count=_int_or_none(session.metadata.get("boot_count")),
        wall_clock_at_start_s=_float_or_none(session.metadata.get("wall_clock_at_start_s")),
        duration_s=session.duration_s, codec=CODEC, sha256=sha, size_bytes=len(csv),
        data=gzip.compress(csv, mtime=0), created_at=datetime.now(UTC),
    ))
    return sha


def latest_rack_recording(db: DbSession, serial: str) -> StoredRackRecording | None:
    """The newest rack recording of ``serial`` (None if the unit never soaked), checked against its SHA-256."""
    row = db.scalars(select(RackRecording).where(RackRecording.serial == serial)
                     .order_by(RackRecording.id.desc()).limit(1)).first()
    if row is None:
        return None
    if row.codec != CODEC:
        raise RackRecordingError(f"rack recording {row.id} of {serial!r}: unknown codec {row.codec!r} "
                                 f"(this version reads {CODEC!r})")
    try:
        csv = gzip.decompress(row.data)
    except (OSError, EOFError) as exc:
        raise RackRecordingError(f"rack recording {row.id} of {serial!r}: not gzip data ({exc})") from exc
    if hashlib.sha256(csv).hexdigest() != row.sha256 or len(csv) != row.size_bytes:
        raise RackRecordingError(f"rack recording {row.id} of {serial!r}: its bytes do not match the SHA-256 stored "
                                 "with it")
    return StoredRackRecording(row.id, parse_session(csv), row.sha256, row.slot, row.station)


class RackArchive(Protocol):
    """Where the rack puts its recordings and the rig role finds them by serial."""

    def save(self, session: Session, *, station: str, slot: int) -> str: ...

    def latest(self, serial: str) -> StoredRackRecording | None: ...


class DatabaseArchive:
    """The line's database (``rack_recordings``): every station of the line reads what the rack wrote."""

    def __init__(self, sessions: Callable[[], DbSession]) -> None:
        self._sessions = sessions

    def save(self, session: Session, *, station: str, slot: int) -> str:
        with self._sessions() as db:
            sha = save_rack_recording(db, session, station=station, slot=slot)
            db.commit()
        return sha

    def latest(self, serial: str) -> StoredRackRecording | None:
        with self._sessions() as db:
            return latest_rack_recording(db, serial)


class MemoryArchive:
    """Recordings in this process only (a simulation, a test): the same bytes and checks as the database's."""

    def __init__(self) -> None:
        self._rows: dict[str, list[tuple[bytes, str, int, str]]] = {}
        self._lock = threading.Lock()

    def save(self, session: Session, *, station: str, slot: int) -> str:
        csv = format_session(session).encode("utf-8")
        sha = hashlib.sha256(csv).hexdigest()
        with self._lock:
            self._rows.setdefault(session.serial, []).append((gzip.compress(csv, mtime=0), sha, slot, station))
        return sha

    def latest(self, serial: str) -> StoredRackRecording | None:
        with self._lock:
            rows = self._rows.get(serial)
            if not rows:
                return None
            data, sha, slot, station = rows[-1]
            n = len(rows)
        csv = gzip.decompress(data)
        if hashlib.sha256(csv).hexdigest() != sha:
            raise RackRecordingError(f"rack recording of {serial!r}: its bytes do not match their SHA-256")
        return StoredRackRecording(n, parse_session(csv), sha, slot, station)


__all__ = ["CODEC", "DatabaseArchive", "MemoryArchive", "RackArchive", "RackRecordingError", "StoredRackRecording",
           "latest_rack_recording", "save_rack_recording"]
