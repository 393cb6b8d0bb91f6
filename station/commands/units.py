"""``station units list|show|params|disposition``: per-unit records in the station database."""

from __future__ import annotations

import json
import sys
from collections.abc import Callable
from typing import TYPE_CHECKING, Annotated, Any

import typer

from station.kernel.errors import StationError
from station.store.url import ENV_VAR

if TYPE_CHECKING:  # the database code loads only when a command runs
    pass

units_app = typer.Typer(no_args_is_help=True, help="Per-unit records in the station database.")

DbOption = Annotated[
    str | None,
    typer.Option("--db", help=f"database URL (default: ${ENV_VAR} or sqlite:///station.sqlite)"),
]


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
    """List every unit: runs, latest outcome, failed attempts since its last disposition."""
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
    typer.echo(f"{'serial':<24} {'runs':>4} {'attempts':>8}  {'last outcome':<12} last run started")
    for u in rows:
        typer.echo(f"{u.serial:<24} {u.runs:>4} {u.attempts:>8}  {u.last_outcome:<12} {u.last_started_at or '-'}")


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
    from station.store.db import shown_url

    typer.echo(f"unit {detail.serial} in {shown_url(db)}: {len(detail.runs)} run(s), {detail.attempts} failed "
               "attempt(s) since its last disposition")
    for r in detail.runs:
        typer.echo(f"  {r.started_at}  run {r.run_id} on {r.station} slot {r.slot}: {r.outcome}"
                   f"{' - ' + r.message if r.message else ''}")
        typer.echo(f"      {r.checks} checks, {len(r.failed_checks)} failed{': ' if r.failed_checks else ''}"
                   f"{', '.join(r.failed_checks[:5])}; limits {r.limits_version or '-'}; "
                   f"software {r.software_version or '-'}; operator {r.operator or '-'}")
        if r.session_path:
            typer.echo(f"      recording {r.session_path} sha256 {r.session_sha256}")
    for w in detail.eeprom_writes:
        typer.echo(f"  EEPROM {w['written_at']}: image {w['image_sha256'][:16]}..., {w['attempts']} attempt(s), "
                   f"{'verified' if w['verified'] else 'NOT verified'}"
                   + ("" if w.get("state", "complete") == "complete" else f" ({w['state']})"))
    for d in detail.dispositions:
        typer.echo(f"  disposition {d['decided_at']}: {d['decision']} by {d['operator'] or '-'} {d['note']}")
    if detail.latest_params_json:
        typer.echo(f"  latest parameter set: run {detail.latest_params_run_id}")


@units_app.command("params")
def units_params(
    serial: Annotated[str, typer.Argument(help="the unit's serial number")],
    db: DbOption = None,
) -> None:
    """Print the unit's newest PASS parameter set as JSON (station-params/1, SI units)."""
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
