"""A crossed Gage R&R study run on the simulated station: every part in every nest, ``repeats`` times.

The parts are simulated units of one seed (the same truth and serial each time they are loaded); each run
loads one part per nest and measures them all with the station's own sequence and fit, recorded in the
database under the study's lot, exactly as a plant would run the study on a real rig. Part ``p`` sits in
nest ``j`` in the run ``s = p - j (mod parts)`` of each repeat, so ``repeats * parts`` runs of ``nests``
units cover every cell ``repeats`` times (it needs parts >= nests: a part cannot be in two nests at once).
Every placement gets its own noise streams (a repeat is a new measurement, not a replay).

The nests' mounting errors are the simulated rig's configuration (``nest_errors_deg``).
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

from station.compose import Station, StationConfig
from station.kernel.errors import StationError
from station.kernel.plan import RigPlan, default_plan
from station.kernel.virtual_clock import VirtualClock, acting
from station.sequence.options import SequenceOptions
from station.sequence.runner import RunResult
from station.sim.fakes import FakeStation


@dataclass(frozen=True)
class StudyDesign:
    """``parts`` x ``nests`` x ``repeats``; the parts are units ``0 .. parts-1`` of ``seed``."""

    parts: int
    nests: int
    repeats: int
    seed: int = 0

    def __post_init__(self) -> None:
        if self.nests < 2 or self.parts < 2 or self.repeats < 2:
            raise StationError("a Gage R&R study needs at least 2 parts, 2 nests and 2 repeats")
        if self.parts < self.nests:
            raise StationError(f"{self.parts} parts cannot fill {self.nests} nests in every run; "
                               "use at least as many parts as nests")

    def schedule(self) -> list[tuple[int, ...]]:
        """Per run, the part in each nest."""
        return [tuple((s + j) % self.parts for j in range(self.nests))
                for _ in range(self.repeats) for s in range(self.parts)]


@dataclass(frozen=True)
class SimRig:
    """Where the simulated runs go: the rig's name (its lock and nest-calibration key ``fake-rig://NAME``), its
    nests' mounting errors, the clock scale and plan, the limits, the database and the output folder."""

    station_id: str
    db_url: str
    scale: float
    plan: RigPlan
    nest_errors_deg: Sequence[Sequence[float]] | None
    limits_path: Path | None
    out_dir: Path | None

    def run(self, seed: int, keys: Sequence[int], noise_index: int, lot: str, *, nest_calibration: bool,
            on_start: Callable[[FakeStation], None] | None = None) -> RunResult:
        """One run of the station's sequence with units ``keys`` of ``seed`` in its nests (retest policy off:
        a study measures the same parts again on purpose)."""
        # on the virtual clock a run repeats bit for bit (docs/simulation.md): a study measures the station, not the
        # host's thread scheduling
        clock = VirtualClock()
        with acting(clock, name="msa"), \
                FakeStation(len(keys), self.scale, seed, name=self.station_id, plan=self.plan, unit_keys=keys,
                            noise_index=noise_index, nest_errors_deg=self.nest_errors_deg, clock=clock) as sim:
            if on_start is not None:
                on_start(sim)
            config = StationConfig(
                sim.rig_url, tuple(sim.sensor_urls), station_id=self.station_id, db_url=self.db_url, record=True,
                limits_path=self.limits_path, out_dir=self.out_dir, clock_scale=self.scale, plan=self.plan, lot=lot,
                rig_options=sim.rig_client_options(), sensor_options=sim.sensor_client_options(),
                nest_calibration=nest_calibration,
            )
            return Station(config, clock=sim.clock, options=SequenceOptions(), admit=lambda *_: None).run()


def run_study(
    design: StudyDesign,
    db_url: str,
    lot: str,
    *,
    scale: float = 120.0,
    plan: RigPlan | None = None,
    nest_errors_deg: Sequence[Sequence[float]] | None = None,
    limits_path: Path | None = None,
    station_id: str = "msa-sim",
    on_run: Callable[[int, int, RunResult], None] | None = None,
    nest_calibration: bool = True,
    out_dir: Path | None = Path("msa-out"),
) -> list[RunResult]:
    """Run every run of the study on the in-process simulated station, recording into ``db_url``.

    ``on_run(k, total, result)`` after each run. The retest policy does not apply: a study measures
    the same parts again on purpose. ``nest_calibration``: apply the rig's newest nest calibration in the
    database (as every production run does). ``out_dir``: where the sessions and parameter files go (the
    records keep the parameter sets, which a nest calibration reads).
    """
    rig = SimRig(station_id, db_url, scale, plan if plan is not None else default_plan(), nest_errors_deg,
                 limits_path, out_dir)
    runs = design.schedule()
    results: list[RunResult] = []
    for k, parts in enumerate(runs):
        result = rig.run(design.seed, parts, k + 1, lot, nest_calibration=nest_calibration)
        results.append(result)
        if on_run is not None:
            on_run(k, len(runs), result)
    return results


REFERENCE_KEY = 10_000
"""The reference unit's identity among the simulated units of a seed (far from the parts' 0 .. parts-1)."""


def run_nest_calibration(
    nests: int,
    db_url: str,
    *,
    seed: int = 0,
    scale: float = 120.0,
    plan: RigPlan | None = None,
    nest_errors_deg: Sequence[Sequence[float]] | None = None,
    limits_path: Path | None = None,
    station_id: str = "msa-sim",
    on_run: Callable[[int, int, RunResult], None] | None = None,
    out_dir: Path | None = Path("msa-out"),
) -> tuple[str, list[RunResult], Path | None]:
    """Run the reference unit once in every nest (the other nests hold parts), recorded in ``db_url``.

    Returns the reference unit's serial, the runs, and its "laboratory calibration": the simulated unit's
    true parameter set written to ``out_dir/reference-lab.json`` (None without ``out_dir``), which a real
    line would have from a calibration elsewhere; ``station nest-cal estimate [--reference-params FILE]``
    (:func:`station.commands.nest_cal.estimate_from_records`) then fits the nests from the runs.
    """
    rig = SimRig(station_id, db_url, scale, plan if plan is not None else default_plan(), nest_errors_deg,
                 limits_path, out_dir)
    results: list[RunResult] = []
    found: dict[str, object] = {}

    def note_reference(sim: FakeStation, nest: int) -> None:
        truth = sim.units[nest].truth
        found["serial"] = truth.serial
        if out_dir is not None and "lab" not in found:
            out_dir.mkdir(parents=True, exist_ok=True)
            lab_path = out_dir / "reference-lab.json"
            lab_path.write_text(truth.as_parameter_set(1.0 / rig.plan.sample_rate_hz).to_json())
            found["lab"] = lab_path

    for j in range(nests):
        keys = [REFERENCE_KEY if i == j else 20_000 + i for i in range(nests)]
        result = rig.run(seed, keys, 1000 + j, "nest-calibration", nest_calibration=False,
                         on_start=functools.partial(note_reference, nest=j))
        results.append(result)
        if on_run is not None:
            on_run(j, nests, result)
    lab = found.get("lab")
    return str(found.get("serial", "")), results, lab if isinstance(lab, Path) else None
