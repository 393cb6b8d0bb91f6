"""``station demo``: a whole simulated station, end to end, in one command.

:func:`run_demo` starts a simulated rig (real Modbus/TCP server on 127.0.0.1) and N
simulated sensors (real ptys) on one simulated clock, opens them with the same
client code a real station uses, runs the default sequence (300 s power-on rest,
six 30 s poses, 18 rate steps of 12 s: about 15 minutes of rig time) for all units
concurrently, fits each unit, checks the limits of the limits file (default
``fixtures/limits/default.toml``: Table 1 ranges and fit quality), saves every session
CSV and parameter JSON, writes each PASS unit's calibration image into its simulated
EEPROM (:class:`~station.sequence.provision.EepromProvisioner`), lets the unit's firmware
(:mod:`station.sim.firmware`, Algorithm 1) load it, verifies the corrected output on the
rig (:class:`~station.sequence.verify.RigVerifier`), and prints a live progress display,
a summary table and the verification residuals.

``station demo --rig-only`` runs it on a :class:`~station.kernel.virtual_clock.VirtualClock` (the same
seed gives the same bytes under any load; docs/simulation.md): the sequence takes what its work costs, about
10 s of wall time on an idle machine; on the scaled clock (``station demo --rig-only --clock scaled``) about 30 s.

SIGTERM and SIGHUP do what Ctrl-C does, as in ``station run`` (:func:`station.compose.abort_on_signals`): the
run ends ABORTED with the signal's name, the rig at rest, every unit's result recorded (none UNFINISHED).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, fields, replace
from pathlib import Path
from typing import Any

import numpy as np
from rich.console import Console

from station.compose import Station, StationConfig, abort_on_signals
from station.fit.calibrate import FitOptions
from station.kernel.clock import Clock, SimClock
from station.kernel.display import limits_identity
from station.kernel.plan import RigPlan, default_plan
from station.kernel.thermal_plan import ThermalPlan
from station.kernel.virtual_clock import acting, is_virtual
from station.physics.effects import Effects
from station.sequence.options import SequenceOptions
from station.sequence.prompts import Operator
from station.sequence.provision import ProvisionRecord
from station.sequence.records import Record
from station.sequence.runner import RunResult, SequenceRunner
from station.sim.firmware import install_firmware
from station.sim.station_sim import SimStation
from station.terminal import ProgressDisplay, provisioning_table, summary_table

DEMO_UNITS = 4
DEMO_SCALE = 30.0
DEMO_OUT = Path("demo-out")


def run_demo(
    units: int = DEMO_UNITS,
    scale: float = DEMO_SCALE,
    seed: int = 0,
    out_dir: Path | None = DEMO_OUT,
    *,
    plan: RigPlan | None = None,
    effects: Effects | None = None,
    options: SequenceOptions | None = None,
    console: Console | None = None,
    limits_path: Path | None = None,
    provision: bool = True,
    db_url: str | None = None,
    record: bool = False,
    subscribers: Sequence[Callable[[Record], None]] = (),
    on_provision: Callable[[ProvisionRecord], None] | None = None,
    admit: Callable[[str, str], str | None] | None = None,
    lot: str = "",
    operator: str = "",
    prompter: Operator | None = None,
    clock: Clock | None = None,
) -> RunResult:
    """Start the simulated station, run the sequence for ``units`` units at clock ``scale``, print, return.

    The station itself is the composition root's (:class:`station.compose.Station`), given the
    simulated peers' URLs: the same code as ``station run`` against real hardware.

    Args:
        units: sensors in the fixture.
        scale: simulated seconds per wall second.
        seed: the same seed gives the same units.
        out_dir: where session CSVs and parameter JSONs go (None: not saved).
        plan: the sequence (default: :func:`station.kernel.plan.default_plan`).
        effects: optional physics of the simulated units.
        options: sequence options (polling is adapted to ``scale``).
        console: where to print (default: stdout).
        limits_path: limits file (default ``fixtures/limits/default.toml``).
        provision: write each PASS unit's image into its EEPROM and verify its corrected output.
        db_url, record: record the run in the database at ``db_url`` (None: the default database)
            when ``record``; the store's retest gate then applies.
        subscribers: more record subscribers (called after the progress display).
        on_provision: called with each unit's EEPROM write and verification record.
        admit: the retest policy (see :class:`~station.sequence.runner.SequenceRunner`).
        lot, operator: the production lot and the operator recorded with the run ('' none).
        prompter: answers the station's prompts (None: a run without prompts).
        clock: the clock of the simulated station and the station (default ``SimClock(scale)``); a
            :class:`~station.kernel.virtual_clock.VirtualClock` makes the run repeat bit for bit.

    In the main thread SIGTERM and SIGHUP abort the run as Ctrl-C does (the result is ABORTED); a signal before
    the run started raises :class:`KeyboardInterrupt`.
    """
    console = console if console is not None else Console()
    plan = plan if plan is not None else default_plan()
    wall0 = time.monotonic()
    runners: list[SequenceRunner] = []
    clock = clock if clock is not None else SimClock(scale)
    # on a virtual clock this thread owns time from the start: none passes while the station is set up
    with abort_on_signals(lambda: runners[-1] if runners else None), acting(clock, name="demo"), \
            SimStation(units, scale, seed, plan=plan, effects=effects, clock=clock) as sim:
        for u in sim.units:
            install_firmware(u.sensor, sim.clock)
        console.print(f"simulated rig at {sim.rig_url}; {units} sensor(s) on "
                      f"{', '.join(u.sensor.device for u in sim.units)}; {clock_words(sim.clock)}")
        config = StationConfig(
            sim.rig_url, tuple(sim.sensor_urls), station_id="demo", db_url=db_url, record=record,
            limits_path=limits_path, out_dir=out_dir, clock_scale=sim.scale, plan=plan, provision=provision,
            rig_options=sim.rig_client_options(), sensor_options=sim.sensor_client_options(), lot=lot,
            operator=operator,
        )
        display = ProgressDisplay(console, [u.truth.serial for u in sim.units], sim.scale)
        station = Station(config, clock=sim.clock, options=options, subscribers=[display, *subscribers],
                          admit=admit, on_provision=on_provision, prompter=prompter)
        with display:
            result = station.run(on_runner=runners.append)
    console.print(summary_table(result))
    if station.provisioner is not None and station.provisioner.records:
        console.print(provisioning_table(station.provisioner))
    limits = station.limits
    console.print(f"limits: {limits_identity(f'{limits.name} {limits.version}', limits.sha256)} ({limits.path})")
    if out_dir is not None:
        console.print(f"recordings in {out_dir}/")
    console.print(f"demo finished in {time.monotonic() - wall0:.1f} s wall time")
    return result


def clock_words(clock: Clock) -> str:
    """How the demo's clock runs, for its first line."""
    if is_virtual(clock):
        return "virtual clock (discrete events: the same seed gives the same bytes)"
    return f"clock x{clock.scale:g}"



