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
eq. 1 and eq. 3 of the paper live there); power-on restarts it.

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
import math
import os
import select
import threading
import tty
from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from station.kernel.clock import Clock, WallClock
from station.kernel.errors import FormatError
from station.sensor.commands import (
    MAX_EEPROM_READ,
    BootEvent,
    BootReason,
    Command,
    EepromInfo,
    NakCode,
    OutputMode,
    SensorIdentity,
    SensorStatus,
    decode_command,
    encode_ack,
    encode_nak,
    pack_read_reply,
    pack_write_reply,
    unpack_eeprom_read,
    unpack_eeprom_write,
    unpack_rate,
)
from station.sensor.frames import (
    SAMPLE_FRAME_SIZE,
    SEQ_MODULUS,
    FrameParser,
    FrameType,
    SampleFlag,
    encode_frame,
    encode_sample_frames,
)
from station.sim.eeprom import (
    Eeprom,
    EepromAddressError,
    EepromBusyError,
    EepromError,
    EepromPageBoundaryError,
    EepromWriteProtectedError,
)

DEFAULT_RATES_HZ = (10, 50, 100, 200, 250, 500, 1000)


class SampleSource(Protocol):
    """What the simulated sensor measures.

    ``render`` is called with strictly increasing sensor times (s since power-on),
    in chunks of any size, never twice for the same time within one power cycle,
    and returns ``(accel (n, 3) m/s^2, gyro (n, 3) rad/s, temp (n,) degC)`` as the
    sensor's raw output. ``power_on`` restarts the physics (time base back to 0,
    drift state g(0) = 1 of eq. 3); it is called at every boot, including the first.
    """

    def render(self, t_s: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]: ...

    def power_on(self) -> None: ...


