"""The station's view of a sensor: the :class:`Sensor` protocol, the sample blocks it delivers, its faults.

Implemented by :class:`station.sensor.client.SerialSensor` (the binary protocol over a serial
port, ``serial://``) and by the in-process fake of :mod:`station.sim` for tests. The sequence,
provisioning and verification type against :class:`Sensor`, never against a transport.

Failures are station faults (:class:`~station.kernel.errors.HardwareError`), not unit
failures: :class:`SensorTimeout` (no answer), :class:`SensorNak` (refused),
:class:`CrcStormError` (CRC error rate over the window above threshold; latched until
:meth:`Sensor.clear_fault`), :class:`SensorLinkError` (the port itself failed).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol, Self, runtime_checkable

import numpy as np

from station.kernel.errors import HardwareError
from station.sensor.commands import Command, EepromInfo, NakCode, OutputMode, SensorIdentity, SensorStatus
from station.sensor.frames import SampleFlag


class SensorTimeout(HardwareError):
    """The sensor did not answer (command after all attempts, or samples within the timeout)."""


class SensorNak(HardwareError):
    """The sensor refused a command; ``code`` is the :class:`NakCode`, ``command`` the :class:`Command`."""

    def __init__(self, command: int, code: int) -> None:
        try:
            cname = Command(command).name
        except ValueError:
            cname = f"0x{command:02x}"
        try:
            ename = NakCode(code).name
        except ValueError:
            ename = f"0x{code:02x}"
        super().__init__(f"sensor refused {cname}: {ename}")
        self.command = command
        self.code = code


class CrcStormError(HardwareError):
    """Too many frames fail their CRC: cabling, baud rate or EMI problem at the station."""


class SensorLinkError(HardwareError):
    """The serial port could not be opened, or failed while in use."""


@dataclass(frozen=True, eq=False)
class SampleBlock:
    """Decoded samples, in arrival order.

    Attributes:
        seq: (n,) sequence counter (u16, wraps).
        t_s: (n,) sensor time since power-on (s, µs resolution).
        accel_mps2: (n, 3) specific force (m/s^2).
        gyro_radps: (n, 3) angular rate (rad/s).
        temp_degc: (n,) temperature (degC), NaN if the sensor has none.
        flags: (n,) :class:`~station.sensor.frames.SampleFlag` bits.
    """

    seq: np.ndarray
    t_s: np.ndarray
    accel_mps2: np.ndarray
    gyro_radps: np.ndarray
    temp_degc: np.ndarray
    flags: np.ndarray

    def __len__(self) -> int:
        return int(self.seq.shape[0])

    @property
    def corrected(self) -> np.ndarray:
        """(n,) bool: the sample is corrected output (else raw)."""
        return (self.flags & SampleFlag.CORRECTED) != 0

    @classmethod
    def empty(cls) -> SampleBlock:
        return cls(
            np.zeros(0, np.uint16),
            np.zeros(0),
            np.zeros((0, 3)),
            np.zeros((0, 3)),
            np.zeros(0),
            np.zeros(0, np.uint8),
        )

    @classmethod
    def from_records(cls, rec: np.ndarray) -> SampleBlock:
        """From a structured array of :data:`~station.sensor.frames.SAMPLE_PAYLOAD_DTYPE`."""
        return cls(
            seq=rec["seq"].astype(np.uint16),
            t_s=rec["t_us"].astype(np.float64) * 1e-6,
            accel_mps2=rec["accel"].astype(np.float64),
            gyro_radps=rec["gyro"].astype(np.float64),
            temp_degc=rec["temp"].astype(np.float64),
            flags=rec["flags"].astype(np.uint8),
        )

    @classmethod
    def concat(cls, blocks: list[SampleBlock]) -> SampleBlock:
        if not blocks:
            return cls.empty()
        if len(blocks) == 1:
            return blocks[0]
        return cls(
            *(np.concatenate([getattr(b, name) for b in blocks]) for name in cls.__dataclass_fields__)
        )

    def split(self, k: int) -> tuple[SampleBlock, SampleBlock]:
        """The first ``k`` samples and the rest."""
        names = self.__dataclass_fields__
        head = SampleBlock(*(getattr(self, n)[:k] for n in names))
        tail = SampleBlock(*(getattr(self, n)[k:] for n in names))
        return head, tail


@dataclass(frozen=True)
class LinkStats:
    """Link and capture counters of one :class:`SerialSensor` (see also ParserStats).

    Attributes:
        frames: valid frames received.
        samples: sample frames received.
        crc_errors, bad_headers, resyncs, bytes_discarded: parser counters.
        gaps, lost_frames, duplicates, restarts: sample sequence accounting.
        retries: command retransmissions.
        timeouts: commands that got no answer after all attempts.
        naks: commands refused.
        boots: BOOT events received.
        stray_replies: ACK/NAK frames that matched no outstanding command.
        buffer_overruns: samples dropped because the client buffer was full (nobody read them).
        crc_storm: the CRC-storm fault is latched.
    """

    frames: int
    samples: int
    crc_errors: int
    bad_headers: int
    resyncs: int
    bytes_discarded: int
    gaps: int
    lost_frames: int
    duplicates: int
    restarts: int
    retries: int
    timeouts: int
    naks: int
    boots: int
    stray_replies: int
    buffer_overruns: int
    crc_storm: bool


@runtime_checkable
class Sensor(Protocol):
    """One IMU on the fixture, as the station sees it.

    Commands return once the sensor acknowledged them and raise a
    :class:`~station.kernel.errors.HardwareError` subclass otherwise. Sample times are
    sensor time since power-on (s); ``read_samples`` durations and timeouts are seconds of
    the clock the sensor was opened with.
    """

    url: str

    def identify(self) -> SensorIdentity: ...

    def status(self) -> SensorStatus: ...

    def start_stream(self, rate_hz: int | None = None) -> None: ...

    def stop_stream(self) -> None: ...

    def set_output(self, mode: OutputMode | str) -> None: ...

    def eeprom_info(self) -> EepromInfo: ...

    def eeprom_read(self, addr: int, n: int) -> bytes: ...

    def eeprom_write_page(self, addr: int, data: bytes) -> None: ...

    def power_cycle(self, boot_timeout_s: float | None = None) -> None: ...

    def clear_fault(self) -> None: ...

    def read_samples(
        self, n: int | None = None, *, duration_s: float | None = None, timeout_s: float | None = None
    ) -> SampleBlock: ...

    def drain(self) -> SampleBlock: ...

    def stats(self) -> LinkStats: ...

    def close(self) -> None: ...

    def __enter__(self) -> Self:
        """``with open_sensor(url) as sensor:`` closes the link on leaving."""
        ...

    def __exit__(self, *exc: object) -> None: ...


__all__ = [
    "CrcStormError",
    "LinkStats",
    "SampleBlock",
    "Sensor",
    "SensorLinkError",
    "SensorNak",
    "SensorTimeout",
]
