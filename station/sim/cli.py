"""The simulator's commands, contributed to ``station`` through the ``station.commands`` entry point.

``station simulate`` writes one simulated session recording, ``station sim`` serves a simulated
rig and sensors on their real transports (Modbus/TCP on 127.0.0.1, ptys), ``station demo`` runs
the whole station against them. They live here so that nothing outside :mod:`station.sim`
imports the simulator: :func:`register` is loaded by ``station.cli`` from the entry point.
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Annotated

import numpy as np
import typer

from station.cli import DbOption, fail
from station.kernel.errors import StationError


def simulate(
    output: Annotated[Path, typer.Option("-o", "--output", help="session CSV to write")],
    seed: Annotated[int, typer.Option(min=0, max=2**63 - 1, help="seed: the same seed gives the same bytes")] = 0,
    effect: Annotated[list[str] | None, typer.Option(help="extra physics NAME=VALUE (repeatable)")] = None,
    sample_rate: Annotated[float | None, typer.Option(min=1.0, max=10000.0,
                                                      help="sample rate (Hz); default from the plan")] = None,
    random_plan: Annotated[bool, typer.Option(help="draw a random rig plan from the seed")] = False,
    temperature_plateaus: Annotated[str | None, typer.Option(
        help="climate-chamber plateaus in degC, e.g. '25,45,5,25': the plan runs once per plateau after a soak",
    )] = None,
    soak: Annotated[float, typer.Option(min=0.0, help="soak before each later plateau (s)")] = 600.0,
) -> None:
    """Simulate one unit on the rig and write its session recording."""
    from dataclasses import replace

    from station.commands.output import check_output, write_failed
    from station.kernel.plan import default_plan
    from station.kernel.plan import random_plan as draw_plan
    from station.physics.effects import Effects
    from station.session import write_session
    from station.sim.session_sim import simulate_session

    try:
        check_output(output)
        effects = Effects.parse(effect or [])
        plan = draw_plan(np.random.default_rng(seed)) if random_plan else default_plan()
        if sample_rate is not None:
            plan = replace(plan, sample_rate_hz=sample_rate)
        plateaus = None
        if temperature_plateaus is not None:
            try:
                plateaus = tuple(float(v) for v in temperature_plateaus.split(",") if v.strip())
            except ValueError:
                raise StationError(f"--temperature-plateaus {temperature_plateaus!r}: expected numbers like "
                                   "25,45,5,25") from None
            if not plateaus or not all(np.isfinite(plateaus)) or not all(-60.0 <= p <= 150.0 for p in plateaus):
                raise StationError("--temperature-plateaus: one or more plateaus in -60..150 degC")
        result = simulate_session(seed, plan=plan, effects=effects, temperature_plateaus_degc=plateaus,
                                  soak_s=soak)
        try:
            write_session(result.session, output)
        except OSError as exc:
            raise write_failed(exc, output) from None
    except StationError as exc:
        raise fail(exc) from None
    typer.echo(f"wrote {output} ({len(result.session)} samples, {result.session.duration_s:.1f} s, "
               f"serial {result.session.serial})")


def demo(
    units: Annotated[int, typer.Option(min=1, max=64, help="units in the fixture")] = 4,
    scale: Annotated[float | None, typer.Option(min=0.1, help="simulated seconds per wall second "
                                                "(default 30, with --thermal 120)")] = None,
    seed: Annotated[int, typer.Option(min=0, max=2**63 - 1, help="seed: the same seed gives the same units")] = 0,
    out: Annotated[Path, typer.Option(help="directory for session CSVs and parameter JSONs")] = Path("demo-out"),
    db: DbOption = None,
    limits: Annotated[Path | None, typer.Option("--limits", help="limits file (default: fixtures/limits/default.toml)")]
    = None,
    thermal: Annotated[bool, typer.Option("--thermal", help="thermal calibration in a simulated climate chamber: "
                                          "plateaus at 5/15/25/45 degC, verification at 35 degC; the last unit has "
                                          "no temperature effects (the reference)")] = False,
) -> None:
    """Simulated rig + N sensors, the whole sequence, fit, limits, summary: the station end to end.

    With ``--thermal`` a simulated climate chamber (Modbus/TCP) joins: the units carry temperature bias and
    scale coefficients, are calibrated at four temperatures and verified at a fifth, and a table compares
    the corrected errors there with and without the thermal model.

    Exit code: 0 all PASS, 1 a unit FAILed, 2 ERROR (station fault), 3 a unit REFUSED by the retest
    policy, 4 a unit to RETEST (inconclusive verdict), 130 ABORTED (Ctrl-C, SIGTERM, SIGHUP).
    """
    from station.sim.demo import DEMO_SCALE, THERMAL_SCALE, run_demo, run_thermal_demo

    try:
        if thermal:
            result, _ = run_thermal_demo(units, scale or THERMAL_SCALE, seed, out, db_url=db, record=True,
                                         limits_path=limits)
        else:
            result = run_demo(units, scale or DEMO_SCALE, seed, out, db_url=db, record=True, limits_path=limits)
    except StationError as exc:
        raise fail(exc) from None
    raise typer.Exit(result.outcome.exit_code)


def sim(
    units: Annotated[int, typer.Option(min=1, max=64, help="simulated sensors")] = 4,
    scale: Annotated[float, typer.Option(min=0.1, help="simulated seconds per wall second")] = 1.0,
    seed: Annotated[int, typer.Option(min=0, max=2**63 - 1, help="seed: the same seed gives the same units")] = 0,
    port: Annotated[int, typer.Option(min=0, max=65535, help="Modbus/TCP port of the rig (0: a free port)")] = 0,
    chamber: Annotated[bool, typer.Option("--chamber", help="also serve a simulated climate chamber (Modbus/TCP "
                                          "on a free port); the units' temperature follows it")] = False,
) -> None:
    """Start a simulated rig and sensors, print their URLs, run until Ctrl-C (or SIGTERM).

    Each simulated unit runs the calibration firmware (Algorithm 1 from its EEPROM image), as a real
    unit does, so ``station run`` against it provisions and verifies the corrected output.
    """
    import signal
    import threading

    from station.sim.firmware import install_firmware
    from station.sim.station_sim import SimStation

    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())

    with SimStation(units, scale, seed, port=port, chamber={} if chamber else None) as station:
        for unit in station.units:
            install_firmware(unit.sensor, station.clock)
        sys.stdout.flush()
        typer.echo(f"rig: {station.rig_url}")
        if station.chamber is not None:
            typer.echo(f"chamber: {station.chamber_url}")
        for unit in station.units:
            typer.echo(f"sensor {unit.slot}: {unit.sensor.url} (serial {unit.truth.serial})")
        args = " ".join(f"--sensor {u}" for u in station.sensor_urls)
        typer.echo(f"run the sequence with:\n  station run --rig '{station.rig_url}' {args} --scale {scale:g}")
        typer.echo("Ctrl-C stops the simulation.")
        sys.stdout.flush()
        try:
            while not stop.wait(0.5):
                pass
        except KeyboardInterrupt:
            pass
        typer.echo("stopped")


def register(app: typer.Typer) -> None:
    """Add ``simulate``, ``demo`` and ``sim`` to the ``station`` command."""
    app.command()(simulate)
    app.command()(demo)
    app.command()(sim)
