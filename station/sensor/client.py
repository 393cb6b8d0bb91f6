"""Station-side client of the IMU serial protocol: :func:`open_sensor` returns a :class:`SerialSensor`.

A background reader thread parses everything the sensor sends: SAMPLE frames are
decoded in batches into a bounded buffer (:meth:`SerialSensor.read_samples`),
ACK/NAK frames complete the one outstanding command, BOOT events are counted.
Commands work while streaming (their answers interleave with samples); each is
retried a bounded number of times with the same command sequence number, which the
sensor answers from its cache instead of executing twice. What a command means, and
the sample buffer, are :class:`~station.sensor.base.ProtocolSensor`'s; this module is the
serial transport under it.

Failures are station faults (:class:`~station.kernel.errors.HardwareError`), not unit
failures: :class:`SensorTimeout` (no answer), :class:`SensorNak` (refused),
:class:`CrcStormError` (CRC error rate over the window above threshold; latched until
:meth:`SerialSensor.clear_fault`), :class:`SensorLinkError` (the port itself failed).

Time: ``command_timeout_s`` is wall-clock time (it covers OS and link latency);
``read_samples`` durations and timeouts are in the given clock's seconds (a
:class:`~station.kernel.clock.SimClock` shortens the wall wait by its scale).
"""

from __future__ import annotations

import contextlib
import threading
import time
from collections import deque
from dataclasses import dataclass, field

import serial

from station.kernel.clock import Clock
from station.kernel.errors import FormatError
from station.kernel.virtual_clock import is_virtual
from station.sensor.base import ProtocolSensor
from station.sensor.commands import BootEvent, Command, Reply, decode_reply, encode_command
from station.sensor.frames import Frame, FrameParser, FrameType, ParserStats, decode_sample_payloads
from station.sensor.protocol import (
    CrcStormError,
    SampleBlock,
    SensorLinkError,
    SensorNak,
    SensorTimeout,
)
from station.sensor.serial_url import parse_sensor_url

_T_SAMPLE = int(FrameType.SAMPLE)
_T_REPLY = (int(FrameType.ACK), int(FrameType.NAK))


@dataclass
class _Pending:
    seq: int
    command: int
    event: threading.Event = field(default_factory=threading.Event)
    reply: Reply | None = None


