"""The heartbeat a Modbus device's watchdog expects, shared by the rig and the chamber clients.

:class:`Heartbeat` writes an incrementing counter to the device's HEARTBEAT holding register from a
daemon thread every ``heartbeat_period_s`` (device seconds on the device's clock: wall period =
period / clock scale; on a :class:`~station.kernel.virtual_clock.VirtualClock` the thread is an actor
waiting on the clock). A failed beat is counted and logged, never raised: the device's watchdog decides
what a missing heartbeat means.
"""

from __future__ import annotations

import logging
import threading
from typing import ClassVar

from station.kernel.clock import Clock
from station.kernel.virtual_clock import Actor, acting, enroll, wait_event


class Heartbeat:
    """Heartbeat thread mixin; the device class sets the class attributes, :attr:`clock` and
    :attr:`heartbeat_period_s`, calls :meth:`_init_heartbeat` and provides :meth:`_write`."""

    #: the device named in the thread name and the log ('rig', 'chamber')
    _role: ClassVar[str]
    #: the HEARTBEAT holding register's address
    _heartbeat_register: ClassVar[int]
    #: where failed beats are logged
    _log: ClassVar[logging.Logger]

    clock: Clock
    heartbeat_period_s: float

    def _init_heartbeat(self) -> None:
        self.heartbeat_failures = 0
        self.last_heartbeat_error: Exception | None = None
        self._hb_counter = 0
        self._hb_stop = threading.Event()
        self._hb_thread: threading.Thread | None = None

    def _write(self, address: int, values: list[int], what: str, retries: int | None = None) -> None:
        raise NotImplementedError

    def beat(self) -> None:
        """Write the next heartbeat value once (the heartbeat thread calls this periodically)."""
        self._hb_counter = (self._hb_counter + 1) & 0xFFFF
        self._write(self._heartbeat_register, [self._hb_counter], "heartbeat", retries=0)

    def _heartbeat_loop(self, actor: Actor | None) -> None:
        with acting(self.clock, actor):
            self._beat_until_stopped()

    def _beat_until_stopped(self) -> None:
        while not self._hb_stop.is_set():
            try:
                self.beat()
            except Exception as exc:  # keep beating; the device's watchdog decides
                self.heartbeat_failures += 1
                self.last_heartbeat_error = exc
                self._log.warning("%s heartbeat failed: %s", self._role, exc)
            wait_event(self.clock, self._hb_stop, self.heartbeat_period_s)

    def start_heartbeat(self) -> None:
        """Start the heartbeat thread (idempotent)."""
        if self._hb_thread is not None and self._hb_thread.is_alive():
            return
        self._hb_stop.clear()
        name = f"{self._role}-heartbeat"
        self._hb_thread = threading.Thread(target=self._heartbeat_loop, args=(enroll(self.clock, name),), name=name,
                                           daemon=True)
        self._hb_thread.start()

    def stop_heartbeat(self) -> None:
        """Stop the heartbeat thread; the device's watchdog will trip if nothing else beats."""
        self._hb_stop.set()
        if self._hb_thread is not None:
            self._hb_thread.join()
            self._hb_thread = None


__all__ = ["Heartbeat"]
