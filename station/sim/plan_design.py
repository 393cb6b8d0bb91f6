"""``station plan``: the shortest line plan (rig part and rack time) whose predicted accuracy meets the limits.

The predicted accuracy is the joint fit's own: for each candidate plan a few units of the sensor class are
simulated through the line (:func:`station.sim.line_sim.simulate_line`, fixed seeds, the figures that set the
stated stds stratified over the class: :func:`design_units`) and fitted
(:func:`station.fit.joint.fit_joint`); the standard uncertainties the fit states (from its likelihood: the
Fisher information of M and b_stat, T_c's profile) are compared with the limits file's fit-quality limits
(the largest standard uncertainty of M and b_stat of each triad) times a planning margin, on every simulated
unit. The joint fit's stated uncertainties are honest on simulated units (``tests/test_fit_joint.py``: the
spread of the normalized errors within 0.4-1.6), which is what lets them predict.

Candidates: rack times and pose holds (the rest of the rig part as :func:`station.kernel.line_plan.line_rig_plan`);
for each rack time the pose holds are tried from the shortest up, the first that meets every limit kept, and the
plan with the shortest predicted rig time (ties: the shorter rack) is chosen. The gyro's T_c must be resolved on
every axis of every simulated unit (the rack's purpose). ``match_full`` (e.g. 1.1): also the median over the
elements of each stated std of M and b_stat must be at most that factor times the full rig plan's on the same
unit (fitted from a simulated full-plan recording): the limits file bounds what a unit may ship with, this what
the line must keep of today's accuracy.

Rig time per plan = the rig trajectory's duration plus :data:`STEP_OVERHEAD_S` per step (the sequence's
confirmations, clock syncs and capture starts; measured with ``benchmarks/bench_line.py``: 262 s for a 236.5 s
trajectory of 13 steps, 892 s for the full plan's 818 s of 25 steps, at clock scale 30: 2-3 s per step).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from station.fit.calibrate import FitOptions, fit_session
from station.fit.joint import fit_joint
from station.kernel.errors import StationError
from station.kernel.limits_file import LimitsFile
from station.kernel.line_plan import ANY_ORIENTATION, RACK_TILT_TOLERANCE_DEG, LinePlan, line_rig_plan
from station.kernel.parameters import ParameterSet
from station.kernel.plan import default_plan
from station.kernel.sensor_class import TABLE1, SensorClass
from station.physics.trajectory import build_trajectory
from station.physics.unit import UnitTruth, draw_unit
from station.sim.line_sim import simulate_line
from station.sim.session_sim import simulate_session

#: sequence overhead per rig step (s), see the module docstring
STEP_OVERHEAD_S = 3.0
#: the rest the runner holds first on the rig (s)
RIG_REST_S = 2.0


def design_units(seeds: Sequence[int], sensor_class: SensorClass = TABLE1) -> list[UnitTruth]:
    """The designer's units: each drawn with its seed as :func:`~station.sim.line_sim.simulate_line` draws it, then
    the figures the line's stated stds follow set by a Latin hypercube over the units' axes instead of at
    random: the white-noise std of each triad (accel M's std follows it), b_drift of each triad (the simulated
    stochastic drift is ``drift_noise_rel |b_drift|``; the gyro's b_stat and b_drift stds follow it) and T_c of
    each triad (how long that drift stays correlated). With n units
    the 3n axis values of a figure are the centres of 3n equal strata of its Table 1 range, in an order drawn from
    the seeds: a few units then span the class, where three random draws can all fall low (measured:
    ``benchmarks/line_designer_units.py``). The other parameters stay as drawn."""
    c = sensor_class
    seeds = list(seeds)
    cells = 3 * len(seeds)
    rng = np.random.default_rng(np.random.SeedSequence([*seeds, 70_501]))

    def strata(lo: float, hi: float) -> np.ndarray:
        centres = lo + (hi - lo) * (np.arange(cells) + 0.5) / cells
        return rng.permutation(centres).reshape(len(seeds), 3)

    deg = np.pi / 180.0
    a_noise, a_drift = strata(*c.accel_noise_std_mps2), strata(*c.accel_bias_drift_mps2)
    a_tc = strata(*c.accel_correlation_time_s)
    w_noise = strata(*c.gyro_noise_std_dps) * deg
    w_drift = strata(*c.gyro_bias_drift_dps) * deg
    w_tc = strata(*c.gyro_correlation_time_s)
    units = []
    for k, seed in enumerate(seeds):
        u = draw_unit(c, np.random.default_rng(np.random.SeedSequence(seed).spawn(2)[0]))
        accel = replace(u.accel, noise_std=a_noise[k], outlier_size=c.outlier_sigma * a_noise[k], bias_drift=a_drift[k],
                        drift_noise=c.drift_noise_rel * np.abs(a_drift[k]), correlation_time_s=a_tc[k])
        gyro = replace(u.gyro, noise_std=w_noise[k], outlier_size=c.outlier_sigma * w_noise[k], bias_drift=w_drift[k],
                       drift_noise=c.drift_noise_rel * np.abs(w_drift[k]), correlation_time_s=w_tc[k])
        units.append(replace(u, accel=accel, gyro=gyro))
    return units


@dataclass(frozen=True)
class Candidate:
    """One evaluated plan.

    Attributes:
        plan: the line plan.
        rig_s: predicted rig time of one run (s).
        worst: per limited figure, the largest stated std over the simulated units divided by its limit.
        gyro_tc_resolved: the gyro's T_c resolved on every axis of every simulated unit.
        meets: every ``worst`` <= the margin and the gyro's T_c resolved.
    """

    plan: LinePlan
    rig_s: float
    worst: dict[str, float]
    gyro_tc_resolved: bool
    meets: bool


def rig_time_s(plan: LinePlan) -> float:
    """Predicted rig time of one run (s): trajectory plus :data:`STEP_OVERHEAD_S` per step."""
    rig = replace(plan.rig, rest_s=RIG_REST_S)
    steps = 1 + len(rig.poses) + len(rig.rate_steps)
    return float(build_trajectory(rig).duration_s + STEP_OVERHEAD_S * steps)


#: the figures the limits bound: the standard uncertainties of M and b_stat of each triad
FIGURES = ("accel.misalignment_std", "accel.bias_static_std", "gyro.misalignment_std", "gyro.bias_static_std")


def _limits(limits: LimitsFile) -> dict[str, float]:
    fq = limits.fit_quality
    caps = (fq.accel_misalignment_std, fq.accel_bias_static_std_mps2, fq.gyro_misalignment_std,
            fq.gyro_bias_static_std_radps)
    return {k: float(v) for k, v in zip(FIGURES, caps, strict=True) if v is not None}


_FULL_CACHE: dict[tuple[int, str], dict[str, np.ndarray]] = {}


def _std(p: ParameterSet, key: str) -> np.ndarray:
    triad, name = key.split(".")
    return np.asarray(getattr(getattr(p, triad), name), dtype=float)


def full_plan_stds(seed: int, limits: LimitsFile, unit: UnitTruth) -> dict[str, np.ndarray]:
    """The full rig plan's stated stds of M and b_stat on the designer's unit of ``seed`` (cached)."""
    key = (seed, str(limits.path))
    if key not in _FULL_CACHE:
        session = simulate_session(seed + 101, plan=default_plan(), unit=unit).session
        p = fit_session(session, FitOptions(tc_range_s=dict(limits.correlation_time_s)))
        _FULL_CACHE[key] = {k: _std(p, k) for k in FIGURES}
    return _FULL_CACHE[key]


def evaluate(plan: LinePlan, limits: LimitsFile, seeds: Sequence[int], margin: float,
             match_full: float | None = None) -> Candidate:
    """Simulate ``seeds`` units through ``plan``, fit them jointly, compare the stated stds with the limits
    (and, with ``match_full``, with that factor times the full rig plan's stated stds of the same unit)."""
    caps = _limits(limits)
    opts = FitOptions(tc_range_s=dict(limits.correlation_time_s))
    worst = dict.fromkeys(caps, 0.0)
    if match_full is not None:
        worst.update({f"{k} / full": 0.0 for k in FIGURES})
    resolved = True
    for seed, unit in zip(seeds, design_units(seeds), strict=True):
        line = simulate_line(seed, plan=plan, unit=unit)
        p = fit_joint(line.rack, line.rig, opts, max_transfer_s=plan.max_transfer_s,
                      rack_orientation=plan.rack_orientation, rack_tilt_tolerance_deg=plan.rack_tilt_tolerance_deg)
        for key, cap in caps.items():
            worst[key] = max(worst[key], float(np.nanmax(_std(p, key))) / cap)
        if match_full is not None:
            full = full_plan_stds(seed, limits, unit)
            for key in FIGURES:
                # the median over the elements: M's elements differ by design (poses against the rest's axis)
                ratio = float(np.nanmedian(_std(p, key) / full[key])) / match_full
                worst[f"{key} / full"] = max(worst[f"{key} / full"], ratio * margin)
        resolved &= bool(np.all(np.isfinite(p.gyro.correlation_time_s)))
    meets = resolved and all(v <= margin for v in worst.values())
    return Candidate(plan, rig_time_s(plan), worst, resolved, meets)


def design(
    limits: LimitsFile,
    *,
    rack_times_s: Sequence[float] = (1800.0, 2700.0, 3600.0),
    pose_holds_s: Sequence[float] = (15.0, 20.0, 25.0, 30.0),
    seeds: Sequence[int] = (31, 32, 33),
    margin: float = 0.8,
    match_full: float | None = None,
    rack_orientation: str = ANY_ORIENTATION,
    rack_tilt_tolerance_deg: float = RACK_TILT_TOLERANCE_DEG,
) -> tuple[Candidate | None, list[Candidate]]:
    """The chosen plan (None when no candidate meets the limits) and every candidate evaluated; every candidate
    carries ``rack_orientation`` and ``rack_tilt_tolerance_deg`` (how the line's rack holds its units)."""
    tried: list[Candidate] = []
    for rack_s in rack_times_s:
        for hold in sorted(pose_holds_s):
            plan = LinePlan(rack_s=float(rack_s), rig=replace(line_rig_plan(), pose_hold_s=float(hold)),
                            rack_orientation=rack_orientation, rack_tilt_tolerance_deg=rack_tilt_tolerance_deg)
            try:
                cand = evaluate(plan, limits, seeds, margin, match_full)
            except StationError:
                continue
            tried.append(cand)
            if cand.meets:
                break
    ok = [c for c in tried if c.meets]
    best = min(ok, key=lambda c: (c.rig_s, c.plan.rack_s)) if ok else None
    return best, tried


@dataclass(frozen=True)
class Throughput:
    """Units per hour of the line's stations (loading and unloading not included)."""

    rig_per_unit_s: float
    rig_units_per_h: float
    rack_units_per_h: float
    line_units_per_h: float


def throughput(candidate: Candidate, rig_units: int, rack_slots: int) -> Throughput:
    """The rig runs ``rig_units`` per run; the rack holds ``rack_slots`` for ``rack_s`` plus the rig's wait."""
    per_unit = candidate.rig_s / rig_units
    rig_h = 3600.0 / per_unit
    rack_h = rack_slots * 3600.0 / candidate.plan.rack_s
    return Throughput(per_unit, rig_h, rack_h, min(rig_h, rack_h))


__all__ = [
    "FIGURES",
    "RIG_REST_S",
    "STEP_OVERHEAD_S",
    "Candidate",
    "Throughput",
    "design",
    "evaluate",
    "full_plan_stds",
    "rig_time_s",
    "throughput",
]
