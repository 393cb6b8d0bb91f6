"""The ``station`` command: the production commands, the record commands, and the plugins' commands.

Every command reports expected failures (a malformed file, an unfittable session, a
station fault) as one line on stderr and a non-zero exit code, never a traceback.
"""

from __future__ import annotations

import sys
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any, Literal

import numpy as np
import typer

from station.kernel.errors import StationError

if TYPE_CHECKING:
    from station.compose import StationConfig

#: Help text is Markdown: docstrings reflow by paragraph and ``code`` shows as code, not as literal backticks.
MARKUP: Literal["markdown"] = "markdown"


def _hide_flag_types() -> None:
    """typer (0.29) prints every option's value type in the help, ``<bool>`` also for a flag, which takes no
    value; keep the type for options that take one. (Once per process: the station's apps share typer's class.)"""
    import typer.core

    shown = typer.core.TyperOption.display_type_rich
    if shown.__name__ == "display_type_without_flags":
        return

    def display_type_without_flags(self: typer.core.TyperOption, ctx: Any) -> str | None:
        return None if self.is_flag else shown(self, ctx)

    # typer has no setting for it: the help's type column comes from this method only
    typer.core.TyperOption.display_type_rich = display_type_without_flags  # type: ignore[method-assign]


_hide_flag_types()
app = typer.Typer(add_completion=False, no_args_is_help=True, rich_markup_mode=MARKUP,
                  help="IMU end-of-line calibration station.")
import_app = typer.Typer(no_args_is_help=True, rich_markup_mode=MARKUP,
                         help="Convert recordings made elsewhere into session CSV v1.")
app.add_typer(import_app, name="import")


def _add_subapps() -> None:
    from station.commands.diagnose import diagnose as diagnose_command
    from station.commands.eeprom import eeprom_app
    from station.commands.golden import golden_app
    from station.commands.interchange import export_command, import_imu_tk_command, import_openaxes_command
    from station.commands.msa import msa_app
    from station.commands.nest_cal import nest_app
    from station.commands.roles import line_app
    from station.commands.units import units_app

    app.add_typer(eeprom_app, name="eeprom")
    app.add_typer(units_app, name="units")
    app.add_typer(msa_app, name="msa")
    app.add_typer(nest_app, name="nest-cal")
    app.add_typer(golden_app, name="golden")
    app.add_typer(line_app, name="line")
    app.command(name="diagnose")(diagnose_command)
    app.command(name="export")(export_command)
    import_app.command("openaxes")(import_openaxes_command)
    import_app.command("imu-tk")(import_imu_tk_command)


DbOption = Annotated[
    str | None, typer.Option("--db", help="database URL (default $STATION_DB or sqlite:///station.sqlite)")
]


_add_subapps()


def _add_plugins() -> None:
    """Commands that other packages contribute through the ``station.commands`` entry point group.

    Each entry point names a ``register(app)`` function. The simulated station (``station.sim``)
    adds ``demo``, ``sim`` and ``simulate`` this way, so nothing in the station imports the simulator.
    """
    from importlib.metadata import entry_points

    for ep in entry_points(group="station.commands"):
        ep.load()(app)


def fail(exc: StationError, code: int = 2) -> typer.Exit:
    """One line on stderr and the exit to raise: how every command reports an expected failure."""
    typer.echo(f"error: {exc}", err=True)
    return typer.Exit(code)


