"""Line throughput of a rack and one rig, from the plan designer and from a simulated run (a part of
``bench_line.py``, and a command of its own: ``python benchmarks/line_throughput.py --help``).

Designer: :func:`station.sim.plan_design.throughput` on the plan's predicted rig time per run
(:func:`station.sim.plan_design.rig_time_s`: trajectory + 3 s per step) for ``rig_units`` per run and ``rack_slots``
slots soaking ``rack_s``: rig units/h, rack units/h, line = the smaller.

Simulated run (:class:`station.sim.line_station.SimLine`: the real rack and rig roles, relay board and rig on
Modbus/TCP, sensors on ptys), on the virtual clock by default (``clock="virtual"``: the same seed gives the same
recordings, outcomes and simulated times under any load; ``"scaled"`` keeps the ``SimClock`` it ran on before):
``rack_slots`` units soak together for the plan's ``rack_s``, then go to the rig in batches of ``rig_units`` (each
batch carried in ``load_s``; the units of the slots in ``interrupt`` lose power on the way), each batch a rig-role
run of the composition root (``Station`` with the line plan: decisions, rig part, joint fit, limits, EEPROM write
and verification). To keep the CPU time small the units sample at ``rate_hz`` (10 Hz instead of 100 Hz): enough for
the rack (the fastest warm-up, T_c 50 s, is 500 samples), not the product's rate on the rig; the simulated seconds,
the steps and the counts are those of the real sequence; the fits are cheaper and less exact, and the fit wants 50
samples in every segment, so the rig's first rest is held 5 s instead of 2 s and the six rate holds 5 s instead of
3 s (:func:`low_rate`): 15 s more per run than the plan at 100 Hz. The designer's figures are given for both plans.

Rig time of a batch = the sequence until the rig is at rest + the verification (simulated s; on the virtual clock
these do not depend on the host) + the fits and saving (wall s of this machine, as on a real station; on the virtual
clock no simulated time passes during them, so they are given apart and added only in the "with fits" figures).
Measured throughput: rig units/h = units / sum of the batches' rig times; rack units/h = slots x 3600 / (soak + boot
+ the mean wait of a unit between its soak's end and its batch); line = the smaller (steady state, the rack refilled
as units leave); also the first load's own figure: units / (first power-on .. last batch done), which includes the
first soak. Rig utilisation: the batches' rig time over the time from the first batch's loading to the last batch's
end, and in the steady state line units/h over rig units/h (the rig's share of the hour that the rack keeps busy).
"""

from __future__ import annotations

import argparse
import contextlib
import tempfile
import time
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path

from station.compose import Station
from station.kernel.clock import Clock, SimClock
from station.kernel.line_plan import LinePlanFile, load_line_plan_file
from station.kernel.virtual_clock import VirtualClock, acting
from station.line.recordings import DatabaseArchive
from station.sim.line_station import SimLine
from station.sim.plan_design import Candidate, rig_time_s, throughput
from station.store.db import open_database


@dataclass(frozen=True)
class UnitRow:
    """One unit through the simulated line: its soak, the rig role's decision, its outcome."""

    slot: int
    serial: str
    batch: int
    recorded: bool  # the rack stored its soak
    soak_error: str
    interrupted: bool  # lost power on the way to the rig (injected)
    decision: str  # the rig role's plan for it, and why
    outcome: str
    message: str
    written: bool  # its EEPROM image was written
    verified: bool  # and verified on the rig


@dataclass(frozen=True)
class BatchRow:
    units: int
    outcomes: dict[str, int]
    verified: int
    sequence_s: float
    verify_s: float
    post_wall_s: float
    wait_s: float
    start_s: float  # line clock when the batch's loading began (s since the first power-on)
    end_s: float  # line clock when its run ended

    @property
    def rig_s(self) -> float:
        """Simulated rig time: the sequence and the verification (s)."""
        return self.sequence_s + self.verify_s

    @property
    def rig_with_fits_s(self) -> float:
        return self.rig_s + self.post_wall_s


