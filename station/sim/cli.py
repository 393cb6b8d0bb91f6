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
from station.kernel.line_plan import ANY_ORIENTATION, LinePlan


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
    scale: Annotated[float | None, typer.Option(min=0.1, help="simulated seconds per wall second of the scaled "
                                                "clock (default 30, with --thermal 120); giving it selects that "
                                                "clock")] = None,
    seed: Annotated[int, typer.Option(min=0, max=2**63 - 1, help="seed: the same seed gives the same units")] = 0,
    out: Annotated[Path, typer.Option(help="directory for session CSVs and parameter JSONs")] = Path("demo-out"),
    db: DbOption = None,
    limits: Annotated[Path | None, typer.Option("--limits", help="limits file (default: fixtures/limits/default.toml)")]
    = None,
    thermal: Annotated[bool, typer.Option("--thermal", help="thermal calibration in a simulated climate chamber: "
                                          "plateaus at 5/15/25/45 degC, verification at 35 degC; the last unit has "
                                          "no temperature effects (the reference)")] = False,
    rig_only: Annotated[bool, typer.Option("--rig-only", help="the single rig alone: power-on rest, six poses and "
                                           "18 rate steps on the rig (about 15 simulated minutes), no rack")] = False,
    line: Annotated[bool, typer.Option("--line", hidden=True, help="the calibration line (the default)")] = False,
    rack_s: Annotated[float, typer.Option("--rack-s", min=60.0, help="the line: rest in the rack from power-on "
                                          "(simulated s)")] = 1200.0,
    plan: Annotated[Path | None, typer.Option("--plan", help="the line: a plan file written by `station plan` "
                                              "(default: the built-in line plan)")] = None,
    lot: Annotated[str | None, typer.Option("--lot", help="production lot of the units, recorded with the run "
                                                          "(quality page filter, certificate)")] = None,
    operator: Annotated[str | None, typer.Option(help="operator name for the records")] = None,
    clock: Annotated[str, typer.Option("--clock", help="'virtual' (default without --scale): discrete-event "
                                       "time, the same seed gives the same bytes under any load; 'scaled': "
                                       "simulated time runs --scale times the wall clock (the line demo picks "
                                       "its own scale, at most 30, without --scale)")] = "",
) -> None:
    """The calibration line, simulated end to end: rack, rig, fit, limits, EEPROM, summary.

    The units soak in a simulated rack (relay board on Modbus/TCP, sensors on ptys) from power-on, go powered to
    the simulated rig for the line plan's poses and rate steps, are fitted over both recordings, written and
    verified; both roles share the database (``--db``). It prints ``rig time per unit`` (simulated seconds).
    It runs on the virtual clock (the same seed gives the same bytes); ``--clock scaled`` runs it on a scaled
    clock (``--scale``; the line picks its own, at most 30, without it).

    With ``--rig-only`` the single rig runs the whole default sequence (warm-up on the rig), as before the line.

    With ``--thermal`` a simulated climate chamber (Modbus/TCP) joins: the units carry temperature bias and
    scale coefficients, are calibrated at four temperatures and verified at a fifth, and a table compares
    the corrected errors there with and without the thermal model.

    Exit code: 0 all PASS, 1 a unit FAILed, 2 ERROR (station fault), 3 a unit REFUSED by the retest
    policy, 4 a unit to RETEST (inconclusive verdict), 130 ABORTED (Ctrl-C, SIGTERM, SIGHUP).
    """
    from station.kernel.clock import SimClock
    from station.kernel.virtual_clock import VirtualClock
    from station.sequence.prompts import AutoConfirm
    from station.sim.demo import DEMO_SCALE, THERMAL_SCALE, run_demo, run_line_demo, run_thermal_demo

    if rig_only and (line or thermal):
        raise fail(StationError("--rig-only is the single rig alone: not with --line or --thermal"))
    mode = clock or ("scaled" if scale is not None else "virtual")
    if mode not in ("virtual", "scaled"):
        raise fail(StationError(f"--clock {clock!r}: 'virtual' or 'scaled'"))
    if mode == "virtual" and scale is not None:
        raise fail(StationError("--scale sets the speed of the scaled clock: give --clock scaled (or no --scale)"))
    try:
        if not rig_only and not thermal:
            # scaled without --scale: the line picks its scale from the sensors' frame rate (at most 30)
            line_clock = VirtualClock() if mode == "virtual" else SimClock(scale) if scale is not None else None
            result = run_line_demo(units, rack_s, seed, limits_path=limits, out_dir=out, db_url=db, plan_path=plan,
                                   lot=lot or "", operator=operator or "", prompter=AutoConfirm("the demo"),
                                   clock=line_clock)
        elif thermal:
            thermal_clock = VirtualClock() if mode == "virtual" else SimClock(scale or THERMAL_SCALE)
            result, _ = run_thermal_demo(units, thermal_clock.scale, seed, out, db_url=db, record=True,
                                         limits_path=limits, lot=lot or "", operator=operator or "",
                                         clock=thermal_clock)
        else:  # the simulated fixture loads itself: its prompts are shown and confirmed at once
            sim_clock = VirtualClock() if mode == "virtual" else SimClock(scale or DEMO_SCALE)
            result = run_demo(units, sim_clock.scale, seed, out, db_url=db, record=True, limits_path=limits,
                              lot=lot or "", operator=operator or "", prompter=AutoConfirm("the demo"), clock=sim_clock)
    except StationError as exc:
        raise fail(exc) from None
    except KeyboardInterrupt:
        typer.echo("aborted before the run started; nothing was moved or written", err=True)
        raise typer.Exit(130) from None
    raise typer.Exit(result.outcome.exit_code)


