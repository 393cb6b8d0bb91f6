"""Open the station database by URL and bring its schema up to date (Alembic migrations).

The default is a SQLite file ``station.sqlite`` in the working directory; a
``postgresql+psycopg://user@host:port/dbname`` URL works the same and lets several
stations write to one database. :func:`open_database` runs ``alembic upgrade head``
on open, so a new file or an empty database gets the schema and an old one is
migrated. The migrations live in ``migrations/`` at the top of the source tree.
"""

from __future__ import annotations

import os
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from alembic import command
from alembic.config import Config
from alembic.runtime.migration import MigrationContext
from alembic.script import ScriptDirectory
from alembic.util.exc import CommandError
from sqlalchemy import Engine, create_engine, event, make_url, text
from sqlalchemy.exc import ArgumentError, OperationalError, SQLAlchemyError
from sqlalchemy.orm import Session, sessionmaker

from station.kernel.datafiles import data_path
from station.kernel.errors import path_problem, shorten
from station.store.default_url import DEFAULT_URL, ENV_VAR
from station.store.opening import (
    DatabaseRefused,
    StoreError,
    check_keeps_records,
    check_schema,
    check_url,
    classify_failure,
    lock_timeout_s,
)

"""The default database: a SQLite file in the working directory."""

"""Environment variable that overrides :data:`DEFAULT_URL`."""

MIGRATIONS_DIR = data_path("migrations")

_MIGRATION_LOCK = threading.Lock()  # Alembic's context is process-global: one migration at a time per process
_PG_LOCK_KEY = 0x5354_4154  # advisory lock id on PostgreSQL: one migrating station at a time



def database_url(url: str | None = None) -> str:
    """``url`` if given, else ``$STATION_DB``, else :data:`DEFAULT_URL`."""
    return url or os.environ.get(ENV_VAR) or DEFAULT_URL


def alembic_config(url: str) -> Config:
    """An Alembic configuration for ``url`` with the station's migrations (no alembic.ini needed)."""
    if not (MIGRATIONS_DIR / "env.py").is_file():
        raise StoreError(f"migrations not found in {MIGRATIONS_DIR}")
    cfg = Config()
    cfg.set_main_option("script_location", str(MIGRATIONS_DIR))
    cfg.set_main_option("sqlalchemy.url", url.replace("%", "%%"))
    return cfg


def make_engine(url: str) -> Engine:
    """An engine for ``url``; SQLite gets foreign keys on and the stated busy timeout (:func:`lock_timeout_s`,
    several writers); PostgreSQL the same ``lock_timeout``."""
    if url.startswith("sqlite"):
        engine = create_engine(url, connect_args={"timeout": lock_timeout_s()})

        @event.listens_for(engine, "connect")
        def _pragmas(dbapi_conn: Any, _record: Any) -> None:
            cur = dbapi_conn.cursor()
            cur.execute("PRAGMA foreign_keys=ON")
            cur.execute("PRAGMA journal_mode=WAL")
            cur.close()

        return engine
    if make_url(url).get_backend_name() == "postgresql":
        ms = int(lock_timeout_s() * 1000)
        return create_engine(url, pool_pre_ping=True, connect_args={"options": f"-c lock_timeout={ms}"})
    return create_engine(url, pool_pre_ping=True)


def _migrate(engine: Engine, revision: str, up: bool) -> None:
    with _MIGRATION_LOCK, engine.begin() as conn:
        if conn.dialect.name == "postgresql":  # several stations starting at once: one migrates, the others wait
            conn.execute(text("SELECT pg_advisory_xact_lock(:k)"), {"k": _PG_LOCK_KEY})
        cfg = alembic_config(engine.url.render_as_string(hide_password=False))
        cfg.attributes["connection"] = conn
        (command.upgrade if up else command.downgrade)(cfg, revision)


def upgrade(engine: Engine, revision: str = "head") -> None:
    """Run ``alembic upgrade <revision>`` on ``engine``'s database (serialized between stations)."""
    _migrate(engine, revision, True)


def downgrade(engine: Engine, revision: str = "base") -> None:
    """Run ``alembic downgrade <revision>`` on ``engine``'s database."""
    _migrate(engine, revision, False)


def current_revision(engine: Engine) -> str | None:
    """The database's Alembic revision (None: no schema yet)."""
    with engine.connect() as conn:
        return MigrationContext.configure(conn).get_current_revision()


