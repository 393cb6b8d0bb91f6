"""``station golden register|list|chart``: the golden (reference) unit a station checks itself with.

``register`` takes the unit's references from its own repeated runs in the database (at least ten, twenty
recommended: by ``--lot`` or ``--run``), the allowed deviations from a stated family-wise false-stop rate per
check (:mod:`station.kernel.golden`), and says how large a shift one check catches; ``list`` shows the
registrations and their rule; ``chart`` shows, per parameter, the individuals chart of the unit's checks with
the Nelson run rules (the chart's sigma: the registered repeatability, with its degrees of freedom). A
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
    false_stop_rate: Annotated[float, typer.Option(min=1e-6, max=0.2, help="family-wise probability that a "
                                                   "stable station fails one golden check (0.0027: 3-sigma)")]
    = 0.0027,
    fraction: Annotated[float, typer.Option(min=0.0, max=1.0, help="or this fraction of the limit width, "
                                            "whichever is larger")] = 0.1,
    db: DbOption = None,
) -> None:
    """Register SERIAL as a golden unit, its references from its own runs in the database (ten or more)."""
    from station.kernel.golden import RECOMMENDED_REGISTRATION_RUNS, detectable_shift, register_golden
    from station.store.db import open_database
    from station.store.golden_records import save_golden, unit_runs

    try:
        with open_database(db, must_exist=True) as database:
            runs = unit_runs(database, serial, tuple(run or ()), lot)
            golden = register_golden(serial, datetime.now(UTC).isoformat(timespec="seconds"), runs,
                                     false_stop_rate=false_stop_rate, fraction=fraction)
            version = save_golden(database, golden)
    except StationError as exc:
        raise refuse(exc) from None
    rule = golden.rule
    assert rule is not None
    typer.echo(f"golden unit {serial} registered (version {version}) from {len(runs)} runs: "
               f"{len(golden.references)} parameters")
    typer.echo(f"  {rule.describe()}")
    typer.echo(f"  sensitivity: one check catches a shift of one parameter of {rule.k:.3g} sigma with 50 %, "
               f"{detectable_shift(rule.k, rule.runs, 0.9):.3g} sigma with 90 % probability (sigma: the station's "
               f"repeatability on this unit; where 10 % of the limit width is larger, that is the bound)")
    if rule.runs < RECOMMENDED_REGISTRATION_RUNS:
        typer.echo(f"  note: {RECOMMENDED_REGISTRATION_RUNS} runs or more make the check more sensitive")


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
        typer.echo("  " + (golden.rule.describe() if golden.rule is not None
                           else "station-golden/1 registration: stored allowed deviations, no false-stop rate "
                                "recorded"))


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
    golden = units[serial][1]
    trends = golden_trends(golden, [c.deviations for c in checks], run_rules)
    runs = max((r.runs for r in golden.references), default=0)
    caption = (f"chart sigma: the repeatability registered from {runs} runs ({runs - 1} degrees of freedom; "
               f"its own relative uncertainty about {100 / max(2 * (runs - 1), 1) ** 0.5:.0f} %)")
    if as_json:
        rule = golden.rule
        sys.stdout.write(json.dumps({"serial": serial, "checks": [c.checked_at.isoformat() for c in checks],
                                     "caption": caption, "sigma_dof": runs - 1,
                                     "rule": None if rule is None else golden.to_json()["rule"],
                                     "parameters": [{"parameter": t.parameter, "unit": t.unit,
                                                     "deviation": list(t.deviations), "z": list(t.z),
                                                     "rules": [list(r) for r in t.rules],
                                                     "first_signal": t.first_signal} for t in trends]},
                                    indent=2) + "\n")
        return
    typer.echo(f"golden unit {serial}: {len(checks)} checks; {caption}")
    if golden.rule is not None:
        typer.echo(f"  check: {golden.rule.describe()}")
    for t in trends:
        if t.first_signal is None:
            continue
        fired = sorted({r for rs in t.rules for r in rs})
        typer.echo(f"  {t.parameter}: signal at check {t.first_signal + 1} "
                   f"({checks[t.first_signal].checked_at:%Y-%m-%d %H:%M} UTC): "
                   + "; ".join(f"rule {r} ({RULES[r]})" for r in fired))
    if all(t.first_signal is None for t in trends):
        typer.echo("  every parameter in control")
