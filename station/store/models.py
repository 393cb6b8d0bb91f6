"""The station's durable records: SQLAlchemy 2 typed ORM tables.

One row per station, fixture slot, unit (serial number) and run; per run the
steps' timing and per unit in the run (:class:`RunUnit`) its outcome, every limit
check, the fitted parameter set, the session recording and any EEPROM writes.
Dispositions record a person's decision about a unit that the retest policy
refused.

Units: times of steps in station clock seconds (s); measured values and limits in
the SI unit named in ``LimitCheck.unit`` (m/s^2, rad/s, s or 1). Wall-clock times
are UTC. A float the runner reports as NaN (no uncertainty, unresolved) is stored
as NULL.

A run is written UNFINISHED when it starts and gets its outcome only in the
transaction that records its end, so a killed process can never leave a PASS
behind; :func:`station.store.recorder.recover_unfinished` closes such runs.
The schema is created by the Alembic migrations in ``migrations/``, never by
``create_all`` in production code; the migrations in ``migrations/versions/`` must
build exactly these classes (a test compares them).

The ``quality_*`` tables (migration 0003) are the narrow, indexed copy of every finished unit result and its
product-limit values that the quality statistics aggregate in SQL (see :mod:`station.store.quality`); they
are written in the same transaction as a run's end and rebuilt from the records by the migration.
"""

from __future__ import annotations

from datetime import datetime

from sqlalchemy import (
    Boolean,
    DateTime,
    Float,
    ForeignKey,
    Index,
    Integer,
    LargeBinary,
    MetaData,
    String,
    Text,
    UniqueConstraint,
    true,
)
from sqlalchemy.orm import DeclarativeBase, Mapped, mapped_column, relationship

UNFINISHED = "UNFINISHED"
"""Outcome of a run (and of its units) until its end is recorded."""

NAMING = {
    "ix": "ix_%(column_0_label)s",
    "uq": "uq_%(table_name)s_%(column_0_name)s",
    "fk": "fk_%(table_name)s_%(column_0_name)s_%(referred_table_name)s",
    "pk": "pk_%(table_name)s",
}


class Base(DeclarativeBase):
    """Declarative base with deterministic constraint names (needed for migrations)."""

    metadata = MetaData(naming_convention=NAMING)


class Station(Base):
    """A calibration station (one rig and its fixture), identified by name."""

    __tablename__ = "stations"

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    name: Mapped[str] = mapped_column(String(100), unique=True)
    created_at: Mapped[datetime] = mapped_column(DateTime(timezone=True))

    slots: Mapped[list[FixtureSlot]] = relationship(back_populates="station", order_by="FixtureSlot.slot")


class FixtureSlot(Base):
    """One slot of a station's fixture and the sensor URL it was last used with."""

    __tablename__ = "fixture_slots"
    __table_args__ = (UniqueConstraint("station_id", "slot"),)

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    station_id: Mapped[int] = mapped_column(ForeignKey("stations.id"), index=True)
    slot: Mapped[int] = mapped_column(Integer)
    sensor_url: Mapped[str] = mapped_column(String(500), default="")

    station: Mapped[Station] = relationship(back_populates="slots")


class Unit(Base):
    """A device under calibration, identified by its serial number."""

    __tablename__ = "units"

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    serial: Mapped[str] = mapped_column(String(100), unique=True)
    created_at: Mapped[datetime] = mapped_column(DateTime(timezone=True))

    results: Mapped[list[RunUnit]] = relationship(back_populates="unit")
    dispositions: Mapped[list[Disposition]] = relationship(back_populates="unit", order_by="Disposition.id")


