"""One fixture slot during a run: its sensor, everything it streamed, its captured windows.

A :class:`UnitChannel` owns the station side of one sensor for one run. The
sensor streams from power-on to the end of the run; the client's reader thread
buffers the frames, and :meth:`UnitChannel.collect_until` moves them into the
channel's record. Each step adds a :class:`Window` in *sensor* time (s since the
sensor's power-on). Windows are placed with the sensor clock offset measured by
:meth:`UnitChannel.sync` (GET_STATUS round trips, the shortest wins, as in NTP),
so a window never starts before the rig confirmed the step (plus a settle guard),
and it ends before the next rig command because the station waits for a sample at
or after its end before moving on. :func:`build_session` turns the record and the
windows into a :class:`~station.session.model.Session`: windows become rest, pose
and rate segments with the commanded references, everything between them a move
segment without reference. Units: s, m/s^2, rad/s.
"""

from __future__ import annotations

import contextlib
import math
import threading
import time
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from station.kernel.clock import Clock
from station.kernel.errors import HardwareError
from station.kernel.virtual_clock import is_virtual, wait_event
from station.sensor.commands import SensorIdentity
from station.sensor.protocol import SampleBlock, Sensor, SensorTimeout
from station.session.model import Kind, Session

_POLL_WALL_S = 0.02
#: Sample times are whole microseconds: window bounds compare with this slack (s) so that float
#: round-off never moves a sample that sits exactly on a bound to the other side.
_T_SLACK_S = 1e-7


def _bound(t_s: np.ndarray, bound_s: float) -> int:
    """Index of the first sample at or after ``bound_s`` (s)."""
    return int(np.searchsorted(t_s, bound_s - _T_SLACK_S, side="left"))


class CaptureStopped(Exception):
    """Internal: the run asked a capture to stop (abort or a rig fault); not a unit result."""


@dataclass(frozen=True, eq=False)
class Window:
    """A captured step in sensor time [t0_s, t1_s) (s) and what the rig imposed during it.

    Attributes:
        step: step name; kind: rest, pose or rate.
        ref_accel_mps2: specific force the rig imposes, nominal sensor frame (m/s^2), (3,).
        ref_gyro_radps: angular rate the rig imposes, nominal sensor frame (rad/s), (3,).
    """

    step: str
    kind: Kind
    t0_s: float
    t1_s: float
    ref_accel_mps2: np.ndarray
    ref_gyro_radps: np.ndarray