# --- the line demo: warm-up in a soak rack, poses and rates on the rig ---------------------------------

LINE_UNITS = 2
LINE_RACK_S = 1200.0
#: total sample frames per wall second the simulated sensors may produce (sets the clock scale)
LINE_MAX_FRAMES = 12000.0


def run_line_demo(
    units: int = LINE_UNITS,
    rack_s: float = LINE_RACK_S,
    seed: int = 0,
    *,
    transfer_s: float = 30.0,
    console: Console | None = None,
    limits_path: Path | None = None,
    max_frames: float = LINE_MAX_FRAMES,
    interrupt: Sequence[int] = (),
    out_dir: Path | None = DEMO_OUT,
    db_url: str | None = None,
    plan_path: Path | None = None,
    lot: str = "",
    operator: str = "",
    prompter: Operator | None = None,
    clock: Clock | None = None,
) -> RunResult:
    """The calibration line, simulated: ``units`` units soak ``rack_s`` in a rack (relay board on Modbus/TCP,
    sensors on ptys, each still in its slot's orientation), are carried powered to the rig (``transfer_s``), run
    the line plan's rig part there (``plan_path``: a file of ``station plan``; default the built-in line plan)
    and are fitted over both recordings; prints the run and ``rig time per unit: <seconds> s`` (simulated
    seconds of rig time divided by the units).

    Both roles share the database at ``db_url`` (None: the default database): the rack stores its recordings
    (``rack_recordings``), the rig role is the composition root's (:class:`station.compose.Station` with
    ``line``: the rig lock, the run tables with the plan file's SHA-256, every PASS unit's EEPROM written,
    read back and verified on the rig). On the default scaled clock the scale is chosen so the sensors send at
    most ``max_frames`` frames per wall second, and at most the plain demo's ``DEMO_SCALE``. The units of the slots in
    ``interrupt`` lose power on the way to the rig: the rig role refuses them (they get the full plan or go
    back to the rack) and says why.

    ``clock``: the line's clock (default ``SimClock`` at that scale); on a
    :class:`~station.kernel.virtual_clock.VirtualClock` this thread is its actor from set-up to the end of the
    rig role's run, and the same seed gives the same recordings and parameter sets under any load
    (docs/simulation.md).
    """
    from station.kernel.line_plan import load_line_plan_file
    from station.line.recordings import DatabaseArchive
    from station.sim.line_station import SimLine
    from station.store.db import open_database

    console = console if console is not None else Console()
    wall0 = time.monotonic()
    line = load_line_plan_file(plan_path)
    plan = line.rig_plan()
    if clock is None:
        clock = SimClock(max(1.0, min(DEMO_SCALE, max_frames / (units * plan.sample_rate_hz))))
    scale = clock.scale
    runners: list[SequenceRunner] = []
    # on a virtual clock this thread owns time from the start: none passes while the line is set up, and the
    # soak, the transfer and the rig role's run each let it pass only through the clock's waits
    with abort_on_signals(lambda: runners[-1] if runners else None), acting(clock, name="demo"), \
            SimLine(units, scale, seed, plan, clock=clock, rack_orientation=line.plan.rack_orientation) as sim:
        console.print(f"soak rack: relay board at {sim.board_url}, {units} unit(s) on "
                      f"{', '.join(u.sensor.device for u in sim.sim.units)}; {clock_words(clock)}; "
                      f"{rack_s:g} s from power-on")
        with open_database(db_url) as database:
            soaked = sim.soak(range(units), rack_s, DatabaseArchive(database.sessions), station="demo-rack")
        for r in soaked.units:
            if r.session is not None:
                console.print(f"  slot {r.slot}: {r.serial} {len(r.session)} samples"
                              + (f"; {r.note}" if r.note else ""))
            else:
                console.print(f"  slot {r.slot}: {r.serial or '?'} no recording: {r.error}")
        # carried to the rig, still powered (the relay stays on: the unit's supply travels with it)
        sim.to_rig(range(units), transfer_s, interrupt)
        config = sim.rig_config(range(units), line, db_url=db_url, out_dir=out_dir, station_id="demo-line",
                                limits_path=limits_path, lot=lot, operator=operator)
        display = ProgressDisplay(console, [u.truth.serial for u in sim.sim.units], scale)
        station = Station(config, clock=sim.clock, subscribers=[display], prompter=prompter)
        with display:
            result = station.run(on_runner=runners.append)
    for serial, d in getattr(runners[-1], "decisions", {}).items():
        console.print(f"  {serial}: {d.plan}{' (' + d.reason + ')' if d.reason else ''}")
    console.print(summary_table(result))
    if station.provisioner is not None and station.provisioner.records:
        console.print(provisioning_table(station.provisioner))
    for unit in result.units:
        if unit.params is not None:
            extra = unit.params.quality.extra.get("line", {})
            tc = unit.params.gyro.correlation_time_s
            console.print(f"  {unit.serial}: rack {extra.get('rack_span_s', 0):.0f} s + rig; gyro T_c "
                          f"{', '.join('-' if not np.isfinite(v) else f'{v:.0f}' for v in tc)} s")
    console.print(f"plan {line.version}, sha256 {line.sha256[:12]}")
    if out_dir is not None:
        console.print(f"recordings in {out_dir}/")
    console.print(f"rig time per unit: {result.sequence_s / max(units, 1):.0f} s")
    verify_s = float(getattr(runners[-1], "verify_s", 0.0)) if runners else 0.0
    console.print(f"with write and verification: {(result.sequence_s + verify_s) / max(units, 1):.0f} s "
                  f"({verify_s:.0f} s per batch)")
    console.print(f"line demo finished in {time.monotonic() - wall0:.1f} s wall time")
    return result


