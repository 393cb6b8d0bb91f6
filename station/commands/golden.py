"""``station golden register|list|chart``: the golden (reference) unit a station checks itself with.

``register`` takes the unit's references from its own repeated runs in the database (at least five: by
``--lot`` or ``--run``); ``list`` shows the registrations; ``chart`` shows, per parameter, the individuals
chart of the unit's checks with the Nelson run rules (the chart's sigma: the registered repeatability). A
station with ``golden = "per-shift"`` in its configuration admits production units only after a passing
golden run in the current shift.
"""

from __future__ import annotations

import json
import sys
from datetime import UTC, datetime
from typing import Annotated

import typer

from station.commands.common_options import DbOption, refuse
from station.kernel.errors import StationError

golden_app = typer.Typer(no_args_is_help=True, help="The golden unit: register it, list, chart its checks.")

@golden_app.command("register")
def register_command(
    serial: Annotated[str, typer.Argument(help="the golden unit's serial")],
    lot: Annotated[str | None, typer.Option(help="use its runs of this lot")] = None,
    run: Annotated[list[str] | None, typer.Option("--run", help="use these runs (repeatable)")] = None,
    k_sigma: Annotated[float, typer.Option(min=1.0, max=10.0, help="allowed deviation in repeatability sigmas")]
    = 4.0,
    fraction: Annotated[float, typer.Option(min=0.0, max=1.0, help="or this fraction of the limit width, "
                                            "whichever is larger")] = 0.1,
    db: DbOption = None,
) -> None:
    """Register SERIAL as a golden unit, its references from its own runs in the database (five or more)."""
    from station.kernel.golden import register_golden
    from station.store.db import open_database
    from station.store.golden_records import save_golden, unit_runs

    try:
        with open_database(db, must_exist=True) as database:
            runs = unit_runs(database, serial, tuple(run or ()), lot)
            golden = register_golden(serial, datetime.now(UTC).isoformat(timespec="seconds"), runs,
                                     k_sigma=k_sigma, fraction=fraction)
            version = save_golden(database, golden)
    except StationError as exc:
        raise refuse(exc) from None
    typer.echo(f"golden unit {serial} registered (version {version}) from {len(runs)} runs: "
               f"{len(golden.references)} parameters")


@golden_app.command("list")
def list_command(as_json: Annotated[bool, typer.Option("--json", help="print as JSON")] = False,
                 db: DbOption = None) -> None:
    """The registered golden units (newest registration of each) and their last check."""
    from station.store.db import open_database
    from station.store.golden_records import golden_checks, golden_units

    try:
        with open_database(db, must_exist=True) as database:
            units = golden_units(database)
            checks = golden_checks(database)
    except StationError as exc:
        raise refuse(exc) from None
    if as_json:
        sys.stdout.write(json.dumps([{**g.to_json(), "version": v} for v, g in units.values()], indent=2) + "\n")
        return
    if not units:
        typer.echo("no golden unit registered")
    for serial, (version, golden) in units.items():
        mine = [c for c in checks if c.serial == serial]
        last = (f"last check {mine[-1].checked_at:%Y-%m-%d %H:%M} UTC on {mine[-1].station}: "
                f"{'PASS' if mine[-1].passed else 'FAIL'}" if mine else "never checked")
        typer.echo(f"{serial} v{version} registered {golden.registered_at}: {len(golden.references)} parameters; "
                   f"{len(mine)} checks; {last}")


@golden_app.command("chart")
def chart_command(
    serial: Annotated[str, typer.Argument(help="the golden unit's serial")],
    as_json: Annotated[bool, typer.Option("--json", help="print as JSON")] = False,
    db: DbOption = None,
) -> None:
    """Individuals chart of every parameter over the unit's checks, with the Nelson rules that fired."""
    from station.kernel.golden import golden_trends
    from station.store.db import open_database
    from station.store.golden_records import golden_checks, golden_units
    from station.store.spc import RULES, run_rules

    try:
        with open_database(db, must_exist=True) as database:
            units = golden_units(database)
            if serial not in units:
                raise StationError(f"{serial!r} is not a registered golden unit")
            checks = golden_checks(database, serial=serial)
    except StationError as exc:
        raise refuse(exc) from None
    trends = golden_trends(units[serial][1], [c.deviations for c in checks], run_rules)
    if as_json:
        sys.stdout.write(json.dumps({"serial": serial, "checks": [c.checked_at.isoformat() for c in checks],
                                     "parameters": [{"parameter": t.parameter, "unit": t.unit,
                                                     "deviation": list(t.deviations), "z": list(t.z),
                                                     "rules": [list(r) for r in t.rules],
                                                     "first_signal": t.first_signal} for t in trends]},
                                    indent=2) + "\n")
        return
    typer.echo(f"golden unit {serial}: {len(checks)} checks")
    for t in trends:
        if t.first_signal is None:
            continue
        fired = sorted({r for rs in t.rules for r in rs})
        typer.echo(f"  {t.parameter}: signal at check {t.first_signal + 1} "
                   f"({checks[t.first_signal].checked_at:%Y-%m-%d %H:%M} UTC): "
                   + "; ".join(f"rule {r} ({RULES[r]})" for r in fired))
    if all(t.first_signal is None for t in trends):
        typer.echo("  every parameter in control")