def sim(
    units: Annotated[int, typer.Option(min=1, max=64, help="simulated sensors")] = 4,
    scale: Annotated[float, typer.Option(min=0.1, help="simulated seconds per wall second")] = 1.0,
    seed: Annotated[int, typer.Option(min=0, max=2**63 - 1, help="seed: the same seed gives the same units")] = 0,
    port: Annotated[int, typer.Option(min=0, max=65535, help="Modbus/TCP port of the rig (0: a free port)")] = 0,
    chamber: Annotated[bool, typer.Option("--chamber", help="also serve a simulated climate chamber (Modbus/TCP "
                                          "on a free port); the units' temperature follows it")] = False,
    clock: Annotated[str, typer.Option("--clock", help="'scaled' (default): simulated time runs --scale times the "
                                       "wall clock, as real hardware does; 'virtual': a discrete-event clock served "
                                       "on 127.0.0.1 (`station run --clock virtual://...`): the same seed gives the "
                                       "same bytes")] = "scaled",
) -> None:
    """Start a simulated rig and sensors, print their URLs, run until Ctrl-C (or SIGTERM).

    Each simulated unit runs the calibration firmware (Algorithm 1 from its EEPROM image), as a real
    unit does, so ``station run`` against it provisions and verifies the corrected output.

    With ``--clock virtual`` this process owns a virtual clock and serves it; the station's threads become its
    actors, so time moves only when all of them wait (docs/simulation.md).
    """
    import contextlib
    import signal
    import threading

    from station.kernel.clock import Clock, SimClock
    from station.kernel.virtual_clock import VirtualClock
    from station.sim.firmware import install_firmware
    from station.sim.station_sim import SimStation
    from station.timelink import ClockServer

    if clock not in ("scaled", "virtual"):
        raise fail(StationError(f"--clock {clock!r}: 'scaled' or 'virtual'"))
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())

    sim_clock: Clock = VirtualClock() if clock == "virtual" else SimClock(scale)
    with contextlib.ExitStack() as stack:
        served = stack.enter_context(ClockServer(sim_clock)) if isinstance(sim_clock, VirtualClock) else None
        station = stack.enter_context(SimStation(units, scale, seed, port=port, chamber={} if chamber else None,
                                                 clock=sim_clock))
        for unit in station.units:
            install_firmware(unit.sensor, station.clock)
        sys.stdout.flush()
        typer.echo(f"rig: {station.rig_url}")
        if station.chamber is not None:
            typer.echo(f"chamber: {station.chamber_url}")
        for unit in station.units:
            typer.echo(f"sensor {unit.slot}: {unit.sensor.url} (serial {unit.truth.serial})")
        args = " ".join(f"--sensor {u}" for u in station.sensor_urls)
        timing = f"--clock {served.url}" if served is not None else f"--scale {scale:g}"
        if served is not None:
            typer.echo(f"clock: {served.url}")
        typer.echo(f"run the sequence with:\n  station run --rig '{station.rig_url}' {args} {timing}")
        typer.echo("Ctrl-C stops the simulation.")
        sys.stdout.flush()
        try:
            while not stop.wait(0.5):
                pass
        except KeyboardInterrupt:
            pass
        typer.echo("stopped")