def _print_params(params: object) -> None:
    """The parameter set for people, in the display convention (:mod:`station.kernel.display`)."""
    from rich.console import Console
    from rich.table import Table

    from station.kernel.display import display_for, display_of_check
    from station.kernel.parameters import ParameterSet

    assert isinstance(params, ParameterSet)
    console = Console()
    for key, name, tri, unit in (("accel", "accelerometer", params.accel, "m/s^2"),
                                 ("gyro", "gyroscope", params.gyro, "rad/s")):
        shown = display_of_check(f"{key}.bias_static.x", unit)
        table = Table(title=f"{params.serial} {name} (value ± u, u the standard uncertainty; biases and noise in "
                            f"{shown.unit}, M as ppm: diagonal M_ii - 1, off-diagonal M_ij)")
        table.add_column("parameter")
        for ax in "xyz":
            table.add_column(ax, justify="right")

        def row(label: str, v: np.ndarray, s: np.ndarray | None, names: list[str], si: str,
                table: Table = table, parameter: str = "", triad: str = key) -> None:
            cells = []
            for i, a in enumerate(v):
                d = display_of_check(names[i], si)
                if not np.isfinite(a):
                    cells.append("unresolved")
                elif parameter and not params.quality.is_determined(triad, parameter, i):
                    cells.append("not determined (see below)")
                else:
                    cells.append(d.format(float(a), float(s[i]) if s is not None else None, unit=False))
            table.add_row(label, *cells)

        for i, ax in enumerate("xyz"):
            row(f"M row {ax} (ppm)", tri.misalignment[i], tri.misalignment_std[i],
                [f"{key}.M.{ax}{b}" for b in "xyz"], "1")
        each = [f"{key}.x"] * 3
        row(f"bias static ({shown.unit})", tri.bias_static, tri.bias_static_std, each, unit, parameter="bias_static")
        row(f"bias drift ({shown.unit})", tri.bias_drift, tri.bias_drift_std, each, unit, parameter="bias_drift")
        row("T_c (s)", tri.correlation_time_s, tri.correlation_time_s_std, each, "s", parameter="correlation_time_s")
        row(f"noise std ({shown.unit})", tri.noise_std, tri.noise_std_std, each, unit)
        row(f"residual rms ({shown.unit})", tri.residual_rms, None, each, unit)
        tempco = display_of_check("x", f"{unit}/K")
        for j in range(tri.temp_bias_coeff.shape[1]):  # the temperature terms (station-params/2), where fitted
            if np.any(tri.temp_bias_coeff[:, j]):
                unit_j = f"{shown.unit}/K" if j == 0 else f"{shown.unit}/K^{j + 1}"
                table.add_row(f"T bias ({unit_j})", *[
                    tempco.format(float(a), float(b), unit=False)
                    for a, b in zip(tri.temp_bias_coeff[:, j], tri.temp_bias_coeff_std[:, j], strict=True)])
        for j in range(tri.temp_scale_coeff.shape[1]):
            if np.any(tri.temp_scale_coeff[:, j]):
                unit_j = "ppm/K" if j == 0 else f"ppm/K^{j + 1}"
                table.add_row(f"T scale ({unit_j})", *[
                    display_for("scale_tempco").format(float(a), float(b), unit=False)
                    for a, b in zip(tri.temp_scale_coeff[:, j], tri.temp_scale_coeff_std[:, j], strict=True)])
        console.print(table)
    for u in params.quality.undetermined:
        console.print(f"{u.triad} {'xyz'[u.axis]} {_PARAMETER_LABELS[u.parameter]}: not determined ({u.reason})")
    if params.quality.undetermined:
        from station.eeprom.image import image_notes
        from station.fit.export import export_notes

        for line in (*image_notes(params), *(f"an export writes {n}" for n in export_notes(params))):
            console.print(line)
    note = params.thermal
    if note.fitted:
        console.print(f"temperature terms fitted about T_ref = {params.reference_temperature_degc:.2f} degC "
                      f"(temperature span {note.span_k:.1f} K); orders {note.orders}")
    elif note.status != "absent":
        console.print(f"temperature terms: {note.status}: {note.reason}")
    nl = params.quality.scale_nonlinearity
    if nl is not None:
        from station.kernel.display import format_value

        if nl.fitted:
            parts = []
            for name, label, power in (("scale_quadratic", "k2", 1), ("scale_cubic", "k3", 2)):
                k, k_std = getattr(params.gyro, name), getattr(params.gyro, f"{name}_std")
                parts += [f"{label} {a} " + format_value(1e6 * k[i] * REF_RATE_RADPS**power,
                                                         1e6 * k_std[i] * REF_RATE_RADPS**power, "ppm")
                          for i, a in enumerate("xyz") if k[i] != 0]
            console.print("gyro scale nonlinearity u + k2 u^2 + k3 u^3 (IEEE 952) fitted (relative error at "
                          "200 deg/s): " + ", ".join(parts))
        else:
            console.print(f"gyro scale nonlinearity: {nl.status}: {nl.reason}")
    anl = params.quality.accel_scale_polynomial
    if anl is not None:
        from station.kernel.found_terms import found_terms

        if anl.fitted:
            parts = [f"{t.name.split('.', 1)[1]} {t.shown()}" for t in found_terms(params).polynomial
                     if t.name.startswith("accel.") and t.applied]
            console.print("accelerometer scale polynomial u + k2 u^2 + k3 u^3 fitted: " + ", ".join(parts))
        else:
            console.print(f"accelerometer scale polynomial: {anl.status}: {anl.reason}")
    offset = params.quality.time_offset
    if offset is not None:
        if offset.fitted:
            console.print("time offset (sensor lag behind the rig) fitted, applied by Algorithm 1: "
                          + format_value(1e3 * params.time_offset_s, 1e3 * params.time_offset_std_s, "ms"))
        elif offset.status == "not_determined":
            console.print(f"time offset: not determined: {offset.reason}")
        else:
            value = format_value(1e3 * offset.estimate_s, 1e3 * offset.std_s, "ms")
            console.print(f"time offset: {offset.status} ({value}): {offset.reason}")


