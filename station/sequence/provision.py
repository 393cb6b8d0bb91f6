"""Provisioning as a step of the sequence, in phases, recorded ahead: intend, write, verify, complete.

:class:`EepromProvisioner` implements the runner's :class:`~station.sequence.runner.Provisioner`
protocol for PASS units of a complete, fault-free run:

1. :meth:`~EepromProvisioner.intend` builds the unit's image, decides where it goes
   (:func:`station.eeprom.provision.plan_write`: serial, free A/B slot, update count; nothing is
   written) and commits the intent to the journal (:class:`ProvisionJournal`) *before* the first
   page goes to the unit;
2. :meth:`~EepromProvisioner.write` programs the pages (header page last) and reads them back
   (:func:`station.eeprom.provision.program_image`), records the write as complete, then
   power-cycles the sensor so its firmware loads it;
3. :meth:`~EepromProvisioner.verify` runs the optional verification of the corrected output
   (:mod:`station.sequence.verify`);
4. :meth:`~EepromProvisioner.complete` records the verification, or the fault that stopped it, and
   raises :class:`VerificationFailed` when the unit missed its limits.

A failed write is a :class:`~station.kernel.errors.HardwareError` (the runner makes the unit ERROR);
a verification fault (the rig or the link) is an ERROR with the write recorded; a failed
verification is a :class:`VerificationFailed` (the unit FAILs).

A crash between the intent and its completion leaves an open intent. :func:`reconcile_unit` (called
when a run starts and by ``station eeprom read``) compares it with the unit's current image: the image
is there (the write reached its header page) -> the write is recorded as complete; it is not -> the
intent is closed as not applied. Either way the database and the unit agree again, and the
reconciliation is reported. See docs/provisioning.md.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from datetime import UTC, datetime
from typing import TYPE_CHECKING, Protocol

from station.eeprom.image import DEFAULT_SLOTS, CalibrationImage, SlotLayout, run_image
from station.eeprom.provision import (
    ProvisionError,
    SerialMismatchError,
    WritePlan,
    WriteReport,
    current_image_sha256,
    plan_write,
    program_image,
)
from station.kernel.errors import HardwareError, StationError, UnitRejected
from station.kernel.measurement import Measurement
from station.sensor.protocol import Sensor

if TYPE_CHECKING:
    from station.sequence.runner import UnitResult
    from station.sequence.verify import VerificationResult

log = logging.getLogger(__name__)


class VerificationFailed(UnitRejected):
    """The unit's corrected output is outside the verification limits (see ``result``): a FAIL."""

    def __init__(self, message: str, result: VerificationResult) -> None:
        super().__init__(message, result.checks)
        self.result = result


class Verifier(Protocol):
    """Post-calibration verification of a freshly written unit (see :mod:`station.sequence.verify`)."""

    def verify(self, sensor: Sensor, image: CalibrationImage) -> VerificationResult: ...


@dataclass(frozen=True)
class OpenIntent:
    """An intent to write recorded without a completion: row ``intent``, the image's ``sha256``, its target
    ``slot`` ('A'/'B') and ``update_count``."""

    intent: int
    serial: str
    sha256: str
    slot: str
    update_count: int


class ProvisionJournal(Protocol):
    """Where EEPROM writes are recorded ahead (the station database: :class:`station.store.write_ahead.StoreJournal`).

    Each call is durable when it returns.
    """

    def intend(self, plan: WritePlan, slot: int | None) -> int:
        """Record the intent to write ``plan`` (fixture ``slot``); its id."""
        ...

    def written(self, intent: int, report: WriteReport) -> None:
        """The image was written and read back: the intent is complete."""
        ...

    def verified(self, intent: int, passed: bool | None, message: str) -> None:
        """The verification of a written image (``passed`` None: not verified, ``message`` says why)."""
        ...

    def open_intents(self, serial: str) -> list[OpenIntent]:
        """``serial``'s intents without a completion."""
        ...

    def any_open(self) -> bool:
        """Whether any unit has an intent without a completion."""
        ...

    def reconcile(self, intent: int, on_unit: bool, note: str) -> None:
        """Close an open intent: its image is the unit's current one (``on_unit``) or not."""
        ...


