"""Durable per-unit records: SQLite by default, PostgreSQL for several stations (SQLAlchemy 2 + Alembic).

- :mod:`station.store.models`: the tables (stations, fixture slots, units, runs, steps, limit checks,
  parameter sets, session recordings, EEPROM writes, dispositions).
- :mod:`station.store.db`: :func:`open_database` (URL, migrations on open).
- :mod:`station.store.recorder`: :class:`Recorder`, the runner subscriber; :func:`recover_unfinished`.
- :mod:`station.store.queries`: :func:`list_units`, :func:`show_unit`, :func:`attempt_count`.
- :mod:`station.commands.units`: ``station units ...`` and :func:`attach_recorder`.
"""


# Lazy (PEP 562): importing the package, e.g. for its CLI commands, loads no heavy dependency.
_EXPORTS = {
    "DEFAULT_URL": "station.store.default_url",
    "Database": "station.store.db",
    "StoreError": "station.store.db",
    "open_database": "station.store.db",
    "UnitDetail": "station.store.queries",
    "UnitRun": "station.store.queries",
    "UnitSummary": "station.store.queries",
    "attempt_count": "station.store.queries",
    "latest_parameter_set": "station.store.queries",
    "list_units": "station.store.queries",
    "show_unit": "station.store.queries",
    "Recorder": "station.store.recorder",
    "RunContext": "station.store.recorder",
    "record_disposition": "station.store.recorder",
    "record_eeprom_write": "station.store.recorder",
    "recover_unfinished": "station.store.recorder",
}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str) -> object:
    if name in _EXPORTS:
        import importlib

        return getattr(importlib.import_module(_EXPORTS[name]), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
