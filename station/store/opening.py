"""Checks before the station database is opened or migrated: nothing is written to a database
this program must not touch.

* the URL's scheme is one this station speaks (``sqlite``, ``postgresql``), else it is named;
* a SQLite path that is a directory, or a file that cannot be written, is refused;
* a SQLite file that is not a database or fails SQLite's integrity check is refused (corrupt);
* a database with tables but no Alembic version is foreign (not made by the station);
* a database whose schema revision this program does not know is newer than this program:
  refused with its revision and the newest revision this program knows.
"""

from __future__ import annotations

import os
import sqlite3
from pathlib import Path

from sqlalchemy import Engine, inspect, text
from sqlalchemy.engine import make_url
from sqlalchemy.exc import ArgumentError

from station.kernel.errors import StationError, path_problem

#: URL schemes (dialect names) the station's store works with
SUPPORTED_SCHEMES = ("sqlite", "postgresql")


class StoreError(StationError):
    """The station database could not be opened, migrated or written."""


class DatabaseRefused(StoreError):
    """A database the station does not open: unsupported, corrupt, foreign, newer, or one that keeps nothing."""


class DatabaseLocked(StoreError):
    """Another process held the database locked for longer than the station waits (:data:`LOCK_TIMEOUT_S`)."""


class DatabaseFull(StoreError):
    """The disk (or the PostgreSQL server's) holding the database is full: nothing more can be recorded."""


#: How long a command waits for a database another process holds locked (s); ``$STATION_DB_LOCK_TIMEOUT_S``.
LOCK_TIMEOUT_S = 10.0


def lock_timeout_s() -> float:
    """The stated wait for a locked database (s): ``$STATION_DB_LOCK_TIMEOUT_S`` or :data:`LOCK_TIMEOUT_S`."""
    text = os.environ.get("STATION_DB_LOCK_TIMEOUT_S", "")
    try:
        value = float(text) if text else LOCK_TIMEOUT_S
    except ValueError:
        return LOCK_TIMEOUT_S
    return value if 0 <= value <= 3600 else LOCK_TIMEOUT_S


def check_keeps_records(url: str, shown: str) -> None:
    """Refuse, for a command that writes, a database that loses its records when the command ends: SQLite's
    in-memory database (``:memory:``, ``mode=memory``) and its private temporary file (an empty file name)."""
    try:
        parsed = make_url(url)
    except (ArgumentError, ValueError):
        return  # check_url names what is wrong with it
    if parsed.get_backend_name() != "sqlite":
        return
    name = parsed.database or ""
    memory = name == ":memory:" or (name.startswith("file:") and ("mode=memory" in name or ":memory:" in name))
    memory = memory or parsed.query.get("mode") == "memory"
    if memory or name == "":
        what = "an in-memory database" if memory else "a temporary database SQLite deletes when the command ends"
        raise DatabaseRefused(f"{shown}: {what} keeps no records; a command that writes needs a database that "
                              "outlives it (sqlite:///station.sqlite or postgresql+psycopg://USER@HOST/DB)")


def disk_free_bytes(url: str) -> int | None:
    """Free bytes on the file system of a SQLite database file (None: not a SQLite file, or unknown)."""
    try:
        parsed = make_url(url)
    except (ArgumentError, ValueError):
        return None
    name = parsed.database or ""
    if parsed.get_backend_name() != "sqlite" or name in ("", ":memory:") or name.startswith("file:"):
        return None
    parent = Path(name).parent
    try:
        st = os.statvfs(parent if str(parent) else ".")
    except (OSError, ValueError):
        return None
    return st.f_bavail * st.f_frsize


