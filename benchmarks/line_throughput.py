"""Line throughput of a rack and one rig, from the plan designer and from a simulated run (a part of
``bench_line.py``).

Designer: :func:`station.sim.plan_design.throughput` on the plan's predicted rig time per run
(:func:`station.sim.plan_design.rig_time_s`: trajectory + 3 s per step) for ``rig_units`` per run and ``rack_slots``
slots soaking ``rack_s``: rig units/h, rack units/h, line = the smaller.

Simulated run (:class:`station.sim.line_station.SimLine`: the real rack and rig roles, relay board and rig on
Modbus/TCP, sensors on ptys, one simulated clock): ``rack_slots`` units soak together for the plan's ``rack_s``,
then go to the rig in batches of ``rig_units`` (each batch carried in ``load_s``), each batch a rig-role run of the
composition root (``Station`` with the line plan: decisions, rig part, joint fit, limits, EEPROM write and
verification). To keep the wall time small the units sample at ``rate_hz`` (10 Hz instead of 100 Hz): the simulated
seconds, the steps and the counts are those of the real sequence; the fits are cheaper and less exact (units may
fail uncertainty limits they pass at 100 Hz: then fewer are written and verified, which shortens the rig time a
little; the table says how many were), and the fit wants 50 samples in every segment, so the rig's first rest is
held 5 s instead of 2 s and the six rate holds 5 s instead of 3 s (:func:`low_rate`): 15 s more per run than the
plan at 100 Hz. The designer's figures are given for both plans. Rig time of a batch = the sequence until the rig is
at rest + the verification (simulated s) + the fits and saving (wall s of this machine, as on a real station).
Measured throughput: rig units/h = units / sum of the batches' rig times; rack units/h = slots x 3600 / (soak + boot
+ the mean wait of a unit between its soak's end and its batch); line = the smaller (steady state, the rack refilled
as units leave); also the first load's own figure: units / (first power-on .. last batch done), which includes the
first soak.
"""

from __future__ import annotations

import tempfile
import time
from dataclasses import dataclass, replace
from pathlib import Path

from station.compose import Station
from station.kernel.line_plan import LinePlanFile
from station.line.recordings import DatabaseArchive
from station.sim.line_station import SimLine
from station.sim.plan_design import Candidate, rig_time_s, throughput
from station.store.db import open_database


@dataclass(frozen=True)
class BatchRow:
    units: int
    outcomes: dict[str, int]
    verified: int
    sequence_s: float
    verify_s: float
    post_wall_s: float
    wait_s: float

    @property
    def rig_s(self) -> float:
        return self.sequence_s + self.verify_s + self.post_wall_s


@dataclass(frozen=True)
class ThroughputRun:
    rack_slots: int
    rig_units: int
    rack_s: float
    soak_s: float
    batches: tuple[BatchRow, ...]
    makespan_s: float
    wall_s: float
    cpu_s: float

    @property
    def rig_units_per_h(self) -> float:
        return 3600.0 * sum(b.units for b in self.batches) / sum(b.rig_s for b in self.batches)

    @property
    def rack_units_per_h(self) -> float:
        n = sum(b.units for b in self.batches)
        mean_wait = sum(b.wait_s * b.units for b in self.batches) / n
        return 3600.0 * self.rack_slots / (self.soak_s + mean_wait)

    @property
    def first_load_units_per_h(self) -> float:
        return 3600.0 * sum(b.units for b in self.batches) / self.makespan_s


def low_rate(line: LinePlanFile, rate_hz: int) -> LinePlanFile:
    """The plan at ``rate_hz``; the fit wants 50 samples in every segment, so the rig's first rest and the rate
    holds are held at least 50 samples long."""
    hold = 50.0 / rate_hz
    rig = replace(line.plan.rig, sample_rate_hz=float(rate_hz), rest_s=max(line.plan.rig.rest_s, 2.0, hold),
                  rate_hold_s=max(line.plan.rig.rate_hold_s, hold))
    return replace(line, plan=replace(line.plan, rig=rig))


def designer(line: LinePlanFile, rig_units: int, rack_slots: int) -> tuple[float, float, float, float]:
    """(rig s per run, rig units/h, rack units/h, line units/h) predicted by the plan designer."""
    cand = Candidate(line.plan, rig_time_s(line.plan), {}, True, True)
    t = throughput(cand, rig_units, rack_slots)
    return cand.rig_s, t.rig_units_per_h, t.rack_units_per_h, t.line_units_per_h


