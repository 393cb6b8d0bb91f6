"""``station eeprom ...``: make, inspect and write calibration images (``kalibr``: an alias of ``station export``).

A Typer sub-app; ``station/cli.py`` mounts it with ``app.add_typer(eeprom_app, name="eeprom")``.
Parameter sets come from the unit store (the newest PASS parameter set of the serial, in
``--db``, default ``$STATION_DB`` or ``sqlite:///station.sqlite``) or from a parameter JSON
(``--params``, the format ``station fit --json`` writes). Expected failures print one line on
stderr and exit with code 2.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable
from datetime import UTC, datetime
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any, TypeVar

import numpy as np
import typer

from station.fit.export import kalibr_imu_yaml
from station.kernel.errors import StationError
from station.kernel.parameters import ParameterSet

if TYPE_CHECKING:
    from station.eeprom.image import CalibrationImage

T = TypeVar("T")

eeprom_app = typer.Typer(no_args_is_help=True, rich_markup_mode="markdown",
                         help="Calibration images in the unit's EEPROM.")


def _fail(exc: StationError | str, code: int = 2) -> typer.Exit:
    typer.echo(f"error: {exc}", err=True)
    return typer.Exit(code)


ParamsOption = Annotated[
    Path | None, typer.Option("--params", help="parameter JSON of the unit (default: the newest PASS set in the store)")
]
DbOption = Annotated[str | None, typer.Option("--db", help="database URL (default $STATION_DB or sqlite:///station.sqlite)")]


def _unit_params(serial: str | None, path: Path | None, db_url: str | None) -> ParameterSet:
    """The unit's parameter set from ``path`` if given, else its newest PASS set in the store."""
    if path is not None:
        return _load_params(path, serial)
    from station.store.queries import latest_parameter_set

    return _from_store(db_url, serial, latest_parameter_set)


def _from_store(db_url: str | None, serial: str | None, query: Callable[[Any, str], T | None]) -> T:
    """``query(database, serial)`` on the existing store; refused in one line when it finds nothing."""
    if serial is None:
        raise StationError("give the unit's SERIAL or --params")
    from station.store.db import open_database

    db = open_database(db_url, must_exist=True)
    try:
        found = query(db, serial)
    finally:
        db.close()
    if found is None:
        raise StationError(f"no PASS parameter set of serial {serial!r} in the store {db.url}")
    return found


def _refuse_scrapped(serial: str | None, db_url: str | None, *, required: bool) -> None:
    """Refuse a scrapped unit (its 'scrap' disposition in the store): no image is made or written for it.

    ``required``: the store must exist (the image comes from it); with parameters from a file and no store
    there is no record to check.
    """
    if serial is None:
        return
    from station.kernel.display import local_time
    from station.store.db import open_database
    from station.store.queries import scrapped_at

    try:
        db = open_database(db_url, must_exist=True)
    except StationError:
        if required:
            raise
        return
    try:
        when = scrapped_at(db, serial)
    finally:
        db.close()
    if when is not None:
        raise StationError(f"{serial} was scrapped ({local_time(when)}): no calibration image is made or written "
                           "for a scrapped unit")


def _unit_image(serial: str | None, path: Path | None, db_url: str | None, station_id: str) -> CalibrationImage:
    """The image to write or save: of the file at ``path`` (station ``station_id``, now), else the store's.

    A scrapped unit is refused (:func:`_refuse_scrapped`)."""
    from station.eeprom.image import CalibrationImage, decode_image

    _refuse_scrapped(serial if serial is not None else None, db_url, required=path is None)
    if path is not None:
        return CalibrationImage.from_params(_load_params(path, serial), station_id, datetime.now(UTC))
    from station.store.queries import unit_image

    return decode_image(_from_store(db_url, serial, unit_image).data)


def _load_params(path: Path, serial: str | None) -> ParameterSet:
    params = ParameterSet.read(path)
    if serial is not None and params.serial != serial:
        raise StationError(f"{path} holds the parameters of serial {params.serial!r}, not {serial!r}")
    return params