def _held(line_plan: LinePlan) -> str:
    """How the plan's rack holds its units, for people."""
    if line_plan.rack_orientation == ANY_ORIENTATION:
        return "units in any orientation"
    return f"units {line_plan.rack_orientation} up within {line_plan.rack_tilt_tolerance_deg:g} deg"


def plan(
    limits: Annotated[Path | None, typer.Option("--limits", help="limits file (default: fixtures/limits/default.toml)")]
    = None,
    out: Annotated[Path, typer.Option(help="where the plan file goes")] = Path("line-plan.json"),
    rig_units: Annotated[int, typer.Option("--rig-units", min=1, max=64, help="units per rig run")] = 16,
    rack_slots: Annotated[int, typer.Option("--rack-slots", min=1, max=64, help="slots of the soak rack")] = 64,
    units: Annotated[int, typer.Option("--units", min=1, max=20, help="simulated units per candidate")] = 3,
    match_full: Annotated[float | None, typer.Option("--match-full", min=1.0, help="also keep the median stated "
                                                     "std of M and b_stat within this factor of the full rig "
                                                     "plan's on the same units")] = None,
    rack_orientation: Annotated[str, typer.Option("--rack-orientation", help="how the rack holds its units: 'any' "
                                                  "(any fixed orientation, unknown) or a pose such as '+z' (every "
                                                  "slot that axis up, e.g. on its base: the fit ties the rest's "
                                                  "level along gravity to its norm)")] = "any",
    rack_tilt_tolerance: Annotated[float, typer.Option("--rack-tilt-tolerance", help="with a pose: the largest "
                                                       "tilt of a unit's rest against it (deg); farther is "
                                                       "refused")] = 5.0,
) -> None:
    """The shortest line plan (rig part and rack time) whose predicted accuracy meets the limits file.

    Each candidate is predicted from the joint fit's stated uncertainties on simulated units of the sensor
    class; prints every candidate, the chosen plan's rig time, units per hour of rig, rack and line, and writes
    the plan file (``station-line-plan/1``).
    """
    from station.kernel.limits_file import load_limits
    from station.kernel.line_plan import line_plan_to_json
    from station.sim.plan_design import design, throughput

    try:
        LinePlan(rack_orientation=rack_orientation, rack_tilt_tolerance_deg=rack_tilt_tolerance)  # refused here
        lim = load_limits(limits)
        best, tried = design(lim, seeds=tuple(range(31, 31 + units)), match_full=match_full,
                             rack_orientation=rack_orientation, rack_tilt_tolerance_deg=rack_tilt_tolerance)
    except StationError as exc:
        raise fail(exc) from None
    typer.echo("rack s | pose hold s | rig s (predicted) | largest stated std / limit | gyro T_c resolved | meets")
    for c in tried:
        worst = ", ".join(f"{k} {v:.2f}" for k, v in c.worst.items())
        typer.echo(f"{c.plan.rack_s:6.0f} | {c.plan.rig.pose_hold_s:11.0f} | {c.rig_s:17.0f} | {worst} | "
                   f"{'yes' if c.gyro_tc_resolved else 'no'} | {'yes' if c.meets else 'no'}")
    if best is None:
        typer.echo("no candidate meets the limits")
        raise typer.Exit(1)
    t = throughput(best, rig_units, rack_slots)
    out.write_text(line_plan_to_json(best.plan) + "\n")
    typer.echo(f"chosen: rack {best.plan.rack_s:.0f} s ({_held(best.plan)}), poses {best.plan.rig.pose_hold_s:.0f} s; "
               "rig time per run "
               f"{best.rig_s:.0f} s, per unit at N={rig_units} {t.rig_per_unit_s:.0f} s")
    typer.echo(f"units/h: rig {t.rig_units_per_h:.0f}, rack ({rack_slots} slots) {t.rack_units_per_h:.0f}, "
               f"line {t.line_units_per_h:.0f}")
    typer.echo(f"wrote {out}")
