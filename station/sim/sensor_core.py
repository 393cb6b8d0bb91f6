"""The simulated IMU's firmware without I/O: commands, streaming, boots (:class:`SensorCore`).

One core runs behind each simulated sensor, whatever carries its protocol: the pty peer of
:mod:`station.sim.sensor_peer` (frames, bit errors, retransmission cache, a firmware thread) and
the in-process fake of :mod:`station.sim.fakes` (direct calls). :meth:`SensorCore.execute` runs
one command from its code and argument bytes and answers with the reply payload, or a NAK code
(station/sensor/protocol.md); :meth:`SensorCore.due_samples` renders the samples whose time has
come on the clock as SAMPLE payload records; :meth:`SensorCore.boot` is a power-on or reset.

Timing follows the given :class:`~station.kernel.clock.Clock`: sample ``k`` after START_STREAM has
sensor time ``t0 + k / rate`` (whole µs since power-on). Values come from a pluggable
:class:`SampleSource` (the sensor physics); power-on restarts it. In CORRECTED output mode each
chunk goes through the :data:`Corrector` (the calibration firmware of :mod:`station.sim.firmware`).

:class:`SensorUnit` is what both transports share around a core: the power switches, the
``go_silent`` fault and the EEPROM, identity and corrector of the unit.
"""

from __future__ import annotations

