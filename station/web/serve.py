"""``station serve``: run the status page and API with uvicorn (binds to 127.0.0.1 unless told otherwise).

:func:`serve` blocks until interrupted; :class:`ServerThread` runs the app in a background
thread of a process that also runs the sequence (so the page shows that run live).
"""

from __future__ import annotations

import asyncio
import signal
import socket
import ssl
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from types import FrameType

import uvicorn
from fastapi import FastAPI

from station.kernel.errors import StationError
from station.web.app import create_app
from station.web.console import ConsoleOperator
from station.web.state import LiveStatus


class _Server(uvicorn.Server):
    """uvicorn's server that also exits on SIGHUP and, before it shuts down, hands the signal to ``on_exit``."""

    def __init__(self, config: uvicorn.Config, on_exit: Callable[[str], None] | None) -> None:
        super().__init__(config)
        self.on_exit = on_exit
        self.exit_reason = "aborted: the station is shutting down"

    def handle_exit(self, sig: int, frame: FrameType | None) -> None:
        self.exit_reason = f"aborted by {signal.Signals(sig).name}"
        super().handle_exit(sig, frame)

    async def shutdown(self, sockets: list[socket.socket] | None = None) -> None:
        if self.on_exit is not None:
            await asyncio.to_thread(self.on_exit, self.exit_reason)
        await super().shutdown(sockets)


@dataclass(frozen=True)
class Tls:
    """The server's certificate and private key (PEM files): the page and API over HTTPS only."""

    cert: Path
    key: Path

    def check(self) -> None:
        """Refuse files that are missing or cannot be read (before the server starts)."""
        for what, path in (("certificate", self.cert), ("private key", self.key)):
            if not path.is_file():
                raise TlsError(f"TLS {what} {str(path)!r} is not a file")
        try:
            ssl.create_default_context(ssl.Purpose.CLIENT_AUTH).load_cert_chain(self.cert, self.key)
        except (ssl.SSLError, OSError) as exc:
            raise TlsError(f"TLS certificate {str(self.cert)!r} and key {str(self.key)!r} cannot be used: "
                           f"{exc}") from None


class TlsError(StationError):
    """The TLS certificate or key given to ``station serve`` cannot be used."""


def serve(host: str = "127.0.0.1", port: int = 8000, db_url: str | None = None, token: str | None = None,
          live: LiveStatus | None = None, on_exit: Callable[[str], None] | None = None,
          prompter: ConsoleOperator | None = None, tls: Tls | None = None) -> None:
    """Serve the web application on ``host``:``port`` until SIGINT, SIGTERM or SIGHUP.

    Args:
        host: address to bind (127.0.0.1: this machine only; 0.0.0.0 for the line's network).
        port: TCP port.
        db_url: station database URL (None: ``$STATION_DB`` or ``sqlite:///station.sqlite``).
        token: bearer token for the write actions (None: read-only, they answer 401).
        live: the live status of a sequence running in this process (None: an idle station).
        on_exit: called with the reason (``'aborted by SIGTERM'``) before the server shuts down: the
            station aborts a run in progress there and waits until the rig is at rest.
        prompter: the operator console answering the station's prompts (None: the station runs without them).
        tls: serve HTTPS with this certificate and key (the console's session cookie is then ``Secure``);
            None: plain HTTP.
    """
    if tls is not None:
        tls.check()
    app = create_app(db_url, token=token, live=live, prompter=prompter, https_only=tls is not None)
    server = _Server(uvicorn.Config(app, host=host, port=port, log_level="info",
                                    ssl_certfile=None if tls is None else str(tls.cert),
                                    ssl_keyfile=None if tls is None else str(tls.key)), on_exit)
    previous = signal.signal(signal.SIGHUP, server.handle_exit)
    try:
        server.run()
    finally:
        signal.signal(signal.SIGHUP, previous)


class ServerThread:
    """uvicorn serving ``app`` in a daemon thread from construction until :meth:`stop`.

    Args:
        app: the application (see :func:`create_app`).
        host, port: where to listen (port 0: a free port, see :attr:`port`).
        start_timeout_s: how long to wait for the server to listen (s).
    """

    def __init__(self, app: FastAPI, host: str = "127.0.0.1", port: int = 0, *, start_timeout_s: float = 20.0,
                 log_level: str = "warning") -> None:
        self.host = host
        self.server = uvicorn.Server(uvicorn.Config(app, host=host, port=port, log_level=log_level,
                                                    timeout_graceful_shutdown=1))
        self.thread = threading.Thread(target=self.server.run, name="station-web", daemon=True)
        self.thread.start()
        deadline = time.monotonic() + start_timeout_s
        while not self.server.started:
            if time.monotonic() > deadline or not self.thread.is_alive():
                raise StationError(f"the web server did not start on {host}:{port}")
            time.sleep(0.02)
        self.port = int(self.server.servers[0].sockets[0].getsockname()[1])

    @property
    def url(self) -> str:
        """Base URL, e.g. ``http://127.0.0.1:8000``."""
        return f"http://{self.host}:{self.port}"

    def stop(self, timeout_s: float = 10.0) -> None:
        """Ask the server to exit and wait up to ``timeout_s`` (s); open event streams are cut after 1 s."""
        self.server.should_exit = True
        self.thread.join(timeout_s)

    def __enter__(self) -> ServerThread:
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()