def simulate(line: LinePlanFile, *, rack_slots: int = 64, rig_units: int = 16, rate_hz: int = 10, seed: int = 0,
             load_s: float = 30.0, max_frames: float = 12000.0, scale_cap: float = 30.0) -> ThroughputRun:
    line = low_rate(line, rate_hz)
    plan = line.rig_plan()
    scale = max(1.0, min(scale_cap, max_frames / (rack_slots * rate_hz)))
    wall0, cpu0 = time.monotonic(), time.process_time()
    batches: list[BatchRow] = []
    with tempfile.TemporaryDirectory() as tmp, SimLine(rack_slots, scale, seed, plan) as sim:
        db_url = f"sqlite:///{Path(tmp) / 'line.sqlite'}"
        with open_database(db_url) as database:
            soak = sim.soak(range(rack_slots), line.plan.rack_s, DatabaseArchive(database.sessions))
        lost: dict[str, int] = {}
        for r in soak.units:
            if r.session is None:
                lost[r.error] = lost.get(r.error, 0) + 1
        print(f"  rack: {rack_slots} units soaked {soak.ended_s - soak.started_s:.0f} s (clock x{scale:g}, "
              f"{time.monotonic() - wall0:.0f} s wall); {rack_slots - sum(lost.values())} recordings stored"
              + "".join(f"; {n} without a recording: {why}" for why, n in lost.items()), flush=True)
        for b in range(0, rack_slots, rig_units):
            slots = list(range(b, min(b + rig_units, rack_slots)))
            wait = sim.clock.now() - soak.ended_s
            sim.to_rig(slots, load_s)
            cfg = sim.rig_config(slots, line, db_url=db_url, station_id="sim-rig")
            runners: list = []
            result = Station(cfg, clock=sim.clock).run(on_runner=runners.append)
            outcomes: dict[str, int] = {}
            for u in result.units:
                outcomes[u.outcome.value] = outcomes.get(u.outcome.value, 0) + 1
            station = runners[-1]
            verified = len(getattr(station.provisioner, "records", {}) or {}) if station.provisioner else 0
            batches.append(BatchRow(len(slots), outcomes, verified, result.sequence_s,
                                    float(getattr(station, "verify_s", 0.0)), result.post_wall_s, wait + load_s))
            print(f"  rig batch {len(batches)}: {len(slots)} units, {outcomes}, rig {batches[-1].rig_s:.0f} s "
                  f"(sequence {result.sequence_s:.0f} s, verification {batches[-1].verify_s:.0f} s, fits "
                  f"{result.post_wall_s:.1f} s wall)", flush=True)
        makespan = sim.clock.now() - soak.started_s
    return ThroughputRun(rack_slots, rig_units, line.plan.rack_s, soak.ended_s - soak.started_s, tuple(batches),
                         makespan, time.monotonic() - wall0, time.process_time() - cpu0)


def print_table(line: LinePlanFile, run: ThroughputRun, rate_hz: int) -> None:
    n = sum(b.units for b in run.batches)
    print(f"\nline throughput, a {run.rack_slots}-slot rack ({run.rack_s:.0f} s) and one rig at N={run.rig_units}:\n")
    print("| source | rig s per run | rig units/h | rack units/h | line units/h |")
    print("|---|---|---|---|---|")
    for label, lf in (("plan designer, the plan", line),
                      (f"plan designer, the plan at {rate_hz} Hz", low_rate(line, rate_hz))):
        rig_s, rig_h, rack_h, line_h = designer(lf, run.rig_units, run.rack_slots)
        print(f"| {label} | {rig_s:.0f} | {rig_h:.0f} | {rack_h:.0f} | {line_h:.0f} |")
    mean_rig = sum(b.rig_s for b in run.batches) / len(run.batches)
    print(f"| simulated run at {rate_hz} Hz, {len(run.batches)} rig batches, {n} units | {mean_rig:.0f} "
          f"| {run.rig_units_per_h:.0f} "
          f"| {run.rack_units_per_h:.0f} | {min(run.rig_units_per_h, run.rack_units_per_h):.0f} "
          f"(first load alone: {run.first_load_units_per_h:.0f}) |")
    print("\n| batch | units | outcomes | written + verified | sequence s | verification s | fits s (wall) "
          "| waited after soak s |")
    print("|---|---|---|---|---|---|---|---|")
    for k, b in enumerate(run.batches, 1):
        print(f"| {k} | {b.units} | {', '.join(f'{v} {o}' for o, v in sorted(b.outcomes.items()))} | {b.verified} "
              f"| {b.sequence_s:.0f} | {b.verify_s:.0f} | {b.post_wall_s:.1f} | {b.wait_s:.0f} |")
    print(f"\nsimulated run: soak {run.soak_s:.0f} s, first power-on to last batch done {run.makespan_s:.0f} s; "
          f"{run.wall_s:.0f} s wall, {run.cpu_s:.0f} s CPU of this process")


__all__ = ["BatchRow", "ThroughputRun", "designer", "low_rate", "print_table", "simulate"]
