"""``station msa report``: a crossed Gage R&R study of every limited parameter, from the records.

The study's runs are chosen by lot (``--lot``), run ids (``--run``, repeatable) or a start-time window
(``--since``/``--until``); the parts are the units' serials, the appraisers the rig's nests (``--by nest``,
the default), rigs or operators. Printed as a table; ``--json`` (format ``station-msa/1``) and ``--csv FILE``
for tools. Values and standard deviations are in each parameter's SI unit as the limits file states it;
percentages of the total variation (%TV) and of the tolerance (%tol, 6 sigma over the limits' width).
"""

from __future__ import annotations

import csv
import json
import math
import sys
from datetime import UTC, datetime
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from station.kernel.errors import StationError
from station.store.default_url import ENV_VAR

if TYPE_CHECKING:
    from station.msa.study import StudyReport

msa_app = typer.Typer(no_args_is_help=True, help="Measurement system analysis (Gage R&R) of the station.")

BY = ("nest", "rig", "operator")


def _when(text: str | None, what: str) -> datetime | None:
    if text is None:
        return None
    try:
        t = datetime.fromisoformat(text)
    except ValueError:
        raise StationError(f"{what} {text[:40]!r}: expected an ISO date or time, e.g. 2026-11-28T06:00") from None
    return t if t.tzinfo is not None else t.replace(tzinfo=UTC)


def study_report(db_url: str | None, *, lot: str | None = None, runs: tuple[str, ...] = (),
                 since: datetime | None = None, until: datetime | None = None, by: str = "nest",
                 level: float = 0.90) -> StudyReport:
    """Read the selected runs from the database at ``db_url`` and analyse them."""
    from station.msa.study import StudyPoint, analyse
    from station.store.db import open_database
    from station.store.msa_rows import StudySelection, study_values

    if by not in BY:
        raise StationError(f"--by {by!r}: one of {', '.join(BY)}")
    if lot is None and not runs and since is None and until is None:
        raise StationError("choose the study's runs: --lot, --run or --since/--until")
    with open_database(db_url, must_exist=True) as database:
        values = study_values(database, StudySelection(lot=lot, run_uids=runs, since=since, until=until))
    if not values:
        raise StationError("no tested unit results in the selected runs")

    def appraiser(v: object) -> str:
        from station.store.msa_rows import StudyValue

        assert isinstance(v, StudyValue)
        return f"nest {v.nest + 1}" if by == "nest" else (v.rig if by == "rig" else (v.operator or "(none)"))

    # the product parameters; the fit-quality checks (fit.*) judge a recording, not a characteristic of the part
    points = [StudyPoint(v.parameter, v.unit, v.serial, appraiser(v), v.value, v.low, v.high) for v in values
              if not v.parameter.startswith("fit.")]
    return analyse(points, by=by, level=level)


def print_report(report: StudyReport) -> None:
    """The study as a table on the terminal, standard deviations in the display convention's units."""
    from rich.console import Console
    from rich.table import Table

    from station.kernel.display import Display, display_of_check, format_number

    console = Console(width=None if sys.stdout.isatty() else 160)
    console.print(f"Gage R&R by ANOVA: {len(report.parts)} parts x {len(report.appraisers)} {report.by}s "
                  f"({', '.join(report.appraisers)}); intervals {100 * report.level:.0f} % two-sided; "
                  "EV repeatability, AV reproducibility, GRR both, PV part variation (standard deviations)")
    table = Table()
    for col in ("parameter", "unit", "r", "EV", "AV", "GRR", "PV", "%GRR tol", "%GRR TV", "ndc", "verdict"):
        table.add_column(col, justify="left" if col in ("parameter", "unit", "verdict") else "right")
    for p in report.parameters:
        g = p.study
        d = display_of_check(p.parameter, p.unit)
        if g is None:
            table.add_row(p.parameter, d.unit, "", "", "", "", "", "", "", "", f"not analysed: {p.reason}")
            continue

        def pct(x: float | None) -> str:
            return "" if x is None or not math.isfinite(x) else f"{x:.1f}"

        def sd(x: float, d: Display = d) -> str:
            return format_number(d.spread(x))

        table.add_row(
            p.parameter, d.unit, str(g.repeats), sd(g.repeatability.std), sd(g.reproducibility.std),
            sd(g.grr.std), sd(g.part.std), pct(g.grr.pct_tolerance), pct(g.grr.pct_total),
            str(g.ndc) if g.determined else "n/a",
            g.verdict + ("" if g.ndc_adequate or not g.determined else " (ndc < 5)"),
        )
    console.print(table)
    dropped = sum(p.dropped for p in report.parameters)
    if dropped:
        console.print(f"{dropped} values left out to balance the design (the newest repeats of fuller cells)")


@msa_app.command("report")
def report_command(
    lot: Annotated[str | None, typer.Option(help="the study's lot")] = None,
    run: Annotated[list[str] | None, typer.Option("--run", help="a run id of the study (repeatable)")] = None,
    since: Annotated[str | None, typer.Option(help="runs started at or after this ISO time (UTC if no zone)")] = None,
    until: Annotated[str | None, typer.Option(help="runs started before this ISO time")] = None,
    by: Annotated[str, typer.Option(help="what the appraisers are: nest, rig or operator")] = "nest",
    level: Annotated[float, typer.Option(min=0.5, max=0.999, help="confidence level of the intervals")] = 0.90,
    as_json: Annotated[bool, typer.Option("--json", help="print the study as JSON (station-msa/1)")] = False,
    csv_path: Annotated[Path | None, typer.Option("--csv", help="also write the study as CSV to this file")] = None,
    db: Annotated[str | None, typer.Option("--db", help=f"database URL (default: ${ENV_VAR} or "
                                                        "sqlite:///station.sqlite)")] = None,
) -> None:
    """Analyse a crossed study (parts x nests x repeats) recorded in the database."""
    from station.commands.output import check_output

    try:
        if csv_path is not None:
            check_output(csv_path, suffix=".csv", what="--csv")
        report = study_report(db, lot=lot, runs=tuple(run or ()), since=_when(since, "--since"),
                              until=_when(until, "--until"), by=by, level=level)
    except StationError as exc:
        typer.echo(f"error: {exc}", err=True)
        raise typer.Exit(2) from None
    if csv_path is not None:
        with csv_path.open("w", newline="") as fh:
            csv.writer(fh).writerows(report.to_csv_rows())
    if as_json:
        sys.stdout.write(json.dumps(report.to_json(), indent=2) + "\n")
        return
    print_report(report)