@dataclass(frozen=True)
class ThroughputRun:
    rack_slots: int
    rig_units: int
    rack_s: float
    soak_s: float
    batches: tuple[BatchRow, ...]
    units: tuple[UnitRow, ...]
    makespan_s: float
    wall_s: float
    cpu_s: float
    clock: str
    rate_hz: int

    def rig_units_per_h(self, fits: bool = False) -> float:
        rig = sum(b.rig_with_fits_s if fits else b.rig_s for b in self.batches)
        return 3600.0 * sum(b.units for b in self.batches) / rig

    @property
    def rack_units_per_h(self) -> float:
        n = sum(b.units for b in self.batches)
        mean_wait = sum(b.wait_s * b.units for b in self.batches) / n
        return 3600.0 * self.rack_slots / (self.soak_s + mean_wait)

    def line_units_per_h(self, fits: bool = False) -> float:
        return min(self.rig_units_per_h(fits), self.rack_units_per_h)

    @property
    def first_load_units_per_h(self) -> float:
        return 3600.0 * sum(b.units for b in self.batches) / self.makespan_s

    @property
    def rig_busy_share(self) -> float:
        """The batches' rig time over the time from the first batch's loading to the last one's end."""
        span = self.batches[-1].end_s - self.batches[0].start_s
        return sum(b.rig_s for b in self.batches) / span

    def outcome_counts(self) -> dict[str, int]:
        out: dict[str, int] = {}
        for u in self.units:
            out[u.outcome] = out.get(u.outcome, 0) + 1
        return out


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
             load_s: float = 30.0, interrupt: Sequence[int] = (), clock: str = "virtual",
             max_frames: float = 12000.0, scale_cap: float = 30.0, out: Path | None = None) -> ThroughputRun:
    """Run the line (see the module docstring). ``clock``: ``"virtual"`` or ``"scaled"`` (``SimClock`` at the scale
    that keeps the sensors at ``max_frames`` frames per wall second, at most ``scale_cap``). ``out``: also write
    each unit's row there (CSV)."""
    line = low_rate(line, rate_hz)
    plan = line.rig_plan()
    if clock == "virtual":
        line_clock: Clock = VirtualClock()
    elif clock == "scaled":
        line_clock = SimClock(max(1.0, min(scale_cap, max_frames / (rack_slots * rate_hz))))
    else:
        raise ValueError(f"clock must be 'virtual' or 'scaled', got {clock!r}")
    wall0, cpu0 = time.monotonic(), time.process_time()
    batches: list[BatchRow] = []
    units: list[UnitRow] = []
    # on the virtual clock this thread owns time from set-up to the last batch (as ``station demo``)
    actor = acting(line_clock, name="throughput") if clock == "virtual" else contextlib.nullcontext()
    with tempfile.TemporaryDirectory() as tmp, actor, \
            SimLine(rack_slots, line_clock.scale, seed, plan, clock=line_clock) as sim:
        db_url = f"sqlite:///{Path(tmp) / 'line.sqlite'}"
        with open_database(db_url) as database:
            soak = sim.soak(range(rack_slots), line.plan.rack_s, DatabaseArchive(database.sessions))
        soaked = {r.slot: r for r in soak.units}
        lost: dict[str, int] = {}
        for r in soak.units:
            if r.session is None:
                lost[r.error] = lost.get(r.error, 0) + 1
        print(f"  rack: {rack_slots} units soaked {soak.ended_s - soak.started_s:.0f} s ({clock} clock, "
              f"{time.monotonic() - wall0:.0f} s wall); {rack_slots - sum(lost.values())} recordings stored"
              + "".join(f"; {n} without a recording: {why}" for why, n in lost.items()), flush=True)
        for b in range(0, rack_slots, rig_units):
            slots = list(range(b, min(b + rig_units, rack_slots)))
            cut = [k for k in interrupt if k in slots]
            start = sim.clock.now()
            wait = start - soak.ended_s
            sim.to_rig(slots, load_s, interrupt=cut)
            serials = {sim.serial(k): k for k in slots}
            cfg = sim.rig_config(slots, line, db_url=db_url, station_id="sim-rig")
            runners: list = []
            station = Station(cfg, clock=sim.clock)
            result = station.run(on_runner=runners.append)
            outcomes: dict[str, int] = {}
            for u in result.units:
                outcomes[u.outcome.value] = outcomes.get(u.outcome.value, 0) + 1
            runner = runners[-1]
            records = dict(getattr(station.provisioner, "records", {}) or {}) if station.provisioner else {}
            decisions = getattr(runner, "decisions", {})
            for u in result.units:
                k = serials.get(u.serial, -1)
                rec = records.get(u.serial)
                verification = getattr(rec, "verification", None)
                d = decisions.get(u.serial)
                r = soaked.get(k)
                units.append(UnitRow(k, u.serial, len(batches) + 1, r is not None and r.session is not None,
                                     r.error if r is not None else "", k in cut,
                                     "" if d is None else d.plan + (f" ({d.reason})" if d.reason else ""),
                                     u.outcome.value, u.message, rec is not None,
                                     verification is not None and bool(verification.passed)))
            batches.append(BatchRow(len(slots), outcomes, sum(1 for r in records.values()
                                                              if getattr(r.verification, "passed", False)),
                                    result.sequence_s, float(getattr(runner, "verify_s", 0.0)),
                                    result.post_wall_s, wait + load_s, start - soak.started_s,
                                    sim.clock.now() - soak.started_s))
            print(f"  rig batch {len(batches)}: {len(slots)} units, {outcomes}, rig {batches[-1].rig_s:.0f} s "
                  f"(sequence {result.sequence_s:.0f} s, verification {batches[-1].verify_s:.0f} s; fits "
                  f"{result.post_wall_s:.1f} s wall)", flush=True)
        makespan = sim.clock.now() - soak.started_s
    run = ThroughputRun(rack_slots, rig_units, line.plan.rack_s, soak.ended_s - soak.started_s, tuple(batches),
                        tuple(units), makespan, time.monotonic() - wall0, time.process_time() - cpu0, clock, rate_hz)
    if out is not None:
        write_units(run, out)
    return run


