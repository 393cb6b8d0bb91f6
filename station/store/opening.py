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

from station.kernel.errors import StationError

#: URL schemes (dialect names) the station's store works with
SUPPORTED_SCHEMES = ("sqlite", "postgresql")


class StoreError(StationError):
    """The station database could not be opened, migrated or written."""


class DatabaseRefused(StoreError):
    """A database the station does not open: unsupported, corrupt, foreign or newer."""


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
