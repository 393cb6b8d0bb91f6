"""``station units list|show`` and :func:`attach_recorder`, which connects a run to the database.

Wiring in ``station/cli.py``::

    from station.store.commands import units_app
    app.add_typer(units_app, name="units")

and in ``demo`` / ``run``: ``attach_recorder(subscribers.append, db_url, station_name=...)`` before the run.
"""

from __future__ import annotations

import json
import sys
from collections.abc import Callable
from typing import TYPE_CHECKING, Annotated, Any

import typer

from station.errors import StationError
from station.store.url import ENV_VAR

if TYPE_CHECKING:  # the database code loads only when a command runs
    from station.sequence.records import Record
    from station.store.recorder import Recorder, RunContext

units_app = typer.Typer(no_args_is_help=True, help="Per-unit records in the station database.")

DbOption = Annotated[
    str | None,
    typer.Option("--db", help=f"database URL (default: ${ENV_VAR} or sqlite:///station.sqlite)"),
]


def run_context(plan: Any = None, limits: Any = None, operator: str = "") -> RunContext:
    """A :class:`RunContext` fingerprinting a rig plan (:class:`~station.sim.plan.RigPlan`) and product limits.

    The sequence version names the step count, the hashes are SHA-256 of the frozen objects' ``repr``;
    the limits version is their ``name`` (for a limits file: its name, version and the file's SHA-256).
    None leaves the corresponding fields empty.
    """
    from station.store.recorder import RunContext, digest_of

    kw: dict[str, str] = {"operator": operator}
    if limits is not None and hasattr(limits, "sha256") and hasattr(limits, "version"):
        # a limits file (station.sequence.limits_file.LimitsFile): its own version and file hash
        kw["limits_version"] = f"{limits.name} {limits.version}"
        kw["limits_hash"] = str(limits.sha256)
    elif limits is not None:
        kw["limits_version"] = str(getattr(limits, "name", ""))
        kw["limits_hash"] = digest_of(limits)
    if plan is not None:
        from station.sequence.steps import plan_steps

        kw["sequence_version"] = f"plan/{len(plan_steps(plan))} steps"
        kw["sequence_hash"] = digest_of(plan)
    return RunContext(**kw)


def attach_recorder(
    runner_or_subscribe: Any,
    db_url: str | None = None,
    *,
    station_name: str | None = None,
    operator: str = "",
    plan: Any = None,
    limits: Any = None,
    context: RunContext | None = None,
) -> Recorder:
    """Open the database at ``db_url`` (migrating it), recover stale runs, subscribe a :class:`Recorder`.

    Args:
        runner_or_subscribe: a :class:`~station.sequence.runner.SequenceRunner` (its ``subscribe`` is used;
            its station name, plan and limits are taken), or any callable taking a subscriber, such as
            ``subscribers.append`` of the list later given to the runner.
        db_url: database URL (None: ``$STATION_DB`` or ``sqlite:///station.sqlite``).
        station_name: recover only this station's UNFINISHED runs (default: the runner's station; None
            without a runner: every stale run).
        operator: who runs the station.
        plan, limits: the rig plan and product limits the run uses, fingerprinted into the run row
            (taken from the runner when one is given).
        context: overrides everything derived above.

    Returns the recorder; its ``db`` stays open for the process (``recorder.db.close()`` to release it).
    Raises :class:`~station.store.db.StoreError` if the database cannot be opened.
    """
    from station.store.db import open_database
    from station.store.recorder import Recorder

    db = open_database(db_url)
    subscribe: Callable[[Callable[[Record], None]], Any]
    if hasattr(runner_or_subscribe, "subscribe"):
        subscribe = runner_or_subscribe.subscribe
        plan = plan if plan is not None else getattr(runner_or_subscribe, "plan", None)
        limits = limits if limits is not None else getattr(runner_or_subscribe, "limits", None)
        if station_name is None:
            station_name = getattr(runner_or_subscribe, "station", None)
    else:
        subscribe = runner_or_subscribe
    ctx = context if context is not None else run_context(plan, limits, operator)
    recorder = Recorder(db, ctx)
    recovered = recorder.recover(station_name)
    if recovered:
        typer.echo(f"recovered {len(recovered)} unfinished run(s): {', '.join(recovered)}", err=True)
    subscribe(recorder)
    return recorder


def _query(db_url: str | None, query: Callable[..., Any], *args: Any, **kwargs: Any) -> Any:
    """Open the store, run ``query(database, *args, **kwargs)``, close it; a StationError is one line, exit 2."""
    from station.store.db import open_database

    try:
        with open_database(db_url) as database:
            return query(database, *args, **kwargs)
    except StationError as exc:
        typer.echo(f"error: {exc}", err=True)
        raise typer.Exit(2) from None


@units_app.command("list")
def units_list(db: DbOption = None) -> None:
    """List every unit: runs, latest outcome, attempts since its last disposition."""
    from station.store.queries import list_units

    rows = _query(db, list_units)
    if not rows:
        typer.echo("no units recorded")
        return
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
    typer.echo(f"unit {detail.serial}: {len(detail.runs)} run(s), {detail.attempts} attempt(s) since last disposition")
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
                   f"{'verified' if w['verified'] else 'NOT verified'}")
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
    serial: Annotated[str, typer.Argument(help="the unit's serial number")],
    decision: Annotated[str, typer.Argument(help="e.g. retest, scrap, rework")],
    operator: Annotated[str, typer.Option(help="who decided")] = "",
    note: Annotated[str, typer.Option(help="why")] = "",
    db: DbOption = None,
) -> None:
    """Record a disposition: the retest policy counts attempts again from here."""
    from station.store.recorder import record_disposition

    _query(db, record_disposition, serial, decision, operator=operator, note=note)
    typer.echo(f"recorded disposition {decision!r} for {serial}")