def image_summary(img: Any) -> dict[str, Any]:
    """A JSON-friendly view of a :class:`~station.eeprom.image.CalibrationImage` (SI units, NaN as None)."""

    def arr(a: np.ndarray) -> Any:
        return [None if not math.isfinite(v) else v for v in np.asarray(a).ravel().tolist()]

    def triad(t: Any) -> dict[str, Any]:
        return {
            "misalignment": arr(t.misalignment),
            "bias_static": arr(t.bias_static),
            "bias_drift": arr(t.bias_drift),
            "correlation_time_s": arr(t.correlation_time_s),
            "noise_std": arr(t.noise_std),
        }

    fx = img.effects
    effects = {} if fx is None else {"effects": {
        "reference_temperature_degc": None if not math.isfinite(fx.reference_temperature_degc)
        else fx.reference_temperature_degc,
        "time_offset_s": fx.time_offset_s,
        "accel_temp_bias_mps2_per_k_j": arr(fx.temp_bias[0]), "gyro_temp_bias_radps_per_k_j": arr(fx.temp_bias[1]),
        "accel_temp_scale_per_k_j": arr(fx.temp_scale[0]), "gyro_temp_scale_per_k_j": arr(fx.temp_scale[1]),
        "accel_nonlinearity_per_mps2": arr(fx.nonlinearity[0]), "gyro_nonlinearity_per_radps": arr(fx.nonlinearity[1]),
    }}
    return {
        "layout_version": img.layout_version,
        "serial": img.serial,
        "params_id": img.params_id.hex(),
        "station_id": img.station_id,
        "calibration_time": img.calibration_time.isoformat(),
        "update_count": img.update_count,
        "sample_period_s": img.sample_period_s,
        "moving_average_length": img.ma_length,
        "accel_mps2": triad(img.accel),
        "gyro_radps": triad(img.gyro),
        "g_sensitivity_radps_per_mps2": arr(img.g_sensitivity),
        **effects,
    }


@eeprom_app.command("image")
def image_cmd(
    serial: Annotated[str, typer.Argument(help="the unit's serial number")],
    output: Annotated[Path, typer.Option("-o", "--output", help="image file to write")],
    params_path: ParamsOption = None,
    db: DbOption = None,
    station_id: Annotated[str, typer.Option("--station", help="station id written into the image")] = "station",
) -> None:
    """Make the EEPROM image of a unit: the one its newest PASS run wrote (or would write), or of --params.

    A scrapped unit is refused (exit 2), with --params too when the store knows the serial.

    From the store the image is byte for byte the one the run wrote (as the API's ``eeprom.bin``); with
    ``--params`` it is built from the file, with ``--station`` and the current time.
    """
    from station.commands.output import check_output
    from station.eeprom.image import check_writable, decode_image, encode_image, image_sha256

    try:
        check_output(output, inputs=[params_path] if params_path is not None else [])
        image = _unit_image(serial, params_path, db, station_id)
        check_writable(image)
        data = encode_image(image)
        decode_image(data)
        output.write_bytes(data)
    except StationError as exc:
        raise _fail(exc) from None
    except OSError as exc:
        raise _fail(f"cannot write {output}: {exc.strerror or exc}") from None
    typer.echo(f"wrote {output}: {len(data)} bytes, serial {serial}, sha256 {image_sha256(data)}")


@eeprom_app.command("decode")
def decode_cmd(
    path: Annotated[Path, typer.Argument(metavar="IMAGE.bin", help="an image file (or an EEPROM dump with --dump)")],
    dump: Annotated[bool, typer.Option("--dump", help="the file is a whole EEPROM: decode both slots")] = False,
) -> None:
    """Decode and check an image (magic, version, length, CRC-32); print its content as JSON."""
    from station.eeprom.image import decode_image, read_all_slots, select_image

    try:
        raw = path.read_bytes()
    except OSError as exc:
        raise _fail(f"cannot read {path}: {exc.strerror or exc}") from None
    try:
        if dump:
            slots = read_all_slots(raw)
            current = select_image(slots)
            out: dict[str, Any] = {
                "current": current.name if current is not None else None,
                "slots": {s.name: image_summary(s.image) if s.image else {"error": s.error} for s in slots},
            }
        else:
            out = image_summary(decode_image(raw))
    except StationError as exc:
        raise _fail(f"{path}: {exc}") from None
    typer.echo(json.dumps(out, indent=2))


