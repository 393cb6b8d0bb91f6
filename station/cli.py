"""The ``station`` command: wires sessions, simulator, fit and corrector together.

Every command reports expected failures (a malformed file, an unfittable session, a
station fault) as one line on stderr and a non-zero exit code, never a traceback.
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Annotated

import numpy as np
import typer

from station.errors import StationError

app = typer.Typer(add_completion=False, no_args_is_help=True, help="IMU end-of-line calibration station.")
import_app = typer.Typer(no_args_is_help=True, help="Convert recordings made elsewhere into session CSV v1.")
app.add_typer(import_app, name="import")


def _fail(exc: StationError, code: int = 2) -> typer.Exit:
    typer.echo(f"error: {exc}", err=True)
    return typer.Exit(code)


@app.command()
def simulate(
    output: Annotated[Path, typer.Option("-o", "--output", help="session CSV to write")],
    seed: Annotated[int, typer.Option(help="seed: the same seed gives the same bytes")] = 0,
    effect: Annotated[list[str] | None, typer.Option(help="extra physics NAME=VALUE (repeatable)")] = None,
    sample_rate: Annotated[float | None, typer.Option(help="sample rate (Hz); default from the plan")] = None,
    random_plan: Annotated[bool, typer.Option(help="draw a random rig plan from the seed")] = False,
) -> None:
    """Simulate one unit on the rig and write its session recording."""
    from dataclasses import replace

    from station.session import write_session
    from station.sim.effects import Effects
    from station.sim.plan import default_plan
    from station.sim.plan import random_plan as draw_plan
    from station.sim.session_sim import simulate_session

    try:
        effects = Effects.parse(effect or [])
        plan = draw_plan(np.random.default_rng(seed)) if random_plan else default_plan()
        if sample_rate is not None:
            plan = replace(plan, sample_rate_hz=sample_rate)
        result = simulate_session(seed, plan=plan, effects=effects)
        write_session(result.session, output)
    except StationError as exc:
        raise _fail(exc) from None
    typer.echo(f"wrote {output} ({len(result.session)} samples, {result.session.duration_s:.1f} s, "
               f"serial {result.session.serial})")


def _print_params(params: object) -> None:
    from rich.console import Console
    from rich.table import Table

    from station.fit.params import ParameterSet

    assert isinstance(params, ParameterSet)
    console = Console()
    for name, tri, unit, scale in (("accelerometer", params.accel, "m/s^2", 1.0),
                                   ("gyroscope", params.gyro, "deg/s", float(np.degrees(1.0)))):
        table = Table(title=f"{params.serial} {name} ({unit}; uncertainties are 1 sigma)")
        table.add_column("parameter")
        for ax in "xyz":
            table.add_column(ax, justify="right")

        def row(
            label: str, v: np.ndarray, s: np.ndarray, k: float = scale, fmt: str = "{:.6f}", table: Table = table
        ) -> None:
            cells = []
            for a, b in zip(v, s, strict=True):
                if not np.isfinite(a):
                    cells.append("unresolved")
                else:
                    cells.append(f"{fmt.format(a * k)} ± {fmt.format(b * k)}")
            table.add_row(label, *cells)

        for i, ax in enumerate("xyz"):
            row(f"M row {ax}", tri.misalignment[i], tri.misalignment_std[i], 1.0)
        row("bias static", tri.bias_static, tri.bias_static_std)
        row("bias drift", tri.bias_drift, tri.bias_drift_std)
        row("T_c (s)", tri.correlation_time_s, tri.correlation_time_s_std, 1.0, "{:.1f}")
        row("noise std", tri.noise_std, tri.noise_std_std)
        row("residual rms", tri.residual_rms, np.zeros(3))
        console.print(table)


@app.command()
def fit(
    session_path: Annotated[Path, typer.Argument(metavar="SESSION.csv", help="session CSV v1 recording")],
    as_json: Annotated[bool, typer.Option("--json", help="print the parameter set as JSON")] = False,
    g_sensitivity: Annotated[bool, typer.Option(help="also fit gyro g-sensitivity")] = False,
) -> None:
    """Fit the parameter set of eq. (1) to a session and print it."""
    from station.fit.calibrate import FitOptions, fit_session
    from station.session import read_session

    try:
        params = fit_session(read_session(session_path), FitOptions(g_sensitivity=g_sensitivity))
    except StationError as exc:
        raise _fail(exc) from None
    if as_json:
        sys.stdout.write(params.to_json() + "\n")
    else:
        _print_params(params)


@app.command()
def correct(
    session_path: Annotated[Path, typer.Argument(metavar="SESSION.csv")],
    params_path: Annotated[Path, typer.Option("--params", help="parameter JSON from `station fit --json`")],
    output: Annotated[Path, typer.Option("-o", "--output", help="corrected session CSV to write")],
) -> None:
    """Apply Algorithm 1 to a session; writes a session CSV v1 with corrected measurements."""
    from station.correct.session_correct import correct_session
    from station.fit.params import ParameterSet
    from station.session import read_session, write_session

    try:
        params = ParameterSet.from_json(params_path.read_text())
        write_session(correct_session(read_session(session_path), params), output)
    except StationError as exc:
        raise _fail(exc) from None
    except OSError as exc:
        raise _fail(StationError(str(exc))) from None
    typer.echo(f"wrote {output}")


@import_app.command("imucal")
def import_imucal(
    csv_path: Annotated[Path, typer.Argument(help="imucal session CSV")],
    output: Annotated[Path, typer.Option("-o", "--output", help="session CSV v1 to write")],
    segments: Annotated[Path | None, typer.Option(help="imucal segment list JSON (Ferraris session)")] = None,
    serial: Annotated[str, typer.Option(help="serial number to record")] = "imucal-example",
) -> None:
    """Convert an imucal Ferraris recording (+ segment list) or annotated session."""
    from station.session import write_session
    from station.session.imucal_import import import_imucal_annotated, import_imucal_ferraris

    try:
        if segments is not None:
            session = import_imucal_ferraris(csv_path, segments, serial=serial)
        else:
            session = import_imucal_annotated(csv_path, serial=serial)
        write_session(session, output)
    except StationError as exc:
        raise _fail(exc) from None
    typer.echo(f"wrote {output} ({len(session)} samples)")


def main() -> None:  # pragma: no cover - console entry
    app()


if __name__ == "__main__":  # pragma: no cover
    main()