# --- the thermal demo ---------------------------------------------------------------------------------

THERMAL_SCALE = 120.0
#: Temperature effects of the demo's units: bias 0.005 m/s^2/K times the unit's shape (0.25-0.5 mg/K; gyro
#: 5 x that in deg/s/K: 0.0125-0.025 deg/s/K), scale 200 ppm/K times the shape (100-200 ppm/K).
THERMAL_EFFECTS = Effects(temperature_bias=0.005, temperature_scale=200.0)


def thermal_demo_plan() -> ThermalPlan:
    """Plateaus at 5, 15, 25, 45 degC (six poses, +-100 deg/s about each axis), a raw check and the
    verification at 35 degC, 50 Hz. Four temperatures: the fit chooses polynomial orders up to 3 per axis, which
    three plateaus leave no freedom to check."""
    base = RigPlan(sample_rate_hz=50.0, rest_s=300.0, pose_hold_s=20.0, rate_hold_s=10.0, settle_s=1.0)
    steps = tuple((axis, sign * 100.0) for axis in "xyz" for sign in (1.0, -1.0))
    return ThermalPlan(base=base, plateaus_degc=(5.0, 15.0, 25.0, 45.0), rate_steps=steps, verify_degc=35.0,
                       raw_check=True, soak_rate_k_per_min=0.1, soak_window_s=120.0, soak_poll_s=20.0)