#: How ``station fit`` names the parameters whose determinability the fit states.
_PARAMETER_LABELS = {"bias_static": "bias static", "bias_drift": "bias drift", "correlation_time_s": "T_c"}

#: The rate at which ``station fit`` states the gyro nonlinearity as a relative scale error (200 deg/s, rad/s).
REF_RATE_RADPS = float(np.radians(200.0))


@app.command()
def fit(
    session_path: Annotated[Path, typer.Argument(metavar="SESSION.csv", help="session CSV v1 recording")],
    as_json: Annotated[bool, typer.Option("--json", help="print the parameter set as JSON")] = False,
    g_sensitivity: Annotated[bool, typer.Option(help="also fit gyro g-sensitivity")] = False,
    rig_free: Annotated[bool, typer.Option(
        "--rig-free", help="fit without rig references (gravity norm and move rotations); chosen automatically "
                           "when the poses carry no reference")] = False,
    limits: Annotated[Path | None, typer.Option(
        "--limits", help="limits file whose correlation_time_s ranges are eq. 3's T_c prior (as the station's run "
                         "uses them); without it T_c comes from the recording alone")] = None,
    thermal: Annotated[str, typer.Option(
        help="temperature terms: auto (when the recording's temperature course separates them from the warm-up), "
             "off, require (not for a rig-free fit)")] = "auto",
    scale_nonlinearity: Annotated[str, typer.Option(
        help="scale polynomial y = u + k2 u^2 + k3 u^3 of the gyro (IEEE 952: k3 where the rate steps hold two or "
             "more rate magnitudes, k2 where they also hold both signs) and the accelerometer (k2 where the poses "
             "hold +g, -g and 0 along the axis, k3 with a second magnitude): auto (each kept where significant), "
             "off")] = "auto",
    time_offset: Annotated[str, typer.Option(
        help="the sensor's time offset behind the rig, estimated on the moves and rate ramps and applied by "
             "Algorithm 1: auto (kept where significant), off")] = "auto",
    accel_drift: Annotated[bool, typer.Option(
        "--accel-drift/--no-accel-drift",
        help="rig-free fit: the accelerometer's eq. 3 warm-up drift (default); --no-accel-drift fits imu_tk's model "
             "(no drift), whose constant bias is what imu_tk and OpenAXES files can hold")] = True,
) -> None:
    """Fit the parameter set of eq. (1) to a session and print it.

    Exit code: 0 a calibration; 2 the recording is refused (one line on stderr); 3 the fit ran but
    contradicts its own recording (goodness-of-fit test, ``quality.goodness_of_fit``; for a rig-free fit
    the leave-poses-out cross-validation): the parameters are printed, and stderr names what failed.
    """
    from station.kernel.limits_file import load_limits
    from station.session import check_session_file, read_session

    try:
        if thermal not in ("auto", "off", "require"):
            raise StationError(f"--thermal {thermal!r}: expected auto, off or require")
        if scale_nonlinearity not in ("auto", "off"):
            raise StationError(f"--scale-nonlinearity {scale_nonlinearity!r}: expected auto or off")
        if time_offset not in ("auto", "off"):
            raise StationError(f"--time-offset {time_offset!r}: expected auto or off")
        check_session_file(session_path)  # a device, a huge or a foreign file: refused before the fit's imports
        from station.fit.calibrate import FitOptions, fit_session
        from station.fit.determinability import assess
        from station.fit.goodness import EXIT_GOODNESS, summary
        from station.fit.rigfree_fit import RigFreeOptions, fit_rig_free, is_rig_free

        limits_file = load_limits(limits) if limits is not None else None
        tc_range = dict(limits_file.correlation_time_s) if limits_file is not None else {}
        session = read_session(session_path)
        free = rig_free or is_rig_free(session)
        if free and g_sensitivity:
            raise StationError("--g-sensitivity needs rig references; the rig-free fit does not fit it")
        if free and thermal == "require":
            raise StationError("--thermal require needs rig references; the rig-free fit has no temperature terms")
        if not accel_drift and not free:
            raise StationError("--no-accel-drift is for the rig-free fit (the rig fit decides the drift by its test)")
        params = (fit_rig_free(session, RigFreeOptions(tc_range_s=tc_range, accel_drift=accel_drift)) if free
                  else fit_session(session, FitOptions(g_sensitivity=g_sensitivity, tc_range_s=tc_range,
                                                       thermal=thermal, scale_nonlinearity=scale_nonlinearity,
                                                       time_offset=time_offset)))
        if limits_file is not None:  # the b_stat rule needs the limit ranges' widths
            params = assess(params, params.quality.record_end_s, limits_file.product)
    except StationError as exc:
        raise fail(exc) from None
    if as_json:
        sys.stdout.write(params.to_json() + "\n")
    else:
        _print_params(params)
        if free:
            _print_rig_free(params.quality.rig_free or {})
    verdict = params.quality.goodness_of_fit
    if verdict is not None and not verdict.passed:
        reason = verdict.note if free else summary(verdict)
        typer.echo(f"error: not a calibration: the fit fails its goodness-of-fit test: {reason}", err=True)
        raise typer.Exit(EXIT_GOODNESS)


