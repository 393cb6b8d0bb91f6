"""``station units list|show|params|disposition``: per-unit records in the station database."""

from __future__ import annotations

import json
import sys
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import typer

from station.commands.common_options import DbOption
from station.kernel.errors import StationError

if TYPE_CHECKING:  # the database code loads only when a command runs
    pass

units_app = typer.Typer(no_args_is_help=True, rich_markup_mode="markdown",
                        help="Per-unit records in the station database.")



def _query(db_url: str | None, query: Callable[..., Any], *args: Any, writes: bool = False, **kwargs: Any) -> Any:
    """Open the existing store, run ``query(database, *args, **kwargs)``, close it.

    A missing SQLite file is refused, never created; ``writes``: so is one that keeps nothing (in memory); a
    StationError (a locked database after the stated wait, a full disk) is one line, exit 2.
    """
    from station.store.db import open_database

    try:
        with open_database(db_url, must_exist=True, for_writing=writes) as database:
            return query(database, *args, **kwargs)
    except StationError as exc:
        typer.echo(f"error: {exc}", err=True)
        raise typer.Exit(2) from None


@units_app.command("list")
def units_list(
    as_json: Annotated[bool, typer.Option("--json", help="print as JSON (a list of objects)")] = False,
    db: DbOption = None,
) -> None:
    """List every unit: runs, latest outcome, failed attempts since its last disposition, that disposition
    (a scrapped unit shows SCRAPPED for good), when its last run started (local time)."""
    from dataclasses import asdict

    from station.store.queries import list_units

    rows = _query(db, list_units)
    if as_json:
        sys.stdout.write(json.dumps([asdict(u) for u in rows], indent=2) + "\n")
        return
    from station.store.db import shown_url

    if not rows:
        typer.echo(f"no units recorded in {shown_url(db)}")
        return
    typer.echo(f"{len(rows)} unit(s) in {shown_url(db)}")
    from station.kernel.display import local_time

    typer.echo(f"{'serial':<24} {'runs':>4} {'attempts':>8}  {'last outcome':<12} {'disposition':<16} last run started")
    for u in rows:
        shown = "SCRAPPED" if u.disposition == "scrap" else (u.disposition or "-")
        typer.echo(f"{u.serial:<24} {u.runs:>4} {u.attempts:>8}  {u.last_outcome:<12} {shown:<16} "
                   f"{local_time(u.last_started_at) if u.last_started_at else '-'}")


@units_app.command("show")
def units_show(
    serial: Annotated[str, typer.Argument(help="the unit's serial number")],
    as_json: Annotated[bool, typer.Option("--json", help="print as JSON")] = False,
    db: DbOption = None,
) -> None:
    """Show one unit: its runs (newest first), limit verdicts, latest parameter set, EEPROM writes."""
    from station.store.queries import show_unit

    detail = _query(db, show_unit, serial)
    if detail is None:
        typer.echo(f"error: no unit with serial {serial!r}", err=True)
        raise typer.Exit(1)
    if as_json:
        sys.stdout.write(json.dumps(detail.to_dict(), indent=2) + "\n")
        return
    from station.kernel.display import limits_identity, local_time
    from station.store.db import shown_url

    scrapped = any(d["decision"] == "scrap" for d in detail.dispositions)
    typer.echo(f"unit {detail.serial} in {shown_url(db)}: {len(detail.runs)} run(s), {detail.attempts} failed "
               "attempt(s) since its last disposition" + ("; SCRAPPED" if scrapped else ""))
    for r in detail.runs:
        typer.echo(f"  {local_time(r.started_at)}  run {r.run_id} on {r.station} slot {r.slot}: {r.outcome}"
                   f"{' - ' + r.message if r.message else ''}")
        typer.echo(f"      {r.checks} checks, {len(r.failed_checks)} failed{': ' if r.failed_checks else ''}"
                   f"{', '.join(r.failed_checks[:5])}; limits {limits_identity(r.limits_version, r.limits_hash)}; "
                   f"software {r.software_version or '-'}; operator {r.operator or '-'}; lot {r.lot or '-'}")
        if r.session_path:
            typer.echo(f"      recording {r.session_path} sha256 {r.session_sha256}")
    for w in detail.eeprom_writes:
        typer.echo(f"  EEPROM {local_time(w['written_at'])}: image {w['image_sha256'][:16]}..., "
                   f"{w['attempts']} attempt(s), {'verified' if w['verified'] else 'NOT verified'}"
                   + ("" if w.get("state", "complete") == "complete" else f" ({w['state']})"))
    for d in detail.dispositions:
        typer.echo(f"  disposition {local_time(d['decided_at'])}: {d['decision']} by {d['operator'] or '-'} "
                   f"{d['note']}")
    if detail.latest_params_json:
        typer.echo(f"  latest parameter set: run {detail.latest_params_run_id}")