@dataclass(frozen=True)
class CheckErrors:
    """Corrected errors over a check recording's windows: worst pose specific-force error (m/s^2), worst
    static rate (rad/s), worst rate-step error relative to the rate (1)."""

    pose_accel_mps2: float
    pose_gyro_radps: float
    rate_rel: float


def check_errors(session: Any, params: Any, skip_s: float = 1.5) -> CheckErrors:
    """Run Algorithm 1 (``station correct``) with ``params`` over a check recording and measure the window
    means against the rig's references (the first ``skip_s`` of a window, the moving average's span, skipped)."""
    from station.correct.session_correct import correct_session
    from station.session.model import Kind

    corrected = correct_session(session, params)
    skip = round(skip_s * session.sample_rate_hz)
    acc, gyr, rel = 0.0, 0.0, 0.0
    for seg in corrected.segments_of(Kind.POSE, Kind.RATE):
        sl = slice(seg.start + skip, seg.stop)
        if sl.stop - sl.start < 10:
            continue
        a = corrected.accel_mps2[sl].mean(axis=0) - corrected.ref_accel_mps2[seg.start]
        w = corrected.gyro_radps[sl].mean(axis=0) - corrected.ref_gyro_radps[seg.start]
        if seg.kind == Kind.POSE:
            acc = max(acc, float(np.max(np.abs(a))))
            gyr = max(gyr, float(np.max(np.abs(w))))
        else:
            ref = corrected.ref_gyro_radps[seg.start]
            k = int(np.argmax(np.abs(ref)))
            rel = max(rel, abs(float(w[k])) / abs(float(ref[k])))
    return CheckErrors(acc, gyr, rel)