class Run(Base):
    """One run of the sequence on one station (all units of the fixture).

    ``outcome`` is PASS, FAIL, ERROR, ABORTED or UNFINISHED (not ended yet, or the
    process died). Versions and SHA-256 hashes identify the software, the sequence
    (plan) and the product limits the run used.
    """

    __tablename__ = "runs"

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    run_uid: Mapped[str] = mapped_column(String(100), unique=True)
    station_id: Mapped[int] = mapped_column(ForeignKey("stations.id"), index=True)
    outcome: Mapped[str] = mapped_column(String(16), index=True)
    started_at: Mapped[datetime] = mapped_column(DateTime(timezone=True))
    finished_at: Mapped[datetime | None] = mapped_column(DateTime(timezone=True))
    duration_s: Mapped[float | None] = mapped_column(Float)
    wall_s: Mapped[float | None] = mapped_column(Float)
    software_version: Mapped[str] = mapped_column(String(100), default="")
    sequence_version: Mapped[str] = mapped_column(String(100), default="")
    sequence_hash: Mapped[str] = mapped_column(String(64), default="")
    limits_version: Mapped[str] = mapped_column(String(100), default="")
    limits_hash: Mapped[str] = mapped_column(String(64), default="")
    operator: Mapped[str] = mapped_column(String(100), default="")
    lot: Mapped[str] = mapped_column(String(100), default="", server_default="")  # production lot of the units
    rig: Mapped[str] = mapped_column(String(200), default="")
    host: Mapped[str] = mapped_column(String(200), default="")
    pid: Mapped[int] = mapped_column(Integer, default=0)
    rig_at_rest: Mapped[bool | None] = mapped_column(Boolean)
    message: Mapped[str] = mapped_column(Text, default="")

    station: Mapped[Station] = relationship()
    units: Mapped[list[RunUnit]] = relationship(back_populates="run", order_by="RunUnit.slot")
    steps: Mapped[list[StepTiming]] = relationship(back_populates="run", order_by="StepTiming.step_index")


class RunUnit(Base):
    """One fixture slot in one run: the unit (once its serial is known) and its outcome."""

    __tablename__ = "run_units"
    __table_args__ = (UniqueConstraint("run_id", "slot"),)

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    run_id: Mapped[int] = mapped_column(ForeignKey("runs.id"), index=True)
    slot: Mapped[int] = mapped_column(Integer)
    sensor_url: Mapped[str] = mapped_column(String(500), default="")
    unit_id: Mapped[int | None] = mapped_column(ForeignKey("units.id"), index=True)
    outcome: Mapped[str] = mapped_column(String(16))
    message: Mapped[str] = mapped_column(Text, default="")

    run: Mapped[Run] = relationship(back_populates="units")
    unit: Mapped[Unit | None] = relationship(back_populates="results")
    checks: Mapped[list[LimitCheck]] = relationship(back_populates="run_unit", order_by="LimitCheck.id")
    parameter_sets: Mapped[list[ParameterSetRecord]] = relationship(back_populates="run_unit")
    recordings: Mapped[list[SessionRecording]] = relationship(back_populates="run_unit")
    eeprom_writes: Mapped[list[EepromWrite]] = relationship(back_populates="run_unit")


class StepTiming(Base):
    """One step of a run: planned hold, start and duration on the station clock (s)."""

    __tablename__ = "step_timings"
    __table_args__ = (UniqueConstraint("run_id", "step_index"),)

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    run_id: Mapped[int] = mapped_column(ForeignKey("runs.id"), index=True)
    step_index: Mapped[int] = mapped_column(Integer)
    name: Mapped[str] = mapped_column(String(100))
    kind: Mapped[str] = mapped_column(String(20))
    hold_s: Mapped[float] = mapped_column(Float)
    started_t_s: Mapped[float] = mapped_column(Float)
    duration_s: Mapped[float | None] = mapped_column(Float)
    ok: Mapped[bool | None] = mapped_column(Boolean)
    units_active: Mapped[int | None] = mapped_column(Integer)
    message: Mapped[str] = mapped_column(Text, default="")

    run: Mapped[Run] = relationship(back_populates="steps")