def _print_rig_free(q: Mapping[str, Any]) -> None:
    cv = q.get("cross_validation") or {}
    typer.echo(f"rig-free fit ({q['convention']})")
    typer.echo(f"  {q['still_segments']} still segments ({q['distinct_poses']} distinct orientations), "
               f"{q['moves']} moves; gravity {q['gravity_mps2']} m/s^2")
    typer.echo(f"  gravity-norm RMS {1e3 * float(q['accel_norm_rms_mps2']):.2f} mm/s^2 fitted"
               + (f", {1e3 * cv['accel_norm_rms_mps2']:.2f} held out" if cv else ""))
    typer.echo(f"  move gravity-direction RMS {float(q['gyro_direction_rms_deg']):.3f} deg fitted"
               + (f", {cv['gyro_direction_rms_deg']:.3f} held out ({cv['folds']}-fold leave-poses-out)"
                  if cv else ""))
    timing = q.get("read_timing")
    if isinstance(timing, dict) and timing.get("selected"):
        typer.echo(f"  gyro read timing: {timing['reason']}")


@app.command()
def correct(
    session_path: Annotated[Path, typer.Argument(metavar="SESSION.csv")],
    params_path: Annotated[Path, typer.Option("--params", help="parameter JSON from `station fit --json`")],
    output: Annotated[Path, typer.Option("-o", "--output", help="corrected session CSV to write")],
    force: Annotated[bool, typer.Option("--force", help="apply parameters of another serial")] = False,
) -> None:
    """Apply Algorithm 1 to a session; writes a session CSV v1 with corrected measurements.

    Refused (exit 2, nothing written): an output that is the input, parameters of another serial
    (unless --force), and parameters the firmware's image would refuse (``station.eeprom.image.image_problems``:
    non-finite values, M singular or far from the identity, absurd biases, a moving-average length the
    corrector cannot hold, a sample period that is not the recording's rate).
    """
    from datetime import UTC, datetime

    from station.commands.output import check_output
    from station.correct.session_correct import correct_session
    from station.eeprom.image import CalibrationImage, check_writable
    from station.kernel.parameters import ParameterSet
    from station.session import read_session, write_session

    try:
        check_output(output, inputs=(session_path, params_path))
        params = ParameterSet.read(params_path)
        session = read_session(session_path)
        image = CalibrationImage.from_params(params, "correct", datetime.now(UTC))
        check_writable(image, (session.sample_rate_hz,))
        if params.serial != session.serial and not force:
            raise StationError(f"{params_path} holds the parameters of serial {params.serial!r}, the recording is of "
                               f"{session.serial!r} (--force to apply them anyway)")
        write_session(correct_session(session, params), output)
    except StationError as exc:
        raise fail(exc) from None
    except OSError as exc:
        raise fail(StationError(f"cannot write {output}: {exc.strerror or exc}")) from None
    typer.echo(f"wrote {output}")


