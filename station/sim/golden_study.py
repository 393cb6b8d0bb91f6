"""A golden unit that drifts, run on the simulated station shift after shift until its chart signals.

The golden unit is registered from ``registration_runs`` runs of the unadulterated unit; then at every
shift start it is run again with its accelerometer x static bias moved by ``drift_sigmas`` registered
repeatabilities per shift (an ageing unit, or a station drifting by as much). Each run is the station's own
sequence, fit and golden check, recorded in the database; the individuals chart over the checks with the
Nelson rules (:func:`station.kernel.golden.golden_trends`) says at which shift the drift is caught.

:func:`predicted_detection` gives what the chart rules predict for that drift: the distribution of the first
signalling shift for ``z_k = d k + r e_k``, ``e_k ~ N(0, 1)``, ``r`` the true scatter over the one the chart was
registered with (an estimate from the registration runs), by Monte Carlo over the same rules.
:func:`predicted_check_failure` does the same for the golden check's own limit on the drifting parameter.
Every other referenced parameter is stable, so a check failing on any of them is a false stop; the stated
family-wise false-stop rate bounds how often that happens per check.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from datetime import UTC, datetime
from pathlib import Path

import numpy as np

from station.compose import Station, StationConfig
from station.kernel.golden import (
    DEFAULT_FALSE_STOP_RATE,
    RECOMMENDED_REGISTRATION_RUNS,
    GoldenCheck,
    GoldenUnit,
    golden_trends,
    register_golden,
)
from station.kernel.plan import RigPlan, default_plan
from station.kernel.virtual_clock import VirtualClock, acting
from station.physics.unit import UnitTruth
from station.sequence.options import SequenceOptions
from station.sim.fakes import FakeStation
from station.store.db import open_database
from station.store.golden_records import golden_checks, golden_units, save_golden, unit_runs
from station.store.spc import run_rules

PARAMETER = "accel.bias_static.x"


@dataclass(frozen=True)
class DriftOutcome:
    """What the drifting golden unit did: per shift its check, the first shift its chart signalled, the first
    shift its check failed (on any parameter), on the drifting parameter, and on another (a false stop)."""

    serial: str
    repeatability: float
    drift_per_shift: float
    checks: tuple[GoldenCheck, ...]
    first_signal_shift: int | None
    first_limit_fail_shift: int | None
    golden: GoldenUnit | None = None

    @property
    def first_drift_fail_shift(self) -> int | None:
        """The first shift whose check failed on the drifting parameter (a true detection)."""
        return next((i + 1 for i, c in enumerate(self.checks) if any(d.parameter == PARAMETER for d in c.failed)),
                    None)

    @property
    def false_stops(self) -> tuple[int, ...]:
        """The shifts whose check failed on a parameter other than the drifting one (all of them stable) by a
        deviation outside its allowance: what the stated false-stop rate bounds."""
        return tuple(i + 1 for i, c in enumerate(self.checks)
                     if any(d.parameter != PARAMETER and d.deviation is not None for d in c.failed))

    @property
    def unmeasured_stops(self) -> tuple[int, ...]:
        """The shifts whose check failed because a referenced parameter was not measured (the fit could not
        determine it): a stop too, but not one the false-stop rate speaks for."""
        return tuple(i + 1 for i, c in enumerate(self.checks) if any(d.deviation is None for d in c.failed))


def predicted_detection(drift_sigmas: float, shifts: int, trials: int = 4000, seed: int = 0,
                        registration_runs: int | None = RECOMMENDED_REGISTRATION_RUNS) -> np.ndarray:
    """The first signalling shift (1-based; ``shifts + 1``: none) of ``trials`` simulated charts.

    The drift is ``drift_sigmas`` chart sigmas per shift. The chart's sigma is the repeatability estimated
    from ``registration_runs`` runs (None: known exactly), so each trial draws the ratio of the true
    scatter to that estimate, ``sqrt((n - 1) / chi2_{n-1})``, as the real registration does.
    """
    rng = np.random.default_rng(seed)
    out = np.empty(trials, dtype=int)
    k = np.arange(1, shifts + 1)
    for i in range(trials):
        ratio = 1.0
        if registration_runs is not None:
            ratio = float(np.sqrt((registration_runs - 1) / rng.chisquare(registration_runs - 1)))
        z = drift_sigmas * k + ratio * rng.normal(0.0, 1.0, shifts)
        flags = run_rules([float(v) for v in z])
        out[i] = next((j + 1 for j, f in enumerate(flags) if f), shifts + 1)
    return out


def predicted_check_failure(drift_sigmas: float, allowed_sigmas: float, shifts: int, registration_runs: int,
                            trials: int = 4000, seed: int = 0) -> np.ndarray:
    """The first shift (1-based; ``shifts + 1``: none) at which the golden check fails on the drifting parameter.

    Deviation at shift ``k``, in registered sigmas: ``d k + r (u + e_k)``, ``u ~ N(0, 1/n)`` the registered
    mean's error (the same for every shift), ``e_k ~ N(0, 1)``, ``r`` the true over the registered sigma
    (drawn as in :func:`predicted_detection`); it fails when its magnitude exceeds ``allowed_sigmas`` (the
    registered allowance over the registered sigma).
    """
    rng = np.random.default_rng(seed)
    n = registration_runs
    out = np.empty(trials, dtype=int)
    k = np.arange(1, shifts + 1)
    for i in range(trials):
        ratio = float(np.sqrt((n - 1) / rng.chisquare(n - 1)))
        z = drift_sigmas * k + ratio * (rng.normal(0.0, 1.0 / np.sqrt(n)) + rng.normal(0.0, 1.0, shifts))
        hits = np.nonzero(np.abs(z) > allowed_sigmas)[0]
        out[i] = int(hits[0]) + 1 if hits.size else shifts + 1
    return out


def run_drifting_golden(
    db_url: str,
    *,
    seed: int = 0,
    registration_runs: int = RECOMMENDED_REGISTRATION_RUNS,
    shifts: int = 12,
    drift_sigmas: float = 0.5,
    scale: float = 120.0,
    plan: RigPlan | None = None,
    out_dir: Path | None = Path("golden-out"),
    station_id: str = "golden-sim",
    on_run: Callable[[str, int], None] | None = None,
    false_stop_rate: float = DEFAULT_FALSE_STOP_RATE,
    fraction: float = 0.1,
) -> DriftOutcome:
    """Register the golden unit from its runs, then run it once per shift with a growing bias."""
    plan = plan if plan is not None else default_plan()
    base = datetime(2026, 1, 5, 6, 0, tzinfo=UTC)

    def one_run(noise: int, change: Callable[[int, UnitTruth], UnitTruth] | None) -> tuple[Station, str]:
        clock = VirtualClock()  # the run repeats bit for bit: the study sees the unit's noise, not thread timing
        with acting(clock, name="golden"), \
                FakeStation(1, scale, seed, name=station_id, plan=plan, unit_keys=[30_000], noise_index=noise,
                            truth_change=change, clock=clock) as sim:
            serial = sim.units[0].truth.serial
            config = StationConfig(sim.rig_url, tuple(sim.sensor_urls), station_id=station_id, db_url=db_url,
                                   record=True, out_dir=out_dir, clock_scale=scale, plan=plan, lot="golden")
            station = Station(config, clock=sim.clock, options=SequenceOptions(), admit=lambda *_: None)
            station.run()
        return station, serial

    serial = ""
    for i in range(registration_runs):
        _, serial = one_run(1 + i, None)
        if on_run is not None:
            on_run("registration", i)
    with open_database(db_url) as db:
        golden = register_golden(serial, base.isoformat(), unit_runs(db, serial), false_stop_rate=false_stop_rate,
                                 fraction=fraction)
        save_golden(db, golden)
    ref = golden.reference(PARAMETER)
    assert ref is not None
    step = drift_sigmas * ref.repeatability
    checks: list[GoldenCheck] = []
    for k in range(1, shifts + 1):

        def aged(slot: int, truth: UnitTruth, k: int = k) -> UnitTruth:
            bias = truth.accel.bias_static.copy()
            bias[0] += k * step
            return replace(truth, accel=replace(truth.accel, bias_static=bias))

        station, _ = one_run(100 + k, aged)
        checks.extend(station.golden_checks)
        if on_run is not None:
            on_run("shift", k)
    with open_database(db_url) as db:
        stored = golden_checks(db, serial=serial)
        (trend,) = [t for t in golden_trends(golden_units(db)[serial][1], [c.deviations for c in stored], run_rules)
                    if t.parameter == PARAMETER]
    first_fail = next((i + 1 for i, c in enumerate(checks) if not c.passed), None)
    first = trend.first_signal
    return DriftOutcome(serial, ref.repeatability, step, tuple(checks), None if first is None else first + 1,
                        first_fail, golden)


__all__ = ["DriftOutcome", "predicted_check_failure", "predicted_detection", "run_drifting_golden"]
