"""Station-side client of the IMU serial protocol: :func:`open_sensor` returns a :class:`SerialSensor`.

A background reader thread parses everything the sensor sends: SAMPLE frames are
decoded in batches into a bounded buffer (:meth:`SerialSensor.read_samples`),
ACK/NAK frames complete the one outstanding command, BOOT events are counted.
Commands work while streaming (their answers interleave with samples); each is
retried a bounded number of times with the same command sequence number, which the
sensor answers from its cache instead of executing twice.

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

import numpy as np
import serial

from station.kernel.clock import Clock, WallClock
from station.kernel.errors import FormatError, HardwareError
from station.sensor.commands import (
    MAX_EEPROM_READ,
    BootEvent,
    Command,
    EepromInfo,
    NakCode,
    OutputMode,
    Reply,
    SensorIdentity,
    SensorStatus,
    decode_reply,
    encode_command,
    pack_eeprom_read,
    pack_eeprom_write,
    pack_output,
    pack_rate,
    unpack_read_reply,
    unpack_write_reply,
)
from station.sensor.frames import FrameParser, FrameType, decode_sample_payloads
from station.sensor.protocol import (
    CrcStormError,
    LinkStats,
    SampleBlock,
    SensorLinkError,
    SensorNak,
    SensorTimeout,
)
from station.sensor.url import parse_sensor_url

_T_SAMPLE = int(FrameType.SAMPLE)
_T_REPLY = (int(FrameType.ACK), int(FrameType.NAK))


@dataclass
class _Pending:
    seq: int
    command: int
    event: threading.Event = field(default_factory=threading.Event)
    reply: Reply | None = None


class SerialSensor:
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
        if attempts < 1:
            raise ValueError("attempts must be >= 1")
        self._port = port
        self.url = url if url is not None else f"serial://{port.port}"
        self._clock: Clock = clock if clock is not None else WallClock()
        self.command_timeout_s = float(command_timeout_s)
        self.attempts = int(attempts)
        self._crc_window = int(crc_window_frames)
        self._crc_threshold = float(crc_error_threshold)
        self._max_buffered = int(max_buffered_samples)

        self._parser = FrameParser()
        self._cmd_lock = threading.Lock()
        self._next_cmd_seq = 0
        self._pending: _Pending | None = None
        self._cond = threading.Condition()
        self._blocks: deque[SampleBlock] = deque()
        self._n_buffered = 0
        self._boot_event = threading.Event()
        self._counts = {"samples": 0, "retries": 0, "timeouts": 0, "naks": 0, "boots": 0, "stray": 0, "overruns": 0}
        self._win: deque[tuple[int, int]] = deque()
        self._win_good = 0
        self._win_bad = 0
        self._storm: str | None = None
        self._link_error: str | None = None
        self.identity: SensorIdentity | None = None
        self._rate_hz: int | None = None

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
                    self._store(SampleBlock.from_records(decode_sample_payloads(payloads)))
                    payloads = []
                if f.type in _T_REPLY:
                    self._dispatch(f)
                elif f.type == FrameType.EVENT:
                    try:
                        BootEvent.decode(f.payload)
                    except FormatError:
                        continue
                    self._counts["boots"] += 1
                    self._boot_event.set()
            if payloads:
                self._store(SampleBlock.from_records(decode_sample_payloads(payloads)))
            n_frames, n_crc = self._parser.frames, self._parser.crc_errors
            self._update_crc_window(n_frames - last_frames, n_crc - last_crc)
            last_frames, last_crc = n_frames, n_crc

    def _dispatch(self, frame: object) -> None:
        try:
            reply = decode_reply(frame)  # type: ignore[arg-type]
        except FormatError:
            self._counts["stray"] += 1
            return
        p = self._pending
        if p is not None and p.seq == reply.seq and p.command == reply.command and not p.event.is_set():
            p.reply = reply
            p.event.set()
        else:
            self._counts["stray"] += 1

    def _store(self, block: SampleBlock) -> None:
        with self._cond:
            self._blocks.append(block)
            self._n_buffered += len(block)
            self._counts["samples"] += len(block)
            while self._n_buffered > self._max_buffered and self._blocks:
                excess = self._n_buffered - self._max_buffered
                first = self._blocks[0]
                if len(first) <= excess:
                    self._blocks.popleft()
                    self._n_buffered -= len(first)
                    self._counts["overruns"] += len(first)
                else:
                    self._blocks[0] = first.split(excess)[1]
                    self._n_buffered -= excess
                    self._counts["overruns"] += excess
            self._cond.notify_all()

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

    def _check_fault(self) -> None:
        if self._link_error is not None:
            raise SensorLinkError(self._link_error)
        if self._storm is not None:
            raise CrcStormError(self._storm)

    def clear_fault(self) -> None:
        """Unlatch a CRC-storm fault and restart its window."""
        with self._cond:
            self._storm = None
            self._win.clear()
            self._win_good = self._win_bad = 0

    # --- commands -----------------------------------------------------------------------------------

    def _write(self, data: bytes) -> None:
        try:
            self._port.write(data)
        except (serial.SerialException, OSError) as exc:
            raise SensorLinkError(f"writing to {self._port.port} failed: {exc}") from exc

    def _command(self, command: Command, args: bytes = b"") -> bytes:
        """Send a command, wait for its ACK with retries; returns the reply data."""
        self._check_fault()
        with self._cmd_lock:
            attempt = 0
            while True:
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
                        if pending.event.wait(self.command_timeout_s):
                            break
                        self._check_fault()
                finally:
                    self._pending = None
                reply = pending.reply
                if reply is None:
                    self._counts["timeouts"] += 1
                    self._check_fault()
                    raise SensorTimeout(
                        f"sensor on {self._port.port} did not answer {command.name} "
                        f"({self.attempts} attempts, {self.command_timeout_s} s each)"
                    )
                if reply.ok:
                    return reply.data
                if reply.error == NakCode.BUSY and attempt < self.attempts:
                    # EEPROM write cycle still running: try again with a fresh sequence number.
                    self._counts["retries"] += 1
                    time.sleep(min(0.01, self.command_timeout_s))
                    continue
                self._counts["naks"] += 1
                raise SensorNak(int(command), reply.error)

    def identify(self) -> SensorIdentity:
        """Serial number, firmware, supported rates and scale factors."""
        try:
            ident = SensorIdentity.decode(self._command(Command.IDENTIFY))
        except FormatError as exc:
            raise HardwareError(f"sensor sent a malformed IDENTIFY reply: {exc}") from exc
        self.identity = ident
        if self._rate_hz is None:
            self._rate_hz = ident.default_rate_hz
        return ident

    def status(self) -> SensorStatus:
        """Streaming state, rate, output mode, uptime, counters."""
        try:
            return SensorStatus.decode(self._command(Command.GET_STATUS))
        except FormatError as exc:
            raise HardwareError(f"sensor sent a malformed STATUS reply: {exc}") from exc

    def start_stream(self, rate_hz: int | None = None) -> None:
        """Start streaming at ``rate_hz`` (Hz; None keeps the sensor's current rate)."""
        self._command(Command.START_STREAM, pack_rate(rate_hz or 0))
        if rate_hz:
            self._rate_hz = rate_hz

    def stop_stream(self) -> None:
        """Stop streaming (samples already sent stay in the buffer)."""
        self._command(Command.STOP_STREAM)

    def set_rate(self, rate_hz: int) -> None:
        """Change the sample rate (Hz), also while streaming."""
        self._command(Command.SET_RATE, pack_rate(rate_hz))
        self._rate_hz = rate_hz

    def set_output(self, mode: OutputMode | str) -> None:
        """Switch between ``raw`` and ``corrected`` output."""
        if isinstance(mode, str):
            try:
                mode = OutputMode[mode.upper()]
            except KeyError as exc:
                raise ValueError(f"output mode must be 'raw' or 'corrected', not {mode!r}") from exc
        self._command(Command.SET_OUTPUT, pack_output(mode))

    def eeprom_info(self) -> EepromInfo:
        """EEPROM size, page size, write-protect state, write-cycle time."""
        try:
            return EepromInfo.decode(self._command(Command.EEPROM_INFO))
        except FormatError as exc:
            raise HardwareError(f"sensor sent a malformed EEPROM_INFO reply: {exc}") from exc

    def eeprom_read(self, addr: int, n: int) -> bytes:
        """``n`` bytes from EEPROM address ``addr`` (split into reads of at most 256 bytes)."""
        out = bytearray()
        while len(out) < n:
            a = addr + len(out)
            k = min(MAX_EEPROM_READ, n - len(out))
            try:
                got_addr, data = unpack_read_reply(self._command(Command.EEPROM_READ, pack_eeprom_read(a, k)))
            except FormatError as exc:
                raise HardwareError(f"sensor sent a malformed EEPROM_READ reply: {exc}") from exc
            if got_addr != a or len(data) != k:
                raise HardwareError(f"EEPROM read of {k} bytes at {a} answered with {len(data)} bytes at {got_addr}")
            out += data
        return bytes(out)

    def eeprom_write_page(self, addr: int, data: bytes) -> None:
        """Write ``data`` (within one page) at ``addr``; returns after the write cycle is acknowledged."""
        try:
            got_addr, length = unpack_write_reply(
                self._command(Command.EEPROM_WRITE_PAGE, pack_eeprom_write(addr, data))
            )
        except FormatError as exc:
            raise HardwareError(f"sensor sent a malformed EEPROM_WRITE_PAGE reply: {exc}") from exc
        if got_addr != addr or length != len(data):
            raise HardwareError(f"EEPROM write of {len(data)} bytes at {addr} acknowledged as {length} at {got_addr}")

    def eeprom_write(self, addr: int, data: bytes, page_size: int | None = None) -> None:
        """Write ``data`` at ``addr`` split at page boundaries (page size from :meth:`eeprom_info` if None)."""
        if page_size is None:
            page_size = self.eeprom_info().page_size
        pos = 0
        while pos < len(data):
            a = addr + pos
            k = min(page_size - a % page_size, len(data) - pos)
            self.eeprom_write_page(a, data[pos : pos + k])
            pos += k

    def power_cycle(self, boot_timeout_s: float | None = None) -> None:
        """Reset the sensor (RESET command) and wait for its BOOT event.

        The sensor restarts its time base, sequence counter and drift physics; streaming
        stops, rate and output mode return to their power-on defaults.
        """
        self._boot_event.clear()
        self._command(Command.RESET)
        if not self._boot_event.wait(boot_timeout_s if boot_timeout_s is not None else self.command_timeout_s):
            raise SensorTimeout(f"sensor on {self._port.port} acknowledged RESET but sent no BOOT event")
        self._rate_hz = self.identity.default_rate_hz if self.identity else None

    # --- samples ------------------------------------------------------------------------------------

    def _wall(self, clock_s: float) -> float:
        return clock_s / self._clock.scale

    def _take_all(self) -> SampleBlock:
        block = SampleBlock.concat(list(self._blocks))
        self._blocks.clear()
        self._n_buffered = 0
        return block

    def _put_back(self, block: SampleBlock) -> None:
        if len(block):
            self._blocks.appendleft(block)
            self._n_buffered += len(block)

    def read_samples(
        self, n: int | None = None, *, duration_s: float | None = None, timeout_s: float | None = None
    ) -> SampleBlock:
        """Wait for and return the next ``n`` samples, or the next ``duration_s`` of sensor time.

        With ``duration_s`` the block holds the samples with ``t < t_first + duration_s``
        (s, sensor time), so at rate f it has ``duration_s * f`` samples if none were lost.
        ``timeout_s`` (clock seconds) defaults to 1.5 times the expected span plus 1 s.

        Raises:
            SensorTimeout: not enough samples in time (those that came stay buffered).
            CrcStormError, SensorLinkError: the link is faulty.
        """
        if (n is None) == (duration_s is None):
            raise ValueError("give exactly one of n and duration_s")
        rate = self._rate_hz or 10
        span = duration_s if duration_s is not None else n / rate  # type: ignore[operator]
        if timeout_s is None:
            timeout_s = 1.5 * span + 1.0
        deadline = time.monotonic() + self._wall(timeout_s) + self.command_timeout_s
        with self._cond:
            while True:
                self._check_fault()
                if n is not None and self._n_buffered >= n:
                    head, tail = self._take_all().split(n)
                    self._put_back(tail)
                    return head
                if duration_s is not None and self._blocks:
                    t_end = self._blocks[0].t_s[0] + duration_s
                    if self._blocks[-1].t_s[-1] >= t_end - 1e-9:
                        block = self._take_all()
                        k = int(np.searchsorted(block.t_s, t_end - 1e-9, side="left"))
                        head, tail = block.split(k)
                        self._put_back(tail)
                        return head
                remaining = deadline - time.monotonic()
                if remaining <= 0:
                    raise SensorTimeout(
                        f"sensor on {self._port.port}: only {self._n_buffered} samples within {timeout_s} s"
                    )
                self._cond.wait(remaining)

    def drain(self) -> SampleBlock:
        """Everything buffered right now, without waiting (raises if the link is faulty)."""
        with self._cond:
            self._check_fault()
            return self._take_all()

    @property
    def buffered(self) -> int:
        """Samples waiting in the buffer."""
        return self._n_buffered

    def stats(self) -> LinkStats:
        """A snapshot of the link and capture counters."""
        p = self._parser.stats()
        c = self._counts
        return LinkStats(
            frames=p.frames,
            samples=c["samples"],
            crc_errors=p.crc_errors,
            bad_headers=p.bad_headers,
            resyncs=p.resyncs,
            bytes_discarded=p.bytes_discarded,
            gaps=p.gaps,
            lost_frames=p.lost_frames,
            duplicates=p.duplicates,
            restarts=p.restarts,
            retries=c["retries"],
            timeouts=c["timeouts"],
            naks=c["naks"],
            boots=c["boots"],
            stray_replies=c["stray"],
            buffer_overruns=c["overruns"],
            crc_storm=self._storm is not None,
        )

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

    def __exit__(self, *exc: object) -> None:
        self.close()


def open_sensor(
    url: str,
    clock: Clock | None = None,
    *,
    command_timeout_s: float = 0.5,
    attempts: int = 3,
    crc_window_frames: int = 500,
    crc_error_threshold: float = 0.1,
    max_buffered_samples: int = 1_000_000,
) -> SerialSensor:
    """Open the sensor at ``url`` (``serial:///dev/ttyUSB0?baud=921600``, ``serial:///dev/pts/N``).

    Input already waiting on the port is discarded. Raises :class:`~station.sensor.url.SensorUrlError`
    for a bad URL and :class:`SensorLinkError` when the port cannot be opened.
    """
    where = parse_sensor_url(url)
    try:
        port = serial.Serial(where.path, baudrate=where.baudrate, timeout=0.1, write_timeout=2.0)
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