@import_app.command("imucal")
def import_imucal(
    csv_path: Annotated[Path, typer.Argument(help="imucal session CSV")],
    output: Annotated[Path, typer.Option("-o", "--output", help="session CSV v1 to write")],
    segments: Annotated[Path | None, typer.Option(help="imucal segment list JSON (Ferraris session)")] = None,
    serial: Annotated[str, typer.Option(help="serial number to record")] = "imucal-example",
    expected_angle: Annotated[float, typer.Option(
        help="angle (deg) of each x_rot/y_rot/z_rot turn: imucal's default -360 (clockwise), +360 counter-clockwise",
    )] = -360.0,
) -> None:
    """Convert an imucal Ferraris recording (+ segment list) or annotated session.

    The result is checked against physics (:mod:`station.fit.consistency`: pose references against the
    measured specific force, each turn against the integrated rate), so swapped labels or a turn in the
    other direction are refused here, not fitted.
    """
    import math

    from station.commands.output import check_output
    from station.fit.consistency import check_import
    from station.session import write_session
    from station.session.imucal_import import import_imucal_annotated, import_imucal_ferraris

    try:
        check_output(output, inputs=[csv_path, *([segments] if segments is not None else [])])
        if not (math.isfinite(expected_angle) and 0 < abs(expected_angle) <= 3600):
            raise StationError(f"--expected-angle {expected_angle:g}: needs a non-zero angle within +-3600 deg")
        if segments is not None:
            session = import_imucal_ferraris(csv_path, segments, serial=serial, expected_angle_deg=expected_angle)
        else:
            session = import_imucal_annotated(csv_path, serial=serial, expected_angle_deg=expected_angle)
        check_import(session)
        write_session(session, output)
    except StationError as exc:
        raise fail(exc) from None
    except OSError as exc:
        raise fail(StationError(f"cannot write {output}: {exc.strerror or exc}")) from None
    typer.echo(f"wrote {output} ({len(session)} samples)")




ConfigOption = Annotated[
    Path | None, typer.Option("--config", help="station configuration file (TOML, station-config/1): rig, sensors, "
                                                "station, db, limits, out, scale, operator, lot; options given here "
                                                "win")
]
LimitsOption = Annotated[
    Path | None, typer.Option("--limits", help="limits file (default: fixtures/limits/default.toml)")
]


