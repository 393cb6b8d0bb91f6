"""The measurements a Gage R&R study reads from the records: one product-limit value per unit result.

A study is a set of runs (chosen by lot, by run ids, or by a time window); each tested unit result in them
contributes, per product-limit parameter, one :class:`StudyValue`: the part (serial), the nest (slot of
the rig), the rig, the operator, the run, and the value with its limits, in the parameter's SI unit as
stored in ``limit_checks``. The analysis (:mod:`station.msa.gage_rr`) is done by the caller; this module
only reads.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from datetime import datetime

from sqlalchemy import select

from station.store.db import Database
from station.store.models import LimitCheck, Run, RunUnit, Unit

TESTED = ("PASS", "FAIL", "RETEST")
"""Unit outcomes that carry a measurement (the run reached a verdict on the unit)."""


@dataclass(frozen=True)
class StudyValue:
    """One measured value of one parameter of one part in one run. ``low``/``high``: its limits (None: none)."""

    parameter: str
    unit: str
    serial: str
    nest: int
    rig: str
    operator: str
    run_uid: str
    started_at: datetime
    value: float
    low: float | None
    high: float | None


@dataclass(frozen=True)
class StudySelection:
    """Which runs form the study: any of lot, run uids, or a start-time window (all given must hold)."""

    lot: str | None = None
    run_uids: tuple[str, ...] = ()
    since: datetime | None = None
    until: datetime | None = None


def study_values(db: Database, selection: StudySelection) -> list[StudyValue]:
    """Every product-limit value of every tested unit result in the selected runs, oldest run first."""
    q = (
        select(LimitCheck.name, LimitCheck.unit, LimitCheck.value, LimitCheck.low, LimitCheck.high,
               Unit.serial, RunUnit.slot, Run.rig, Run.operator, Run.run_uid, Run.started_at)
        .join(RunUnit, LimitCheck.run_unit_id == RunUnit.id)
        .join(Run, RunUnit.run_id == Run.id)
        .join(Unit, RunUnit.unit_id == Unit.id)
        .where(LimitCheck.step == "limits", RunUnit.outcome.in_(TESTED))
        .order_by(Run.started_at, Run.id, RunUnit.slot, LimitCheck.id)
    )
    if selection.lot is not None:
        q = q.where(Run.lot == selection.lot)
    if selection.run_uids:
        q = q.where(Run.run_uid.in_(selection.run_uids))
    if selection.since is not None:
        q = q.where(Run.started_at >= selection.since)
    if selection.until is not None:
        q = q.where(Run.started_at < selection.until)
    out: list[StudyValue] = []
    with db.transaction() as s:
        for name, unit, value, low, high, serial, slot, rig, operator, run_uid, started in s.execute(q):
            if value is None or not math.isfinite(value):
                continue
            out.append(StudyValue(str(name), str(unit or ""), str(serial), int(slot), str(rig or ""),
                                  str(operator or ""), str(run_uid), started, float(value),
                                  None if low is None else float(low), None if high is None else float(high)))
    return out
