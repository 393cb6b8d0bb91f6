"""The plan designer's predicted accuracy against the measured one (a part of ``bench_line.py``).

Predicted: what ``station plan`` uses to choose a plan (:mod:`station.sim.plan_design`): the joint fit's
stated standard uncertainties (its likelihood's information) on the designer's own simulated units (seeds
31, 32, 33, their noise and drift stratified over the class: ``plan_design.design_units``) for the plan, per
parameter element the RMS over those units. Measured: on ``n`` other units
(report seeds) simulated through the same plan and fitted the same way, per element the RMS over the units of
the error (estimate - truth). Per parameter group (M, b_stat, b_drift, T_c of each triad) both are the RMS
over the group's elements; the ratio measured / predicted is 1 where the prediction holds.

A second comparison takes the designer's units out: the same fit's stated std on the measured units
themselves (the Fisher information of each unit) against their errors.

"Agrees" is decided by a rule fixed before the report seeds were drawn: the ratio lies within the 95 %
interval a correct prediction would give with that many errors, sqrt(chi2(q; m) / m) for q = 0.025, 0.975
and m = units x elements (taken as independent: optimistic, the elements of one unit are correlated).
T_c and b_drift are compared on the axes whose T_c the fit resolved only (an unresolved T_c is flagged by the
fit, not a number).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.stats import chi2

from station.fit.calibrate import FitOptions
from station.fit.joint import fit_joint
from station.kernel.line_plan import LinePlan
from station.kernel.parameters import ParameterSet
from station.physics.unit import UnitTruth
from station.sim.line_sim import simulate_line
from station.sim.plan_design import design_units

#: (group label, triad, parameter name, display factor, display unit)
GROUPS = (
    ("accel M", "accel", "misalignment", 1e6, "ppm"),
    ("accel b_stat", "accel", "bias_static", 1e3, "mm/s^2"),
    ("accel b_drift", "accel", "bias_drift", 1e3, "mm/s^2"),
    ("accel T_c", "accel", "correlation_time_s", 1.0, "s"),
    ("gyro M", "gyro", "misalignment", 1e6, "ppm"),
    ("gyro b_stat", "gyro", "bias_static", 180.0 / np.pi * 3600.0, "deg/h"),
    ("gyro b_drift", "gyro", "bias_drift", 180.0 / np.pi * 3600.0, "deg/h"),
    ("gyro T_c", "gyro", "correlation_time_s", 1.0, "s"),
)
DESIGN_SEEDS = (31, 32, 33)


@dataclass(frozen=True)
class GroupRow:
    group: str
    unit: str
    predicted: float
    predicted_spread: tuple[float, float]
    measured: float
    stated_report: float
    n: int
    interval: tuple[float, float]

    @property
    def ratio(self) -> float:
        return self.measured / self.predicted

    @property
    def ratio_stated(self) -> float:
        return self.measured / self.stated_report

    @property
    def agrees(self) -> bool:
        lo, hi = self.interval
        return lo <= self.ratio <= hi

    @property
    def agrees_stated(self) -> bool:
        lo, hi = self.interval
        return lo <= self.ratio_stated <= hi


def _values(p: ParameterSet | UnitTruth, triad: str, name: str) -> np.ndarray:
    return np.asarray(getattr(getattr(p, triad), name), dtype=float).reshape(-1)


def _stds(p: ParameterSet, triad: str, name: str) -> np.ndarray:
    return np.asarray(getattr(getattr(p, triad), f"{name}_std"), dtype=float).reshape(-1)


def _tc_mask(p: ParameterSet, triad: str, name: str) -> np.ndarray:
    """Elements that carry a number: all, but for T_c and b_drift the axes whose T_c the fit resolved."""
    tc = np.asarray(getattr(p, triad).correlation_time_s, dtype=float)
    if name in ("correlation_time_s", "bias_drift"):
        return np.isfinite(tc)
    return np.ones(np.asarray(getattr(getattr(p, triad), name)).size, dtype=bool)


def fit_unit(seed: int, plan: LinePlan, options: FitOptions,
             unit: UnitTruth | None = None) -> tuple[ParameterSet, UnitTruth]:
    line = simulate_line(seed, plan=plan, unit=unit)
    return fit_joint(line.rack, line.rig, options, max_transfer_s=plan.max_transfer_s), line.truth


def compare(plan: LinePlan, options: FitOptions, seeds: Sequence[int],
            progress: bool = True) -> list[GroupRow]:
    design = [fit_unit(s, plan, options, u)[0] for s, u in zip(DESIGN_SEEDS, design_units(DESIGN_SEEDS), strict=True)]
    fits = []
    for i, s in enumerate(seeds):
        fits.append(fit_unit(s, plan, options))
        if progress:
            print(f"  predicted vs measured: unit {i + 1}/{len(seeds)} (seed {s})", flush=True)
    rows = []
    for label, triad, name, factor, unit in GROUPS:
        pred_units = []
        for p in design:
            sd = np.where(_tc_mask(p, triad, name), _stds(p, triad, name), np.nan)
            pred_units.append(sd)
        pred_el = np.sqrt(np.nanmean(np.square(pred_units), axis=0))  # per element, RMS over design units
        predicted = float(np.sqrt(np.nanmean(np.square(pred_el))))
        per_design = [float(np.sqrt(np.nanmean(np.square(u)))) for u in pred_units]
        errs, stated = [], []
        for p, truth in fits:
            mask = _tc_mask(p, triad, name)
            e = (_values(p, triad, name) - _values(truth, triad, name))[mask]
            errs.append(e)
            stated.append(_stds(p, triad, name)[mask])
        e_all = np.concatenate(errs)
        s_all = np.concatenate(stated)
        m = int(e_all.size)
        measured = float(np.sqrt(np.mean(np.square(e_all)))) if m else float("nan")
        lo, hi = (float(np.sqrt(chi2.ppf(q, m) / m)) if m else float("nan") for q in (0.025, 0.975))
        rows.append(GroupRow(label, unit, predicted * factor, (min(per_design) * factor, max(per_design) * factor),
                             measured * factor, float(np.sqrt(np.mean(np.square(s_all)))) * factor if m else
                             float("nan"), m, (lo, hi)))
    return rows


def print_table(rows: Sequence[GroupRow], n_units: int) -> None:
    print(f"\npredicted (designer: stated std on its units {', '.join(map(str, DESIGN_SEEDS))}) against measured "
          f"(RMS error vs truth over {n_units} units):\n")
    print("| group | predicted std (designer) | its 3 units min-max | measured RMS error | measured / predicted "
          "| agrees | stated std on these units | measured / stated | agrees | 95 % interval if equal |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        if r.n == 0:
            print(f"| {r.group} | {r.predicted:.4g} {r.unit} | - | not determined on any axis |" + " - |" * 6)
            continue
        print(f"| {r.group} | {r.predicted:.4g} {r.unit} | {r.predicted_spread[0]:.4g}-{r.predicted_spread[1]:.4g} "
              f"| {r.measured:.4g} (n={r.n}) | {r.ratio:.2f} | {'yes' if r.agrees else 'NO'} | {r.stated_report:.4g} "
              f"| {r.ratio_stated:.2f} | {'yes' if r.agrees_stated else 'NO'} "
              f"| {r.interval[0]:.2f}-{r.interval[1]:.2f} |")


__all__ = ["DESIGN_SEEDS", "GROUPS", "GroupRow", "compare", "fit_unit", "print_table"]
