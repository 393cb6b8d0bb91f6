"""A unit's things a request asks for, found in the store: the unit (404 when unknown), its session recordings,
the recording its plots are made from and the origin of its EEPROM image."""

from __future__ import annotations

from pathlib import Path

from fastapi import HTTPException

from station.store.db import Database
from station.store.queries import UnitDetail, show_unit
from station.web.diagnosis_worker import Recording


def unit_or_404(db: Database, serial: str) -> UnitDetail:
    """The unit ``serial``; HTTP 404 when the store does not know it."""
    detail = show_unit(db, serial)
    if detail is None:
        raise HTTPException(404, f"unknown unit {serial}")
    return detail


def recordings(detail: UnitDetail) -> list[Recording]:
    """The unit's runs with a session recording that is still on disk, newest first."""
    return [Recording(r.run_id, Path(r.session_path), r.session_sha256) for r in detail.runs
            if r.session_path and r.session_sha256 and Path(r.session_path).is_file()]


def recording_or_404(db: Database, serial: str, run_id: str | None) -> Recording:
    """The unit's recording of run ``run_id`` (None: its newest recording); HTTP 404 when there is none."""
    for rec in recordings(unit_or_404(db, serial)):
        if run_id is None or rec.run_id == run_id:
            return rec
    if run_id is None:
        raise HTTPException(404, f"no session recording of unit {serial}")
    raise HTTPException(404, f"no session recording of unit {serial} in run {run_id}")


def plot_source(detail: UnitDetail) -> tuple[str, str] | None:
    """(run id, session path) of the recording the unit's latest parameter set was fitted to, if still on disk."""
    if detail.latest_params_json is None:
        return None
    for run in detail.runs:
        if run.run_id == detail.latest_params_run_id and run.session_path and Path(run.session_path).is_file():
            return run.run_id, run.session_path
    return None


__all__ = ["plot_source", "recording_or_404", "recordings", "unit_or_404"]
