"""``station nest-cal estimate|show``: each nest's mounting error, from a reference unit run in every nest.

On the line: run the reference unit once in every nest of the rig (``station run`` with it loaded in nest 1,
then nest 2, ...; production units may fill the other nests), then ``station nest-cal estimate --serial REF``.
The estimate is stored as the rig's next version and applies to every later run on that rig (the station
configuration's ``rig_key``, default its rig URL); the unit's record names the version it was fitted with.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import numpy as np
import typer

from station.commands.common_options import DbOption
from station.kernel.errors import StationError

if TYPE_CHECKING:
    from station.kernel.nest_frames import NestCalibration

nest_app = typer.Typer(no_args_is_help=True, help="Nest mounting errors of a rig (reference-unit calibration).")

def estimate_from_records(db_url: str | None, rig: str, serial: str, runs: tuple[str, ...] = (),
                          store: bool = True, reference: Path | None = None) -> NestCalibration:
    """Estimate the nests of ``rig`` from reference unit ``serial``'s stored fits (one per nest) and store it.

    ``reference``: the reference unit's parameter set from a calibration elsewhere (station-params JSON):
    the nests' tilts are then absolute, else relative to the mean nest.
    """
    from station.fit.nest_estimate import NestFits, TriadFit, estimate_nest_calibration
    from station.store.db import open_database
    from station.store.nest_records import reference_fits, save_nest_calibration

    with open_database(db_url, must_exist=True) as database:
        fits = reference_fits(database, serial, runs)
        if not fits:
            raise StationError(f"no stored fit of reference unit {serial!r}: run it in every nest first")
        per = {slot: NestFits(TriadFit(p.accel.misalignment, p.accel.misalignment_std),
                              TriadFit(p.gyro.misalignment, p.gyro.misalignment_std)) for slot, p in fits.items()}
        ref = None
        if reference is not None:
            from station.kernel.parameters import ParameterSet

            p_ref = ParameterSet.read(reference)
            ref = NestFits(TriadFit(p_ref.accel.misalignment, p_ref.accel.misalignment_std),
                           TriadFit(p_ref.gyro.misalignment, p_ref.gyro.misalignment_std))
        cal = estimate_nest_calibration(rig, serial, per, ref)
        return save_nest_calibration(database, cal) if store else cal


def describe(cal: NestCalibration) -> list[str]:
    """Lines for people: per nest its tilt (deg) with the standard uncertainty and the accel/gyro agreement."""
    lines = [f"nest calibration {cal.label}: reference unit {cal.reference_serial}, {cal.created_at}; "
             f"rotation sensor -> nest about x, y, z (deg, datum: {cal.datum})"]
    for j, (rot, std, agree) in enumerate(zip(cal.rotations_deg, cal.rotations_std_deg, cal.agreement_deg,
                                              strict=True)):
        parts = ", ".join(f"{a} {v:+.4f} ± {s:.4f}" for a, v, s in zip("xyz", rot, std, strict=True))
        lines.append(f"  nest {j + 1}: {parts}; tilt {float(np.linalg.norm(rot)):.4f} deg; "
                     f"accel and gyro estimates {agree:.4f} deg apart")
    return lines


@nest_app.command("estimate")
def estimate_command(
    serial: Annotated[str, typer.Option("--serial", help="the reference unit's serial")],
    rig_key: Annotated[str, typer.Option("--rig-key", help="the rig (its configuration's rig_key or rig URL)")],
    run: Annotated[list[str] | None, typer.Option("--run", help="use only these runs (repeatable)")] = None,
    reference: Annotated[Path | None, typer.Option(
        "--reference-params", help="the reference unit's parameter set from a laboratory calibration (JSON): "
                                   "absolute nest tilts; without it they are relative to the mean nest")] = None,
    dry_run: Annotated[bool, typer.Option("--dry-run", help="estimate and print, do not store")] = False,
    as_json: Annotated[bool, typer.Option("--json", help="print it as JSON (station-nests/1)")] = False,
    db: DbOption = None,
) -> None:
    """Fit the nests' mounting errors from the reference unit's runs and store them as the rig's next version."""
    try:
        cal = estimate_from_records(db, rig_key, serial, tuple(run or ()), store=not dry_run, reference=reference)
    except StationError as exc:
        typer.echo(f"error: {exc}", err=True)
        raise typer.Exit(2) from None
    if as_json:
        sys.stdout.write(json.dumps(cal.to_json(), indent=2) + "\n")
        return
    for line in describe(cal):
        typer.echo(line)
    if dry_run:
        typer.echo("(not stored: --dry-run)")


@nest_app.command("show")
def show_command(
    rig_key: Annotated[str | None, typer.Option("--rig-key", help="only this rig")] = None,
    as_json: Annotated[bool, typer.Option("--json", help="print them as JSON")] = False,
    db: DbOption = None,
) -> None:
    """List the stored nest calibrations (every version)."""
    from station.store.db import open_database
    from station.store.nest_records import nest_calibrations

    try:
        with open_database(db, must_exist=True) as database:
            cals = nest_calibrations(database, rig_key)
    except StationError as exc:
        typer.echo(f"error: {exc}", err=True)
        raise typer.Exit(2) from None
    if as_json:
        sys.stdout.write(json.dumps([c.to_json() for c in cals], indent=2) + "\n")
        return
    if not cals:
        typer.echo("no nest calibrations stored")
    for cal in cals:
        for line in describe(cal):
            typer.echo(line)
