"""Commands of rig-free calibration: ``station import openaxes|imu-tk`` and ``station export``.

The importers label rest, pose and move segments with the still detector
(:mod:`station.session.still`, its knobs as options) and write session CSV v1 whose poses carry no
reference, which ``station fit`` then fits rig-free. ``station export`` writes a parameter set for Kalibr
(imu.yaml), imu_tk (its own ``CalibratedTriad`` files, or ``station-imutk/1`` JSON) or OpenAXES (its
coefficient list).
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from station.kernel.errors import StationError

if TYPE_CHECKING:
    from station.kernel.parameters import ParameterSet
    from station.session.still import StillOptions

WindowOption = Annotated[float, typer.Option("--still-window", help="still detector: moving window (s)")]
ThresholdOption = Annotated[float, typer.Option(
    "--still-threshold", help="still detector: still below this many times the initial still's activity")]
MinStillOption = Annotated[float, typer.Option("--min-still", help="still detector: shortest still interval (s)")]
InitialOption = Annotated[float, typer.Option(
    "--initial-still", help="still detector: the recording starts still for at least this long (s)")]
LatitudeOption = Annotated[float | None, typer.Option(
    "--latitude", help="site latitude (deg): local gravity from WGS 84 normal gravity when --gravity is not given")]
HeightOption = Annotated[float, typer.Option("--height", help="site height above the ellipsoid (m), with --latitude")]
RateOption = Annotated[float, typer.Option(
    "--still-rate", help="still detector: gyro rate (deg/s) above which a sample is never still")]


def _gravity(gravity: float | None, latitude: float | None, height: float, default: float) -> tuple[float, dict]:
    """The local gravity and the metadata that says where it came from."""
    from station.session.multipos_import import normal_gravity_mps2

    if gravity is not None and latitude is not None:
        raise StationError("give --gravity or --latitude, not both")
    if latitude is not None:
        return normal_gravity_mps2(latitude, height), {"latitude_deg": f"{latitude:g}",
                                                      "gravity_source": f"WGS 84 normal gravity at {height:g} m"}
    return (default if gravity is None else gravity), {}


def _fail(exc: StationError) -> typer.Exit:
    typer.echo(f"error: {exc}", err=True)
    return typer.Exit(2)


def _still_options(window: float, threshold: float, min_still: float, initial: float, rate: float) -> StillOptions:
    from station.session.still import StillOptions

    return StillOptions(window_s=window, threshold=threshold, min_still_s=min_still, initial_still_s=initial,
                        still_rate_dps=rate)


def _report(session: object, output: Path) -> None:
    from station.session.model import Kind, Session

    assert isinstance(session, Session)
    poses = len(session.segments_of(Kind.POSE))
    rest = session.segments_of(Kind.REST)
    rest_text = f"initial still {session.t_s[rest[0].stop - 1] - session.t_s[rest[0].start]:.1f} s" if rest \
        else "no initial still found"
    typer.echo(f"wrote {output} ({len(session)} samples at {session.sample_rate_hz:.4f} Hz; {rest_text}, "
               f"{poses} still poses)")


def import_openaxes_command(
    log: Annotated[Path, typer.Argument(metavar="LOG.csv", help="OpenAXES log (semicolon-separated)")],
    output: Annotated[Path, typer.Option("-o", "--output", help="session CSV v1 to write")],
    accel: Annotated[str, typer.Option("--accel", help="which accelerometer: adxl355 or bmi160")] = "adxl355",
    gravity: Annotated[float | None, typer.Option(
        "--gravity", help="local gravity (m/s^2), written as gravity_mps2 [default: 9.8128, OpenAXES's site "
                          "Hannover, or from --latitude]")] = None,
    latitude: LatitudeOption = None,
    height: HeightOption = 0.0,
    serial: Annotated[str | None, typer.Option(help="serial number (default: from the IMU name and MAC)")] = None,
    still_window: WindowOption = 1.0,
    still_threshold: ThresholdOption = 3.0,
    min_still: MinStillOption = 1.5,
    initial_still: InitialOption = 10.0,
    still_rate: RateOption = 1.0,
) -> None:
    """Convert an OpenAXES hand-held calibration log (one accelerometer and the gyroscope) to session CSV v1."""
    from station.commands.output import check_output
    from station.session import write_session
    from station.session.multipos_import import import_openaxes

    try:
        check_output(output, inputs=[log])
        g, extra = _gravity(gravity, latitude, height, 9.8128)
        session = import_openaxes(log, accel=accel.lower(), gravity_mps2=g, serial=serial,
                                  still=_still_options(still_window, still_threshold, min_still, initial_still,
                                                       still_rate))
        session = session.replace(metadata={**session.metadata, **extra})
        write_session(session, output)
    except StationError as exc:
        raise _fail(exc) from None
    except OSError as exc:
        raise _fail(StationError(f"cannot write {output}: {exc.strerror or exc}")) from None
    _report(session, output)


def _offsets(text: str, name: str) -> float | tuple[float, float, float]:
    try:
        values = [float(v) for v in text.split(",")]
    except ValueError:
        raise StationError(f"{name} {text!r}: give one number or three separated by commas (x,y,z)") from None
    if len(values) == 1:
        return values[0]
    if len(values) == 3:
        return (values[0], values[1], values[2])
    raise StationError(f"{name} {text!r}: give one number or three separated by commas (x,y,z)")


def import_imu_tk_command(
    accel_file: Annotated[Path, typer.Argument(metavar="ACC", help="imu_tk accelerometer file: rows 'time x y z'")],
    gyro_file: Annotated[Path, typer.Argument(metavar="GYRO", help="imu_tk gyroscope file, same times")],
    output: Annotated[Path, typer.Option("-o", "--output", help="session CSV v1 to write")],
    accel_lsb_per_mps2: Annotated[float, typer.Option(
        "--accel-lsb-per-mps2", help="nominal accelerometer sensitivity (counts per m/s^2; 1 if already m/s^2)")] = 1.0,
    gyro_lsb_per_radps: Annotated[float, typer.Option(
        "--gyro-lsb-per-radps", help="nominal gyro sensitivity (counts per rad/s; 1 if already rad/s)")] = 1.0,
    offset_lsb: Annotated[str, typer.Option(
        "--offset-lsb", help="nominal offset subtracted from the raw counts, one number or x,y,z "
                             "(both sensors unless --gyro-offset-lsb)")] = "0",
    gyro_offset_lsb: Annotated[str | None, typer.Option(
        "--gyro-offset-lsb", help="the gyro's nominal offset, if not --offset-lsb")] = None,
    gravity: Annotated[float | None, typer.Option(
        "--gravity", help="local gravity (m/s^2) [default: 9.80665, or from --latitude]")] = None,
    latitude: LatitudeOption = None,
    height: HeightOption = 0.0,
    serial: Annotated[str, typer.Option(help="serial number to record")] = "imu-tk",
    still_window: WindowOption = 1.0,
    still_threshold: ThresholdOption = 3.0,
    min_still: MinStillOption = 1.5,
    initial_still: InitialOption = 10.0,
    still_rate: RateOption = 1.0,
) -> None:
    """Convert imu_tk's text files (accelerometer and gyroscope, raw counts) to session CSV v1."""
    from station.commands.output import check_output
    from station.session import write_session
    from station.session.multipos_import import import_imu_tk

    try:
        check_output(output, inputs=[accel_file, gyro_file])
        a_off = _offsets(offset_lsb, "--offset-lsb")
        g_off = a_off if gyro_offset_lsb is None else _offsets(gyro_offset_lsb, "--gyro-offset-lsb")
        g, extra = _gravity(gravity, latitude, height, 9.80665)
        session = import_imu_tk(accel_file, gyro_file, accel_lsb_per_mps2=accel_lsb_per_mps2,
                                gyro_lsb_per_radps=gyro_lsb_per_radps, accel_offset_lsb=a_off, gyro_offset_lsb=g_off,
                                gravity_mps2=g, serial=serial,
                                still=_still_options(still_window, still_threshold, min_still, initial_still,
                                                     still_rate))
        session = session.replace(metadata={**session.metadata, **extra})
        write_session(session, output)
    except StationError as exc:
        raise _fail(exc) from None
    except OSError as exc:
        raise _fail(StationError(f"cannot write {output}: {exc.strerror or exc}")) from None
    _report(session, output)


