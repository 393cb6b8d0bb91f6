"""Write a calibration image into a unit through the sensor protocol, safely.

:func:`write_image`:

1. IDENTIFY: the serial the sensor reports must equal the image's, else
   :class:`SerialMismatchError` (an image is bound to its unit); the content must be usable by
   the firmware at the unit's own sample rates (:func:`station.eeprom.image.check_writable`),
   else :class:`~station.eeprom.image.ImageRefused`, before anything is written.
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

Every failure is a :class:`~station.kernel.errors.HardwareError` (a station fault). The
provisioning step of the sequence (:mod:`station.sequence.provision`) calls it.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field

from station.eeprom.image import (
    DEFAULT_SLOTS,
    WIDE_SLOTS,
    CalibrationImage,
    ImageError,
    SlotLayout,
    SlotState,
    check_writable,
    decode_image,
    encode_image,
    image_sha256,
    next_write_in,
    read_slots,
    select_image,
    slots_for,
)
from station.kernel.errors import HardwareError
from station.sensor.protocol import Sensor

log = logging.getLogger(__name__)


class ProvisionError(HardwareError):
    """Writing the calibration into the unit failed."""


class SerialMismatchError(ProvisionError):
    """The sensor reports another serial number than the image was made for."""


class EepromUnusableError(ProvisionError):
    """The unit's EEPROM is write protected or too small for the two image slots."""


class ReadbackMismatchError(ProvisionError):
    """The image read back differs from the one written, after every attempt."""


@dataclass(frozen=True)
class WriteReport:
    """One completed image write.

    Attributes:
        serial: the unit; slot: 'A' or 'B'; address: EEPROM address of the slot.
        update_count: the new image's count; previous_count: the replaced current image's (0: none).
        attempts: write + read-back rounds needed (1 = first time right).
        length: image bytes; sha256: hex SHA-256 of the bytes written.
        image: the image as written (with its update count); data: its bytes, as read back.
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
    data: bytes = field(default=b"", repr=False, compare=False)


def read_unit_slots(
    sensor: Sensor, layout: SlotLayout = DEFAULT_SLOTS, *, eeprom_size: int | None = None
) -> list[SlotState]:
    """Read and decode the unit's image slots (EEPROM_READ): both of ``layout`` (layout 1) and, when the
    EEPROM holds them (``eeprom_size``, asked with EEPROM_INFO when not given), both :data:`WIDE_SLOTS` (layout 2)."""
    slots = read_slots(sensor.eeprom_read(layout.base, 2 * layout.slot_size), layout)
    if layout != WIDE_SLOTS:
        size = eeprom_size if eeprom_size is not None else sensor.eeprom_info().size
        if size >= WIDE_SLOTS.end:
            slots += read_slots(bytes(WIDE_SLOTS.base) + sensor.eeprom_read(WIDE_SLOTS.base, 2 * WIDE_SLOTS.slot_size),
                                WIDE_SLOTS)
    return slots


def read_current_image(sensor: Sensor, layout: SlotLayout = DEFAULT_SLOTS) -> CalibrationImage | None:
    """The unit's current image (valid, highest update count, either region), or None."""
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


@dataclass(frozen=True)
class WritePlan:
    """What a write will put where, decided before anything is written (:func:`plan_write`).

    Attributes:
        serial: the unit; slot: 'A' or 'B' (the free slot); address: EEPROM address of the slot.
        update_count: the new image's count; previous_count: the current image's (0: none).
        image: the image as it will be written (with its update count); data: its bytes;
        sha256: hex SHA-256 of ``data``; page_size: the EEPROM's page size (bytes).
    """

    serial: str
    slot: str
    address: int
    update_count: int
    previous_count: int
    sha256: str
    image: CalibrationImage = field(repr=False, compare=False)
    data: bytes = field(default=b"", repr=False, compare=False)
    page_size: int = 32