class SerialSensor(ProtocolSensor):
    """One connected sensor. Create with :func:`open_sensor`.

    Args:
        port: an open pyserial port.
        clock: the station clock (for sample-time waits); default wall clock.
        command_timeout_s: wall seconds to wait for each command attempt's answer.
        attempts: transmissions per command (>= 1).
        crc_window_frames: size of the CRC-storm window (frames, good + CRC-failed).
        crc_error_threshold: CRC-failed fraction of the window that latches a :class:`CrcStormError`.
        max_buffered_samples: samples kept for :meth:`read_samples`; older ones are dropped beyond it.
    """

    def __init__(
        self,
        port: serial.Serial,
        clock: Clock | None = None,
        *,
        command_timeout_s: float = 0.5,
        attempts: int = 3,
        crc_window_frames: int = 500,
        crc_error_threshold: float = 0.1,
        max_buffered_samples: int = 1_000_000,
        url: str | None = None,
    ) -> None:
        super().__init__(
            clock,
            url if url is not None else f"serial://{port.port}",
            str(port.port),
            command_timeout_s=command_timeout_s,
            attempts=attempts,
            max_buffered_samples=max_buffered_samples,
        )
        self._port = port
        self._crc_window = int(crc_window_frames)
        self._crc_threshold = float(crc_error_threshold)

        self._parser = FrameParser()
        self._next_cmd_seq = 0
        self._pending: _Pending | None = None
        self._win: deque[tuple[int, int]] = deque()
        self._win_good = 0
        self._win_bad = 0

        self._stop = threading.Event()
        self._reader = threading.Thread(target=self._read_loop, name=f"sensor-reader-{port.port}", daemon=True)
        self._reader.start()

    # --- reader thread ----------------------------------------------------------------------------

    def _read_loop(self) -> None:
        try:
            self._read_frames()
        except Exception as exc:  # a bug must not leave callers waiting for answers that never come
            self._link_error = f"reader of {self._port.port} crashed: {exc!r}"
            with self._cond:
                self._cond.notify_all()
            raise

    def _read_frames(self) -> None:
        port = self._port
        last_frames = 0
        last_crc = 0
        while not self._stop.is_set():
            try:
                data = port.read(1)  # blocks up to the port timeout for the first byte
                waiting = port.in_waiting if data else 0
                if waiting:
                    data += port.read(waiting)
            except (serial.SerialException, OSError, TypeError, AttributeError) as exc:
                if not self._stop.is_set():
                    self._link_error = f"serial port {port.port} failed: {exc}"
                    with self._cond:
                        self._cond.notify_all()
                return
            if not data:
                continue
            frames = self._parser.feed(data)
            payloads: list[bytes] = []
            for f in frames:
                if f.type == _T_SAMPLE:
                    payloads.append(f.payload)
                    continue
                if payloads:
                    # Samples sent before an answer are buffered before the waiting command returns.
                    self._received_samples(SampleBlock.from_records(decode_sample_payloads(payloads)))
                    payloads = []
                if f.type in _T_REPLY:
                    self._dispatch(f)
                elif f.type == FrameType.EVENT:
                    try:
                        BootEvent.decode(f.payload)
                    except FormatError:
                        continue
                    self._received_boot()
            if payloads:
                self._received_samples(SampleBlock.from_records(decode_sample_payloads(payloads)))
            n_frames, n_crc = self._parser.frames, self._parser.crc_errors
            self._update_crc_window(n_frames - last_frames, n_crc - last_crc)
            last_frames, last_crc = n_frames, n_crc

    def _dispatch(self, frame: Frame) -> None:
        try:
            reply = decode_reply(frame)
        except FormatError:
            self._counts["stray"] += 1
            return
        p = self._pending
        if p is not None and p.seq == reply.seq and p.command == reply.command and not p.event.is_set():
            p.reply = reply
            p.event.set()
        else:
            self._counts["stray"] += 1

    def _update_crc_window(self, good: int, bad: int) -> None:
        if good == 0 and bad == 0:
            return
        with self._cond:
            self._update_window_locked(good, bad)

    def _update_window_locked(self, good: int, bad: int) -> None:
        self._win.append((good, bad))
        self._win_good += good
        self._win_bad += bad
        while len(self._win) > 1:
            g0, b0 = self._win[0]
            if self._win_good + self._win_bad - g0 - b0 < self._crc_window:
                break
            self._win.popleft()
            self._win_good -= g0
            self._win_bad -= b0
        total = self._win_good + self._win_bad
        if self._storm is None and total >= self._crc_window and self._win_bad > self._crc_threshold * total:
            self._storm = (
                f"CRC storm on {self._port.port}: {self._win_bad} of the last {total} frames failed their CRC "
                f"(threshold {self._crc_threshold:.0%})"
            )
            self._cond.notify_all()

    # --- faults -------------------------------------------------------------------------------------

    def clear_fault(self) -> None:
        """Unlatch a CRC-storm fault and restart its window."""
        with self._cond:
            self._storm = None
            self._win.clear()
            self._win_good = self._win_bad = 0

    # --- the transport --------------------------------------------------------------------------------

    def _write(self, data: bytes) -> None:
        try:
            self._port.write(data)
        except (serial.SerialException, OSError) as exc:
            raise SensorLinkError(f"writing to {self._port.port} failed: {exc}") from exc

    def _exchange(self, command: Command, args: bytes, attempt: int) -> tuple[Reply | None, int]:
        """Send one COMMAND frame (a new sequence number) until answered or out of attempts."""
        seq = self._next_cmd_seq
        self._next_cmd_seq = (seq + 1) & 0xFFFF
        frame = encode_command(seq, command, args)
        pending = _Pending(seq, int(command))
        self._pending = pending
        try:
            while attempt < self.attempts:
                if attempt:
                    self._counts["retries"] += 1
                attempt += 1
                self._write(frame)
                if self._await(pending):
                    break
                self._check_fault()
        finally:
            self._pending = None
        return pending.reply, attempt

    def _await(self, pending: _Pending) -> bool:
        """Wait for the answer to one transmission: ``command_timeout_s`` wall seconds.

        On a virtual clock the sensor answers after every sample due by now, and time may have run far
        ahead of the link: while frames keep arriving the link is alive, and the wait goes on (the backlog
        is finite, as no time passes meanwhile); ``command_timeout_s`` then counts from the last frame.
        """
        if not is_virtual(self._clock):
            return pending.event.wait(self.command_timeout_s)
        seen = self._parser.frames
        while not pending.event.wait(self.command_timeout_s):
            if self._parser.frames == seen:
                return False
            seen = self._parser.frames
        return True

    def _wall(self, clock_s: float) -> float:
        return clock_s / self._clock.scale

    def _read(self, n: int | None, duration_s: float | None, timeout_s: float) -> SampleBlock:
        deadline = time.monotonic() + self._wall(timeout_s) + self.command_timeout_s
        with self._cond:
            while True:
                self._check_fault()
                block = self._buffer.take(n, duration_s)
                if block is not None:
                    return block
                remaining = deadline - time.monotonic()
                if remaining <= 0:
                    raise self._samples_timeout(timeout_s)
                self._cond.wait(remaining)

    def _parser_stats(self) -> ParserStats:
        return self._parser.stats()

    # --- lifetime -----------------------------------------------------------------------------------

    def close(self) -> None:
        """Stop the reader thread and close the port (idempotent)."""
        if self._stop.is_set():
            return
        self._stop.set()
        with contextlib.suppress(AttributeError, OSError, serial.SerialException):
            self._port.cancel_read()
        self._reader.join(timeout=2.0)
        with contextlib.suppress(OSError, serial.SerialException):
            self._port.close()

    def __enter__(self) -> SerialSensor:
        return self