def target_lines(errors: dict[tuple[int, str], CheckErrors]) -> list[str]:
    """The thermal demo's targets per unit with temperature effects: corrected errors with the thermal model within
    2x of the reference unit's (no temperature effects) and at least 10x better than without the model."""
    refs = [e for (_, label), e in errors.items() if label == "reference"]
    if not refs:
        return ["no reference unit: the targets cannot be judged"]
    ref = refs[0]
    out = []
    for slot in sorted({s for s, label in errors if label != "reference"}):
        wo, th = errors.get((slot, "without")), errors.get((slot, "thermal model"))
        parts = []
        for name, attr in (("pose accel", "pose_accel_mps2"), ("pose gyro", "pose_gyro_radps"),
                           ("rate step", "rate_rel")):
            r0 = getattr(ref, attr)
            text = f"{name}: without/reference {getattr(wo, attr) / r0:.1f}x" if wo is not None else name
            if th is not None:
                text += (f", thermal/reference {getattr(th, attr) / r0:.2f}x (target <= 2), without/thermal "
                         f"{getattr(wo, attr) / getattr(th, attr):.1f}x (target >= 10)" if wo is not None else "")
            parts.append(text)
        out.append(f"slot {slot}: " + "; ".join(parts))
    return out


def _without_thermal(options: FitOptions) -> FitOptions | None:
    """The fit's options with its thermal model switched off (None: the fit has no thermal model)."""
    names = {f.name for f in fields(FitOptions)}
    return replace(options, thermal="off") if "thermal" in names else None


def _thermal_note(params: Any) -> tuple[bool, str]:
    """(the parameter set carries fitted temperature terms, why not)."""
    note = getattr(params, "thermal", None)
    if note is None:
        return False, "the fit has no thermal model"
    if note.reason:
        return bool(getattr(note, "fitted", False)), f"{note.status}: {note.reason}"
    return bool(getattr(note, "fitted", False)), f"status {note.status}; awaits the thermal fit"