class UnitChannel:
    """The station side of one fixture slot for one run.

    Args:
        slot: fixture slot (0-based).
        url: the sensor URL (for reports).
        sensor: an open sensor client.
        clock: the station clock (the sensor's samples are mapped onto it by :meth:`sync`).
    """

    def __init__(self, slot: int, url: str, sensor: Sensor, clock: Clock) -> None:
        self.slot = slot
        self.url = url
        self.sensor = sensor
        self.clock = clock
        self.identity: SensorIdentity | None = None
        self.rate_hz = 0
        self.windows: list[Window] = []
        self.offset_s: float | None = None  # station clock minus sensor time (s)
        self.sync_halfwidth_s = math.inf  # half the best round trip of the last sync (s)
        self.active = True
        self._blocks: list[SampleBlock] = []
        self._all = SampleBlock.empty()
        self._t_first: float | None = None
        self._t_last = -math.inf

    @property
    def serial(self) -> str:
        return self.identity.serial if self.identity is not None else ""

    @property
    def t_last_s(self) -> float:
        """Sensor time of the newest sample received (s), -inf before the first."""
        return self._t_last

    @property
    def t_first_s(self) -> float | None:
        """Sensor time of the first sample of the stream (s)."""
        return self._t_first

    # --- sensor control -----------------------------------------------------------------------

    def power_on(self, rate_hz: int) -> SensorIdentity:
        """Power-cycle the sensor (drift restarts, eq. 3: g(0) = 1), identify it, stream at ``rate_hz``.

        A CRC-storm latch of an earlier run is cleared first (it latches again if the link is still
        bad), and samples from before the power cycle still in the client's buffer are dropped.
        """
        self.sensor.clear_fault()
        self.sensor.power_cycle()
        self.sensor.drain()  # the BOOT event came after every frame sent before the reset
        ident = self.sensor.identify()
        if rate_hz not in ident.rates_hz:
            raise HardwareError(
                f"sensor {ident.serial} does not support {rate_hz} Hz (it offers {', '.join(map(str, ident.rates_hz))})"
            )
        self.identity = ident
        self.rate_hz = rate_hz
        self.sensor.start_stream(rate_hz)
        return ident

    def sync(self, tries: int = 3) -> float:
        """Measure the offset station clock minus sensor time (s) by GET_STATUS round trips."""
        best: tuple[float, float] | None = None
        for _ in range(max(1, tries)):
            t_a = self.clock.now()
            status = self.sensor.status()
            t_b = self.clock.now()
            half = 0.5 * (t_b - t_a)
            if best is None or half < best[1]:
                best = (0.5 * (t_a + t_b) - status.uptime_s, half)
        assert best is not None
        self.offset_s, self.sync_halfwidth_s = best
        return best[0]

    def latest_sensor_time(self, t_station_s: float) -> float:
        """The latest sensor time (s) that station time ``t_station_s`` can be, given the last :meth:`sync`.

        The sensor read its clock somewhere inside the best round trip, so the midpoint offset is
        uncertain by the half-width. A reply queued behind streamed frames makes the trip long and
        one-sided (late); a window placed with this bound never starts before the station's instant.
        """
        if self.offset_s is None:
            raise HardwareError(f"sensor {self.serial or self.url}: clock offset not measured (sync first)")
        return t_station_s - self.offset_s + self.sync_halfwidth_s

    def stop_stream(self) -> None:
        """Stop streaming; link errors are ignored (teardown)."""
        with contextlib.suppress(HardwareError):
            self.sensor.stop_stream()

    # --- samples ------------------------------------------------------------------------------

    def pull(self) -> int:
        """Move the samples the client has buffered into the record; returns how many."""
        block = self.sensor.drain()
        n = len(block)
        if n == 0:
            return 0
        if block.t_s[0] <= self._t_last or np.any(np.diff(block.t_s) <= 0):
            raise HardwareError(f"sensor {self.serial or self.url} restarted or repeated samples during the run")
        if self._t_first is None:
            self._t_first = float(block.t_s[0])
        self._t_last = float(block.t_s[-1])
        self._blocks.append(block)
        return n

    def collect_until(self, t_end_s: float, stop: threading.Event, silence_wall_s: float) -> None:
        """Collect samples until one at or after sensor time ``t_end_s`` (s) has arrived.

        Raises:
            SensorTimeout: no sample for ``silence_wall_s`` wall seconds.
            CaptureStopped: ``stop`` was set.
            CrcStormError, SensorLinkError: the link is faulty.
        """
        if is_virtual(self.clock):
            self._collect_virtual(t_end_s, stop)
            return
        last_progress = time.monotonic()
        while True:
            if self.pull():
                last_progress = time.monotonic()
            if self._t_last >= t_end_s - _T_SLACK_S:
                return
            if stop.is_set():
                raise CaptureStopped
            if time.monotonic() - last_progress > silence_wall_s:
                raise SensorTimeout(
                    f"sensor {self.serial or self.url} went silent: no sample for {silence_wall_s:.2f} s (wall) "
                    f"after t = {self._t_last:.3f} s"
                )
            time.sleep(_POLL_WALL_S)

    def _collect_virtual(self, t_end_s: float, stop: threading.Event) -> None:
        """:meth:`collect_until` on a virtual clock: decided from the samples' own times, never their arrival.

        A GET_STATUS round trip is the barrier: the sensor sends every sample due before it answers, and its
        uptime is the sensor time now. After it the record holds exactly the samples due by now; if the one
        at or after ``t_end_s`` is not among them, the time until it is due (on the sensor's sample grid)
        passes on the clock, and the barrier is repeated.
        """
        period = 1.0 / self.rate_hz if self.rate_hz else 0.01
        while True:
            now_s = self.sensor.status().uptime_s
            self.pull()
            if self._t_last >= t_end_s - _T_SLACK_S:
                return
            if stop.is_set():
                raise CaptureStopped
            due = now_s + period
            if math.isfinite(self._t_last) and math.isfinite(t_end_s):
                due = self._t_last + max(1, math.ceil((t_end_s - _T_SLACK_S - self._t_last) / period)) * period
            if wait_event(self.clock, stop, max(due - now_s, 0.0) + 1e-6):
                raise CaptureStopped

    def wait_first(self, stop: threading.Event, silence_wall_s: float) -> float:
        """Wait for the first sample of the stream; returns its sensor time (s)."""
        if self._t_first is None:
            self.collect_until(-math.inf, stop, silence_wall_s)
        assert self._t_first is not None
        return self._t_first

    def recent_temperature(self, span_s: float) -> tuple[np.ndarray, np.ndarray]:
        """(sensor time s, temperature degC) of the samples received in the last ``span_s`` (s) of the
        stream, without assembling the whole record (for soak gates polled over hours)."""
        if self._t_first is None:
            return np.zeros(0), np.zeros(0)
        start = self._t_last - span_s
        parts: list[SampleBlock] = []
        for block in reversed(self._blocks):
            parts.append(block)
            if len(block) and block.t_s[0] <= start:
                break
        else:
            parts.append(self._all)
        t = np.concatenate([b.t_s for b in reversed(parts)]) if parts else np.zeros(0)
        temp = np.concatenate([b.temp_degc for b in reversed(parts)]) if parts else np.zeros(0)
        keep = t >= start
        return t[keep], temp[keep]

    def samples(self) -> SampleBlock:
        """Every sample received so far, in order."""
        if self._blocks:
            self._all = SampleBlock.concat([self._all, *self._blocks])
            self._blocks = []
        return self._all

    def window_samples(self, t0_s: float, t1_s: float) -> SampleBlock:
        """The received samples with ``t0_s <= t < t1_s`` (sensor time, s)."""
        block = self.samples()
        a, b = _bound(block.t_s, t0_s), _bound(block.t_s, t1_s)
        head, _ = block.split(b)
        return head.split(a)[1]


