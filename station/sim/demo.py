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

At the default clock scale (30 simulated seconds per wall second) the sequence
takes about 30 s of wall time; fits and set-up add a few seconds per unit.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from pathlib import Path

from rich.console import Console

from station.compose import Station, StationConfig
from station.kernel.plan import RigPlan, default_plan
from station.physics.effects import Effects
from station.sequence.options import SequenceOptions
from station.sequence.provision import ProvisionRecord
from station.sequence.records import Record
from station.sequence.runner import RunResult
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
    """
    console = console if console is not None else Console()
    plan = plan if plan is not None else default_plan()
    wall0 = time.monotonic()
    with SimStation(units, scale, seed, plan=plan, effects=effects) as sim:
        for u in sim.units:
            install_firmware(u.sensor, sim.clock)
        console.print(f"simulated rig at {sim.rig_url}; {units} sensor(s) on "
                      f"{', '.join(u.sensor.device for u in sim.units)}; clock x{scale:g}")
        config = StationConfig(
            sim.rig_url, tuple(sim.sensor_urls), station_id="demo", db_url=db_url, record=record,
            limits_path=limits_path, out_dir=out_dir, clock_scale=scale, plan=plan, provision=provision,
            rig_options=sim.rig_client_options(),
        )
        display = ProgressDisplay(console, [u.truth.serial for u in sim.units], scale)
        station = Station(config, clock=sim.clock, options=options, subscribers=[display, *subscribers],
                          admit=admit, on_provision=on_provision)
        with display:
            result = station.run()
    console.print(summary_table(result))
    if station.provisioner is not None and station.provisioner.records:
        console.print(provisioning_table(station.provisioner))
    limits = station.limits
    console.print(f"limits: {limits.name} {limits.version} ({limits.path})")
    if out_dir is not None:
        console.print(f"recordings in {out_dir}/")
    console.print(f"demo finished in {time.monotonic() - wall0:.1f} s wall time")
    return result


__all__ = ["DEMO_OUT", "DEMO_SCALE", "DEMO_UNITS", "run_demo"]
