"""A simulated IMU behind a real pseudo-terminal, speaking the binary sensor protocol.

:class:`SimulatedSensor` opens a pty pair, makes the slave raw and serves the
protocol (station/sensor/protocol.md) on the master side in a background thread. The
station connects to ``sensor.url`` (``serial:///dev/pts/N``) with the same
:func:`station.sensor.client.open_sensor` it uses for real hardware.

Timing follows the given :class:`~station.kernel.clock.Clock`: sample ``k`` after
START_STREAM has sensor time ``t0 + k / rate`` (whole µs since power-on), and frames
are produced in chunks every ``tick_s`` wall seconds for every sample whose time
has come, so at ``SimClock(scale=s)`` the sensor sends ``rate * s`` frames per wall
second. Values come from a pluggable :class:`SampleSource` (the sensor physics,
eq. 1 and eq. 3 of the paper live there); power-on restarts it. What the firmware does
with a command or a stream is :class:`~station.sim.sensor_core.SensorCore`'s, shared with
the in-process fake (:mod:`station.sim.fakes`); this module is its wire: frames, the
retransmission cache, the transmit backlog and the link faults.

Fault switches (attributes, may be changed any time): ``bit_error_rate`` (per bit,
on everything sent), ``drop_frame_rate`` (sample frames only), ``go_silent`` (the
firmware hangs: reads and ignores commands, sends nothing; its clock and sample
counter run on, so recovery shows up as a gap), plus the EEPROM's own faults
(``sensor.eeprom``; a power-loss fault switches the sensor off until
:meth:`SimulatedSensor.power_on`). Fault decisions for sample frames are drawn
from generators seeded by ``seed`` in frame order, so they do not depend on how
the frames were chunked.
"""

from __future__ import annotations

import contextlib
import os
import select
import sys
import threading
import tty
from dataclasses import dataclass
from typing import Any

import numpy as np

from station.kernel.clock import Clock
from station.kernel.errors import FormatError
from station.kernel.virtual_clock import follow, is_virtual
from station.sensor.commands import BootEvent, BootReason, Command, NakCode, decode_command, encode_ack, encode_nak
from station.sensor.frames import SAMPLE_FRAME_SIZE, FrameParser, FrameType, encode_frame, frame_sample_records
from station.sim.sensor_core import (
    DEFAULT_RATES_HZ,
    Corrector,
    SampleSource,
    SensorCore,
    SensorUnit,
    identity_corrector,
)


@dataclass(frozen=True)
class PeerStats:
    """What the simulated sensor did (counters since construction).

    Attributes:
        boots: power-ons and resets.
        commands: command frames received (retries included).
        sample_frames: sample frames produced (sent, dropped or overrun).
        frames_dropped: sample frames removed by ``drop_frame_rate``.
        frames_silenced: sample frames not sent because of ``go_silent``.
        bits_flipped: bits inverted by ``bit_error_rate``.
        tx_overruns: sample frames dropped because the transmit backlog was full.
        bytes_sent: bytes written to the pty.
    """

    boots: int
    commands: int
    sample_frames: int
    frames_dropped: int
    frames_silenced: int
    bits_flipped: int
    tx_overruns: int
    bytes_sent: int