def build_session(channel: UnitChannel, gravity_mps2: float, metadata: Mapping[str, str]) -> Session | None:
    """The channel's recording as a session (None if fewer than 2 samples).

    Windows become segments of their kind with the commanded references; runs of
    samples between (and after) windows become ``move`` segments with empty references.
    Segment indices count up in time order. ``metadata`` adds to serial, sample rate and gravity.
    """
    block = channel.samples()
    n = len(block)
    if n < 2:
        return None
    t = block.t_s
    wid = np.full(n, -1, dtype=np.int64)
    for k, w in enumerate(channel.windows):
        wid[_bound(t, w.t0_s) : _bound(t, w.t1_s)] = k
    change = np.flatnonzero(np.diff(wid) != 0) + 1
    starts = np.concatenate(([0], change))
    stops = np.concatenate((change, [n]))
    segment = np.empty(n, dtype=np.int64)
    kind = np.empty(n, dtype=np.int8)
    ref_f = np.full((n, 3), np.nan)
    ref_w = np.full((n, 3), np.nan)
    for index, (a, b) in enumerate(zip(starts, stops, strict=True)):
        segment[a:b] = index
        k = int(wid[a])
        if k < 0:
            kind[a:b] = int(Kind.MOVE)
            continue
        w = channel.windows[k]
        kind[a:b] = int(w.kind)
        ref_f[a:b] = w.ref_accel_mps2
        ref_w[a:b] = w.ref_gyro_radps
    meta = {
        "serial": channel.serial or f"slot{channel.slot}",
        "sample_rate_hz": str(channel.rate_hz),
        "gravity_mps2": repr(float(gravity_mps2)),
        **dict(metadata),
    }
    if channel.identity is not None:
        meta.setdefault("firmware", channel.identity.firmware)
    return Session(
        metadata=meta,
        t_s=t,
        segment=segment,
        kind=kind,
        accel_mps2=block.accel_mps2,
        gyro_radps=block.gyro_radps,
        temp_degc=block.temp_degc,
        ref_accel_mps2=ref_f,
        ref_gyro_radps=ref_w,
    )
