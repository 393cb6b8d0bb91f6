"""Clocks: the wall clock a real rig lives by, a scaled clock for simulation, a manual one for deterministic runs.

Simulated peers and the station read time through a :class:`Clock`. With
``SimClock(scale=60)`` a sequence whose real duration is an hour runs in a minute,
while the same station code runs against real hardware on :class:`WallClock`.
Times are seconds.
"""

from __future__ import annotations

import threading
import time
from typing import Protocol


class Clock(Protocol):
    """Seconds since an arbitrary epoch, and sleeping in the same seconds."""

    def now(self) -> float: ...

    def sleep(self, seconds: float) -> None: ...

    @property
    def scale(self) -> float: ...


class WallClock:
    """Real time (monotonic)."""

    scale = 1.0

    def now(self) -> float:
        return time.monotonic()

    def sleep(self, seconds: float) -> None:
        if seconds > 0:
            time.sleep(seconds)


class SimClock:
    """Simulated time running ``scale`` times faster than the wall clock.

    ``now()`` starts at ``start`` (s). Sleeping ``s`` simulated seconds takes
    ``s / scale`` wall seconds.
    """

    def __init__(self, scale: float = 1.0, start: float = 0.0) -> None:
        if scale <= 0:
            raise ValueError("clock scale must be positive")
        self._scale = float(scale)
        self._start = float(start)
        self._t0 = time.monotonic()
        self._lock = threading.Lock()

    @property
    def scale(self) -> float:
        return self._scale

    def now(self) -> float:
        return self._start + (time.monotonic() - self._t0) * self._scale

    def sleep(self, seconds: float) -> None:
        if seconds > 0:
            time.sleep(seconds / self._scale)


class ManualClock:
    """Simulated time that moves only when someone sleeps on it (or :meth:`advance`): deterministic runs.

    ``now()`` starts at ``start`` (s); ``sleep(s)`` returns at once, ``s`` later. Whoever waits on
    it drives it, so a single thread that polls by sleeping sees the same times on every run.
    ``scale`` is 1 (there is no wall time to relate to).
    """

    scale = 1.0

    def __init__(self, start: float = 0.0) -> None:
        self._t = float(start)
        self._lock = threading.Lock()

    def now(self) -> float:
        return self._t

    def sleep(self, seconds: float) -> None:
        self.advance(seconds)

    def advance(self, seconds: float) -> None:
        """Move time forward by ``seconds`` (negative values are ignored)."""
        if seconds > 0:
            with self._lock:
                self._t += seconds
