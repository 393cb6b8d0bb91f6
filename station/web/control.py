"""Starting and aborting runs from the web API: the hooks behind ``POST /api/runs`` and its abort.

One run at a time, in a background thread, on the station the server was started with: the
control is given the station's ``run`` (:meth:`station.compose.Station.run`), which opens the
hardware, runs the sequence and hands the runner over before it starts. The runner's records
go to the store's recorder first and then to the live status.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Mapping
from typing import Any, Protocol

from station.kernel.errors import StationBusy, StationError
from station.sequence.runner import RunResult, SequenceRunner


class RunOnce(Protocol):
    """Runs the sequence once (:meth:`station.compose.Station.run`); calls ``on_runner`` with the runner before it
    starts. ``serials``: fixture slot -> the serial scanned for it."""

    def __call__(self, on_runner: Callable[[SequenceRunner], None], operator: str | None = None, *,
                 lot: str | None = None, serials: Mapping[int, str] | None = None) -> RunResult: ...


class StationControl:
    """Runs the calibration sequence on request.

    Args:
        run: runs the sequence once on the station's hardware (:meth:`station.compose.Station.run`).
        on_error: called with a station fault that ended a run before it started (e.g. the rig
            cannot be opened).
    """

    def __init__(self, run: RunOnce, *, on_error: Callable[[str], None] | None = None) -> None:
        self.run = run
        self.on_error = on_error
        self._lock = threading.Lock()
        self._runner: SequenceRunner | None = None
        self._thread: threading.Thread | None = None
        self.last_result: RunResult | None = None

    @property
    def busy(self) -> bool:
        return self._thread is not None and self._thread.is_alive()

    def start(self, options: dict[str, Any] | None = None, timeout_s: float = 30.0) -> str:
        """Start a run; returns its id once the runner exists. Raises :class:`StationBusy`.

        ``options``: ``operator``, ``lot``, ``serials`` (nest numbered from 1 -> scanned serial), as
        :class:`~station.web.models.StartRunRequest`."""
        with self._lock:
            if self.busy:
                raise StationBusy("a run is in progress")
            ready = threading.Event()
            failure: list[str] = []

            def handed(runner: SequenceRunner) -> None:
                self._runner = runner
                ready.set()

            def work() -> None:
                try:
                    opts = options or {}
                    operator, lot = opts.get("operator"), opts.get("lot")
                    serials = {int(nest) - 1: str(serial) for nest, serial in (opts.get("serials") or {}).items()}
                    self.last_result = self.run(handed, str(operator) if operator else None,
                                                lot=str(lot) if lot else None, serials=serials or None)
                except StationError as exc:
                    failure.append(str(exc))
                    if self.on_error is not None:
                        self.on_error(str(exc))
                finally:
                    ready.set()

            self._thread = threading.Thread(target=work, name="station-run", daemon=True)
            self._thread.start()
        ready.wait(timeout_s)
        if self._runner is None or failure:
            raise StationError(f"the run did not start: {failure[0] if failure else 'timeout'}")
        return self._runner.run_id

    def abort(self, run_id: str) -> bool:
        """Abort the run ``run_id`` if it is the one in progress; False otherwise."""
        runner = self._runner
        if runner is None or runner.run_id != run_id or not self.busy:
            return False
        runner.abort()
        return True

    def stop(self, reason: str = "aborted: the station is shutting down", timeout_s: float | None = None) -> None:
        """Abort the run in progress with ``reason`` and wait until it has ended (rig at rest, recorded)."""
        runner = self._runner
        if runner is not None and self.busy:
            runner.abort(reason)
            self.wait(timeout_s)

    def wait(self, timeout_s: float | None = None) -> RunResult | None:
        """Wait for the run in progress to end; its result (None if none ran or it is still going)."""
        if self._thread is not None:
            self._thread.join(timeout_s)
        return None if self.busy else self.last_result