def classify_failure(exc: BaseException, url: str, shown: str) -> StoreError | None:
    """A locked database or a full disk as what it is (None: neither)."""
    text = str(getattr(exc, "orig", None) or exc).lower()
    if "database is locked" in text or "database table is locked" in text or "lock timeout" in text \
            or "canceling statement due to lock timeout" in text:
        return DatabaseLocked(f"the station database {shown} is locked by another process: waited "
                              f"{lock_timeout_s():g} s (STATION_DB_LOCK_TIMEOUT_S); nothing was recorded, try again "
                              "when it is released")
    free = disk_free_bytes(url)
    full_text = "database or disk is full" in text or "no space left" in text or "could not extend file" in text \
        or "disk full" in text
    if full_text or ("disk i/o error" in text and free is not None and free < 1 << 20):
        room = f" ({free} bytes free)" if free is not None else ""
        return DatabaseFull(f"the disk holding the station database {shown} is full{room}: nothing more can be "
                            "recorded; free space and run again")
    return None


def check_url(url: str, shown: str) -> None:
    """Refuse a URL that does not parse or whose scheme the station does not support."""
    try:
        parsed = make_url(url)
    except (ArgumentError, ValueError) as exc:
        raise DatabaseRefused(f"{shown}: not a database URL (sqlite:///FILE or postgresql+psycopg://...)") from exc
    if parsed.get_backend_name() not in SUPPORTED_SCHEMES:
        raise DatabaseRefused(
            f"{shown}: URL scheme {parsed.drivername!r} is not supported; the station stores in "
            "sqlite:///FILE or postgresql+psycopg://USER@HOST/DB"
        )
    if parsed.get_backend_name() == "sqlite":
        _check_sqlite_file(parsed.database or "", shown)


def _check_sqlite_file(database: str, shown: str) -> None:
    if database in ("", ":memory:") or database.startswith("file:"):
        return
    path = Path(database)
    try:
        path.exists()
    except (OSError, ValueError) as exc:
        raise DatabaseRefused(f"{shown}: {path_problem(exc, database)}") from None
    if path.is_dir():
        raise DatabaseRefused(f"{shown}: {path} is a directory, not a database file")
    parent = path.parent if str(path.parent) else Path(".")
    if not path.exists():
        if not parent.is_dir():
            raise DatabaseRefused(f"{shown}: directory {parent} does not exist")
        return
    if not os.access(path, os.R_OK | os.W_OK) or not os.access(parent, os.W_OK | os.X_OK):
        raise DatabaseRefused(f"{shown}: {path} (or its directory) is not writable; the station writes its records")
    with open(path, "rb") as handle:
        head = handle.read(16)
    if path.stat().st_size and head != b"SQLite format 3\x00":
        raise DatabaseRefused(f"{shown}: {path} is not a SQLite database")
    try:
        conn = sqlite3.connect(f"file:{path}?mode=ro", uri=True)
        try:
            rows = conn.execute("PRAGMA quick_check(1)").fetchall()
        finally:
            conn.close()
    except sqlite3.DatabaseError as exc:
        known = classify_failure(exc, f"sqlite:///{path}", shown)
        if known is not None:
            raise known from exc
        if "disk i/o error" in str(exc).lower() or "unable to open" in str(exc).lower():
            raise StoreError(f"{shown}: {path} could not be read ({exc})") from exc
        raise DatabaseRefused(f"{shown}: {path} is corrupt ({exc})") from exc
    if rows != [("ok",)]:
        raise DatabaseRefused(f"{shown}: {path} is corrupt (SQLite integrity check: {rows[0][0]})")


def check_schema(engine: Engine, known: set[str], head: str | None, shown: str) -> None:
    """Refuse a foreign database and one whose schema revision is not among ``known``."""
    with engine.connect() as conn:
        tables = set(inspect(conn).get_table_names())
        if not tables:
            return
        if "alembic_version" not in tables:
            listed = ", ".join(sorted(tables)[:5]) + (", ..." if len(tables) > 5 else "")
            raise DatabaseRefused(f"{shown}: not a station database (it holds {listed} and no schema version)")
        revisions = [row[0] for row in conn.execute(text("SELECT version_num FROM alembic_version"))]
    unknown = [r for r in revisions if r not in known]
    if unknown:
        raise DatabaseRefused(
            f"{shown}: schema revision {unknown[0]} is newer than this program (it knows revisions up to {head}); "
            "use the station version that made it, or another database"
        )