class LimitCheck(Base):
    """One measured value against its limits: a capture gate (``step`` = the step) or a product limit
    (``step`` = 'limits'). ``value``, ``low``, ``high`` and ``std`` are in ``unit``."""

    __tablename__ = "limit_checks"

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    run_unit_id: Mapped[int] = mapped_column(ForeignKey("run_units.id"), index=True)
    step: Mapped[str] = mapped_column(String(100))
    name: Mapped[str] = mapped_column(String(100))
    value: Mapped[float | None] = mapped_column(Float)
    low: Mapped[float | None] = mapped_column(Float)
    high: Mapped[float | None] = mapped_column(Float)
    std: Mapped[float | None] = mapped_column(Float)
    unit: Mapped[str] = mapped_column(String(20), default="")
    passed: Mapped[bool] = mapped_column(Boolean)
    verdict: Mapped[str | None] = mapped_column(String(12))  # PASS, MARGINAL, INCONCLUSIVE, FAIL (None: older)
    k: Mapped[float | None] = mapped_column(Float)  # coverage factor of the uncertainty interval used

    run_unit: Mapped[RunUnit] = relationship(back_populates="checks")


class ParameterSetRecord(Base):
    """A fitted parameter set: the JSON as saved (``format`` e.g. 'station-params/1'), its SHA-256,
    and the standard uncertainties (the ``*_std`` fields per triad) as a JSON object for queries."""

    __tablename__ = "parameter_sets"

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    run_unit_id: Mapped[int] = mapped_column(ForeignKey("run_units.id"), index=True)
    unit_id: Mapped[int] = mapped_column(ForeignKey("units.id"), index=True)
    format: Mapped[str] = mapped_column(String(50))
    sha256: Mapped[str] = mapped_column(String(64))
    params_json: Mapped[str] = mapped_column(Text)
    uncertainties_json: Mapped[str] = mapped_column(Text)
    path: Mapped[str] = mapped_column(String(1000), default="")
    created_at: Mapped[datetime] = mapped_column(DateTime(timezone=True))

    run_unit: Mapped[RunUnit] = relationship(back_populates="parameter_sets")


class SessionRecording(Base):
    """The session CSV of a unit in a run: where it was saved, its SHA-256 and size (bytes)."""

    __tablename__ = "session_recordings"

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    run_unit_id: Mapped[int] = mapped_column(ForeignKey("run_units.id"), index=True)
    path: Mapped[str] = mapped_column(String(1000))
    sha256: Mapped[str] = mapped_column(String(64))
    size_bytes: Mapped[int] = mapped_column(Integer)

    run_unit: Mapped[RunUnit] = relationship(back_populates="recordings")


class RackRecording(Base):
    """A unit's soak-rack rest (the line's rack role writes it, the rig role reads it by serial):
    the session CSV (``station.session.csv_v1``) gzip-compressed in ``data``, the SHA-256 and size of the
    uncompressed CSV, the unit's power-on counter and the station clock at its first sample
    (what :func:`station.fit.joint.check_power` compares with the rig's recording)."""

    __tablename__ = "rack_recordings"

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    serial: Mapped[str] = mapped_column(String(100), index=True)
    station: Mapped[str] = mapped_column(String(100))
    slot: Mapped[int] = mapped_column(Integer)
    boot_count: Mapped[int | None] = mapped_column(Integer, nullable=True)
    wall_clock_at_start_s: Mapped[float | None] = mapped_column(Float, nullable=True)
    duration_s: Mapped[float] = mapped_column(Float)
    codec: Mapped[str] = mapped_column(String(20))
    sha256: Mapped[str] = mapped_column(String(64))
    size_bytes: Mapped[int] = mapped_column(Integer)
    data: Mapped[bytes] = mapped_column(LargeBinary)
    created_at: Mapped[datetime] = mapped_column(DateTime(timezone=True))


