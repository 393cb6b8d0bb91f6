"""Write a calibration image into a unit through the sensor protocol, safely.

:func:`write_image`:

1. IDENTIFY: the serial the sensor reports must equal the image's, else
   :class:`SerialMismatchError` (an image is bound to its unit).
2. EEPROM_INFO: refuse a write-protected or too small EEPROM.
3. Read both slots, pick the one *not* holding the current image, give the new image
   the next update count (:func:`station.eeprom.image.next_write`).
4. Write the slot page by page (EEPROM_WRITE_PAGE, each ACKed after its write cycle),
   the page holding the header last; then read the whole image back and compare byte for
   byte. A mismatch rewrites the same slot, at most ``max_attempts`` times in all, then
   :class:`ReadbackMismatchError`. Link faults (timeouts, NAKs) propagate at once.

A power loss at any point leaves the other slot untouched, so the old image stays
current; the new one becomes current only once its last byte (its header page) and
CRC are in place.

:class:`EepromProvisioner` implements the sequence runner's ``Provisioner``: called
only for PASS units, it writes the unit's image, power-cycles the sensor so its
firmware loads it, and runs the optional post-calibration verification
(:mod:`station.eeprom.verify`). Every failure is a :class:`~station.errors.HardwareError`
(the runner makes the unit's outcome ERROR); a failed verification is a
:class:`VerificationFailed`.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass, field
from datetime import UTC, datetime
from typing import TYPE_CHECKING, Protocol

from station.eeprom.image import (
    DEFAULT_SLOTS,
    SLOT_NAMES,
    CalibrationImage,
    ImageError,
    SlotLayout,
    SlotState,
    decode_image,
    encode_image,
    image_sha256,
    next_write,
    read_slots,
    select_image,
)
from station.errors import HardwareError, UnitRejected
from station.sensor.client import SerialSensor

if TYPE_CHECKING:
    from station.eeprom.verify import VerificationResult
    from station.sequence.runner import UnitResult

log = logging.getLogger(__name__)


class ProvisionError(HardwareError):
    """Writing the calibration into the unit failed."""


class SerialMismatchError(ProvisionError):
    """The sensor reports another serial number than the image was made for."""


class EepromUnusableError(ProvisionError):
    """The unit's EEPROM is write protected or too small for the two image slots."""


class ReadbackMismatchError(ProvisionError):
    """The image read back differs from the one written, after every attempt."""


class VerificationFailed(UnitRejected):
    """The unit's corrected output is outside the verification limits (see ``result``): a FAIL."""

    def __init__(self, message: str, result: VerificationResult) -> None:
        super().__init__(message, tuple((c.name, c.value, c.limit, c.unit, c.passed) for c in result.checks))
        self.result = result


@dataclass(frozen=True)
class WriteReport:
    """One completed image write.

    Attributes:
        serial: the unit; slot: 'A' or 'B'; address: EEPROM address of the slot.
        update_count: the new image's count; previous_count: the replaced current image's (0: none).
        attempts: write + read-back rounds needed (1 = first time right).
        length: image bytes; sha256: hex SHA-256 of the bytes written.
        image: the image as written (with its update count).
    """

    serial: str
    slot: str
    address: int
    update_count: int
    previous_count: int
    attempts: int
    length: int
    sha256: str
    image: CalibrationImage = field(repr=False, compare=False)


def read_unit_slots(sensor: SerialSensor, layout: SlotLayout = DEFAULT_SLOTS) -> list[SlotState]:
    """Read and decode both image slots of the unit (EEPROM_READ)."""
    return read_slots(sensor.eeprom_read(layout.base, 2 * layout.slot_size), layout)


def read_current_image(sensor: SerialSensor, layout: SlotLayout = DEFAULT_SLOTS) -> CalibrationImage | None:
    """The unit's current image (valid, highest update count), or None."""
    current = select_image(read_unit_slots(sensor, layout))
    return current.image if current is not None else None


def _pages(addr: int, data: bytes, page_size: int) -> list[tuple[int, bytes]]:
    out: list[tuple[int, bytes]] = []
    pos = 0
    while pos < len(data):
        a = addr + pos
        k = min(page_size - a % page_size, len(data) - pos)
        out.append((a, data[pos : pos + k]))
        pos += k
    return out