Corrector = Callable[[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]
"""On-sensor correction for CORRECTED output: ``(accel (n,3) m/s^2, gyro (n,3) rad/s) -> same``.

Called in time order with consecutive chunks. If the object also has a ``reset()``
method it is called at every power-on (Algorithm 1 restarts with g = 1)."""


def identity_corrector(accel: np.ndarray, gyro: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Default corrector: passes values through unchanged.

    Placeholder until a sensor is configured with Algorithm 1 (station.correct); with it,
    CORRECTED output equals RAW output except for the CORRECTED flag.
    """
    return accel, gyro


_NAK_FOR: dict[type[EepromError], NakCode] = {
    EepromAddressError: NakCode.ADDRESS_RANGE,
    EepromPageBoundaryError: NakCode.PAGE_BOUNDARY,
    EepromWriteProtectedError: NakCode.WRITE_PROTECTED,
    EepromBusyError: NakCode.BUSY,
}


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


class SimulatedSensor:
    """Simulated IMU firmware on a pty; connect with ``open_sensor(sensor.url)``.

    Args:
        source: the sensor physics (:class:`SampleSource`).
        clock: time base; :class:`~station.kernel.clock.SimClock` runs it faster than real time.
        serial: serial number reported by IDENTIFY.
        firmware: firmware version reported by IDENTIFY.
        rates_hz: supported rates (Hz); each must divide 1e6.
        default_rate_hz: rate after power-on (Hz).
        eeprom: the unit's EEPROM; default 4 KiB, 32-byte pages, 5 ms write cycle on ``clock``.
        corrector: on-sensor correction used in CORRECTED mode; default identity.
        accel_range_mps2, gyro_range_radps: full scale reported by IDENTIFY (values are not clipped).
        accel_resolution_mps2, gyro_resolution_radps: ADC LSB reported by IDENTIFY (0: not quantized).
        seed: seed of the fault-injection generators.
        tick_s: wall-clock period of the firmware loop (s).
        tx_backlog_limit: bytes the sensor buffers when the host does not read; further
            sample frames are dropped and counted as ``tx_overruns``.
    """

    def __init__(
        self,
        source: SampleSource,
        clock: Clock | None = None,
        *,
        serial: str = "SIM-000001",
        firmware: str = "sim-1.0.0",
        rates_hz: tuple[int, ...] = DEFAULT_RATES_HZ,
        default_rate_hz: int = 100,
        eeprom: Eeprom | None = None,
        corrector: Corrector | None = None,
        accel_range_mps2: float = 16 * 9.80665,
        gyro_range_radps: float = math.radians(2000.0),
        accel_resolution_mps2: float = 0.0,
        gyro_resolution_radps: float = 0.0,
        seed: int = 0,
        tick_s: float = 0.01,
        tx_backlog_limit: int = 256 * 1024,
    ) -> None:
        for r in rates_hz:
            if r <= 0 or 1_000_000 % r:
                raise ValueError(f"sample rate {r} Hz must divide 1e6 (whole-µs sample period)")
        if default_rate_hz not in rates_hz:
            raise ValueError("default_rate_hz must be one of rates_hz")
        self._source = source
        self._clock: Clock = clock if clock is not None else WallClock()
        self.identity = SensorIdentity(
            serial=serial,
            firmware=firmware,
            rates_hz=tuple(rates_hz),
            default_rate_hz=default_rate_hz,
            accel_range_mps2=accel_range_mps2,
            gyro_range_radps=gyro_range_radps,
            accel_resolution_mps2=accel_resolution_mps2,
            gyro_resolution_radps=gyro_resolution_radps,
        )
        self.identity.encode()  # validates serial/firmware lengths now
        self.eeprom = eeprom if eeprom is not None else Eeprom(clock=self._clock)
        self.corrector: Corrector = corrector if corrector is not None else identity_corrector
        self.bit_error_rate = 0.0
        self.drop_frame_rate = 0.0
        self.go_silent = False
        self._tick_s = float(tick_s)
        self._tx_limit = int(tx_backlog_limit)

        ss = np.random.SeedSequence(seed)
        drop_ss, count_ss, pos_ss, other_ss = ss.spawn(4)
        self._rng_drop = np.random.default_rng(drop_ss)
        self._rng_flip_count = np.random.default_rng(count_ss)
        self._rng_flip_pos = np.random.default_rng(pos_ss)
        self._rng_other = np.random.default_rng(other_ss)

        self._lock = threading.RLock()
        self._parser = FrameParser(track_sequence=False)
        self._tx = bytearray()
        self._stats = dict.fromkeys(PeerStats.__dataclass_fields__, 0)
        self._powered = False
        self._boot_count = 0
        self._t_power_on = 0.0
        self._streaming = False
        self._rate_hz = default_rate_hz
        self._output = OutputMode.RAW
        self._seq = 0
        self._next_t_us = 0
        self._pending_flags = 0
        self._last_cmd: list[bytes | None] | None = None  # [command payload, reply frame or None while pending]
        self._delayed: list[tuple[float, bytes]] = []  # (clock time due, reply frame)

        self._master, self._slave = os.openpty()
        tty.setraw(self._slave)
        os.set_blocking(self._master, False)
        self.device = os.ttyname(self._slave)
        self.url = f"serial://{self.device}"

        with self._lock:
            self._boot(BootReason.POWER_ON)
        self._stop = threading.Event()
        self._error: BaseException | None = None
        self._thread = threading.Thread(target=self._run, name=f"sim-sensor-{serial}", daemon=True)
        self._thread.start()

    # --- public controls ------------------------------------------------------------------------

    @property
    def powered(self) -> bool:
        """The sensor has power."""
        return self._powered

    def power_off(self) -> None:
        """Cut the power: streaming stops, unsent bytes and half-done commands are lost."""
        with self._lock:
            self._power_off()

    def power_on(self) -> None:
        """Restore power (no-op if on): the sensor boots, sends a BOOT event, physics restarts."""
        with self._lock:
            if not self._powered:
                self._boot(BootReason.POWER_ON)

    def power_cycle(self) -> None:
        """Power off, then on."""
        with self._lock:
            self._power_off()
            self._boot(BootReason.POWER_ON)

    def stats(self) -> PeerStats:
        """A snapshot of the sensor-side counters."""
        with self._lock:
            return PeerStats(**self._stats)

    def close(self) -> None:
        """Stop the firmware thread and close both pty ends."""
        if self._stop.is_set():
            return
        self._stop.set()
        self._thread.join(timeout=5.0)
        for fd in (self._master, self._slave):
            with contextlib.suppress(OSError):
                os.close(fd)

    def __enter__(self) -> SimulatedSensor:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # --- firmware ---------------------------------------------------------------------------------

    def _uptime_us(self) -> int:
        return int((self._clock.now() - self._t_power_on) * 1e6)

    def _period_us(self) -> int:
        return 1_000_000 // self._rate_hz

    def _power_off(self) -> None:
        self._powered = False
        self._streaming = False
        self._tx.clear()
        self._delayed.clear()
        self._last_cmd = None

    def _boot(self, reason: BootReason) -> None:
        self._powered = True
        self._boot_count += 1
        self._stats["boots"] += 1
        self._t_power_on = self._clock.now()
        self._streaming = False
        self._rate_hz = self.identity.default_rate_hz
        self._output = OutputMode.RAW
        self._seq = 0
        self._pending_flags = 0
        self._last_cmd = None
        self._delayed.clear()
        self._parser = FrameParser(track_sequence=False)
        self._source.power_on()
        reset = getattr(self.corrector, "reset", None)
        if callable(reset):
            reset()
        self.eeprom.power_reset()
        self._send(encode_frame(FrameType.EVENT, BootEvent(reason, self._boot_count).encode()))

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
            want_write = bool(self._tx)
            try:
                readable, _, _ = select.select([self._master], [self._master] if want_write else [], [], self._tick_s)
            except (OSError, ValueError):
                return
            with self._lock:
                if readable:
                    self._receive()
                self._service()
                self._flush()

    def _receive(self) -> None:
        try:
            data = os.read(self._master, 65536)
        except (BlockingIOError, InterruptedError):
            return
        except OSError:
            return
        if not self._powered or self.go_silent:
            return  # nobody home / the firmware hangs: input is lost
        for frame in self._parser.feed(data):
            if frame.type == FrameType.COMMAND:
                self._stats["commands"] += 1
                self._handle(frame.payload)

    def _service(self) -> None:
        if not self._powered:
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
        while self._tx:
            try:
                n = os.write(self._master, self._tx[:65536])
            except (BlockingIOError, InterruptedError):
                return
            except OSError:
                self._tx.clear()
                return
            self._stats["bytes_sent"] += n
            del self._tx[:n]

    def _send(self, frame: bytes) -> None:
        """Queue a non-sample frame (ACK/NAK/EVENT), with bit errors if enabled."""
        if self.go_silent or not self._powered:
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
        if not (self._powered and self._streaming):
            return
        now_us = self._uptime_us()
        if self._next_t_us > now_us:
            return
        period = self._period_us()
        n = (now_us - self._next_t_us) // period + 1
        t_us = self._next_t_us + period * np.arange(n, dtype=np.int64)
        accel, gyro, temp = self._source.render(t_us * 1e-6)
        base = 0
        if self._output == OutputMode.CORRECTED:
            accel, gyro = self.corrector(np.asarray(accel, dtype=np.float64), np.asarray(gyro, dtype=np.float64))
            base = int(SampleFlag.CORRECTED)
        flags = np.full(n, base, dtype=np.uint8)
        flags[0] = base | int(self._pending_flags)
        frames = encode_sample_frames(self._seq, t_us, accel, gyro, temp, flags)
        self._seq = (self._seq + n) % SEQ_MODULUS
        self._next_t_us += n * period
        self._pending_flags = 0
        self._stats["sample_frames"] += n
        self._emit_samples(frames)

    def _emit_samples(self, frames: np.ndarray) -> None:
        n = frames.shape[0]
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
        if len(self._tx) + out.nbytes > self._tx_limit:
            self._stats["tx_overruns"] += out.shape[0]
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
        try:
            reply = self._execute(seq, code, args)
        except FormatError:
            reply = encode_nak(seq, code, NakCode.BAD_PAYLOAD)
        except EepromError as exc:
            reply = encode_nak(seq, code, _NAK_FOR.get(type(exc), NakCode.BAD_ARGUMENT))
        if not self._powered:
            return  # power was lost while executing
        if code == Command.RESET and reply is not None:
            self._send(reply)
            self._boot(BootReason.RESET_COMMAND)
            return
        self._last_cmd = [payload, reply]
        if reply is not None:
            self._send(reply)

    def _execute(self, seq: int, code: int, args: bytes) -> bytes | None:
        """Run one command; returns the reply frame, or None if it comes later (or never)."""
        if code == Command.IDENTIFY:
            return encode_ack(seq, code, self.identity.encode())
        if code == Command.GET_STATUS:
            status = SensorStatus(
                streaming=self._streaming,
                output=self._output,
                rate_hz=self._rate_hz,
                uptime_s=self._uptime_us() * 1e-6,
                next_seq=self._seq,
                boot_count=self._boot_count,
                tx_overruns=self._stats["tx_overruns"],
            )
            return encode_ack(seq, code, status.encode())
        if code == Command.START_STREAM:
            rate = unpack_rate(args) or self._rate_hz
            if rate not in self.identity.rates_hz:
                return encode_nak(seq, code, NakCode.UNSUPPORTED_RATE)
            if not self._streaming:
                self._rate_hz = rate
                self._streaming = True
                self._next_t_us = self._uptime_us()
                self._pending_flags = SampleFlag.STREAM_START
            elif rate != self._rate_hz:
                self._change_rate(rate)
            return encode_ack(seq, code)
        if code == Command.STOP_STREAM:
            if args:
                raise FormatError("STOP_STREAM takes no arguments")
            self._streaming = False
            return encode_ack(seq, code)
        if code == Command.SET_RATE:
            rate = unpack_rate(args)
            if rate not in self.identity.rates_hz:
                return encode_nak(seq, code, NakCode.UNSUPPORTED_RATE)
            if self._streaming and rate != self._rate_hz:
                self._change_rate(rate)
            self._rate_hz = rate
            return encode_ack(seq, code)
        if code == Command.SET_OUTPUT:
            if len(args) != 1:
                raise FormatError("SET_OUTPUT takes one byte")
            if args[0] not in (OutputMode.RAW, OutputMode.CORRECTED):
                return encode_nak(seq, code, NakCode.BAD_ARGUMENT)
            self._output = OutputMode(args[0])
            return encode_ack(seq, code)
        if code == Command.EEPROM_INFO:
            info = EepromInfo(
                self.eeprom.size, self.eeprom.page_size, self.eeprom.write_protect, self.eeprom.write_cycle_s
            )
            return encode_ack(seq, code, info.encode())
        if code == Command.EEPROM_READ:
            addr, length = unpack_eeprom_read(args)
            if not 1 <= length <= MAX_EEPROM_READ:
                return encode_nak(seq, code, NakCode.BAD_ARGUMENT)
            return encode_ack(seq, code, pack_read_reply(addr, self.eeprom.read(addr, length)))
        if code == Command.EEPROM_WRITE_PAGE:
            addr, data = unpack_eeprom_write(args)
            programmed = self.eeprom.write_page(addr, data)
            if programmed < len(data):
                self._power_off()  # the power failed in the middle of the write cycle
                return None
            self._delayed.append((self.eeprom.busy_until, encode_ack(seq, code, pack_write_reply(addr, len(data)))))
            return None
        if code == Command.RESET:
            if args:
                raise FormatError("RESET takes no arguments")
            return encode_ack(seq, code)
        return encode_nak(seq, code, NakCode.UNKNOWN_COMMAND)

    def _change_rate(self, rate: int) -> None:
        """Switch rate while streaming: the next sample comes one new period after the last one sent."""
        if self._pending_flags & SampleFlag.STREAM_START:
            self._rate_hz = rate  # nothing sent yet: the first sample keeps its time
            return
        last_t = self._next_t_us - self._period_us()
        self._rate_hz = rate
        self._next_t_us = last_t + self._period_us()
        self._pending_flags |= SampleFlag.RATE_CHANGED