class EepromWrite(Base):
    """A calibration image written into a unit's EEPROM.

    ``written``: the pages were programmed; ``read_back_ok``: the image read back byte for byte;
    ``verified_on_rig``: the unit's corrected output was then checked on the rig and met the
    verification limits (None: not checked, e.g. ``station eeprom write`` off the rig). ``verified``
    is kept for older readers: read back and (where checked) verified on the rig. ``image`` holds the
    bytes written (None for rows of older versions).

    Write-ahead (see docs/provisioning.md): the row is committed as an intent (``state`` 'intended',
    ``written`` False) before the first page goes to the unit, with the image's hash, the target slot
    (``slot_name``) and update count; it is completed ('complete') after the read-back. An intent found
    without a completion is reconciled against the unit's current image: 'complete' when the image is
    there, 'not-applied' when it is not; ``reconciled`` says when and how.
    """

    __tablename__ = "eeprom_writes"

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    run_unit_id: Mapped[int | None] = mapped_column(ForeignKey("run_units.id"), index=True)
    unit_id: Mapped[int] = mapped_column(ForeignKey("units.id"), index=True)
    image_sha256: Mapped[str] = mapped_column(String(64))
    layout_version: Mapped[int] = mapped_column(Integer, default=0)
    attempts: Mapped[int] = mapped_column(Integer)
    verified: Mapped[bool] = mapped_column(Boolean)
    message: Mapped[str] = mapped_column(Text, default="")
    written_at: Mapped[datetime] = mapped_column(DateTime(timezone=True))
    written: Mapped[bool] = mapped_column(Boolean, server_default=true())
    read_back_ok: Mapped[bool] = mapped_column(Boolean, server_default=true())
    verified_on_rig: Mapped[bool | None] = mapped_column(Boolean)
    image: Mapped[bytes | None] = mapped_column(LargeBinary)
    state: Mapped[str] = mapped_column(String(16), server_default="complete", index=True)
    slot_name: Mapped[str] = mapped_column(String(4), server_default="")
    update_count: Mapped[int | None] = mapped_column(Integer)
    intended_at: Mapped[datetime | None] = mapped_column(DateTime(timezone=True))
    completed_at: Mapped[datetime | None] = mapped_column(DateTime(timezone=True))
    reconciled: Mapped[str] = mapped_column(Text, server_default="")

    run_unit: Mapped[RunUnit | None] = relationship(back_populates="eeprom_writes")


class RigLock(Base):
    """Who holds a rig for a run: one row per rig URL while a run holds it (stations on several hosts).

    ``rig_url`` is the normalized URL; ``holder`` names station, host and process; ``since`` is when it
    was taken. The row is deleted when the run ends; a row whose process is gone on the same host is
    taken over.
    """

    __tablename__ = "rig_locks"

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    rig_url: Mapped[str] = mapped_column(String(300), unique=True)
    station: Mapped[str] = mapped_column(String(100))
    host: Mapped[str] = mapped_column(String(255))
    pid: Mapped[int] = mapped_column(Integer)
    since: Mapped[datetime] = mapped_column(DateTime(timezone=True))


class NestCalibrationRecord(Base):
    """A rig's nest calibration (format ``station-nests/1``): ``version`` counts up per ``rig`` key; the
    newest applies to every later run on that rig. ``body`` is the JSON as saved, ``sha256`` its hash."""

    __tablename__ = "nest_calibrations"
    __table_args__ = (UniqueConstraint("rig", "version"),)

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    rig: Mapped[str] = mapped_column(String(300), index=True)
    version: Mapped[int] = mapped_column(Integer)
    reference_serial: Mapped[str] = mapped_column(String(100))
    created_at: Mapped[datetime] = mapped_column(DateTime(timezone=True))
    format: Mapped[str] = mapped_column(String(40))
    body: Mapped[str] = mapped_column(Text)
    sha256: Mapped[str] = mapped_column(String(64))