import math
import threading
from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol, cast

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
    pack_read_reply,
    pack_write_reply,
    unpack_eeprom_read,
    unpack_eeprom_write,
    unpack_rate,
)
from station.sensor.frames import SEQ_MODULUS, SampleFlag, sample_records
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
#: A corrector that also takes the temperature (it says so with ``takes_temperature = True``).
TemperatureCorrector = Callable[[np.ndarray, np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]
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
class Answer:
    """The firmware's answer to one command.

    Attributes:
        ok: ACK (with ``data``) or NAK (with ``error``).
        data: the ACK's reply payload.
        error: the NAK's :class:`NakCode`.
        due_s: clock time at which the answer goes out (an EEPROM write cycle); None: at once.
    """

    ok: bool
    data: bytes = b""
    error: int = 0
    due_s: float | None = None


def _ack(data: bytes = b"", due_s: float | None = None) -> Answer:
    return Answer(True, data, 0, due_s)


def _nak(code: NakCode) -> Answer:
    return Answer(False, b"", int(code))


class SensorCore:
    """The firmware state machine of one simulated IMU (no I/O; callers hold their own lock).

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

    The core starts switched off; :meth:`boot` powers it on.
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
    ) -> None:
        for r in rates_hz:
            if r <= 0 or 1_000_000 % r:
                raise ValueError(f"sample rate {r} Hz must divide 1e6 (whole-µs sample period)")
        if default_rate_hz not in rates_hz:
            raise ValueError("default_rate_hz must be one of rates_hz")
        self.source = source
        self.clock: Clock = clock if clock is not None else WallClock()
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
        self.eeprom = eeprom if eeprom is not None else Eeprom(clock=self.clock)
        self.corrector: Corrector = corrector if corrector is not None else identity_corrector
        self.powered = False
        self.boot_count = 0
        self.tx_overruns = 0  # sample frames the transport could not send (reported by GET_STATUS)
        self.t_power_on = 0.0
        self.streaming = False
        self.rate_hz = default_rate_hz
        self.output = OutputMode.RAW
        self.seq = 0
        self.next_t_us = 0
        self.last_t_us = -1  # time of the last sample rendered since power-on (µs), -1: none
        self.pending_flags = 0

    # --- power --------------------------------------------------------------------------------------

    def uptime_us(self) -> int:
        return int((self.clock.now() - self.t_power_on) * 1e6)

    def period_us(self) -> int:
        return 1_000_000 // self.rate_hz

    def power_off(self) -> None:
        """The power is gone: streaming stops."""
        self.powered = False
        self.streaming = False

    def boot(self, reason: BootReason) -> BootEvent:
        """Power-on or reset: time base, counters, rate and output mode restart, the physics and the
        corrector restart, the EEPROM's write cycle is over; returns the BOOT event to send."""
        self.powered = True
        self.boot_count += 1
        self.t_power_on = self.clock.now()
        self.streaming = False
        self.rate_hz = self.identity.default_rate_hz
        self.output = OutputMode.RAW
        self.seq = 0
        self.last_t_us = -1
        self.pending_flags = 0
        self.source.power_on()
        reset = getattr(self.corrector, "reset", None)
        if callable(reset):
            reset()
        self.eeprom.power_reset()
        return BootEvent(reason, self.boot_count)

    # --- samples ------------------------------------------------------------------------------------

    def due_samples(self) -> np.ndarray | None:
        """The samples whose time has come since the last call, as SAMPLE payload records (None: none)."""
        if not (self.powered and self.streaming):
            return None
        now_us = self.uptime_us()
        if self.next_t_us > now_us:
            return None
        period = self.period_us()
        n = (now_us - self.next_t_us) // period + 1
        t_us = self.next_t_us + period * np.arange(n, dtype=np.int64)
        accel, gyro, temp = self.source.render(t_us * 1e-6)
        base = 0
        if self.output == OutputMode.CORRECTED:
            a64, w64 = np.asarray(accel, dtype=np.float64), np.asarray(gyro, dtype=np.float64)
            if getattr(self.corrector, "takes_temperature", False):  # e.g. a layout-2 image's temperature terms
                thermal = cast(TemperatureCorrector, self.corrector)
                accel, gyro = thermal(a64, w64, np.asarray(temp, dtype=np.float64))
            else:
                accel, gyro = self.corrector(a64, w64)
            base = int(SampleFlag.CORRECTED)
        flags = np.full(n, base, dtype=np.uint8)
        flags[0] = base | int(self.pending_flags)
        records = sample_records(self.seq, t_us, accel, gyro, temp, flags)
        self.seq = (self.seq + n) % SEQ_MODULUS
        self.next_t_us += n * period
        self.last_t_us = int(t_us[-1])
        self.pending_flags = 0
        return records

    def _change_rate(self, rate: int) -> None:
        """Switch rate while streaming: the next sample comes one new period after the last one sent."""
        if self.pending_flags & SampleFlag.STREAM_START:
            self.rate_hz = rate  # nothing sent yet: the first sample keeps its time
            return
        last_t = self.next_t_us - self.period_us()
        self.rate_hz = rate
        self.next_t_us = last_t + self.period_us()
        self.pending_flags |= SampleFlag.RATE_CHANGED

    # --- commands -----------------------------------------------------------------------------------

    def execute(self, code: int, args: bytes) -> Answer | None:
        """Run one command; its answer, or None if none ever comes (the power failed while executing).

        RESET is only acknowledged here: the transport sends the ACK, then calls :meth:`boot`.
        """
        try:
            return self._execute(code, args)
        except FormatError:
            return _nak(NakCode.BAD_PAYLOAD)
        except EepromError as exc:
            return _nak(_NAK_FOR.get(type(exc), NakCode.BAD_ARGUMENT))

    def _execute(self, code: int, args: bytes) -> Answer | None:
        if code == Command.IDENTIFY:
            return _ack(self.identity.encode())
        if code == Command.GET_STATUS:
            status = SensorStatus(
                streaming=self.streaming,
                output=self.output,
                rate_hz=self.rate_hz,
                uptime_s=self.uptime_us() * 1e-6,
                next_seq=self.seq,
                boot_count=self.boot_count,
                tx_overruns=self.tx_overruns,
            )
            return _ack(status.encode())
        if code == Command.START_STREAM:
            rate = unpack_rate(args) or self.rate_hz
            if rate not in self.identity.rates_hz:
                return _nak(NakCode.UNSUPPORTED_RATE)
            if not self.streaming:
                self.rate_hz = rate
                self.streaming = True
                # a restart at the instant of the last sample (no time passes between commands on a virtual
                # clock) begins just after it: the physics renders each time once
                self.next_t_us = max(self.uptime_us(), self.last_t_us + 1)
                self.pending_flags = SampleFlag.STREAM_START
            elif rate != self.rate_hz:
                self._change_rate(rate)
            return _ack()
        if code == Command.STOP_STREAM:
            if args:
                raise FormatError("STOP_STREAM takes no arguments")
            self.streaming = False
            return _ack()
        if code == Command.SET_RATE:
            rate = unpack_rate(args)
            if rate not in self.identity.rates_hz:
                return _nak(NakCode.UNSUPPORTED_RATE)
            if self.streaming and rate != self.rate_hz:
                self._change_rate(rate)
            self.rate_hz = rate
            return _ack()
        if code == Command.SET_OUTPUT:
            if len(args) != 1:
                raise FormatError("SET_OUTPUT takes one byte")
            if args[0] not in (OutputMode.RAW, OutputMode.CORRECTED):
                return _nak(NakCode.BAD_ARGUMENT)
            self.output = OutputMode(args[0])
            return _ack()
        if code == Command.EEPROM_INFO:
            info = EepromInfo(self.eeprom.size, self.eeprom.page_size, self.eeprom.write_protect,
                              self.eeprom.write_cycle_s)
            return _ack(info.encode())
        if code == Command.EEPROM_READ:
            addr, length = unpack_eeprom_read(args)
            if not 1 <= length <= MAX_EEPROM_READ:
                return _nak(NakCode.BAD_ARGUMENT)
            return _ack(pack_read_reply(addr, self.eeprom.read(addr, length)))
        if code == Command.EEPROM_WRITE_PAGE:
            addr, data = unpack_eeprom_write(args)
            programmed = self.eeprom.write_page(addr, data)
            if programmed < len(data):
                self.power_off()  # the power failed in the middle of the write cycle
                return None
            return _ack(pack_write_reply(addr, len(data)), due_s=self.eeprom.busy_until)
        if code == Command.RESET:
            if args:
                raise FormatError("RESET takes no arguments")
            return _ack()
        return _nak(NakCode.UNKNOWN_COMMAND)


class SensorUnit:
    """A simulated unit around a :class:`SensorCore`: power switches, the ``go_silent`` fault, its parts.

    ``go_silent`` (may be changed any time): the firmware hangs: it ignores commands and sends
    nothing, while its clock and sample counter run on (recovery shows up as a gap). Transports
    extend :meth:`_power_off` and :meth:`_boot` with what the wire does (drop unsent bytes, send
    the BOOT event).
    """

    def __init__(self, core: SensorCore) -> None:
        self.core = core
        self.go_silent = False
        self._lock = threading.RLock()

    @property
    def identity(self) -> SensorIdentity:
        return self.core.identity

    @property
    def eeprom(self) -> Eeprom:
        return self.core.eeprom

    @property
    def corrector(self) -> Corrector:
        """The on-sensor correction of CORRECTED output (:func:`station.sim.firmware.install_firmware` sets it)."""
        return self.core.corrector

    @corrector.setter
    def corrector(self, value: Corrector) -> None:
        self.core.corrector = value

    @property
    def powered(self) -> bool:
        """The sensor has power."""
        return self.core.powered

    def power_off(self) -> None:
        """Cut the power: streaming stops, unsent data and half-done commands are lost."""
        with self._lock:
            self._power_off()

    def power_on(self) -> None:
        """Restore power (no-op if on): the sensor boots, sends a BOOT event, physics restarts."""
        with self._lock:
            if not self.core.powered:
                self._boot(BootReason.POWER_ON)

    def power_cycle(self) -> None:
        """Power off, then on."""
        with self._lock:
            self._power_off()
            self._boot(BootReason.POWER_ON)

    def _power_off(self) -> None:
        self.core.power_off()

    def _boot(self, reason: BootReason) -> BootEvent:
        return self.core.boot(reason)


__all__ = [
    "DEFAULT_RATES_HZ",
    "Answer",
    "Corrector",
    "SampleSource",
    "SensorCore",
    "SensorUnit",
    "identity_corrector",
]
