"""The station side of the sensor protocol, whatever carries it: :class:`ProtocolSensor` and :class:`SampleBuffer`.

:class:`ProtocolSensor` implements the :class:`~station.sensor.protocol.Sensor` protocol's
commands on top of one transport hook, ``_exchange`` (send a command's payload, return the
sensor's ACK/NAK or None when it did not answer): the retry and refusal policy (a NAK is a
:class:`SensorNak`, no answer after every attempt a :class:`SensorTimeout`, an EEPROM still busy
is asked again), the typed commands and their reply decoding, power cycling (RESET, then wait
for the BOOT event) and the sample buffer behind ``read_samples``/``drain``. Transports:
:class:`station.sensor.client.SerialSensor` (frames over a serial port, a reader thread) and the
in-process fake of :mod:`station.sim.fakes` (calls into the simulated firmware).
"""

from __future__ import annotations

import threading
import time
from collections import deque

import numpy as np

from station.kernel.clock import Clock, WallClock
from station.kernel.errors import FormatError, HardwareError
from station.kernel.virtual_clock import is_virtual
from station.sensor.commands import (
    MAX_EEPROM_READ,
    Command,
    EepromInfo,
    NakCode,
    OutputMode,
    Reply,
    SensorIdentity,
    SensorStatus,
    pack_eeprom_read,
    pack_eeprom_write,
    pack_output,
    pack_rate,
    unpack_read_reply,
    unpack_write_reply,
)
from station.sensor.frames import ParserStats
from station.sensor.protocol import CrcStormError, LinkStats, SampleBlock, SensorLinkError, SensorNak, SensorTimeout


class SampleBuffer:
    """Received samples waiting to be read, oldest first, at most ``max_samples`` of them."""

    def __init__(self, max_samples: int) -> None:
        self.max_samples = int(max_samples)
        self._blocks: deque[SampleBlock] = deque()
        self._n = 0

    def __len__(self) -> int:
        return self._n

    def put(self, block: SampleBlock) -> int:
        """Append ``block``; returns how many of the oldest samples were dropped to stay within the limit."""
        self._blocks.append(block)
        self._n += len(block)
        dropped = 0
        while self._n > self.max_samples and self._blocks:
            excess = self._n - self.max_samples
            first = self._blocks[0]
            if len(first) <= excess:
                self._blocks.popleft()
                self._n -= len(first)
                dropped += len(first)
            else:
                self._blocks[0] = first.split(excess)[1]
                self._n -= excess
                dropped += excess
        return dropped

    def take_all(self) -> SampleBlock:
        """Everything buffered; the buffer is empty afterwards."""
        block = SampleBlock.concat(list(self._blocks))
        self._blocks.clear()
        self._n = 0
        return block

    def _put_back(self, block: SampleBlock) -> None:
        if len(block):
            self._blocks.appendleft(block)
            self._n += len(block)

    def take(self, n: int | None = None, duration_s: float | None = None) -> SampleBlock | None:
        """The first ``n`` samples, or those within ``duration_s`` of sensor time from the first one; None if
        the buffer does not hold them yet (a span is complete once a sample at or after its end arrived)."""
        if n is not None:
            if self._n < n:
                return None
            head, tail = self.take_all().split(n)
            self._put_back(tail)
            return head
        if duration_s is None or not self._blocks:
            return None
        t_end = self._blocks[0].t_s[0] + duration_s
        if self._blocks[-1].t_s[-1] < t_end - 1e-9:
            return None
        block = self.take_all()
        k = int(np.searchsorted(block.t_s, t_end - 1e-9, side="left"))
        head, tail = block.split(k)
        self._put_back(tail)
        return head

    def shortfall_s(self, n: int | None, duration_s: float | None, rate_hz: float) -> float:
        """Sensor seconds of streaming at ``rate_hz`` still missing for :meth:`take` to succeed (>= 0)."""
        if n is not None:
            return max(n - self._n, 0) / rate_hz
        if not self._blocks:
            return float(duration_s or 0.0) + 1.0 / rate_hz
        return max(self._blocks[0].t_s[0] + float(duration_s or 0.0) - self._blocks[-1].t_s[-1], 0.0)


