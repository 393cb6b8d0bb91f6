"""Durable per-unit records: SQLite by default, PostgreSQL for several stations (SQLAlchemy 2 + Alembic).

- :mod:`station.store.models`: the tables (stations, fixture slots, units, runs, steps, limit checks,
  parameter sets, session recordings, EEPROM writes, dispositions).
- :mod:`station.store.db`: :func:`open_database` (URL, migrations on open).
- :mod:`station.store.recorder`: :class:`Recorder`, the runner subscriber; :func:`recover_unfinished`.
- :mod:`station.store.queries`: :func:`list_units`, :func:`show_unit`, :func:`attempt_count`.
- :mod:`station.store.commands`: ``station units ...`` and :func:`attach_recorder`.
"""

from station.store.db import DEFAULT_URL, Database, StoreError, open_database
from station.store.queries import (
    UnitDetail,
    UnitRun,
    UnitSummary,
    attempt_count,
    latest_parameter_set,
    list_units,
    show_unit,
)
from station.store.recorder import (
    Recorder,
    RunContext,
    record_disposition,
    record_eeprom_write,
    recover_unfinished,
)

__all__ = [
    "DEFAULT_URL",
    "Database",
    "Recorder",
    "RunContext",
    "StoreError",
    "UnitDetail",
    "UnitRun",
    "UnitSummary",
    "attempt_count",
    "latest_parameter_set",
    "list_units",
    "open_database",
    "record_disposition",
    "record_eeprom_write",
    "recover_unfinished",
    "show_unit",
]