class GoldenUnitRecord(Base):
    """A golden unit's registration (format ``station-golden/1``): ``version`` counts up per ``serial``; the
    newest is in force. ``body`` is the JSON as saved."""

    __tablename__ = "golden_units"
    __table_args__ = (UniqueConstraint("serial", "version"),)

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    serial: Mapped[str] = mapped_column(String(100), index=True)
    version: Mapped[int] = mapped_column(Integer)
    registered_at: Mapped[datetime] = mapped_column(DateTime(timezone=True))
    body: Mapped[str] = mapped_column(Text)
    sha256: Mapped[str] = mapped_column(String(64))


class GoldenCheckRecord(Base):
    """One golden-unit run judged against the unit's references: on which station, when, passed or not, and
    per parameter the measured value, deviation and allowed deviation (``body``, JSON)."""

    __tablename__ = "golden_checks"
    __table_args__ = (Index("ix_golden_checks_station_time", "station", "checked_at"),)

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    run_unit_id: Mapped[int | None] = mapped_column(ForeignKey("run_units.id"), index=True)
    serial: Mapped[str] = mapped_column(String(100), index=True)
    station: Mapped[str] = mapped_column(String(100))
    golden_version: Mapped[int] = mapped_column(Integer)
    checked_at: Mapped[datetime] = mapped_column(DateTime(timezone=True))
    passed: Mapped[bool] = mapped_column(Boolean)
    body: Mapped[str] = mapped_column(Text)


class Disposition(Base):
    """A person's decision about a unit (e.g. 'retest', 'scrap', 'rework'); it resets the attempt count."""

    __tablename__ = "dispositions"

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    unit_id: Mapped[int] = mapped_column(ForeignKey("units.id"), index=True)
    decision: Mapped[str] = mapped_column(String(50))
    operator: Mapped[str] = mapped_column(String(100), default="")
    note: Mapped[str] = mapped_column(Text, default="")
    decided_at: Mapped[datetime] = mapped_column(DateTime(timezone=True))

    unit: Mapped[Unit] = relationship(back_populates="dispositions")


class QualityParameter(Base):
    """A product-limit-checked parameter by name (e.g. 'accel.M.xx') with its SI unit.

    ``ref`` (in ``unit``) is subtracted before the sums of :class:`QualityDaily` are formed, so the sums of
    squares of values far from zero (scale factors near 1) keep their precision.
    """

    __tablename__ = "quality_parameters"

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    name: Mapped[str] = mapped_column(String(100), unique=True)
    unit: Mapped[str] = mapped_column(String(20), default="")
    ref: Mapped[float] = mapped_column(Float, default=0.0)


class QualityResult(Base):
    """One unit's result in one finished run, as the quality statistics count it.

    ``tested``: the run reached a verdict on the unit (outcome PASS, FAIL or RETEST); ERROR, ABORTED,
    REFUSED and UNFINISHED results are kept (counted as not tested) but never consume a first pass.
    ``attempt``: 1 for the unit's first tested result, 2 for its second, ...; 0 when not tested.
    ``final_outcome``: the outcome of the unit's newest tested result (kept up to date on all its rows).
    ``latest``: this is the unit's newest result of any kind. ``day`` (YYYY-MM-DD) and ``minute``
    (0-1439) are the UTC date and minute of day of the run's start, for grouping by day and shift.
    """

    __tablename__ = "quality_results"
    __table_args__ = (
        Index("ix_quality_results_day_station", "day", "station_id"),
        Index("ix_quality_results_unit_latest", "unit_id", "latest"),
        Index("ix_quality_results_groups", "day", "minute", "station_id", "lot", "limits_version", "tested",
              "attempt", "outcome", "final_outcome", "unit_id"),
    )

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    run_unit_id: Mapped[int] = mapped_column(ForeignKey("run_units.id"), unique=True)
    unit_id: Mapped[int] = mapped_column(ForeignKey("units.id"))
    station_id: Mapped[int] = mapped_column(ForeignKey("stations.id"))
    lot: Mapped[str] = mapped_column(String(100), default="", index=True)
    limits_version: Mapped[str] = mapped_column(String(100), default="")
    started_at: Mapped[datetime] = mapped_column(DateTime(timezone=True), index=True)
    day: Mapped[str] = mapped_column(String(10))
    minute: Mapped[int] = mapped_column(Integer)
    outcome: Mapped[str] = mapped_column(String(16))
    tested: Mapped[bool] = mapped_column(Boolean)
    attempt: Mapped[int] = mapped_column(Integer)
    final_outcome: Mapped[str] = mapped_column(String(16), default="")
    latest: Mapped[bool] = mapped_column(Boolean)