def head_revision() -> str | None:
    """The newest migration's revision id."""
    return ScriptDirectory.from_config(alembic_config(DEFAULT_URL)).get_current_head()


@dataclass
class Database:
    """An open station database: the engine and a session factory."""

    url: str
    engine: Engine
    sessions: sessionmaker[Session]

    @contextmanager
    def transaction(self) -> Iterator[Session]:
        """A session in one transaction: committed on success, rolled back on any exception.

        A database another process holds locked past the stated wait raises
        :class:`~station.store.opening.DatabaseLocked`, a full disk :class:`~station.store.opening.DatabaseFull`.
        """
        try:
            with self.sessions.begin() as session:
                yield session
        except OperationalError as exc:
            known = classify_failure(exc, self.url, _redact(self.url))
            if known is not None:
                raise known from None
            raise

    def close(self) -> None:
        self.engine.dispose()

    def __enter__(self) -> Database:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def open_database(url: str | None = None, *, migrate: bool = True, must_exist: bool = False,
                  for_writing: bool | None = None) -> Database:
    """Open the database at ``url`` (see :func:`database_url`) and run the migrations up to head.

    ``must_exist``: for commands that only read: a SQLite file that does not exist is refused instead of
    created (an empty database would only say "no units" about the wrong place).
    ``for_writing`` (default: not ``must_exist``): a database that keeps nothing after the command (SQLite
    in memory, or its temporary file) is refused.
    Raises :class:`StoreError` if the database cannot be reached or migrated (``DatabaseLocked`` when another
    process holds it past the stated wait, ``DatabaseFull`` when its disk is full).
    """
    url = database_url(url)
    shown = _redact(url)
    if must_exist:
        _require_existing(url, shown)
    if (not must_exist) if for_writing is None else for_writing:
        check_keeps_records(url, shown)
    try:
        check_url(url, shown)
        script = ScriptDirectory.from_config(alembic_config(url))
        probe = create_engine(url)  # without make_engine's pragmas: WAL mode would rewrite a foreign file's header
        try:
            check_schema(probe, {r.revision for r in script.walk_revisions()}, script.get_current_head(), shown)
        finally:
            probe.dispose()
        engine = make_engine(url)
        if migrate:
            upgrade(engine)
    except DatabaseRefused as exc:
        raise DatabaseRefused(f"cannot open the station database {exc}") from None  # "{url}: why"
    except (SQLAlchemyError, OSError, CommandError) as exc:
        known = classify_failure(exc, url, shown)
        if known is not None:
            raise known from None
        raise StoreError(f"cannot open the station database {shown}: {_first_line(exc)}") from exc
    return Database(url, engine, sessionmaker(engine, expire_on_commit=False))


def _require_existing(url: str, shown: str) -> None:
    try:
        parsed = make_url(url)
    except (ArgumentError, ValueError):
        return  # check_url names what is wrong with it
    file = parsed.database if parsed.get_backend_name() == "sqlite" else None
    if file in (None, "", ":memory:"):
        return
    try:
        exists = Path(str(file)).exists()
    except (OSError, ValueError) as exc:
        raise DatabaseRefused(f"{shown}: {path_problem(exc, str(file))}") from None
    if not exists:
        raise StoreError(f"no station database at {shown} (nothing is created by a command that only reads; "
                         f"give --db or set ${ENV_VAR})")


def store_exists(url: str) -> bool:
    """Whether a station database may be there: a SQLite file that exists, or any server URL."""
    try:
        parsed = make_url(url)
    except (ArgumentError, ValueError):
        return False
    if parsed.get_backend_name() != "sqlite":
        return True
    file = parsed.database or ""
    try:
        return file not in ("", ":memory:") and not file.startswith("file:") and Path(file).is_file()
    except (OSError, ValueError):
        return False


def shown_url(url: str | None = None) -> str:
    """The database URL a command uses (see :func:`database_url`), with any password hidden."""
    return _redact(database_url(url))


def _redact(url: str) -> str:
    from sqlalchemy.engine import make_url

    try:
        return shorten(make_url(url).render_as_string(hide_password=True), 200)
    except Exception:
        return shorten(url.split("@")[-1] if "@" in url else url, 200)


def _first_line(exc: BaseException) -> str:
    """An exception's message without SQLAlchemy's multi-line 'Background on this error' appendix."""
    return str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
