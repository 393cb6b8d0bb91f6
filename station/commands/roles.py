"""``station line rack|rig``: the calibration line's two roles, as separate processes sharing one database.

``station line rack`` powers the given rack slots through the relay board, logs each unit's rest from power-on
for ``--rack-s`` and stores the recordings in the database (``rack_recordings``); the units stay powered.
``station line rig`` runs the line's rig plan (``--plan`` file, default ``line_rig_plan()``) for the units on
the rig: each unit's plan is decided from its rack recording (found by serial) and what it reports now; a unit
that lost power is refused with the reason (it gets the full plan, ``station run``, or goes back to the rack);
the others are fitted over both recordings. It is ``station run --plan`` (the composition root's line role): it
takes the rig lock and records the run in the database's run tables with the plan file and its SHA-256. See
docs/line.md.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from station.commands.common_options import DbOption, refuse
from station.kernel.errors import StationError

# The roles' machinery (compose, the line, the store, the fit: most of a second of imports) is imported in the
# command that runs, not when the command line starts: every `station` command builds this app.

line_app = typer.Typer(no_args_is_help=True, help="The calibration line: soak rack and rig roles.")

@line_app.command("rack")
def rack_command(
    board: Annotated[str, typer.Option("--board", help="relay board URL (modbus-tcp://HOST:PORT?unit=1, "
                                       "modbus-rtu:///dev/ttyUSB0?...)")],
    sensor: Annotated[list[str], typer.Option("--sensor", help="sensor URL of slot 0, 1, ... (repeatable)")],
    rack_s: Annotated[float, typer.Option("--rack-s", min=1.0, help="rest from power-on (s)")] = 3600.0,
    rate: Annotated[int, typer.Option(min=1, help="sample rate (Hz)")] = 100,
    gravity: Annotated[float, typer.Option(min=9.7, max=9.9, help="local gravity (m/s^2)")] = 9.80665,
    station: Annotated[str, typer.Option(help="this rack's name in the records")] = "rack",
    scale: Annotated[float, typer.Option(min=0.1, help="clock scale (1: real time; a simulated rack's scale)")]
    = 1.0,
    db: DbOption = None,
) -> None:
    """Soak the units of the given slots and store their recordings (exit 0: every slot recorded, 2 otherwise)."""
    from station.compose import make_clock
    from station.line.recordings import DatabaseArchive
    from station.line.soak import SoakRack
    from station.rack.board import RelayBoard
    from station.sensor import open_sensor
    from station.store.db import open_database

    clock = make_clock(scale)
    try:
        database = open_database(db)
        archive = DatabaseArchive(database.sessions)
        sensors = [open_sensor(url, clock) for url in sensor]
        try:
            with RelayBoard(board) as relays:
                soaked = SoakRack(relays, sensors, clock, sample_rate_hz=rate, gravity_mps2=gravity,
                                  station=station).soak(range(len(sensors)), rack_s)
            missing = 0
            for r in soaked:
                if r.session is None:
                    missing += 1
                    typer.echo(f"slot {r.slot}: {r.serial or '?'}: no recording: {r.error}")
                else:
                    sha = archive.save(r.session, station=station, slot=r.slot)
                    typer.echo(f"slot {r.slot}: {r.serial}: {len(r.session)} samples, sha256 {sha}"
                               + (f"; {r.note}" if r.note else ""))
        finally:
            for s in sensors:
                s.close()
            database.close()
    except StationError as exc:
        raise refuse(exc) from None
    raise typer.Exit(2 if missing else 0)


@line_app.command("rig")
def rig_command(
    rig: Annotated[str, typer.Option("--rig", help="rig URL")],
    sensor: Annotated[list[str], typer.Option("--sensor", help="sensor URL of fixture slot 0, 1, ... (repeatable)")],
    plan: Annotated[Path | None, typer.Option("--plan", help="line plan file (station-line-plan/1; default: "
                                              "the built-in line plan)")] = None,
    limits: Annotated[Path | None, typer.Option("--limits", help="limits file")] = None,
    out: Annotated[Path | None, typer.Option(help="directory for session CSVs and parameter JSONs")] = None,
    back_to_rack: Annotated[bool, typer.Option("--back-to-rack", help="a unit that lost power goes back to the "
                                               "rack (default: it gets the full plan)")] = False,
    station: Annotated[str, typer.Option(help="this rig's name in the records")] = "rig",
    scale: Annotated[float, typer.Option(min=0.1, help="clock scale (1: real time)")] = 1.0,
    db: DbOption = None,
) -> None:
    """Run the line's rig plan on the units that soaked (``station run --plan`` without prompts): the rig lock,
    the run recorded in the database's run tables with the plan file and its SHA-256, every PASS unit's EEPROM
    written and verified; exit codes as ``station run``'s."""
    from station.compose import Station, StationConfig
    from station.kernel.line_plan import load_line_plan_file
    from station.sequence.runner import SequenceRunner

    try:
        config = StationConfig(rig, tuple(sensor), station_id=station, db_url=db, limits_path=limits, out_dir=out,
                               clock_scale=scale, provision=True, line=load_line_plan_file(plan),
                               back_to_rack=back_to_rack)
        runners: list[SequenceRunner] = []
        result = Station(config).run(on_runner=runners.append)
    except StationError as exc:
        raise refuse(exc) from None
    decisions = getattr(runners[-1], "decisions", {}) if runners else {}
    for serial, d in decisions.items():
        typer.echo(f"{serial}: {d.plan}{' (' + d.reason + ')' if d.reason else ''}")
    for u in result.units:
        typer.echo(f"slot {u.slot} {u.serial}: {u.outcome.value}{' - ' + u.message if u.message else ''}")
    assert config.line is not None
    typer.echo(f"plan {config.line.version}, sha256 {config.line.sha256}")
    typer.echo(f"rig time per unit: {result.sequence_s / max(len(result.units), 1):.0f} s")
    raise typer.Exit(result.outcome.exit_code)


__all__ = ["line_app"]