def station_config(
    config: Path | None, rig: str | None, sensor: list[str] | None, **overrides: object
) -> StationConfig:
    """The station's configuration from ``--config`` and the command's options (the options win)."""
    from station.compose import StationConfig

    given: dict[str, Any] = {k: v for k, v in overrides.items() if v is not None}
    if rig is not None:
        given["rig_url"] = rig
    if sensor:
        given["sensor_urls"] = tuple(sensor)
    if config is not None:
        return StationConfig.from_file(config, **given)
    if "rig_url" not in given or "sensor_urls" not in given:
        raise StationError("give the rig and sensors (--rig and --sensor) or a station configuration (--config)")
    return StationConfig(**given)


@app.command("run")
def run_station(
    rig: Annotated[str | None, typer.Option("--rig", help="rig URL: modbus-tcp://HOST:PORT or "
                                                          "modbus-rtu:///dev/ttyX?baud=N")] = None,
    sensor: Annotated[list[str] | None, typer.Option("--sensor", help="sensor URL serial:///dev/ttyX "
                                                                      "(repeat per unit)")] = None,
    config: ConfigOption = None,
    limits: LimitsOption = None,
    out: Annotated[Path | None, typer.Option(help="directory for session CSVs and parameter JSONs "
                                                  "[default: runs]")] = None,
    scale: Annotated[float | None, typer.Option(min=0.1, help="clock scale; 1 = real time (as `station sim`)")] = None,
    clock: Annotated[str | None, typer.Option("--clock", help="virtual://HOST:PORT: the virtual clock `station sim "
                                              "--clock virtual` serves (a simulated run that repeats bit for "
                                              "bit)")] = None,
    gravity: Annotated[float | None, typer.Option(help="local gravity (m/s^2); default from the plan")] = None,
    latitude: Annotated[float | None, typer.Option(help="site latitude (deg); default from the plan")] = None,
    name: Annotated[str | None, typer.Option("--station", help="station id for the records and images")] = None,
    db: DbOption = None,
    operator: Annotated[str | None, typer.Option(help="operator name for the records")] = None,
    lot: Annotated[str | None, typer.Option("--lot", help="production lot of the units, recorded with the run "
                                                          "(quality page filter, certificate); overrides the "
                                                          "configuration's lot")] = None,
    chamber: Annotated[str | None, typer.Option("--chamber", help="climate chamber URL (modbus-tcp://HOST:PORT): "
                                                "run the thermal plan (plateaus 5/15/25/45 degC, verification at "
                                                "35 degC) instead of the room-temperature sequence")] = None,
    yes: Annotated[bool, typer.Option("--yes", "-y", help="confirm the station's prompts (load, close the lid, "
                                      "unload) without waiting for Enter: CI, a fixture loaded by a robot")] = False,
    plan_file: Annotated[Path | None, typer.Option("--plan", help="a line plan written by `station plan` "
                                                   "(station-line-plan/1): run the line's rig role on units that "
                                                   "soaked in the rack (their recordings in --db)")] = None,
    back_to_rack: Annotated[bool, typer.Option("--back-to-rack", help="with --plan: a unit whose power was "
                                               "interrupted since the rack goes back to the rack (default: it "
                                               "gets the full plan)")] = False,
) -> None:
    """Run the calibration sequence against any rig and sensors (real ones, or `station sim`).

    With ``--plan`` (a line plan file written by ``station plan``) this is the line's rig role: the units come
    powered from the soak rack, each unit's rack recording is found by serial in the database, the rig runs the
    plan's rig part, each unit is fitted over both recordings; a unit whose power was interrupted since the rack
    is REFUSED with the reason (full plan or back to the rack). The run's record names the plan file and its
    SHA-256.

    The station prompts at the terminal before the rig moves (load the units into their nests, close the lid)
    and after the verdicts (unload, each nest with its verdict); Enter confirms, n and Enter cancels (ABORTED,
    nothing moved). Without a terminal on stdin give ``--yes``: otherwise the run ends ERROR before anything moves.

    With ``--chamber`` the thermal plan runs in that climate chamber (``station sim --chamber`` serves one):
    soaks gated on the units' own temperatures, the poses and rate steps at every plateau, the corrected
    output verified at a temperature the fit did not use, the chamber back to ambient at the end.

    Every passing unit is provisioned: its image is written, read back, and its corrected output
    verified on the rig. One run per rig: a second run on a held rig is refused before it touches
    anything. SIGTERM and SIGHUP abort like Ctrl-C (rig to rest, ABORTED with the signal's name).

    Exit code: 0 all PASS, 1 a unit FAILed, 2 ERROR (station fault), 3 a unit REFUSED by the retest
    policy, 4 a unit to RETEST (inconclusive verdict), 130 ABORTED (Ctrl-C, SIGTERM, SIGHUP).
    """
    from dataclasses import replace

    from rich.console import Console

    from station.compose import Station, abort_on_signals
    from station.kernel.display import limits_identity
    from station.kernel.line_plan import load_line_plan_file
    from station.kernel.plan import default_plan
    from station.kernel.thermal_plan import default_thermal_plan
    from station.sequence.prompts import AutoConfirm
    from station.sequence.runner import SequenceRunner
    from station.terminal import ProgressDisplay, TerminalOperator, summary_table

    thermal = default_thermal_plan() if chamber else None
    plan = thermal.base if thermal is not None else default_plan()
    if gravity is not None:
        plan = replace(plan, gravity_mps2=gravity)
    if latitude is not None:
        plan = replace(plan, latitude_deg=latitude)
    if thermal is not None:
        thermal = replace(thermal, base=plan)
    runners: list[SequenceRunner] = []
    console = Console()
    try:
        line_file = load_line_plan_file(plan_file) if plan_file is not None else None
        if line_file is not None:
            rig_part = line_file.plan.rig
            rig_part = replace(rig_part, gravity_mps2=gravity) if gravity is not None else rig_part
            rig_part = replace(rig_part, latitude_deg=latitude) if latitude is not None else rig_part
            line_file = replace(line_file, plan=replace(line_file.plan, rig=rig_part))
        cfg = station_config(config, rig, sensor, station_id=name, db_url=db, out_dir=out, clock_scale=scale,
                             clock_url=clock,
                             plan=plan, operator=operator, lot=lot, limits_path=limits, provision=True,
                             chamber_url=chamber, thermal=thermal, line=line_file, back_to_rack=back_to_rack or None)
        display = ProgressDisplay(console, list(cfg.sensor_urls), cfg.clock_scale)
        prompter = AutoConfirm("--yes") if yes else TerminalOperator(console, cfg.operator)
        with abort_on_signals(lambda: runners[-1] if runners else None):
            station = Station(cfg, subscribers=[display], prompter=prompter)
            lim = station.limits
            console.print(f"station {cfg.station_id}: database {station.recorder.db.url if station.recorder else '-'}, "
                          f"limits {limits_identity(f'{lim.name} {lim.version}', lim.sha256)}"
                          + (f", lot {cfg.lot}" if cfg.lot else ""), soft_wrap=True)
            with display:
                result = station.run(on_runner=runners.append)
    except StationError as exc:
        raise fail(exc) from None
    except KeyboardInterrupt:
        typer.echo("aborted before the run started; nothing was moved or written", err=True)
        raise typer.Exit(130) from None
    for line in station.reconciled:
        typer.echo(line, err=True)
    console.print(summary_table(result))
    if station.provisioner is not None and station.provisioner.records:
        from station.terminal import provisioning_table

        console.print(provisioning_table(station.provisioner))
    if cfg.line is not None:
        console.print(f"plan {cfg.line.version}, sha256 {cfg.line.sha256}", soft_wrap=True)
        console.print(f"rig time per unit: {result.sequence_s / max(len(result.units), 1):.0f} s")
    timing = getattr(runners[-1].sequence, "timing", None) if runners else None
    if timing is not None:
        console.print(f"cycle time per batch of {timing.units}: {timing.cycle_s / 60:.1f} min (sequence incl. soaks "
                      f"{timing.sequence_s / 60:.1f} min, fits {timing.fit_wall_s:.1f} s, verification "
                      f"{timing.verify_s / 60:.1f} min, chamber back to ambient {timing.ambient_s / 60:.1f} min)",
                      soft_wrap=True)
    raise typer.Exit(result.outcome.exit_code)