class SimulatedSensor(SensorUnit):
    """Simulated IMU firmware on a pty; connect with ``open_sensor(sensor.url)``.

    Args:
        source: the sensor physics (:class:`SampleSource`).
        clock: time base; :class:`~station.kernel.clock.SimClock` runs it faster than real time.
        seed: seed of the fault-injection generators.
        tick_s: wall-clock period of the firmware loop (s).
        tx_backlog_limit: bytes the sensor buffers when the host does not read; further
            sample frames are dropped and counted as ``tx_overruns``.
        identity: the unit's keyword arguments of :class:`~station.sim.sensor_core.SensorCore`:
            ``serial``, ``firmware``, ``rates_hz``, ``default_rate_hz``, ``eeprom``, ``corrector``,
            the ranges and resolutions reported by IDENTIFY.
    """

    def __init__(
        self,
        source: SampleSource,
        clock: Clock | None = None,
        *,
        seed: int = 0,
        tick_s: float = 0.01,
        tx_backlog_limit: int = 256 * 1024,
        **identity: Any,
    ) -> None:
        super().__init__(SensorCore(source, clock, **identity))
        self._clock = self.core.clock
        self.bit_error_rate = 0.0
        self.drop_frame_rate = 0.0
        self._tick_s = float(tick_s)
        # On a virtual clock nothing waits for the host to read: time may run ahead of the pty, and a frame
        # lost to the host's speed would make the run depend on it. The backlog is unbounded there.
        self._tx_limit = int(tx_backlog_limit) if not is_virtual(self.core.clock) else sys.maxsize

        ss = np.random.SeedSequence(seed)
        drop_ss, count_ss, pos_ss, other_ss = ss.spawn(4)
        self._rng_drop = np.random.default_rng(drop_ss)
        self._rng_flip_count = np.random.default_rng(count_ss)
        self._rng_flip_pos = np.random.default_rng(pos_ss)
        self._rng_other = np.random.default_rng(other_ss)

        self._parser = FrameParser(track_sequence=False)
        self._tx = bytearray()
        self._tx_sent = 0  # bytes of _tx already written (dropped from its front in large pieces)
        self._stats = dict.fromkeys(PeerStats.__dataclass_fields__, 0)
        self._last_cmd: list[bytes | None] | None = None  # [command payload, reply frame or None while pending]
        self._delayed: list[tuple[float, bytes]] = []  # (clock time due, reply frame)

        self._master, self._slave = os.openpty()
        tty.setraw(self._slave)
        os.set_blocking(self._master, False)
        self.device = os.ttyname(self._slave)
        self.url = f"serial://{self.device}"

        with self._lock:
            self._boot(BootReason.POWER_ON)
        # on a virtual clock time runs at most a horizon ahead of what this sensor has produced
        self._follower = follow(self.core.clock, f"sensor {self.identity.serial}")
        self._stop = threading.Event()
        self._error: BaseException | None = None
        self._thread = threading.Thread(target=self._run, name=f"sim-sensor-{self.identity.serial}", daemon=True)
        self._thread.start()

    # --- public controls ------------------------------------------------------------------------

    def stats(self) -> PeerStats:
        """A snapshot of the sensor-side counters."""
        with self._lock:
            return PeerStats(**{**self._stats, "tx_overruns": self.core.tx_overruns})

    def close(self) -> None:
        """Stop the firmware thread and close both pty ends."""
        if self._stop.is_set():
            return
        self._stop.set()
        self._thread.join(timeout=5.0)
        if self._follower is not None:
            self._follower.close()
        for fd in (self._master, self._slave):
            with contextlib.suppress(OSError):
                os.close(fd)

    def __enter__(self) -> SimulatedSensor:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # --- firmware ---------------------------------------------------------------------------------

    def _power_off(self) -> None:
        super()._power_off()
        self._tx.clear()
        self._tx_sent = 0
        self._delayed.clear()
        self._last_cmd = None

    def _boot(self, reason: BootReason) -> BootEvent:
        self._stats["boots"] += 1
        self._last_cmd = None
        self._delayed.clear()
        self._parser = FrameParser(track_sequence=False)
        event = super()._boot(reason)
        self._send(encode_frame(FrameType.EVENT, event.encode()))
        return event

    @property
    def error(self) -> BaseException | None:
        """The exception that stopped the firmware thread (e.g. from the source), if any."""
        return self._error

    def _run(self) -> None:
        try:
            self._serve()
        except BaseException as exc:  # the firmware "crashes": it stops answering; keep the cause
            self._error = exc
            raise

    def _serve(self) -> None:
        while not self._stop.is_set():
            want_write = len(self._tx) > self._tx_sent
            try:
                readable, _, _ = select.select([self._master], [self._master] if want_write else [], [], self._tick_s)
            except (OSError, ValueError):
                return
            with self._lock:
                if readable:
                    self._receive()
                produced_to = self._clock.now()
                self._service()
                self._flush()
            if self._follower is not None:
                self._follower.caught_up(produced_to)

    def _receive(self) -> None:
        try:
            data = os.read(self._master, 65536)
        except (BlockingIOError, InterruptedError):
            return
        except OSError:
            return
        if not self.core.powered or self.go_silent:
            return  # nobody home / the firmware hangs: input is lost
        for frame in self._parser.feed(data):
            if frame.type == FrameType.COMMAND:
                self._stats["commands"] += 1
                self._handle(frame.payload)

    def _service(self) -> None:
        if not self.core.powered:
            return
        now = self._clock.now()
        if self._delayed:
            due = [d for d in self._delayed if d[0] <= now]
            self._delayed = [d for d in self._delayed if d[0] > now]
            for _, reply in due:
                if self._last_cmd is not None and self._last_cmd[1] is None:
                    self._last_cmd[1] = reply
                self._send(reply)
        self._generate_due()

    def _flush(self) -> None:
        while len(self._tx) > self._tx_sent:
            try:
                with memoryview(self._tx) as view:
                    n = os.write(self._master, view[self._tx_sent : self._tx_sent + 65536])
            except (BlockingIOError, InterruptedError):
                break
            except OSError:
                self._tx.clear()
                self._tx_sent = 0
                return
            self._stats["bytes_sent"] += n
            self._tx_sent += n
        if self._tx_sent >= len(self._tx):
            self._tx.clear()
            self._tx_sent = 0
        elif self._tx_sent > 1 << 20:  # drop the sent front in large pieces (a small del per write is quadratic)
            del self._tx[: self._tx_sent]
            self._tx_sent = 0

    def _send(self, frame: bytes) -> None:
        """Queue a non-sample frame (ACK/NAK/EVENT), with bit errors if enabled."""
        if self.go_silent or not self.core.powered:
            return
        ber = self.bit_error_rate
        if ber > 0:
            buf = np.frombuffer(frame, dtype=np.uint8).copy()
            nbits = buf.size * 8
            k = int(self._rng_other.binomial(nbits, ber))
            if k:
                pos = self._rng_other.integers(0, nbits, size=k)
                np.bitwise_xor.at(buf, pos // 8, (1 << (pos % 8)).astype(np.uint8))
                self._stats["bits_flipped"] += k
            frame = buf.tobytes()
        self._tx += frame

    def _generate_due(self) -> None:
        records = self.core.due_samples()
        if records is None:
            return
        self._stats["sample_frames"] += records.shape[0]
        self._emit_samples(frame_sample_records(records))

    def _emit_samples(self, frames: np.ndarray) -> None:
        n = int(frames.shape[0])
        # Draw fault decisions for every frame, whatever the switches, so they depend on frame order only.
        keep = self._rng_drop.random(n) >= self.drop_frame_rate
        ber = self.bit_error_rate
        if ber > 0:
            nbits = SAMPLE_FRAME_SIZE * 8
            counts = self._rng_flip_count.binomial(nbits, ber, size=n)
            total = int(counts.sum())
            if total:
                pos = self._rng_flip_pos.integers(0, nbits, size=total)
                rows = np.repeat(np.arange(n), counts)
                np.bitwise_xor.at(frames, (rows, pos // 8), (1 << (pos % 8)).astype(np.uint8))
                self._stats["bits_flipped"] += total
        if self.go_silent:
            self._stats["frames_silenced"] += n
            return
        self._stats["frames_dropped"] += int(n - keep.sum())
        out = frames[keep]
        if len(self._tx) - self._tx_sent + out.nbytes > self._tx_limit:
            self.core.tx_overruns += out.shape[0]
            return
        self._tx += out.tobytes()

    # --- commands ---------------------------------------------------------------------------------

    def _handle(self, payload: bytes) -> None:
        if self._last_cmd is not None and self._last_cmd[0] == payload:
            cached = self._last_cmd[1]
            if cached is not None:
                self._send(cached)  # a retry: answer again, do not execute twice
            return  # still executing (EEPROM write cycle): the answer will come
        try:
            seq, code, args = decode_command(payload)
        except FormatError:
            self._send(encode_nak(0, 0, NakCode.BAD_PAYLOAD))
            return
        self._generate_due()  # samples due before the command was received go out first
        answer = self.core.execute(code, args)
        if not self.core.powered:
            self._power_off()  # power was lost while executing
            return
        reply: bytes | None = None
        if answer is not None:
            frame = encode_ack(seq, code, answer.data) if answer.ok else encode_nak(seq, code, NakCode(answer.error))
            if answer.due_s is None:
                reply = frame
            else:
                self._delayed.append((answer.due_s, frame))
        if code == Command.RESET and reply is not None:
            self._send(reply)
            self._boot(BootReason.RESET_COMMAND)
            return
        self._last_cmd = [payload, reply]
        if reply is not None:
            self._send(reply)


__all__ = ["DEFAULT_RATES_HZ", "Corrector", "PeerStats", "SampleSource", "SimulatedSensor", "identity_corrector"]
