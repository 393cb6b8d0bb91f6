"""Write a run's records into the station database, one transaction per state change.

:class:`Recorder` is a subscriber of :class:`station.sequence.runner.SequenceRunner`:

- ``RunStarted``: the station, its fixture slots, the run (outcome UNFINISHED) and
  one :class:`~station.store.models.RunUnit` per slot (UNFINISHED) in one transaction;
- ``StepStarted`` / ``StepFinished``: the step's timing row (station clock, s);
- ``Measured``: buffered and written with the next state change (the step's end,
  or the unit's end for the product limits), so a step's gates land together;
- ``UnitFinished``: the unit's outcome, its session recording (path, SHA-256) and
  its parameter set (JSON, format, uncertainties);
- ``RunFinished``: the run's outcome, end time and durations.

The run's outcome is written only by the transaction that records ``RunFinished``,
so a process killed at any point leaves the run UNFINISHED, never a PASS.
:func:`recover_unfinished` (called by :meth:`Recorder.recover` at the next start)
marks such runs, and their units that had not failed, ERROR (or ABORTED) with a
note. The runner calls subscribers from its own thread and logs their exceptions;
a database failure therefore never stops a run, it is logged.
"""

from __future__ import annotations

import hashlib
import json
import logging
import os
import socket
from collections.abc import Iterable
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import TYPE_CHECKING, Any

from sqlalchemy import select
from sqlalchemy.exc import IntegrityError
from sqlalchemy.orm import Session

import station
from station.sequence.records import (
    Measured,
    Outcome,
    PromptAnswered,
    PromptShown,
    Record,
    RigReading,
    RunFinished,
    RunStarted,
    StepFinished,
    StepStarted,
    UnitFinished,
)
from station.store.db import Database, StoreError
from station.store.models import (
    UNFINISHED,
    Disposition,
    EepromWrite,
    FixtureSlot,
    LimitCheck,
    ParameterSetRecord,
    Run,
    RunUnit,
    SessionRecording,
    StepTiming,
    Unit,
)
from station.store.models import (
    Station as StationRow,
)
from station.store.quality_index import index_run

if TYPE_CHECKING:
    from station.sequence.provision import ProvisionRecord

log = logging.getLogger(__name__)

RECOVERY_NOTE = "the station process ended before the run was finished (recovered at the next start)"


def sha256_bytes(data: bytes) -> str:
    """Hex SHA-256 of ``data``."""
    return hashlib.sha256(data).hexdigest()


