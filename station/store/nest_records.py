"""Nest calibrations in the database: stored versioned per rig, the newest read back for every run.

The reference unit's fits per nest (the input of :func:`station.fit.nest_estimate.estimate_nest_calibration`)
come from its stored parameter sets: per slot, the newest parameter set of that serial, optionally limited
to a set of runs.
"""

from __future__ import annotations

import json
from datetime import UTC, datetime

from sqlalchemy import func, select

from station.kernel.nest_frames import FORMAT, NestCalibration, nest_calibration_from_json
from station.kernel.parameters import ParameterSet
from station.store.db import Database
from station.store.models import NestCalibrationRecord, ParameterSetRecord, Run, RunUnit, Unit


def save_nest_calibration(db: Database, cal: NestCalibration) -> NestCalibration:
    """Store ``cal`` as the rig's next version; returns it with that version."""
    with db.transaction() as s:
        last = s.scalar(select(func.max(NestCalibrationRecord.version)).where(NestCalibrationRecord.rig == cal.rig))
        from dataclasses import replace

        stored = replace(cal, version=int(last or 0) + 1)
        created = datetime.fromisoformat(stored.created_at) if stored.created_at else datetime.now(UTC)
        s.add(NestCalibrationRecord(rig=stored.rig, version=stored.version, reference_serial=stored.reference_serial,
                                    created_at=created, format=FORMAT, body=stored.to_json_text(),
                                    sha256=stored.sha256))
    return stored


def latest_nest_calibration(db: Database, rig: str) -> NestCalibration | None:
    """The rig's newest nest calibration, or None when it has none."""
    with db.transaction() as s:
        row = s.scalars(select(NestCalibrationRecord).where(NestCalibrationRecord.rig == rig)
                        .order_by(NestCalibrationRecord.version.desc()).limit(1)).first()
        return None if row is None else nest_calibration_from_json(json.loads(row.body))


def nest_calibrations(db: Database, rig: str | None = None) -> list[NestCalibration]:
    """Every stored nest calibration (of ``rig``, if given), oldest first."""
    q = select(NestCalibrationRecord).order_by(NestCalibrationRecord.rig, NestCalibrationRecord.version)
    if rig is not None:
        q = q.where(NestCalibrationRecord.rig == rig)
    with db.transaction() as s:
        return [nest_calibration_from_json(json.loads(r.body)) for r in s.scalars(q)]


def reference_fits(db: Database, serial: str, run_uids: tuple[str, ...] = ()) -> dict[int, ParameterSet]:
    """Per slot, the newest parameter set of unit ``serial`` (in ``run_uids`` when given)."""
    q = (select(RunUnit.slot, ParameterSetRecord.params_json)
         .join(ParameterSetRecord, ParameterSetRecord.run_unit_id == RunUnit.id)
         .join(Run, RunUnit.run_id == Run.id).join(Unit, RunUnit.unit_id == Unit.id)
         .where(Unit.serial == serial).order_by(Run.started_at, Run.id))
    if run_uids:
        q = q.where(Run.run_uid.in_(run_uids))
    out: dict[int, ParameterSet] = {}
    with db.transaction() as s:
        for slot, body in s.execute(q):
            out[int(slot)] = ParameterSet.from_json(body)
    return out
