"""Provisioning as a step of the sequence: write a PASS unit's image, power-cycle, verify on the rig.

:class:`EepromProvisioner` implements the runner's ``Provisioner``: called only for PASS
units of a complete, fault-free run, it builds the unit's image, writes it with the
page-level protocol of :func:`station.eeprom.provision.write_image` (A/B slots, read-back),
power-cycles the sensor so its firmware loads it, and runs the optional verification of
the corrected output (:mod:`station.sequence.verify`). A failed write is a
:class:`~station.kernel.errors.HardwareError` (the runner makes the unit ERROR); a failed
verification is a :class:`VerificationFailed` (the unit FAILs).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from datetime import UTC, datetime
from typing import TYPE_CHECKING, Protocol

from station.eeprom.image import DEFAULT_SLOTS, CalibrationImage, SlotLayout, run_image
from station.eeprom.provision import ProvisionError, SerialMismatchError, WriteReport, write_image
from station.kernel.errors import UnitRejected
from station.kernel.measurement import Measurement
from station.sensor.protocol import Sensor

if TYPE_CHECKING:
    from station.sequence.runner import UnitResult
    from station.sequence.verify import VerificationResult


class VerificationFailed(UnitRejected):
    """The unit's corrected output is outside the verification limits (see ``result``): a FAIL."""

    def __init__(self, message: str, result: VerificationResult) -> None:
        super().__init__(message, result.checks)
        self.result = result


class Verifier(Protocol):
    """Post-calibration verification of a freshly written unit (see :mod:`station.sequence.verify`)."""

    def verify(self, sensor: Sensor, image: CalibrationImage) -> VerificationResult: ...


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
        now: calibration-time source (UTC) when :meth:`provision` is not given the run's start;
            default ``datetime.now(UTC)``.
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

    def image_for(self, unit: UnitResult, run_started_at: datetime | None = None) -> CalibrationImage:
        """The unit's image (:func:`~station.eeprom.image.run_image`): station and time are the run's."""
        if unit.params is None:
            raise ProvisionError(f"slot {unit.slot}: no parameter set to write")
        if unit.serial and unit.params.serial != unit.serial:
            raise SerialMismatchError(
                f"slot {unit.slot}: parameter set is for {unit.params.serial!r}, the unit is {unit.serial!r}"
            )
        when = run_started_at if run_started_at is not None else self._now()
        return run_image(unit.params, self.station_id, when)

    def write(self, unit: UnitResult, sensor: Sensor, run_started_at: datetime | None = None) -> WriteReport:
        """Write one PASS unit's image (A/B slots, read back) and power-cycle it so its firmware loads it;
        raises a HardwareError subclass when the writing fails."""
        image = self.image_for(unit, run_started_at)
        report = write_image(sensor, image, layout=self.layout, max_attempts=self.max_attempts)
        if self.power_cycle:
            sensor.power_cycle(self.boot_timeout_s)
        return report

    def finish(
        self, unit: UnitResult, report: WriteReport, result: VerificationResult | None
    ) -> tuple[Measurement, ...] | None:
        """Record a written unit's verification (``result``, None: not verified); returns its checks or
        raises :class:`VerificationFailed` when they are missed."""
        record = ProvisionRecord(report.serial, unit.slot, report, result)
        self.records[report.serial] = record
        if self._on_record is not None:
            self._on_record(record)
        if result is not None and not result.passed:
            raise VerificationFailed(f"verification of corrected output failed: {result.describe()}", result)
        if result is None:
            return None
        return result.checks

    def provision(
        self, unit: UnitResult, sensor: Sensor, run_started_at: datetime | None = None
    ) -> tuple[Measurement, ...] | None:
        """Write, power-cycle, verify one PASS unit; returns the verification checks (None without verifier).

        Raises a HardwareError subclass when the writing fails (station ERROR) and
        VerificationFailed (a UnitRejected) when the corrected output misses its limits (unit FAIL).
        """
        report = self.write(unit, sensor, run_started_at)
        result = self.verifier.verify(sensor, report.image) if self.verifier is not None else None
        return self.finish(unit, report, result)


__all__ = ["EepromProvisioner", "ProvisionRecord", "VerificationFailed", "Verifier"]