def write_image(
    sensor: SerialSensor,
    image: CalibrationImage,
    *,
    layout: SlotLayout = DEFAULT_SLOTS,
    max_attempts: int = 3,
) -> WriteReport:
    """Write ``image`` into the unit's free slot with the next update count; read back and compare.

    Raises:
        SerialMismatchError: the sensor reports another serial.
        EepromUnusableError: write protect asserted, or the EEPROM is too small.
        ReadbackMismatchError: every attempt read back different bytes.
        HardwareError: link faults (SensorTimeout, SensorNak, ...) as they come.
    """
    if max_attempts < 1:
        raise ValueError("max_attempts must be >= 1")
    ident = sensor.identify()
    if ident.serial != image.serial:
        raise SerialMismatchError(
            f"refusing to write: the image is for serial {image.serial!r}, the sensor reports {ident.serial!r}"
        )
    info = sensor.eeprom_info()
    if info.write_protect:
        raise EepromUnusableError(f"EEPROM of {ident.serial} is write protected (WP pin asserted)")
    if info.size < layout.end:
        raise EepromUnusableError(f"EEPROM of {ident.serial} has {info.size} bytes; the two slots need {layout.end}")
    slots = read_unit_slots(sensor, layout)
    target, count = next_write(slots)
    current = select_image(slots)
    previous = current.image.update_count if current is not None and current.image is not None else 0
    new = image.with_update_count(count)
    data = encode_image(new)
    addr = layout.address(target)
    pages = _pages(addr, data, info.page_size)
    pages = pages[1:] + pages[:1]  # the header page last: the slot has no valid magic + CRC until the end
    for attempt in range(1, max_attempts + 1):
        for a, chunk in pages:
            sensor.eeprom_write_page(a, chunk)
        back = sensor.eeprom_read(addr, len(data))
        if back == data:
            try:
                decode_image(back)
            except ImageError as exc:  # cannot happen for bytes equal to what encode produced
                raise ProvisionError(f"image read back from {ident.serial} does not decode: {exc}") from exc
            log.info("%s: image #%d written to slot %s in %d attempt(s)", ident.serial, count, SLOT_NAMES[target],
                     attempt)
            return WriteReport(ident.serial, SLOT_NAMES[target], addr, count, previous, attempt, len(data),
                               image_sha256(data), new)
        bad = sum(1 for x, y in zip(back, data, strict=True) if x != y)
        log.warning("%s: read-back of slot %s differs in %d of %d bytes (attempt %d of %d)", ident.serial,
                    SLOT_NAMES[target], bad, len(data), attempt, max_attempts)
    raise ReadbackMismatchError(
        f"EEPROM of {ident.serial}: slot {SLOT_NAMES[target]} read back different bytes after {max_attempts} "
        f"write attempts; the previous image (count {previous}) is still current"
    )


class Verifier(Protocol):
    """Post-calibration verification of a freshly written unit (see :mod:`station.eeprom.verify`)."""

    def verify(self, sensor: SerialSensor, image: CalibrationImage) -> VerificationResult: ...


@dataclass(frozen=True, eq=False)
class ProvisionRecord:
    """What provisioning did for one unit: the write and, if run, the verification."""

    serial: str
    slot: int
    write: WriteReport
    verification: VerificationResult | None


class EepromProvisioner:
    """The sequence runner's Provisioner: write the PASS unit's image, power-cycle, verify.

    Args:
        station_id: written into each image (ASCII, 1..16 characters).
        verifier: post-calibration verification (None: none).
        layout: image slots.
        max_attempts: write + read-back rounds per unit.
        power_cycle: reset the sensor after writing so its firmware loads the new image.
        boot_timeout_s: wall seconds to wait for the BOOT event after the reset.
        now: calibration-time source (UTC); default ``datetime.now(UTC)``.
        on_record: called with each unit's :class:`ProvisionRecord` (e.g. to store it).

    ``records`` maps serial -> the last :class:`ProvisionRecord`.
    """

    def __init__(
        self,
        station_id: str,
        *,
        verifier: Verifier | None = None,
        layout: SlotLayout = DEFAULT_SLOTS,
        max_attempts: int = 3,
        power_cycle: bool = True,
        boot_timeout_s: float = 2.0,
        now: Callable[[], datetime] | None = None,
        on_record: Callable[[ProvisionRecord], None] | None = None,
    ) -> None:
        self.station_id = station_id
        self.verifier = verifier
        self.layout = layout
        self.max_attempts = max_attempts
        self.power_cycle = power_cycle
        self.boot_timeout_s = boot_timeout_s
        self._now = now if now is not None else (lambda: datetime.now(UTC))
        self._on_record = on_record
        self.records: dict[str, ProvisionRecord] = {}

    def image_for(self, unit: UnitResult) -> CalibrationImage:
        if unit.params is None:
            raise ProvisionError(f"slot {unit.slot}: no parameter set to write")
        if unit.serial and unit.params.serial != unit.serial:
            raise SerialMismatchError(
                f"slot {unit.slot}: parameter set is for {unit.params.serial!r}, the unit is {unit.serial!r}"
            )
        return CalibrationImage.from_params(unit.params, self.station_id, self._now())

    def provision(
        self, unit: UnitResult, sensor: SerialSensor
    ) -> tuple[tuple[str, float, float, str, bool], ...] | None:
        """Write, power-cycle, verify one PASS unit; returns the verification checks (None without verifier).

        Raises a HardwareError subclass when the writing fails (station ERROR) and
        VerificationFailed (a UnitRejected) when the corrected output misses its limits (unit FAIL).
        """
        image = self.image_for(unit)
        report = write_image(sensor, image, layout=self.layout, max_attempts=self.max_attempts)
        if self.power_cycle:
            sensor.power_cycle(self.boot_timeout_s)
        result = self.verifier.verify(sensor, report.image) if self.verifier is not None else None
        record = ProvisionRecord(report.serial, unit.slot, report, result)
        self.records[report.serial] = record
        if self._on_record is not None:
            self._on_record(record)
        if result is not None and not result.passed:
            raise VerificationFailed(f"verification of corrected output failed: {result.describe()}", result)
        if result is None:
            return None
        return tuple((c.name, c.value, c.limit, c.unit, c.passed) for c in result.checks)


__all__ = [
    "EepromProvisioner",
    "EepromUnusableError",
    "ProvisionError",
    "ProvisionRecord",
    "ReadbackMismatchError",
    "SerialMismatchError",
    "VerificationFailed",
    "Verifier",
    "WriteReport",
    "read_current_image",
    "read_unit_slots",
    "write_image",
]