def plan_write(sensor: Sensor, image: CalibrationImage, *, layout: SlotLayout = DEFAULT_SLOTS) -> WritePlan:
    """Identify the unit, check the image and the EEPROM, read both slots and decide the write (nothing written).

    Raises:
        SerialMismatchError: the sensor reports another serial.
        EepromUnusableError: write protect asserted, or the EEPROM is too small.
        HardwareError: link faults (SensorTimeout, SensorNak, ...) as they come.
    """
    ident = sensor.identify()
    if ident.serial != image.serial:
        raise SerialMismatchError(
            f"refusing to write: the image is for serial {image.serial!r}, the sensor reports {ident.serial!r}"
        )
    check_writable(image, tuple(ident.rates_hz))  # ImageRefused: nothing written
    info = sensor.eeprom_info()
    if info.write_protect:
        raise EepromUnusableError(f"EEPROM of {ident.serial} is write protected (WP pin asserted)")
    region = slots_for(image, layout)
    if info.size < region.end:
        raise EepromUnusableError(f"EEPROM of {ident.serial} has {info.size} bytes; the two slots of a layout-"
                                  f"{image.layout_version} image need {region.end}")
    slots = read_unit_slots(sensor, layout, eeprom_size=info.size)
    target, count = next_write_in(region, slots)
    current = select_image(slots)
    previous = current.image.update_count if current is not None and current.image is not None else 0
    new = image.with_update_count(count)
    data = encode_image(new)
    name = SlotState(target, None, layout=region).name
    return WritePlan(ident.serial, name, region.address(target), count, previous, image_sha256(data), new, data,
                     info.page_size)


def program_image(sensor: Sensor, plan: WritePlan, *, max_attempts: int = 3) -> WriteReport:
    """Write ``plan``'s bytes page by page (the header page last), read back and compare; retry on mismatch.

    Raises:
        ReadbackMismatchError: every attempt read back different bytes.
        HardwareError: link faults (SensorTimeout, SensorNak, ...) as they come.
    """
    if max_attempts < 1:
        raise ValueError("max_attempts must be >= 1")
    data, addr, name = plan.data, plan.address, plan.slot
    pages = _pages(addr, data, plan.page_size)
    pages = pages[1:] + pages[:1]  # the header page last: the slot has no valid magic + CRC until the end
    for attempt in range(1, max_attempts + 1):
        for a, chunk in pages:
            sensor.eeprom_write_page(a, chunk)
        back = sensor.eeprom_read(addr, len(data))
        if back == data:
            try:
                decode_image(back)
            except ImageError as exc:  # cannot happen for bytes equal to what encode produced
                raise ProvisionError(f"image read back from {plan.serial} does not decode: {exc}") from exc
            log.info("%s: image #%d written to slot %s in %d attempt(s)", plan.serial, plan.update_count, name,
                     attempt)
            return WriteReport(plan.serial, name, addr, plan.update_count, plan.previous_count, attempt, len(data),
                               plan.sha256, plan.image, back)
        bad = sum(1 for x, y in zip(back, data, strict=True) if x != y)
        log.warning("%s: read-back of slot %s differs in %d of %d bytes (attempt %d of %d)", plan.serial,
                    name, bad, len(data), attempt, max_attempts)
    raise ReadbackMismatchError(
        f"EEPROM of {plan.serial}: slot {name} read back different bytes after {max_attempts} "
        f"write attempts; the previous image (count {plan.previous_count}) is still current"
    )


def write_image(
    sensor: Sensor,
    image: CalibrationImage,
    *,
    layout: SlotLayout = DEFAULT_SLOTS,
    max_attempts: int = 3,
) -> WriteReport:
    """Write ``image`` into the unit's free slot with the next update count; read back and compare
    (:func:`plan_write` then :func:`program_image`).

    Raises:
        SerialMismatchError: the sensor reports another serial.
        EepromUnusableError: write protect asserted, or the EEPROM is too small.
        ReadbackMismatchError: every attempt read back different bytes.
        HardwareError: link faults (SensorTimeout, SensorNak, ...) as they come.
    """
    if max_attempts < 1:
        raise ValueError("max_attempts must be >= 1")
    return program_image(sensor, plan_write(sensor, image, layout=layout), max_attempts=max_attempts)


def current_image_sha256(sensor: Sensor, layout: SlotLayout = DEFAULT_SLOTS) -> tuple[str, int] | None:
    """Hex SHA-256 of the unit's current image bytes and its update count (None: no valid image)."""
    current = read_current_image(sensor, layout)
    if current is None:
        return None
    return image_sha256(encode_image(current)), current.update_count


__all__ = [
    "EepromUnusableError",
    "ProvisionError",
    "ReadbackMismatchError",
    "SerialMismatchError",
    "WritePlan",
    "WriteReport",
    "current_image_sha256",
    "plan_write",
    "program_image",
    "read_current_image",
    "read_unit_slots",
    "write_image",
]