class ProtocolSensor:
    """The :class:`~station.sensor.protocol.Sensor` protocol's semantics over a transport (see the module doc).

    Args:
        clock: the station clock (for sample-time waits); default wall clock.
        url: the sensor's URL; where: how messages name it (a port, the URL).
        command_timeout_s: wall seconds to wait for each command attempt's answer.
        attempts: transmissions per command (>= 1).
        max_buffered_samples: samples kept for :meth:`read_samples`; older ones are dropped beyond it.

    Transports implement ``_exchange``, ``_read``, ``_parser_stats`` and ``close``, and call
    ``_received_samples`` and ``_received_boot`` with what arrives.
    """

    def __init__(
        self,
        clock: Clock | None,
        url: str,
        where: str,
        *,
        command_timeout_s: float = 0.5,
        attempts: int = 3,
        max_buffered_samples: int = 1_000_000,
    ) -> None:
        if attempts < 1:
            raise ValueError("attempts must be >= 1")
        self.url = url
        self._where = where
        self._clock: Clock = clock if clock is not None else WallClock()
        self.command_timeout_s = float(command_timeout_s)
        self.attempts = int(attempts)
        self._cmd_lock = threading.Lock()
        self._cond = threading.Condition()
        self._buffer = SampleBuffer(max_buffered_samples)
        self._boot_event = threading.Event()
        self._counts = {"samples": 0, "retries": 0, "timeouts": 0, "naks": 0, "boots": 0, "stray": 0, "overruns": 0}
        self._storm: str | None = None
        self._link_error: str | None = None
        self.identity: SensorIdentity | None = None
        self._rate_hz: int | None = None

    # --- transport hooks ------------------------------------------------------------------------

    def _exchange(self, command: Command, args: bytes, attempt: int) -> tuple[Reply | None, int]:
        """Send ``command`` until answered, from attempt number ``attempt`` on; (reply or None, attempts used)."""
        raise NotImplementedError

    def _read(self, n: int | None, duration_s: float | None, timeout_s: float) -> SampleBlock:
        """Wait until :meth:`SampleBuffer.take` succeeds within ``timeout_s`` clock seconds."""
        raise NotImplementedError

    def _parser_stats(self) -> ParserStats:
        raise NotImplementedError

    def close(self) -> None:
        raise NotImplementedError

    def _received_samples(self, block: SampleBlock) -> None:
        """Buffer samples that arrived (any thread)."""
        with self._cond:
            self._counts["samples"] += len(block)
            self._counts["overruns"] += self._buffer.put(block)
            self._cond.notify_all()

    def _received_boot(self) -> None:
        self._counts["boots"] += 1
        self._boot_event.set()

    def _samples_timeout(self, timeout_s: float) -> SensorTimeout:
        return SensorTimeout(f"sensor on {self._where}: only {len(self._buffer)} samples within {timeout_s} s")

    # --- faults -------------------------------------------------------------------------------------

    def _check_fault(self) -> None:
        if self._link_error is not None:
            raise SensorLinkError(self._link_error)
        if self._storm is not None:
            raise CrcStormError(self._storm)

    def clear_fault(self) -> None:
        """Unlatch a CRC-storm fault."""
        with self._cond:
            self._storm = None

    # --- commands -----------------------------------------------------------------------------------

    def _command(self, command: Command, args: bytes = b"") -> bytes:
        """Send a command, wait for its ACK with retries; returns the reply data."""
        self._check_fault()
        with self._cmd_lock:
            attempt = 0
            while True:
                reply, attempt = self._exchange(command, args, attempt)
                if reply is None:
                    self._counts["timeouts"] += 1
                    self._check_fault()
                    raise SensorTimeout(
                        f"sensor on {self._where} did not answer {command.name} "
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
            raise SensorTimeout(f"sensor on {self._where} acknowledged RESET but sent no BOOT event")
        self._rate_hz = self.identity.default_rate_hz if self.identity else None

    # --- samples ------------------------------------------------------------------------------------

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
        span = duration_s if duration_s is not None else (n or 0) / rate  # n is given when duration_s is not
        if timeout_s is None:
            timeout_s = 1.5 * span + 1.0
        if is_virtual(self._clock):
            return self._read_virtual(n, duration_s, timeout_s)
        return self._read(n, duration_s, timeout_s)

    def _read_virtual(self, n: int | None, duration_s: float | None, timeout_s: float) -> SampleBlock:
        """:meth:`read_samples` on a virtual clock: a GET_STATUS round trip is the barrier after which every
        sample due by now has been received (the sensor sends them before its answer); if the buffer does not
        hold the span yet, let the missing sensor time pass on the clock and look again."""
        deadline = self._clock.now() + timeout_s
        rate = float(self._rate_hz or 10)
        while True:
            self.status()
            with self._cond:
                self._check_fault()
                block = self._buffer.take(n, duration_s)
                if block is not None:
                    return block
                missing = self._buffer.shortfall_s(n, duration_s, rate)
            if self._clock.now() >= deadline:
                raise self._samples_timeout(timeout_s)
            self._clock.sleep(max(missing, 1e-6) + 1e-6)

    def drain(self) -> SampleBlock:
        """Everything buffered right now, without waiting (raises if the link is faulty).

        On a virtual clock "right now" is exact: a GET_STATUS round trip first (the sensor sends every
        sample due before its answer), so what is taken does not depend on how fast the frames travelled.
        """
        if is_virtual(self._clock) and self._rate_hz is not None:
            self.status()
        with self._cond:
            self._check_fault()
            return self._buffer.take_all()

    @property
    def buffered(self) -> int:
        """Samples waiting in the buffer."""
        return len(self._buffer)

    def stats(self) -> LinkStats:
        """A snapshot of the link and capture counters."""
        p = self._parser_stats()
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

    def __enter__(self) -> ProtocolSensor:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


__all__ = ["ProtocolSensor", "SampleBuffer"]