def write_units(run: ThroughputRun, path: Path) -> None:
    """Each unit's row as CSV."""
    import csv

    with path.open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["slot", "serial", "batch", "recorded", "soak_error", "interrupted", "decision", "outcome",
                    "written", "verified", "message"])
        for u in run.units:
            w.writerow([u.slot, u.serial, u.batch, int(u.recorded), u.soak_error, int(u.interrupted), u.decision,
                        u.outcome, int(u.written), int(u.verified), u.message])


def _why(u: UnitRow) -> str:
    """A FAIL's or REFUSED's reason without its numbers (for counting)."""
    m = u.message
    if u.outcome == "PASS":
        return ""
    if "verification failed" in m:
        return "verification on the rig failed"
    if m.startswith("out of limits"):
        return "out of limits"
    if m.startswith("inconclusive"):
        return "inconclusive (maps to FAIL)"
    if u.outcome == "REFUSED":
        for prefix in ("refused by the line's rack-to-rig decision, ", "refused by the retest policy: "):
            m = m.removeprefix(prefix)
        return m.split("(")[0].strip()
    return m[:60]


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
    mean_fits = sum(b.post_wall_s for b in run.batches) / len(run.batches)
    print(f"| simulated run at {rate_hz} Hz ({run.clock} clock), {len(run.batches)} rig batches, {n} units "
          f"| {mean_rig:.0f} | {run.rig_units_per_h():.0f} | {run.rack_units_per_h:.0f} "
          f"| {run.line_units_per_h():.0f} (first load alone: {run.first_load_units_per_h:.0f}) |")
    print(f"| the same with the fits' wall time on the rig (+{mean_fits:.0f} s per run, this machine) "
          f"| {mean_rig + mean_fits:.0f} | {run.rig_units_per_h(True):.0f} | {run.rack_units_per_h:.0f} "
          f"| {run.line_units_per_h(True):.0f} |")
    print("\n| batch | units | outcomes | written and verified | sequence s | verification s | fits s (wall) "
          "| waited after soak s |")
    print("|---|---|---|---|---|---|---|---|")
    for k, b in enumerate(run.batches, 1):
        print(f"| {k} | {b.units} | {', '.join(f'{v} {o}' for o, v in sorted(b.outcomes.items()))} | {b.verified} "
              f"| {b.sequence_s:.0f} | {b.verify_s:.0f} | {b.post_wall_s:.1f} | {b.wait_s:.0f} |")
    recorded = sum(u.recorded for u in run.units)
    written = sum(u.written for u in run.units)
    verified = sum(u.verified for u in run.units)
    print(f"\nsoaks with a recording: {recorded} of {len(run.units)}; images written {written}, verified {verified}")
    print("\n| outcome | units | why |")
    print("|---|---|---|")
    reasons: dict[tuple[str, str], int] = {}
    for u in run.units:
        key = (u.outcome, _why(u))
        reasons[key] = reasons.get(key, 0) + 1
    for (o, why), c in sorted(reasons.items()):
        print(f"| {o} | {c} | {why} |")
    for u in run.units:
        if u.interrupted:
            print(f"\npower interruption injected: slot {u.slot} ({u.serial}) lost power on the way to the rig: "
                  f"decision {u.decision or '-'}; outcome {u.outcome}: {u.message}")
    share = run.line_units_per_h() / run.rig_units_per_h()
    print(f"\nrig utilisation: busy {100 * run.rig_busy_share:.0f} % from the first batch's loading to the last "
          f"batch's end; steady state (rack-limited) {100 * min(1.0, share):.0f} % (line / rig units per hour)")
    print(f"\nsimulated run: soak {run.soak_s:.0f} s, first power-on to last batch done {run.makespan_s:.0f} s; "
          f"{run.wall_s:.0f} s wall, {run.cpu_s:.0f} s CPU of this process")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--rack-slots", type=int, default=64)
    ap.add_argument("--rig-units", type=int, default=16, help="units per rig run (N)")
    ap.add_argument("--rack-s", type=float, default=None, help="soak (s); default the line plan's")
    ap.add_argument("--rate", type=int, default=10, help="sample rate of the simulated units (Hz)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--load-s", type=float, default=30.0, help="carrying a batch from the rack to the rig (s)")
    ap.add_argument("--interrupt", type=int, nargs="*", default=[0],
                    help="slots whose unit loses power on the way to the rig")
    ap.add_argument("--clock", choices=["virtual", "scaled"], default="virtual")
    ap.add_argument("--units-csv", type=Path, default=None, help="write each unit's row here")
    args = ap.parse_args()
    lf = load_line_plan_file(None)
    if args.rack_s is not None:
        lf = replace(lf, plan=replace(lf.plan, rack_s=args.rack_s))
    run = simulate(lf, rack_slots=args.rack_slots, rig_units=args.rig_units, rate_hz=args.rate, seed=args.seed,
                   load_s=args.load_s, interrupt=args.interrupt, clock=args.clock, out=args.units_csv)
    print_table(lf, run, args.rate)


if __name__ == "__main__":
    main()


__all__ = ["BatchRow", "ThroughputRun", "UnitRow", "designer", "low_rate", "print_table", "simulate", "write_units"]