def run_thermal_demo(
    units: int = DEMO_UNITS,
    scale: float = THERMAL_SCALE,
    seed: int = 0,
    out_dir: Path | None = DEMO_OUT,
    *,
    thermal: ThermalPlan | None = None,
    effects: Effects = THERMAL_EFFECTS,
    reference_unit: bool = True,
    console: Console | None = None,
    limits_path: Path | None = None,
    db_url: str | None = None,
    record: bool = False,
    lot: str = "",
    operator: str = "",
    clock: Clock | None = None,
) -> tuple[RunResult, Any]:
    """``station demo --thermal``: a simulated rig, chamber and ``units`` sensors; the thermal plan
    (:func:`thermal_demo_plan`), fit, EEPROM write, verification at the verification temperature; prints the
    run, the cycle time and, per unit, the corrected errors at the verification temperature with the thermal
    model and without, next to a unit without temperature effects (the last slot when ``reference_unit``).

    ``clock``: as for :func:`run_demo` (default ``SimClock(scale)``; a virtual clock repeats bit for bit).

    Returns the run's result and the runner (its check recordings, verification results and timing).
    """
    from station.fit.calibrate import fit_session

    console = console if console is not None else Console()
    thermal = thermal if thermal is not None else thermal_demo_plan()
    plan = thermal.base
    unit_effects: list[Effects | None] = [None] * units
    if reference_unit and units > 1:
        unit_effects[-1] = Effects()
    wall0 = time.monotonic()
    holder: list[Any] = []
    clock = clock if clock is not None else SimClock(scale)
    with abort_on_signals(lambda: holder[-1] if holder else None), acting(clock, name="demo"), \
            SimStation(units, scale, seed, plan=plan, effects=effects, chamber={"ambient_degc": thermal.ambient_degc},
                       unit_effects=unit_effects, clock=clock) as sim:
        for u in sim.units:
            install_firmware(u.sensor, sim.clock)
        console.print(f"simulated rig at {sim.rig_url}; chamber at {sim.chamber_url}; {units} sensor(s); "
                      f"{clock_words(sim.clock)}")
        config = StationConfig(
            sim.rig_url, tuple(sim.sensor_urls), station_id="demo-thermal", db_url=db_url, record=record,
            limits_path=limits_path, out_dir=out_dir, clock_scale=sim.scale, provision=True,
            rig_options=sim.rig_client_options(), sensor_options=sim.sensor_client_options(),
            chamber_url=sim.chamber_url, thermal=thermal, lot=lot, operator=operator,
        )
        display = ProgressDisplay(console, [u.truth.serial for u in sim.units], sim.scale)
        station = Station(config, clock=sim.clock, subscribers=[display])
        with display:
            result = station.run(on_runner=holder.append)
        shapes = [(u.source.effects, u.truth) for u in sim.units]
    runner = holder[0]
    thermal_seq = runner.sequence
    console.print(summary_table(result))
    t = thermal_seq.timing
    if t is not None:
        console.print(
            f"cycle time per batch of {t.units}: {t.cycle_s / 60:.1f} min (sequence incl. soaks "
            f"{t.sequence_s / 60:.1f} min, fits {t.fit_wall_s:.1f} s, verification at {thermal_seq.verify_degc:g} degC "
            f"{t.verify_s / 60:.1f} min, chamber back to ambient {t.ambient_s / 60:.1f} min); "
            f"{t.per_unit_s / 60:.1f} min per unit", soft_wrap=True
        )
    header = (f"{'slot':>4}  {'serial':<11} {'tempco: accel mg/K, gyro deg/s/K, scale ppm/K':<46} {'model':<14}"
              f"{'pose accel mg':>14} {'pose gyro deg/s':>16} {'rate step % of rate':>20}  on-rig verify")
    lines = [f"corrected errors at {thermal_seq.verify_degc:g} degC, a temperature the fit did not use (Algorithm 1 "
             f"over the raw check recording; on-rig verify: the unit's own corrected output after writing)", header,
             "-" * len(header)]
    errors: dict[tuple[int, str], CheckErrors] = {}
    off = _without_thermal(station.fit_options)
    for r in result.units:
        session = thermal_seq.check_sessions.get(r.slot)
        eff, truth = shapes[r.slot]
        realized = eff.realize(truth.shapes)
        coeff = (f"{np.max(np.abs(realized.accel_temp_bias)) / 9.80665e-3:.2f}, "
                 f"{np.degrees(np.max(np.abs(realized.gyro_temp_bias))):.4f}, "
                 f"{1e6 * np.max(np.abs(realized.gyro_temp_scale)):.0f} (largest axis)") if eff.temperature_bias \
            else "none (reference unit)"
        verify = runner.verification.get(r.slot)
        verdict = (("PASS" if verify.passed else "FAIL") + f" ({r.outcome.value})") if verify is not None \
            else f"not written ({r.outcome.value})"
        rows: list[tuple[str, Any]] = [("-", None)]
        why = "awaits the thermal fit"
        if session is not None and r.params is not None:
            fitted, why = _thermal_note(r.params)
            if off is None or not fitted:
                rows = [("thermal model", None), ("without", r.params)]
            else:
                without = fit_session(r.session, off) if r.session is not None else None
                rows = [("thermal model", r.params), ("without", without)]
        for k, (label, params) in enumerate(rows):
            if params is None:
                cells = "  " + (f"not fitted ({why})"[:60] if label == "thermal model" else "-")
            else:
                e = check_errors(session, params)
                errors[(r.slot, label if eff.temperature_bias else "reference")] = e
                cells = (f"{e.pose_accel_mps2 / 9.80665e-3:>14.3f} {np.degrees(e.pose_gyro_radps):>16.4f} "
                         f"{100 * e.rate_rel:>20.4f}")
            first = k == 0
            lines.append(f"{r.slot if first else '':>4}  {r.serial if first else '':<11} {coeff if first else '':<46} "
                         f"{label:<14}{cells}  {verdict if first else ''}")
    for line in lines:
        console.print(line, markup=False, highlight=False, soft_wrap=True)
    for line in target_lines(errors):
        console.print(line, markup=False, highlight=False, soft_wrap=True)
    console.print(f"demo finished in {time.monotonic() - wall0:.1f} s wall time")
    return result, runner


__all__ = ["DEMO_OUT", "DEMO_SCALE", "DEMO_UNITS", "THERMAL_SCALE", "run_demo", "run_thermal_demo", "thermal_demo_plan"]