EXPORT_FORMATS = ("kalibr", "imu-tk", "imu-tk-json", "openaxes")


def export_command(
    params: Annotated[list[Path] | None, typer.Argument(
        metavar="[PARAMS.json...]", help="parameter set(s) (station-params/2; /1 still read); for openaxes: one per "
                                         "accelerometer, the gyro from the last. Or --serial")] = None,
    fmt: Annotated[str, typer.Option("--format", help="kalibr (imu.yaml noise model), imu-tk (imu_tk's own "
                                                      "PREFIX_acc.calib and PREFIX_gyro.calib), imu-tk-json "
                                                      "(station-imutk/1, with uncertainties) or openaxes "
                                                      "(coefficient list)")] = "",
    output: Annotated[Path | None, typer.Option(
        "-o", "--output", help="file to write (default: stdout); for imu-tk the PREFIX of the two files")] = None,
    serial: Annotated[str | None, typer.Option(
        "--serial", help="the unit's newest PASS parameter set from the store instead of PARAMS.json")] = None,
    db: Annotated[str | None, typer.Option("--db", help="database URL for --serial (default $STATION_DB or "
                                                        "sqlite:///station.sqlite)")] = None,
    rostopic: Annotated[str, typer.Option(help="kalibr: the IMU topic written into the file")] = "/imu0",
) -> None:
    """Write a parameter set for another tool: Kalibr, imu_tk, OpenAXES.

    ``--format imu-tk`` writes the two files imu_tk's ``CalibratedTriad::load`` reads (misalignment T, scale K,
    bias B; imu_tk corrects X' = T K (X - B), in the station's SI units). ``station eeprom kalibr`` is an
    alias of ``--format kalibr`` that will go.
    """
    from station.commands.output import check_output
    from station.fit.export import (
        export_notes,
        imu_tk_calib_files,
        imu_tk_document,
        kalibr_imu_yaml,
        left_out_notes,
        openaxes_text,
    )
    from station.kernel.parameters import ParameterSet

    written: list[Path] = []
    try:
        if fmt not in EXPORT_FORMATS:
            raise StationError(f"--format {fmt!r}: {', '.join(EXPORT_FORMATS)}")
        if bool(params) == (serial is not None):
            raise StationError("give parameter file(s) PARAMS.json or --serial (from the store), one of them")
        if fmt == "imu-tk" and output is None:
            raise StationError("--format imu-tk writes two files: give their prefix with -o (e.g. -o out/unit: "
                               "out/unit_acc.calib, out/unit_gyro.calib)")
        inputs = list(params or [])
        if output is not None and fmt != "imu-tk":
            check_output(output, inputs=inputs)
        sets = [_store_params(serial, db)] if serial is not None else [ParameterSet.read(p) for p in inputs]
        if fmt != "openaxes" and len(sets) != 1:
            raise StationError(f"--format {fmt} exports one parameter set")
        for note in (n for p in sets for n in export_notes(p)):
            typer.echo(f"note: {note}", err=True)
        if fmt != "kalibr":  # the noise model has no place for these: only the calibrations leave them out
            for note in (n for p in sets for n in left_out_notes(p)):
                typer.echo(f"note: {note}", err=True)
        if fmt == "imu-tk":
            assert output is not None
            files = imu_tk_calib_files(sets[0])
            targets = {name: output.with_name(f"{output.name}_{name}.calib") for name in files}
            for target in targets.values():
                check_output(target, inputs=inputs)
            for name, target in targets.items():
                target.write_text(files[name], encoding="utf-8")
                written.append(target)
            typer.echo("wrote " + ", ".join(str(w) for w in written) + " (imu_tk CalibratedTriad files: T, K, B; "
                       "X' = T K (X - B), SI)")
            return
        text = {"kalibr": lambda: kalibr_imu_yaml(sets[0], rostopic), "imu-tk-json": lambda: imu_tk_document(sets[0]),
                "openaxes": lambda: openaxes_text(sets)}[fmt]()
        if output is None:
            sys.stdout.write(text)
        else:
            output.write_text(text, encoding="utf-8")
            typer.echo(f"wrote {output}")
    except StationError as exc:
        raise _fail(exc) from None
    except OSError as exc:
        raise _fail(StationError(f"cannot write {output}: {exc.strerror or exc}")) from None


def _store_params(serial: str, db_url: str | None) -> ParameterSet:
    """The newest PASS parameter set of ``serial`` in the existing store (refused in one line if none)."""
    from station.store.db import open_database
    from station.store.queries import latest_parameter_set

    with open_database(db_url, must_exist=True) as database:
        found = latest_parameter_set(database, serial)
    if found is None:
        raise StationError(f"no PASS parameter set of serial {serial!r} in the store")
    return found