@dataclass(frozen=True, eq=False)
class ProvisionIntent:
    """Phase 1's result: the unit, what will be written where, and the journal's id for it (None: no journal)."""

    unit: UnitResult
    plan: WritePlan
    journal_id: int | None = None


@dataclass(frozen=True, eq=False)
class WrittenImage:
    """Phase 2's result: the unit, the completed write, and the journal's id for it."""

    unit: UnitResult
    report: WriteReport
    journal_id: int | None = None


@dataclass(frozen=True, eq=False)
class ProvisionRecord:
    """What provisioning did for one unit: the write and, if run, the verification (``fault``: why it did not)."""

    serial: str
    slot: int
    write: WriteReport
    verification: VerificationResult | None
    fault: str = ""


class EepromProvisioner:
    """The sequence runner's Provisioner: intend, write (read back, power-cycle), verify, complete.

    Args:
        station_id: written into each image (ASCII, 1..16 characters).
        verifier: post-calibration verification (None: none).
        layout: image slots.
        max_attempts: write + read-back rounds per unit.
        power_cycle: reset the sensor after writing so its firmware loads the new image.
        boot_timeout_s: wall seconds to wait for the BOOT event after the reset.
        now: calibration-time source (UTC) when :meth:`intend` is not given the run's start;
            default ``datetime.now(UTC)``.
        journal: where the writes are recorded ahead (None: not recorded).
        on_record: called with each unit's :class:`ProvisionRecord` when it completes.

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
        journal: ProvisionJournal | None = None,
        on_record: Callable[[ProvisionRecord], None] | None = None,
    ) -> None:
        self.station_id = station_id
        self.verifier = verifier
        self.layout = layout
        self.max_attempts = max_attempts
        self.power_cycle = power_cycle
        self.boot_timeout_s = boot_timeout_s
        self._now = now if now is not None else (lambda: datetime.now(UTC))
        self.journal = journal
        self._on_record = on_record
        self.records: dict[str, ProvisionRecord] = {}

    @property
    def verifies(self) -> bool:
        """Whether :meth:`verify` checks anything (a verifier was given)."""
        return self.verifier is not None

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

    # --- the phases -----------------------------------------------------------------------------------

    def intend(self, unit: UnitResult, sensor: Sensor, run_started_at: datetime | None = None) -> ProvisionIntent:
        """Phase 1: decide the write (nothing written) and record the intent; raises a StationError when
        either fails (then nothing was written to the unit)."""
        plan = plan_write(sensor, self.image_for(unit, run_started_at), layout=self.layout)
        journal_id = self.journal.intend(plan, unit.slot) if self.journal is not None else None
        return ProvisionIntent(unit, plan, journal_id)

    def write(self, intent: ProvisionIntent, sensor: Sensor) -> WrittenImage:
        """Phase 2: program and read back, record the write complete, power-cycle the sensor.

        A failed write (HardwareError) is reconciled at once when the unit still answers, else left open
        for the next start. A power cycle that fails comes after the record: the write stays recorded.
        """
        try:
            report = program_image(sensor, intent.plan, max_attempts=self.max_attempts)
        except HardwareError:
            self._settle(intent, sensor)
            raise
        if self.journal is not None and intent.journal_id is not None:
            self.journal.written(intent.journal_id, report)
        if self.power_cycle:
            sensor.power_cycle(self.boot_timeout_s)
        return WrittenImage(intent.unit, report, intent.journal_id)

    def verify(self, written: WrittenImage, sensor: Sensor) -> VerificationResult | None:
        """Phase 3: the verification of the corrected output (None without a verifier); raises a
        HardwareError on a station fault (then call :meth:`complete` with ``fault``)."""
        return self.verifier.verify(sensor, written.report.image) if self.verifier is not None else None

    @property
    def shares_holds(self) -> bool:
        """Whether :meth:`verify_many` verifies the written units together (the verifier can)."""
        return callable(getattr(self.verifier, "verify_many", None))

    def verify_many(
        self, items: Sequence[tuple[WrittenImage, Sensor]]
    ) -> list[VerificationResult | StationError] | None:
        """Phase 3 for every written unit at once, in the same holds of the rig (one pose, one rate step whatever
        the number of units: :meth:`station.sequence.verify.RigVerifier.verify_many`); per unit its result or its
        link's fault. None when the verifier checks one unit at a time (then call :meth:`verify` for each).
        A rig fault raises (every unit's verification void)."""
        many = getattr(self.verifier, "verify_many", None)
        if many is None:
            return None
        results: list[VerificationResult | StationError] = many([(s, w.report.image) for w, s in items])
        return results

    def complete(self, written: WrittenImage, result: VerificationResult | None,
                 fault: str = "") -> tuple[Measurement, ...] | None:
        """Phase 4: record the verification (``result``; None and ``fault``: why it did not happen); returns
        its checks, or raises :class:`VerificationFailed` when they are missed."""
        report = written.report
        record = ProvisionRecord(report.serial, written.unit.slot, report, result, fault)
        self.records[report.serial] = record
        if self.journal is not None and written.journal_id is not None:
            if result is not None:
                self.journal.verified(written.journal_id, bool(result.passed), result.describe())
            else:
                self.journal.verified(written.journal_id, None, f"not verified: {fault}" if fault else "")
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
        """All four phases for one PASS unit; returns the verification checks (None without verifier).

        Raises a HardwareError subclass when the writing or the verification faults (station ERROR; a
        verification fault after the write is recorded first) and VerificationFailed (a UnitRejected)
        when the corrected output misses its limits (unit FAIL).
        """
        written = self.write(self.intend(unit, sensor, run_started_at), sensor)
        try:
            result = self.verify(written, sensor)
        except StationError as exc:
            self.complete(written, None, f"verification fault: {type(exc).__name__}: {exc}")
            raise
        return self.complete(written, result)

    def _settle(self, intent: ProvisionIntent, sensor: Sensor) -> None:
        """After a failed write: close the intent against the unit's image if the unit still answers."""
        if self.journal is None or intent.journal_id is None:
            return
        try:
            reconcile_unit(self.journal, sensor, intent.plan.serial, self.layout)
        except StationError as exc:
            log.warning("%s: write intent left open for the next start (%s)", intent.plan.serial, exc)


def reconcile_unit(journal: ProvisionJournal, sensor: Sensor, serial: str | None = None,
                   layout: SlotLayout = DEFAULT_SLOTS) -> list[str]:
    """Close ``serial``'s open write intents against the unit's current image; one line per intent closed.

    The intent whose image is the unit's current one is recorded complete (the write reached its header
    page); the others are closed as not applied. ``serial`` None: asked from the sensor. Raises a
    HardwareError when the unit cannot be read (the intents stay open).
    """
    if serial is None:
        serial = sensor.identify().serial
    intents = journal.open_intents(serial)
    if not intents:
        return []
    current = current_image_sha256(sensor, layout)
    lines = []
    for it in intents:
        on_unit = current is not None and current[0] == it.sha256
        if on_unit:
            note = (f"image #{it.update_count} (sha256 {it.sha256[:12]}) is the unit's current image: the write "
                    f"completed but was not recorded; recorded now")
        else:
            now = "no valid image" if current is None else f"image #{current[1]} (sha256 {current[0][:12]})"
            note = (f"image #{it.update_count} (sha256 {it.sha256[:12]}) is not on the unit (it holds {now}): "
                    f"the write did not complete; recorded as not applied")
        journal.reconcile(it.intent, on_unit, note)
        line = f"{serial}: reconciled an unfinished EEPROM write to slot {it.slot}: {note}"
        log.warning("%s", line)
        lines.append(line)
    return lines


__all__ = [
    "EepromProvisioner",
    "OpenIntent",
    "ProvisionIntent",
    "ProvisionJournal",
    "ProvisionRecord",
    "VerificationFailed",
    "Verifier",
    "WrittenImage",
    "reconcile_unit",
]