class QualityValue(Base):
    """One product-limit-checked value (in the parameter's unit) of one tested result: the narrow table."""

    __tablename__ = "quality_values"
    __table_args__ = (Index("ix_quality_values_param_day", "param_id", "day", "value"),)

    result_id: Mapped[int] = mapped_column(ForeignKey("quality_results.id"), primary_key=True)
    param_id: Mapped[int] = mapped_column(ForeignKey("quality_parameters.id"), primary_key=True)
    day: Mapped[str] = mapped_column(String(10))
    value: Mapped[float] = mapped_column(Float)


class QualityDaily(Base):
    """Sums of one parameter's values per day, station, lot and limits version (a rational subgroup).

    ``n`` values; ``s1`` = sum(value - ref), ``s2`` = sum((value - ref)^2) (``ref`` of the parameter);
    ``vmin``/``vmax`` the extremes; ``low``/``high`` the limits in force (null: none on that side);
    ``n_below``/``n_above``: values outside them. Units: the parameter's.
    """

    __tablename__ = "quality_daily"
    __table_args__ = (
        UniqueConstraint("param_id", "day", "station_id", "lot", "limits_version",
                         name="uq_quality_daily_group"),
        Index("ix_quality_daily_day", "day"),
    )

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    param_id: Mapped[int] = mapped_column(ForeignKey("quality_parameters.id"))
    day: Mapped[str] = mapped_column(String(10))
    station_id: Mapped[int] = mapped_column(ForeignKey("stations.id"))
    lot: Mapped[str] = mapped_column(String(100), default="")
    limits_version: Mapped[str] = mapped_column(String(100), default="")
    n: Mapped[int] = mapped_column(Integer)
    s1: Mapped[float] = mapped_column(Float)
    s2: Mapped[float] = mapped_column(Float)
    vmin: Mapped[float] = mapped_column(Float)
    vmax: Mapped[float] = mapped_column(Float)
    low: Mapped[float | None] = mapped_column(Float)
    high: Mapped[float | None] = mapped_column(Float)
    n_below: Mapped[int] = mapped_column(Integer)
    n_above: Mapped[int] = mapped_column(Integer)


class QualityYield(Base):
    """Yield counts of the results per quarter hour of one day, station, lot and limits version (the shift
    calendar's starts are quarter hours, so every shift is a sum of these). See :class:`QualityResult` for
    tested and attempt; ``first_pass``/``final_pass`` count first tested results that passed / whose unit's
    newest tested result is PASS (kept up to date when a unit is retested)."""

    __tablename__ = "quality_yield"
    __table_args__ = (
        UniqueConstraint("day", "quarter", "station_id", "lot", "limits_version", name="uq_quality_yield_group"),
    )

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    day: Mapped[str] = mapped_column(String(10))
    quarter: Mapped[int] = mapped_column(Integer)  # quarter hour of the UTC day of the run start, 0-95
    station_id: Mapped[int] = mapped_column(ForeignKey("stations.id"))
    lot: Mapped[str] = mapped_column(String(100), default="")
    limits_version: Mapped[str] = mapped_column(String(100), default="")
    results: Mapped[int] = mapped_column(Integer)
    not_tested: Mapped[int] = mapped_column(Integer)
    tested: Mapped[int] = mapped_column(Integer)
    first_tested: Mapped[int] = mapped_column(Integer)
    first_pass: Mapped[int] = mapped_column(Integer)
    final_pass: Mapped[int] = mapped_column(Integer)
    retests: Mapped[int] = mapped_column(Integer)