@units_app.command("params")
def units_params(
    serial: Annotated[str, typer.Argument(help="the unit's serial number")],
    db: DbOption = None,
) -> None:
    """Print the unit's newest PASS parameter set as JSON (station-params/2, SI units)."""
    from station.store.queries import latest_parameter_set

    params = _query(db, latest_parameter_set, serial)
    if params is None:
        typer.echo(f"error: no PASS parameter set of serial {serial!r}", err=True)
        raise typer.Exit(2)
    typer.echo(params.to_json())


@units_app.command("disposition")
def units_disposition(
    serial: Annotated[str, typer.Argument(help="the unit's serial number (a unit the station has tested)")],
    decision: Annotated[str, typer.Argument(help="retest, scrap, rework or accept-deviation")],
    operator: Annotated[str, typer.Option(help="who decided (required)")] = "",
    reason: Annotated[str, typer.Option("--reason", "--note", help="why (required)")] = "",
    db: DbOption = None,
) -> None:
    """Record a person's decision about a unit, with who and why.

    ``retest``, ``rework`` and ``accept-deviation`` reset the unit's failed attempts (the retest policy
    counts again from here); ``scrap`` locks the serial: the station refuses the unit from then on.
    """
    from station.store.recorder import record_disposition

    _query(db, record_disposition, serial, decision, operator=operator, note=reason, writes=True)
    typer.echo(f"recorded disposition {decision!r} for {serial}")


@units_app.command("certificate")
def units_certificate(
    serial: Annotated[str, typer.Argument(help="the unit's serial number")],
    output: Annotated[Path, typer.Option("-o", "--output", help="file to write: *.pdf or *.html")],
    run: Annotated[str | None, typer.Option("--run", help="the run (default: the unit's newest run with a verdict "
                                                          "and a parameter set)")] = None,
    db: DbOption = None,
) -> None:
    """Write the unit's calibration certificate (PDF or HTML, by the output's suffix).

    Parameters with expanded uncertainties (k = 2) and their verdicts, the verification on the rig, the limits
    file's name, version and SHA-256, the decision rule (ISO 14253-1 guard bands), station, rig, operator, lot,
    date (local time with zone), the verdict, and the SHA-256 of the stored parameter set (recomputed from the
    database; a record that does not match it is refused). Exit 2: unknown unit or run, or refused.
    """
    from station.commands.output import check_output
    from station.store.certificate import unit_certificate

    suffix = output.suffix.lower()
    try:
        check_output(output, suffix=suffix if suffix in (".pdf", ".html") else ".pdf", what="certificate")
    except StationError as exc:
        typer.echo(f"error: {exc}", err=True)
        raise typer.Exit(2) from None
    cert = _query(db, unit_certificate, serial, run)
    if suffix == ".html":
        from station.store.certificate_html import certificate_html

        data = certificate_html(cert).encode("utf-8")
    else:
        from station.store.certificate_pdf import certificate_pdf

        data = certificate_pdf(cert)
    try:
        output.write_bytes(data)
    except OSError as exc:
        typer.echo(f"error: cannot write {output}: {exc.strerror or exc}", err=True)
        raise typer.Exit(2) from None
    typer.echo(f"wrote {output}: certificate of {cert.serial}, run {cert.run_id}, verdict {cert.verdict}, "
               f"parameter set sha256 {cert.params_sha256}")
