"""A throwaway PostgreSQL cluster and fresh databases on it, for the tests and the benchmarks.

``throwaway_cluster()`` runs Debian's ``initdb`` and ``pg_ctl`` (as the ``postgres`` user when we are root) in a
temporary directory on a free loopback port, yields the server URL (database ``postgres``) and stops and deletes
the cluster afterwards. ``fresh_database(server)`` creates an empty database there and drops it afterwards.
"""

from __future__ import annotations

import contextlib
import glob
import os
import pwd
import shutil
import socket
import subprocess
import tempfile
import uuid
from collections.abc import Iterator
from pathlib import Path

from sqlalchemy import create_engine, text
from sqlalchemy.engine import make_url


class PostgresUnavailable(Exception):
    """No PostgreSQL server can be run here (the reason is the message)."""


class ClusterStartError(Exception):
    """initdb or pg_ctl failed (their output and the server log are the message)."""


def find_initdb() -> Path | None:
    """``initdb`` on the PATH, else the newest of Debian's ``/usr/lib/postgresql/*/bin/initdb``."""
    found = shutil.which("initdb")
    if found:
        return Path(found)
    candidates = sorted(glob.glob("/usr/lib/postgresql/*/bin/initdb"), key=lambda p: int(p.split("/")[4]))
    return Path(candidates[-1]) if candidates else None


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@contextlib.contextmanager
def throwaway_cluster(*, server_options: str = "-c fsync=off", prefix: str = "station-pg-") -> Iterator[str]:
    """Yield the server URL of a temporary cluster started with ``server_options`` (``postgres -c ...``).

    Raises :class:`PostgresUnavailable` (no initdb; root without a ``postgres`` user) or :class:`ClusterStartError`.
    """
    initdb = find_initdb()
    if initdb is None:
        raise PostgresUnavailable("no PostgreSQL server: initdb not found (install Debian's 'postgresql' package)")
    bindir = initdb.resolve().parent
    tmp = Path(tempfile.mkdtemp(prefix=prefix))
    run_as: dict[str, object] = {}
    if os.geteuid() == 0:
        try:
            pw = pwd.getpwnam("postgres")
        except KeyError:
            shutil.rmtree(tmp)
            raise PostgresUnavailable("running as root and there is no 'postgres' user to run the PostgreSQL "
                                      "server as") from None
        os.chown(tmp, pw.pw_uid, pw.pw_gid)
        run_as = {"user": pw.pw_uid, "group": pw.pw_gid, "extra_groups": []}
    data, port = tmp / "data", free_port()
    try:
        subprocess.run([str(bindir / "initdb"), "-D", str(data), "-A", "trust", "-U", "postgres", "-E", "UTF8",
                        "--no-sync"], check=True, capture_output=True, cwd=tmp, **run_as)  # type: ignore[arg-type]
        opts = f"-h 127.0.0.1 -p {port} -k {tmp} {server_options}"
        subprocess.run([str(bindir / "pg_ctl"), "-D", str(data), "-l", str(tmp / "log"), "-o", opts, "-w",
                        "-t", "60", "start"], check=True, capture_output=True, cwd=tmp, **run_as)  # type: ignore[arg-type]
    except subprocess.CalledProcessError as exc:
        log = (tmp / "log").read_text() if (tmp / "log").exists() else ""
        shutil.rmtree(tmp, ignore_errors=True)
        raise ClusterStartError(f"could not start a throwaway PostgreSQL cluster: {exc.stderr!r} {log}") from None
    try:
        yield f"postgresql+psycopg://postgres@127.0.0.1:{port}/postgres"
    finally:
        subprocess.run([str(bindir / "pg_ctl"), "-D", str(data), "-m", "immediate", "-w", "stop"],
                       capture_output=True, cwd=tmp, **run_as)  # type: ignore[arg-type]
        shutil.rmtree(tmp, ignore_errors=True)


@contextlib.contextmanager
def fresh_database(server: str, prefix: str = "station_test_") -> Iterator[str]:
    """Yield the URL of a new empty database on ``server``; dropped afterwards."""
    name = f"{prefix}{uuid.uuid4().hex[:10]}"
    admin = create_engine(server, isolation_level="AUTOCOMMIT")
    with admin.connect() as conn:
        conn.execute(text(f'CREATE DATABASE "{name}"'))
    try:
        yield make_url(server).set(database=name).render_as_string(hide_password=False)
    finally:
        with admin.connect() as conn:
            conn.execute(text(f'DROP DATABASE IF EXISTS "{name}" WITH (FORCE)'))
        admin.dispose()