def open_sensor(
    url: str,
    clock: Clock | None = None,
    *,
    command_timeout_s: float = 0.5,
    attempts: int = 3,
    crc_window_frames: int = 500,
    crc_error_threshold: float = 0.1,
    max_buffered_samples: int = 1_000_000,
    write_timeout_s: float = 2.0,
) -> SerialSensor:
    """Open the sensor at ``url`` (``serial:///dev/ttyUSB0?baud=921600``, ``serial:///dev/pts/N``).

    ``write_timeout_s``: wall seconds a write may take (pyserial's ``write_timeout``, which also counts the time
    the writing thread waited for the CPU).

    Input already waiting on the port is discarded. Raises :class:`~station.sensor.serial_url.SensorUrlError`
    for a bad URL and :class:`SensorLinkError` when the port cannot be opened.
    """
    where = parse_sensor_url(url)
    try:
        port = serial.Serial(where.path, baudrate=where.baudrate, timeout=0.1, write_timeout=write_timeout_s)
    except (serial.SerialException, OSError, ValueError) as exc:
        raise SensorLinkError(f"cannot open sensor port {where.path}: {exc}") from exc
    port.reset_input_buffer()
    return SerialSensor(
        port,
        clock,
        command_timeout_s=command_timeout_s,
        attempts=attempts,
        crc_window_frames=crc_window_frames,
        crc_error_threshold=crc_error_threshold,
        max_buffered_samples=max_buffered_samples,
        url=url,
    )


__all__ = [
    "CrcStormError",
    "SampleBlock",
    "SensorLinkError",
    "SensorNak",
    "SensorTimeout",
    "SerialSensor",
    "open_sensor",
]