def sha256_file(path: Path) -> tuple[str, int]:
    """Hex SHA-256 and size (bytes) of the file at ``path``."""
    h = hashlib.sha256()
    size = 0
    with path.open("rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
            size += len(chunk)
    return h.hexdigest(), size


def digest_of(obj: object) -> str:
    """Hex SHA-256 of ``repr(obj)``: a stable fingerprint of a frozen dataclass (plan, limits)."""
    return sha256_bytes(repr(obj).encode("utf-8"))


@dataclass(frozen=True)
class RunContext:
    """What the records do not carry but every run row needs: who ran it, with which versions.

    Hashes are hex SHA-256 (see :func:`digest_of`); empty strings mean unknown. ``lot``: the production lot
    of the units the station calibrates (from the station configuration; '' when not configured).
    """

    operator: str = ""
    software_version: str = station.__version__
    sequence_version: str = ""
    sequence_hash: str = ""
    limits_version: str = ""
    limits_hash: str = ""
    lot: str = ""


def _now() -> datetime:
    return datetime.now(UTC)


def _parse_time(text: str) -> datetime:
    try:
        t = datetime.fromisoformat(text)
    except ValueError:
        return _now()
    return t if t.tzinfo is not None else t.replace(tzinfo=UTC)


def _num(x: float) -> float | None:
    """A float for the database: NaN becomes NULL (SQLite cannot store NaN)."""
    x = float(x)
    return None if x != x else x


def get_or_create_unit(session: Session, serial: str) -> Unit:
    """The unit row of ``serial``, created if new (safe when two stations create it at once)."""
    unit = session.scalar(select(Unit).where(Unit.serial == serial))
    if unit is not None:
        return unit
    try:
        with session.begin_nested():
            unit = Unit(serial=serial, created_at=_now())
            session.add(unit)
    except IntegrityError:
        unit = session.scalars(select(Unit).where(Unit.serial == serial)).one()
    return unit


def _get_or_create_station(session: Session, name: str) -> StationRow:
    row = session.scalar(select(StationRow).where(StationRow.name == name))
    if row is not None:
        return row
    try:
        with session.begin_nested():
            row = StationRow(name=name, created_at=_now())
            session.add(row)
    except IntegrityError:
        row = session.scalars(select(StationRow).where(StationRow.name == name)).one()
    return row


def _uncertainties(d: Any, prefix: str = "") -> dict[str, Any]:
    """Every ``*_std`` entry of a parameter-set dict, keyed by its dotted path (e.g. 'accel.bias_static_std')."""
    out: dict[str, Any] = {}
    if isinstance(d, dict):
        for k, v in d.items():
            path = f"{prefix}{k}"
            if isinstance(k, str) and k.endswith("_std"):
                out[path] = v
            elif isinstance(v, dict):
                out.update(_uncertainties(v, path + "."))
    return out


@dataclass
class _RunState:
    run_pk: int
    run_units: dict[int, int]  # slot -> run_units.id
    steps: dict[int, int] = field(default_factory=dict)  # step index -> step_timings.id
    pending: list[Measured] = field(default_factory=list)
    linked: set[int] = field(default_factory=set)  # slots whose unit is known


class Recorder:
    """A runner subscriber that writes every record into ``db`` (see the module docstring).

    Args:
        db: an open database (:func:`station.store.db.open_database`).
        context: operator and versions for the run rows.
    """

    def __init__(self, db: Database, context: RunContext | None = None) -> None:
        self.db = db
        self.context = context if context is not None else RunContext()
        self._runs: dict[str, _RunState] = {}
        self.errors: list[str] = []

    def recover(self, station_name: str | None = None, outcome: Outcome = Outcome.ERROR) -> list[str]:
        """Close stale UNFINISHED runs (of ``station_name``, or all); returns their run ids."""
        return recover_unfinished(self.db, station_name, outcome=outcome, exclude=set(self._runs))

    def current_run(self) -> str | None:
        """The run in progress on this recorder (the last started), or None."""
        return next(reversed(self._runs), None)

    def provisioned(self, record: ProvisionRecord) -> None:
        """Store one unit's EEPROM write and verification after the fact (an ``EepromProvisioner`` ``on_record``
        for a provisioner without a journal; the station records ahead instead: :mod:`station.store.write_ahead`).

        Linked to the run in progress on this recorder (the provisioner runs inside it).
        """
        write = record.write
        verification = record.verification
        on_rig = None if verification is None else bool(verification.passed)
        run_id = next(reversed(self._runs), None)
        message = "" if verification is None else verification.describe()
        record_eeprom_write(
            self.db, write.serial, write.sha256, attempts=write.attempts, read_back_ok=True, verified_on_rig=on_rig,
            image=write.data or None, run_id=run_id, slot=record.slot,
            layout_version=write.image.layout_version,
            message=message,
        )

    def __call__(self, record: Record) -> None:
        try:
            self.write(record)
        except Exception as exc:
            self.errors.append(f"{type(record).__name__}: {exc}")
            raise

    def write(self, record: Record) -> None:
        """Write one record (in its own transaction; measurements are buffered to the next one)."""
        if isinstance(record, RunStarted):
            self._run_started(record)
            return
        if isinstance(record, (RigReading, PromptShown, PromptAnswered)):  # for displays, not a state change
            return
        state = self._runs.get(record.run_id)
        if state is None:
            raise StoreError(f"record for unknown run {record.run_id!r}: {type(record).__name__}")
        if isinstance(record, Measured):
            state.pending.append(record)
            return
        with self.db.transaction() as s:
            self._flush(s, state)
            if isinstance(record, StepStarted):
                row = StepTiming(run_id=state.run_pk, step_index=record.index, name=record.name, kind=record.kind,
                                 hold_s=record.hold_s, started_t_s=record.t_s, message="")
                s.add(row)
                s.flush()
                state.steps[record.index] = row.id
            elif isinstance(record, StepFinished):
                step = s.get(StepTiming, state.steps[record.index]) if record.index in state.steps else None
                if step is None:
                    step = StepTiming(run_id=state.run_pk, step_index=record.index, name=record.name, kind="",
                                      hold_s=0.0, started_t_s=record.t_s - record.duration_s)
                    s.add(step)
                step.duration_s, step.ok = record.duration_s, record.ok
                step.units_active, step.message = record.units_active, record.message
            elif isinstance(record, UnitFinished):
                self._unit_finished(s, state, record)
            elif isinstance(record, RunFinished):
                self._run_finished(s, state, record)
        if isinstance(record, RunFinished):
            del self._runs[record.run_id]

    # --- per record -------------------------------------------------------------------------------

    def _run_started(self, r: RunStarted) -> None:
        c = self.context
        with self.db.transaction() as s:
            st = _get_or_create_station(s, r.station)
            slots = {fs.slot: fs for fs in s.scalars(select(FixtureSlot).where(FixtureSlot.station_id == st.id))}
            for k, url in enumerate(r.sensors):
                if k in slots:
                    slots[k].sensor_url = url
                else:
                    s.add(FixtureSlot(station_id=st.id, slot=k, sensor_url=url))
            run = Run(
                run_uid=r.run_id, station_id=st.id, outcome=UNFINISHED, started_at=_parse_time(r.at),
                software_version=c.software_version, sequence_version=c.sequence_version,
                sequence_hash=c.sequence_hash, limits_version=c.limits_version, limits_hash=c.limits_hash,
                operator=c.operator, lot=c.lot, rig=r.rig, host=socket.gethostname(), pid=os.getpid(), message="",
            )
            s.add(run)
            s.flush()
            units = [RunUnit(run_id=run.id, slot=k, sensor_url=url, outcome=UNFINISHED, message="")
                     for k, url in enumerate(r.sensors)]
            s.add_all(units)
            s.flush()
            self._runs[r.run_id] = _RunState(run.id, {u.slot: u.id for u in units})

    def _link(self, s: Session, state: _RunState, slot: int, serial: str) -> RunUnit | None:
        pk = state.run_units.get(slot)
        if pk is None:
            return None
        ru = s.get(RunUnit, pk)
        if ru is not None and serial and slot not in state.linked:
            ru.unit_id = get_or_create_unit(s, serial).id
            state.linked.add(slot)
        return ru

    def _flush(self, s: Session, state: _RunState) -> None:
        for m in state.pending:
            ru = self._link(s, state, m.slot, m.serial)
            if ru is None:
                log.warning("measurement for unknown slot %d ignored", m.slot)
                continue
            c = m.measurement
            s.add(LimitCheck(run_unit_id=ru.id, step=m.step, name=c.name, value=_num(c.value), low=_num(c.low),
                             high=_num(c.high), std=_num(c.std), unit=c.unit, passed=bool(c.passed),
                             verdict=c.verdict.value, k=c.k or None))
        state.pending.clear()

    def _unit_finished(self, s: Session, state: _RunState, r: UnitFinished) -> None:
        ru = self._link(s, state, r.slot, r.serial)
        if ru is None:
            raise StoreError(f"run {r.run_id}: unit finished in unknown slot {r.slot}")
        ru.outcome, ru.message = r.outcome.value, r.message
        if r.session_path:
            path = Path(r.session_path)
            try:
                digest, size = sha256_file(path)
                s.add(SessionRecording(run_unit_id=ru.id, path=str(path), sha256=digest, size_bytes=size))
            except OSError as exc:
                log.error("run %s slot %d: cannot hash the recording %s: %s", r.run_id, r.slot, path, exc)
        if r.params_path and ru.unit_id is not None:
            path = Path(r.params_path)
            try:
                text = path.read_text(encoding="utf-8")
                d = json.loads(text)
                s.add(ParameterSetRecord(
                    run_unit_id=ru.id, unit_id=ru.unit_id, format=str(d.get("format", "")),
                    sha256=sha256_bytes(text.encode("utf-8")), params_json=text,
                    uncertainties_json=json.dumps(_uncertainties(d), sort_keys=True),
                    path=str(path), created_at=_now(),
                ))
            except (OSError, ValueError) as exc:
                log.error("run %s slot %d: cannot read the parameter set %s: %s", r.run_id, r.slot, path, exc)

    def _run_finished(self, s: Session, state: _RunState, r: RunFinished) -> None:
        run = s.get(Run, state.run_pk)
        assert run is not None
        for u in r.units:  # units whose UnitFinished was not seen
            ru = self._link(s, state, u.slot, u.serial)
            if ru is not None and ru.outcome == UNFINISHED:
                ru.outcome, ru.message = u.outcome.value, u.message
        run.outcome = r.outcome.value
        run.finished_at = _now()
        run.duration_s, run.wall_s = _num(r.duration_s), _num(r.wall_s)
        run.message, run.rig_at_rest = r.message, r.rig_at_rest
        s.flush()
        index_run(s, run.id)  # the quality tables learn of the run in the transaction that ends it


def recover_unfinished(
    db: Database,
    station_name: str | None = None,
    *,
    outcome: Outcome = Outcome.ERROR,
    note: str = RECOVERY_NOTE,
    exclude: Iterable[str] = (),
) -> list[str]:
    """Mark stale UNFINISHED runs ``outcome`` (ERROR or ABORTED) with ``note``; returns their run ids.

    A run is stale unless it is in ``exclude`` or was started on this host by a process
    that is still alive. With ``station_name`` only that station's runs are considered
    (several stations may share one database). The run's units that were UNFINISHED or
    PASS get the same outcome (a PASS is only trusted from a finished run); FAIL stays.
    Everything happens in one transaction.
    """
    if outcome not in (Outcome.ERROR, Outcome.ABORTED):
        raise ValueError("a recovered run is ERROR or ABORTED")
    skip = set(exclude)
    host = socket.gethostname()
    recovered: list[str] = []
    with db.transaction() as s:
        q = select(Run).where(Run.outcome == UNFINISHED)
        if station_name is not None:
            q = q.join(StationRow).where(StationRow.name == station_name)
        for run in s.scalars(q.with_for_update() if db.engine.dialect.name == "postgresql" else q):
            if run.run_uid in skip or (run.host == host and run.pid != os.getpid() and process_alive(run.pid)):
                continue
            run.outcome = outcome.value
            run.finished_at = _now()
            run.message = f"{run.message}; {note}" if run.message else note
            for ru in run.units:
                if ru.outcome in (UNFINISHED, Outcome.PASS.value):
                    ru.outcome = outcome.value
                    ru.message = f"{ru.message}; {note}" if ru.message else note
            s.flush()
            index_run(s, run.id)
            recovered.append(run.run_uid)
    return recovered


def process_alive(pid: int) -> bool:
    """Whether a process ``pid`` runs on this host (a recorded run's or a rig lock's owner)."""
    if pid <= 0:
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def record_eeprom_write(
    db: Database,
    serial: str,
    image_sha256: str,
    *,
    attempts: int,
    verified: bool | None = None,
    read_back_ok: bool | None = None,
    verified_on_rig: bool | None = None,
    image: bytes | None = None,
    run_id: str | None = None,
    slot: int | None = None,
    layout_version: int = 0,
    message: str = "",
) -> int:
    """Record an EEPROM write of ``serial``; returns its row id.

    ``read_back_ok``: the image read back byte for byte; ``verified_on_rig``: the corrected output was
    checked on the rig and met its limits (None: not checked). ``verified`` (older callers) stands for
    ``read_back_ok``. The stored ``verified`` is read back and, where checked, verified on the rig.
    ``image``: the bytes written. ``run_id`` and ``slot`` link it to its run (None: outside a run).
    """
    if read_back_ok is None:
        read_back_ok = bool(verified)
    verified = read_back_ok and verified_on_rig is not False
    with db.transaction() as s:
        unit = get_or_create_unit(s, serial)
        ru_id = None
        if run_id is not None and slot is not None:
            ru_id = s.scalar(select(RunUnit.id).join(Run).where(Run.run_uid == run_id, RunUnit.slot == slot))
        row = EepromWrite(run_unit_id=ru_id, unit_id=unit.id, image_sha256=image_sha256,
                          layout_version=layout_version, attempts=attempts, verified=verified, message=message,
                          written_at=_now(), written=True, read_back_ok=read_back_ok,
                          verified_on_rig=verified_on_rig, image=image)
        s.add(row)
        s.flush()
        return row.id


#: What a person may decide about a unit. Every decision but ``scrap`` resets its failed attempts;
#: ``scrap`` locks the serial for good.
DECISIONS = ("retest", "scrap", "rework", "accept-deviation")


class DispositionError(StoreError):
    """A disposition the station refuses: unknown decision or serial, no operator, no reason."""


def record_disposition(db: Database, serial: str, decision: str, *, operator: str = "", note: str = "") -> int:
    """Record ``operator``'s ``decision`` about the known unit ``serial`` with its reason ``note``; the row id.

    ``decision`` is one of :data:`DECISIONS`. Raises :class:`DispositionError` (nothing written) for an
    unknown decision, a serial the station never tested, an empty operator or reason, or any decision
    about a scrapped unit.
    """
    if decision not in DECISIONS:
        raise DispositionError(f"unknown decision {decision!r}: one of {', '.join(DECISIONS)}")
    if not operator.strip():
        raise DispositionError("a disposition needs the operator who decided it (--operator)")
    if not note.strip():
        raise DispositionError("a disposition needs its reason (--reason)")
    with db.transaction() as s:
        unit = s.scalar(select(Unit).where(Unit.serial == serial))
        if unit is None:
            raise DispositionError(f"no unit with serial {serial!r} in {db.url}: nothing recorded")
        scrapped = s.scalar(select(Disposition.id).where(Disposition.unit_id == unit.id,
                                                         Disposition.decision == "scrap"))
        if scrapped is not None:
            raise DispositionError(f"{serial} is scrapped: no further disposition is recorded")
        row = Disposition(unit_id=unit.id, decision=decision, operator=operator, note=note, decided_at=_now())
        s.add(row)
        s.flush()
        return row.id