@eeprom_app.command("write")
def write_cmd(
    serial: Annotated[str, typer.Argument(help="the unit's serial number (must match what the sensor reports)")],
    sensor_url: Annotated[str, typer.Option("--sensor", help="sensor URL, e.g. serial:///dev/ttyUSB0")],
    params_path: ParamsOption = None,
    db: DbOption = None,
    station_id: Annotated[str, typer.Option("--station", help="station id written into the image")] = "station",
    attempts: Annotated[int, typer.Option(help="write + read-back attempts")] = 3,
    power_cycle: Annotated[bool, typer.Option(help="reset the sensor afterwards so it loads the image")] = True,
) -> None:
    """Write a unit's image into its EEPROM (free A/B slot, page by page, read back and compared).

    A scrapped unit is refused before the sensor is touched (exit 2). The write is recorded ahead in the unit
    store: the intent before the first page, the write after the read-back (see docs/provisioning.md)."""
    from station.eeprom.provision import plan_write, program_image
    from station.sensor import open_sensor
    from station.sequence.provision import reconcile_unit
    from station.store.db import open_database
    from station.store.write_ahead import StoreJournal

    try:
        image = _unit_image(serial, params_path, db, station_id)
        database = open_database(db, for_writing=True)
        try:
            journal = StoreJournal(database, source="`station eeprom write`")
            with open_sensor(sensor_url) as sensor:
                for line in reconcile_unit(journal, sensor, serial):
                    typer.echo(line, err=True)
                plan = plan_write(sensor, image)
                intent = journal.intend(plan, None)
                try:
                    report = program_image(sensor, plan, max_attempts=attempts)
                except StationError:
                    for line in _settle(journal, sensor, serial):
                        typer.echo(line, err=True)
                    raise
                journal.written(intent, report)
                journal.verified(intent, None, "not verified on the rig")
                if power_cycle:
                    sensor.power_cycle(2.0)
        finally:
            database.close()
    except StationError as exc:
        raise _fail(exc) from None
    typer.echo(f"wrote image #{report.update_count} to slot {report.slot} of {report.serial} "
               f"({report.length} bytes, {report.attempts} attempt(s), sha256 {report.sha256})")


def _settle(journal: Any, sensor: Any, serial: str) -> list[str]:
    """After a failed write: close its intent against the unit if it still answers (else it stays open)."""
    from station.sequence.provision import reconcile_unit

    try:
        return reconcile_unit(journal, sensor, serial)
    except StationError as exc:
        return [f"{serial}: the write's intent stays open until the unit can be read ({exc})"]


def _existing_store(db_url: str | None) -> Any:
    """The unit store when it exists (None: no store here: nothing to reconcile against)."""
    from station.store.db import database_url, open_database, store_exists

    url = database_url(db_url)
    if not store_exists(url):
        return None
    return open_database(url, must_exist=True)


@eeprom_app.command("read")
def read_cmd(
    sensor_url: Annotated[str, typer.Option("--sensor", help="sensor URL")],
    db: DbOption = None,
) -> None:
    """Read both image slots of a connected unit and print which one is current.

    When the unit store exists, unfinished writes of this unit (an intent without a completion, left by
    a crash) are reconciled against what the unit holds and listed under "reconciled"."""
    from station.eeprom.image import select_image
    from station.eeprom.provision import read_unit_slots
    from station.sensor import open_sensor

    reconciled: list[str] = []
    try:
        database = _existing_store(db)
        try:
            with open_sensor(sensor_url) as sensor:
                serial = sensor.identify().serial
                slots = read_unit_slots(sensor)
                if database is not None:
                    from station.sequence.provision import reconcile_unit
                    from station.store.write_ahead import StoreJournal

                    reconciled = reconcile_unit(StoreJournal(database, source="`station eeprom read`"), sensor,
                                                serial)
        finally:
            if database is not None:
                database.close()
    except StationError as exc:
        raise _fail(exc) from None
    for line in reconciled:
        typer.echo(line, err=True)
    current = select_image(slots, serial)
    out = {
        "serial": serial,
        "current": current.name if current is not None else None,
        "slots": {s.name: image_summary(s.image) if s.image else {"error": s.error} for s in slots},
        "reconciled": reconciled,
    }
    typer.echo(json.dumps(out, indent=2))


# --- Kalibr (moved to `station export --format kalibr`) --------------------------------------------

KALIBR_MOVED = "note: `station eeprom kalibr` moved to `station export --format kalibr`; this alias will go"


@eeprom_app.command("kalibr")
def kalibr_cmd(
    serial: Annotated[str | None, typer.Argument(help="the unit's serial (parameters from the store)")] = None,
    params_path: ParamsOption = None,
    db: DbOption = None,
    output: Annotated[Path | None, typer.Option("-o", "--output", help="imu.yaml to write (default: stdout)")] = None,
    rostopic: Annotated[str, typer.Option(help="IMU topic written into the file")] = "/imu0",
) -> None:
    """Export the unit's noise parameters as a Kalibr imu.yaml (moved: `station export --format kalibr`)."""
    typer.echo(KALIBR_MOVED, err=True)
    try:
        text = kalibr_imu_yaml(_unit_params(serial, params_path, db), rostopic)
    except StationError as exc:
        raise _fail(exc) from None
    if output is None:
        typer.echo(text, nl=False)
    else:
        output.write_text(text)
        typer.echo(f"wrote {output}")