@app.command()
def serve(
    host: Annotated[str, typer.Option(help="address to bind (0.0.0.0: the line's network)")] = "127.0.0.1",
    port: Annotated[int, typer.Option(min=1, max=65535, help="TCP port")] = 8000,
    db: DbOption = None,
    rig: Annotated[str | None, typer.Option("--rig", help="rig URL: lets the API start and abort runs")] = None,
    sensor: Annotated[list[str] | None, typer.Option("--sensor", help="sensor URL (repeat per unit)")] = None,
    config: ConfigOption = None,
    limits: LimitsOption = None,
    scale: Annotated[float | None, typer.Option(min=0.1, help="clock scale of the hardware (as `station sim`)")] = None,
    out: Annotated[Path | None, typer.Option(help="directory for session CSVs and parameter JSONs "
                                                  "[default: runs]")] = None,
    name: Annotated[str | None, typer.Option("--station", help="station id for the records and images")] = None,
    operator: Annotated[str | None, typer.Option(help="the operator recorded on runs started with the bearer token "
                                                 "(API, automation); a signed-in operator's own name wins")] = None,
    tls_cert: Annotated[Path | None, typer.Option(help="TLS certificate (PEM): serve HTTPS; the operator's "
                                                       "session cookie is then sent over HTTPS only")] = None,
    tls_key: Annotated[Path | None, typer.Option(help="the TLS certificate's private key (PEM)")] = None,
) -> None:
    """Operator console, status page and JSON API.

    With a station (--rig/--sensor or --config) the operator console at /operator runs it: sign in, scan the
    lot and serials, answer the station's prompts (load, close the lid, unload), start and abort. Write actions
    need a signed-in operator or the bearer token in $STATION_TOKEN (the token is never shown by a page);
    without a station the server is read-only and they answer 401 (or 503). SIGINT, SIGTERM and SIGHUP abort a
    run in progress (rig to rest, ABORTED with the signal's name) before the server exits.
    """
    import os

    from station.web.serve import Tls
    from station.web.serve import serve as run_server

    if (tls_cert is None) != (tls_key is None):
        raise fail(StationError("--tls-cert and --tls-key go together (the certificate and its private key)"))
    tls = Tls(tls_cert, tls_key) if tls_cert is not None and tls_key is not None else None
    token = os.environ.get("STATION_TOKEN") or None
    live, on_exit, prompter = None, None, None
    if config is not None or (rig is not None and sensor):
        from station.compose import Station
        from station.web.console import ConsoleOperator
        from station.web.control import StationControl
        from station.web.state import LiveStatus

        try:
            cfg = station_config(config, rig, sensor, station_id=name, db_url=db, out_dir=out, clock_scale=scale,
                                 limits_path=limits, provision=True, operator=operator)
            prompter = ConsoleOperator()
            station = Station(cfg, prompter=prompter)
        except StationError as exc:
            raise fail(exc) from None
        assert station.recorder is not None
        db = cfg.db_url
        live = LiveStatus(station.recorder.db)
        live.nests = len(cfg.sensor_urls)
        station.subscribe(live)  # after the recorder: the page reads what it stored
        control = StationControl(station.run, on_error=live.set_fault)
        live.on_start = control.start
        live.on_abort = control.abort
        on_exit = control.stop
    try:
        run_server(host, port, db, token, live, on_exit, prompter, tls)
    except StationError as exc:  # e.g. a database that cannot be opened
        raise fail(exc) from None


if __name__ != "__main__":
    _add_plugins()


def main() -> None:  # pragma: no cover - console entry
    app()


if __name__ == "__main__":  # pragma: no cover - ``python -m station.cli``
    # The plugins import ``station.cli`` by name: run that module, not this ``__main__`` copy of it,
    # or each would load the other half-initialised.
    from station.cli import main as _main

    _main()

