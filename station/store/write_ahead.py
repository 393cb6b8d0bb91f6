"""The write-ahead journal of EEPROM writes in the station database (see docs/provisioning.md).

:class:`StoreJournal` implements :class:`station.sequence.provision.ProvisionJournal` on the
``eeprom_writes`` table: :meth:`~StoreJournal.intend` commits a row in state 'intended' (the image's
SHA-256 and bytes, the target slot and update count, the run and fixture slot) before the first page
is written; :meth:`~StoreJournal.written` completes it after the read-back ('complete');
:meth:`~StoreJournal.verified` adds the on-rig verification (or the fault that stopped it).
:meth:`~StoreJournal.open_intents` and :meth:`~StoreJournal.reconcile` close intents a crash left
open, against what the unit holds. Every call is one transaction.
"""

from __future__ import annotations

from collections.abc import Callable
from datetime import UTC, datetime

from sqlalchemy import select
from sqlalchemy.orm import Session

from station.eeprom.provision import WritePlan, WriteReport
from station.sequence.provision import OpenIntent
from station.store.db import Database, StoreError
from station.store.models import EepromWrite, Run, RunUnit, Unit
from station.store.recorder import get_or_create_unit

INTENDED = "intended"
COMPLETE = "complete"
NOT_APPLIED = "not-applied"


def _now() -> datetime:
    return datetime.now(UTC)


class StoreJournal:
    """EEPROM writes recorded ahead in ``db``.

    Args:
        db: the open station database.
        run_id: the run the writes belong to (None: outside a run, e.g. ``station eeprom write``), or a
            callable giving it when the intent is recorded (the recorder's run in progress).
        source: said in each row's message (e.g. 'run', '`station eeprom write`').
    """

    def __init__(self, db: Database, run_id: str | Callable[[], str | None] | None = None,
                 source: str = "run") -> None:
        self.db = db
        self._run_id = run_id
        self.source = source

    def _run(self) -> str | None:
        return self._run_id() if callable(self._run_id) else self._run_id

    def intend(self, plan: WritePlan, slot: int | None) -> int:
        """Commit the intent to write ``plan`` (before any page is written); its row id."""
        run_id = self._run()
        now = _now()
        with self.db.transaction() as s:
            unit = get_or_create_unit(s, plan.serial)
            ru_id = None
            if run_id is not None and slot is not None:
                ru_id = s.scalar(select(RunUnit.id).join(Run).where(Run.run_uid == run_id, RunUnit.slot == slot))
            row = EepromWrite(run_unit_id=ru_id, unit_id=unit.id, image_sha256=plan.sha256,
                              layout_version=plan.image.layout_version, attempts=0, verified=False,
                              message=f"intended by {self.source}: image #{plan.update_count} to slot {plan.slot}",
                              written_at=now, written=False, read_back_ok=False, verified_on_rig=None,
                              image=plan.data or None, state=INTENDED, slot_name=plan.slot,
                              update_count=plan.update_count, intended_at=now)
            s.add(row)
            s.flush()
            return row.id

    def _row(self, s: Session, intent: int) -> EepromWrite:
        row = s.get(EepromWrite, intent)
        if row is None:
            raise StoreError(f"no EEPROM write intent {intent} in {self.db.url}")
        return row

    def written(self, intent: int, report: WriteReport) -> None:
        """The image was written and read back byte for byte: complete the intent."""
        with self.db.transaction() as s:
            row = self._row(s, intent)
            now = _now()
            row.state, row.written, row.read_back_ok, row.verified = COMPLETE, True, True, True
            row.attempts, row.completed_at, row.written_at = report.attempts, now, now
            row.message = (f"written by {self.source} to slot {report.slot}, read back in {report.attempts} "
                           f"attempt(s)")

    def verified(self, intent: int, passed: bool | None, message: str) -> None:
        """The on-rig verification of a written image: ``passed`` (None: not verified; ``message`` says why)."""
        with self.db.transaction() as s:
            row = self._row(s, intent)
            row.verified_on_rig = passed
            row.verified = bool(row.read_back_ok) and passed is not False
            if message:
                row.message = f"{row.message}; {message}" if row.message else message

    def open_intents(self, serial: str) -> list[OpenIntent]:
        """The intents of ``serial`` without a completion, oldest first."""
        with self.db.transaction() as s:
            rows = s.execute(
                select(EepromWrite.id, EepromWrite.image_sha256, EepromWrite.slot_name, EepromWrite.update_count,
                       EepromWrite.intended_at)
                .join(Unit, EepromWrite.unit_id == Unit.id)
                .where(Unit.serial == serial, EepromWrite.state == INTENDED).order_by(EepromWrite.id)
            ).all()
        return [OpenIntent(r[0], serial, r[1], r[2], r[3] or 0) for r in rows]

    def any_open(self) -> bool:
        """Whether any unit has an intent without a completion (a cheap check before reading units)."""
        with self.db.transaction() as s:
            return s.scalar(select(EepromWrite.id).where(EepromWrite.state == INTENDED).limit(1)) is not None

    def reconcile(self, intent: int, on_unit: bool, note: str) -> None:
        """Close an open intent: the image is on the unit (complete) or it is not (not-applied)."""
        with self.db.transaction() as s:
            row = self._row(s, intent)
            if row.state != INTENDED:
                return
            now = _now()
            row.completed_at = now
            row.reconciled = f"{now.isoformat(timespec='seconds')}: {note}"
            if on_unit:
                row.state, row.written, row.read_back_ok, row.verified = COMPLETE, True, True, True
                row.written_at = now
            else:
                row.state, row.written, row.read_back_ok, row.verified = NOT_APPLIED, False, False, False
            row.message = f"{row.message}; reconciled: {note}"


__all__ = ["COMPLETE", "INTENDED", "NOT_APPLIED", "StoreJournal"]