def msa_simulate(
    parts: Annotated[int, typer.Option(min=2, max=100, help="parts (simulated units) in the study")] = 10,
    nests: Annotated[int, typer.Option(min=2, max=16, help="nests of the rig (the appraisers)")] = 4,
    repeats: Annotated[int, typer.Option(min=2, max=10, help="measurements of every part in every nest")] = 3,
    seed: Annotated[int, typer.Option(min=0, max=2**63 - 1, help="seed of the parts and the nests' errors")] = 0,
    scale: Annotated[float, typer.Option(min=1.0, max=600.0, help="simulated seconds per wall second")] = 120.0,
    nest_error: Annotated[float, typer.Option(min=0.0, max=5.0, help="std (deg) of the nests' mounting errors "
                                              "about each axis (0: perfect nests)")] = 0.3,
    nest_cal: Annotated[bool, typer.Option("--nest-cal", help="first run a reference unit in every nest, "
                                           "estimate the nests and store them: the study then runs with them")]
    = False,
    lot: Annotated[str, typer.Option(help="the study's lot in the records")] = "msa-study",
    as_json: Annotated[bool, typer.Option("--json", help="print the study as JSON (station-msa/1)")] = False,
    db: DbOption = None,
) -> None:
    """Run a crossed Gage R&R study (parts x nests x repeats) on the simulated station and report it.

    Every run is the station's own sequence and fit, recorded under ``--lot``; the report is
    ``station msa report --lot LOT`` of those records. The simulated rig's nests carry mounting errors
    drawn from ``--seed`` (``--nest-error`` deg per axis); ``--nest-cal`` calibrates them out first.
    """
    import json as json_module

    from station.commands.msa import print_report, study_report
    from station.commands.nest_cal import describe, estimate_from_records
    from station.sim.msa_study import StudyDesign, run_nest_calibration, run_study
    from station.store.db import database_url

    try:
        db_url = database_url(db)
        design = StudyDesign(parts, nests, repeats, seed)
        rng = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(77,)))
        errors = [tuple(float(v) for v in rng.normal(0.0, nest_error, 3)) for _ in range(nests)]
        station_id = "msa-sim"
        rig_key = f"fake-rig://{station_id}"

        def progress(k: int, n: int, result: object) -> None:
            outcomes = ", ".join(u.outcome.value for u in getattr(result, "units", ()))
            typer.echo(f"  run {k + 1}/{n}: {outcomes}", err=True)

        typer.echo(f"nests' mounting errors (deg, x/y/z): {errors}", err=True)
        if nest_cal:
            typer.echo(f"nest calibration: the reference unit in each of {nests} nests", err=True)
            serial, _, lab = run_nest_calibration(nests, db_url, seed=seed, scale=scale,
                                             nest_errors_deg=errors, station_id=station_id, on_run=progress)
            cal = estimate_from_records(db_url, rig_key, serial, reference=lab)
            for line in describe(cal):
                typer.echo(line, err=True)
        typer.echo(f"study: {parts} parts x {nests} nests x {repeats} repeats = "
                   f"{len(design.schedule())} runs", err=True)
        run_study(design, db_url, lot, scale=scale, nest_errors_deg=errors,
                  station_id=station_id, on_run=progress, nest_calibration=nest_cal)
        report = study_report(db_url, lot=lot)
    except StationError as exc:
        raise fail(exc) from None
    if as_json:
        sys.stdout.write(json_module.dumps(report.to_json(), indent=2) + "\n")
    else:
        print_report(report)


def register(app: typer.Typer) -> None:
    """Add ``simulate``, ``demo``, ``sim`` and ``plan`` to the ``station`` command."""
    app.command()(simulate)
    app.command()(demo)
    app.command()(sim)
    app.command()(plan)
    from station.commands.msa import msa_app

    msa_app.command("simulate")(msa_simulate)
