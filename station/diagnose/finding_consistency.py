"""Effect-specific consistency checks of the accepted findings.

A physical effect has one set of parameters for the whole recording; structure that another
effect's imperfect model (or physics outside the library) left behind usually does not. Per
finding, the recording's blocks are split in two parts that each reach the effect's signal in a
different way, and the parameters are compared between the parts:

Which splits an effect is checked on is part of its registry entry
(:attr:`station.diagnose.effect_registry.Effect.consistency`; ``not_checked`` says why an effect has none):

* ``tumbles_vs_ramps`` (``time_offset``): the rig's tumbles (moves that turn gravity in the sensor
  frame) against the rate ramps and other changes of the reference (the table spinning up and down
  about a fixed axis);
* ``poses_vs_rates`` (``g_sensitivity``): the static poses (and rest) against the rate steps and moves;
* ``early_vs_late`` (temperature effects, ``earth_rotation``): the early against the late part of
  the recording, split where half of the effect's (whitened) signal energy is reached;
* ``low_vs_high_input`` (scale terms, ``lever_arm``): low against high input magnitudes (rates, for
  the gyroscope and the lever arm), split at the signal energy's median magnitude;
* ``negative_vs_positive_input`` (scale terms): negative against positive inputs;
* ``heating_vs_cooling`` (``temperature_bias``): the blocks where the temperature rises (or stays) against those
  where it falls (its slope over :data:`TEMP_SLOPE_WINDOW_S`). A bias that is a function of the temperature is the
  same function both ways; one that lags or has a play (hysteresis) differs at equal temperature, and a
  temperature bias fitted to it leaves part of it to the other part's coefficient.

A check runs only where both parts hold at least :data:`REACH` of the finding's signal energy; where
not (e.g. a recording without tumbles), it is reported ``not checked`` with the reason.

The statistic (a Wald test of a deviation, in the final model): the finding's regressor ``Z`` is kept
for all blocks and ``Z`` restricted to part B is added, so its coefficient ``delta`` is part B's
parameters minus part A's; every other accepted term and the base model's linear terms stay, fitted
jointly (the drift's T_c and q at the final model's values, the white block noise inflated by the
final model's dispersion per segment kind, :func:`station.diagnose.robust.dispersion`). The identifiable
directions of ``delta`` are those of the part of ``Z_B``'s columns that the rest of the model does not
span (SVD, ``u_i``, ``s_i``, ``v_i``); per direction the whitened residual's projection ``e_i`` gives the
estimate ``e_i / s_i`` of ``v_i . delta`` with standard error ``1 / s_i``. A candidate model only
approximates the physics, so a relative disagreement up to :data:`TOLERANCE` of the finding's own
parameters is allowed: ``chi2 = sum e_i^2 / (1 + (s_i TOLERANCE |v_i| . |theta|)^2)`` with as many
degrees of freedom as directions. The finding fails the check when ``chi2`` exceeds the chi^2 critical
value at :data:`ALPHA` (then it is rejected: structure the two parts disagree on is not the effect).

A check is *informative* only where part B could have shown a disagreement as large as the finding
itself: the same statistic for ``delta = -theta`` (part B showing nothing) must exceed the critical value
(``power_chi2``). An uninformative check is reported and does not count for or against the finding.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy import linalg, stats
from scipy.ndimage import uniform_filter1d

from station.diagnose import robust
from station.diagnose.effect_registry import REGISTRY, SHAPES, unit_factor
from station.diagnose.likelihood import RCOND, SensorProblem
from station.diagnose.residuals import Baseline
from station.diagnose.results import CheckEntry, Rejection, Unexplained
from station.diagnose.robust import AX
from station.session.model import Kind

#: Significance of a consistency check (chi^2 tail): a finding fails below it.
ALPHA = 1e-3
#: Relative disagreement between the parts that a finding's imperfect candidate model may show.
TOLERANCE = 0.15
#: A specific force that changes faster than this (m/s^3, block mean) marks a tumble (gravity turning).
TUMBLE_MPS3 = 0.2
#: Directions of the deviation whose singular value is below this fraction of its columns' norm are not
#: identifiable (the rest of the model spans them).
RANK_TOL = 1e-6

#: What part A and part B of each split are, for the report.
PARTS: dict[str, tuple[str, str]] = {
    "tumbles_vs_ramps": ("tumbles (gravity turning)", "rate ramps and other moves"),
    "poses_vs_rates": ("rest and poses", "rate steps and moves"),
    "early_vs_late": ("early part", "late part"),
    "low_vs_high_input": ("low input magnitudes", "high input magnitudes"),
    "negative_vs_positive_input": ("negative inputs", "positive inputs"),
    "heating_vs_cooling": ("heating (temperature rising or steady)", "cooling (temperature falling)"),
}
#: Short labels of the splits for the CLI table.
SHORT: dict[str, str] = {
    "tumbles_vs_ramps": "tumbles/ramps", "poses_vs_rates": "poses/rates", "early_vs_late": "halves",
    "low_vs_high_input": "low/high input", "negative_vs_positive_input": "-/+ input",
    "heating_vs_cooling": "heating/cooling",
}
#: The temperature's slope (heating or cooling) is taken over this window (s): the sensor's reading is quantized.
TEMP_SLOPE_WINDOW_S = 30.0
#: A part holding less than this share of the finding's whitened signal energy does not reach it.
REACH = 0.02


@dataclass(frozen=True)
class Check:
    """One consistency check of one finding (see the module docstring).

    ``split``: a :data:`PARTS` name, or ``None`` for an effect the registry gives no check (``reason`` says why).
    ``dof == 0``: the check could not run on this recording (``reason`` says why: a part the finding's signal
    does not reach). ``part_a`` / ``part_b``: the finding's parameters fitted on each part alone (per-axis and
    scalar effects), engineering units.
    """

    effect: str
    sensor: str
    split: str | None
    chi2: float = 0.0
    dof: int = 0
    critical: float = 0.0
    power_chi2: float = 0.0
    part_a: dict[str, Any] | None = None
    part_b: dict[str, Any] | None = None
    reason: str = ""

    @property
    def checked(self) -> bool:
        return self.split is not None and self.dof > 0

    @property
    def informative(self) -> bool:
        return self.checked and self.power_chi2 > self.critical

    @property
    def p_value(self) -> float:
        return float(stats.chi2.sf(self.chi2, self.dof)) if self.dof > 0 else 1.0

    @property
    def passes(self) -> bool:
        return not self.informative or self.chi2 <= self.critical

    @property
    def result(self) -> str:
        """``passed``, ``failed``, ``not informative`` (part B could not have shown a disagreement as large as
        the finding) or ``not checked`` (see ``reason``)."""
        if not self.checked:
            return "not checked"
        return "not informative" if not self.informative else "passed" if self.passes else "failed"

    @property
    def summary(self) -> str:
        """One short line for the CLI table."""
        if self.split is None:
            return "not checked"
        label = SHORT[self.split]
        if not self.checked:
            return f"{label}: not checked"
        return f"{label}: {self.result} (p {self.p_value:.2g})"

    def entry(self) -> CheckEntry:
        """This check as the finding's report entry."""
        if self.split is None:
            return CheckEntry(None, "not checked", reason=self.reason)
        parts = PARTS[self.split]
        if not self.checked:
            return CheckEntry(self.split, self.result, parts, reason=self.reason)
        reason = None
        if self.result == "not informative":
            reason = (f"{parts[1]} could not have shown a disagreement as large as the finding "
                      f"(power chi2 {self.power_chi2:.1f} <= {self.critical:.1f})")
        return CheckEntry(self.split, self.result, parts, chi2=round(self.chi2, 2), dof=self.dof,
                          critical_chi2=round(self.critical, 2), p_value=float(f"{self.p_value:.3g}"),
                          power_chi2=round(self.power_chi2, 1), tolerance=TOLERANCE, reason=reason,
                          part_a=self.part_a, part_b=self.part_b if self.part_a is not None else None)


def _block_masks(prob: SensorProblem, baseline: Baseline, split: str, name: str,
                 energy: np.ndarray) -> np.ndarray | None:
    """Block mask of part B of ``split`` for finding ``name`` (energy: its whitened signal energy per block)."""
    sd = prob.sd
    session = baseline.session
    if split == "tumbles_vs_ramps":
        f = np.nan_to_num(session.ref_accel_mps2)
        df = np.linalg.norm(np.gradient(f, session.t_s, axis=0), axis=1)
        return sd.block_mean(df) <= TUMBLE_MPS3
    if split == "poses_vs_rates":
        return np.isin(sd.kind, [int(Kind.RATE), int(Kind.MOVE)])
    if split == "heating_vs_cooling":
        fs = session.sample_rate_hz
        w = max(3, int(TEMP_SLOPE_WINDOW_S * fs) | 1)
        slope = np.gradient(uniform_filter1d(np.asarray(baseline.d_temp, dtype=float), w, mode="nearest"),
                            session.t_s)
        return sd.block_mean(slope) < 0.0
    if split == "early_vs_late":
        order = np.argsort(sd.t_s, kind="stable")
        cum = np.cumsum(energy[order])
        if cum[-1] <= 0:
            return None
        cut = sd.t_s[order][int(np.searchsorted(cum, 0.5 * cum[-1]))]
        return sd.t_s > cut
    gyro_like = sd.sensor == "gyro" or name == "lever_arm"
    inp = sd.block_mean(np.nan_to_num(session.ref_gyro_radps)) if gyro_like else sd.block_mean(sd.u)
    if split == "negative_vs_positive_input":
        k = np.argmax(np.abs(inp), axis=1)
        return inp[np.arange(len(k)), k] > 0
    if split == "low_vs_high_input":
        mag = np.round(np.max(np.abs(inp), axis=1), 9)
        order = np.argsort(mag, kind="stable")
        cum = np.cumsum(energy[order])
        if cum[-1] <= 0:
            return None
        ms = mag[order]
        steps = np.flatnonzero(ms[1:] > ms[:-1])  # cut between distinct magnitudes, nearest half the energy
        if not steps.size:
            return np.zeros(len(mag), dtype=bool)
        cut = ms[steps[int(np.argmin(np.abs(cum[steps] - 0.5 * cum[-1])))]]
        return mag > cut
    raise ValueError(f"unknown split {split!r}")


def _part_values(name: str, sensor: str, x_rest: np.ndarray, wa: np.ndarray, wb: np.ndarray,
                 yw: np.ndarray) -> tuple[dict[str, Any], dict[str, Any]] | tuple[None, None]:
    """The finding's parameters fitted per part (columns ``Z`` on A and ``Z`` on B), engineering units; only for
    per-axis or scalar effects."""
    p = wa.shape[1]
    if p > 3 or name in SHAPES:
        return None, None
    x = np.column_stack([x_rest, wa, wb])
    beta, *_ = linalg.lstsq(x, yw, cond=RCOND, check_finite=False)
    cov = linalg.pinv(x.T @ x)
    n0 = x_rest.shape[1]
    factor, unit = unit_factor(name, sensor)
    out = []
    for lo in (n0, n0 + p):
        v = beta[lo:lo + p] * factor
        s = np.sqrt(np.clip(np.diag(cov)[lo:lo + p], 0.0, None)) * factor
        out.append({"value": [float(f"{a:.4g}") for a in v], "std": [float(f"{a:.3g}") for a in s], "unit": unit})
    return out[0], out[1]


#: The final model's fit under the noise a problem has now: (whitening, whitened data, design, base column count,
#: coefficients).
Fitted = tuple[Any, np.ndarray, np.ndarray, int, np.ndarray]


def final_fit(prob: SensorProblem) -> Fitted:
    """:data:`Fitted` of ``prob``'s accepted terms under the noise ``prob`` has now."""
    chols, yw = prob.whitened()
    x0, nbase = prob.design(chols, prob.accepted)
    beta, *_ = linalg.lstsq(x0, yw, cond=RCOND, check_finite=False)
    return chols, yw, x0, nbase, beta


def _not_checked(name: str, sensor: str, split: str, reason: str) -> Check:
    return Check(name, sensor, split, critical=float(stats.chi2.isf(ALPHA, 1)), reason=reason)


def check_finding(prob: SensorProblem, baseline: Baseline, j: int, name: str, split: str,
                  fitted: Fitted | None = None) -> Check:
    """The consistency check ``split`` of accepted term ``j`` (named ``name``) of ``prob``'s final model; the
    noise as ``prob`` has it now (the caller inflates it by the dispersion). ``fitted``: :func:`final_fit` where
    the caller has it."""
    sd = prob.sd
    chols, yw, x0, nbase, beta = final_fit(prob) if fitted is None else fitted
    col = nbase + sum(a.shape[2] for a in prob.accepted[:j])
    zb = prob.accepted[j]
    p = zb.shape[2]
    theta = beta[col:col + p]
    a_name, b_name = PARTS[split]
    # the finding's whitened signal energy per block (where its information lies)
    sig = (x0[:, col:col + p] @ theta).reshape(3, prob.m)
    energy = np.sum(sig**2, axis=0)
    total = float(energy.sum())
    mask_b = _block_masks(prob, baseline, split, name, energy) if total > 0 else None
    if mask_b is None:
        return _not_checked(name, sd.sensor, split, "the finding's fitted signal is zero")
    share_b = float(energy[mask_b].sum()) / total
    if share_b < REACH or not mask_b.any():
        return _not_checked(name, sd.sensor, split, f"its signal does not reach the {b_name} of this recording "
                                                    f"({100 * share_b:.1f} % of its energy)")
    if share_b > 1.0 - REACH or mask_b.all():
        return _not_checked(name, sd.sensor, split, f"its signal does not reach the {a_name} of this recording "
                                                    f"({100 * (1 - share_b):.1f} % of its energy)")
    wb_full, _ = prob.design(chols, [zb * mask_b[:, None, None]])
    wb = wb_full[:, nbase:]
    coef, *_ = linalg.lstsq(x0, wb, cond=RCOND, check_finite=False)
    wp = wb - x0 @ coef
    r = yw - x0 @ beta
    u, s, vt = linalg.svd(wp, full_matrices=False, check_finite=False)
    norm = float(np.linalg.norm(wb, axis=0).max()) if wb.size else 0.0
    keep = s > RANK_TOL * max(norm, 1e-300)
    if norm == 0.0 or not keep.any():
        return _not_checked(name, sd.sensor, split, f"the rest of the model spans the {b_name}' part of it")
    u, s, vt = u[:, keep], s[keep], vt[keep]
    e = u.T @ r
    allow = TOLERANCE * (np.abs(vt) @ np.abs(theta))
    infl = 1.0 + (s * allow) ** 2
    chi2 = float(np.sum(e**2 / infl))
    power = float(np.sum((s * (vt @ theta)) ** 2 / infl))
    dof = int(keep.sum())
    wa_full, _ = prob.design(chols, [zb * (~mask_b)[:, None, None]])
    x_rest = np.delete(x0, np.s_[col:col + p], axis=1)
    part_a, part_b = _part_values(name, sd.sensor, x_rest, wa_full[:, nbase:], wb, yw)
    return Check(name, sd.sensor, split, chi2, dof, float(stats.chi2.isf(ALPHA, dof)), power, part_a, part_b)


def check(prob: SensorProblem, baseline: Baseline, names: list[str],
          fitted: Fitted | None = None) -> dict[str, list[Check]]:
    """All consistency checks of the accepted findings ``names`` (order of ``prob.accepted``; nuisance terms,
    prefixed ``~``, are not checked), the splits each effect's registry entry names
    (:attr:`station.diagnose.effect_registry.Effect.consistency`), on one sensor's final model under the noise ``prob``
    has (``fitted``: :func:`final_fit` where the caller has it); an effect without checks gets one ``not checked``
    entry with the registry's reason."""
    out: dict[str, list[Check]] = {}
    targets = [(j, n) for j, n in enumerate(names) if n in REGISTRY]
    if not targets:
        return out
    fitted = final_fit(prob) if fitted is None else fitted
    for j, name in targets:
        effect = REGISTRY[name]
        if not effect.consistency:
            out[name] = [Check(name, prob.sd.sensor, None, reason=effect.not_checked)]
        for split in effect.consistency:
            out.setdefault(name, []).append(check_finding(prob, baseline, j, name, split, fitted))
    return out


def not_checked(name: str, sensor: str) -> list[Check]:
    """The entry of a finding the selection does not check as a model term (e.g. ``bias_random_walk``,
    ``outliers``): the registry's reason."""
    effect = REGISTRY.get(name)
    reason = effect.not_checked if effect is not None and effect.not_checked else "not a term of the final model"
    return [Check(name, sensor, None, reason=reason)]


def review(prob: SensorProblem, baseline: Baseline, names: list[str], gains: dict[str, float] | None = None
           ) -> tuple[dict[str, list[Check]], Rejection | None, Unexplained | None]:
    """:func:`check` under the final model's dispersion (:func:`station.diagnose.robust.dispersion`), the
    rejection entry of the worst failing finding (None when every informative check passes) and, where that
    finding's drop-one chi^2 gain (``gains``) shows its structure above the noise, where that structure stays
    unexplained (:func:`locate`)."""
    phi, table = robust.dispersion(prob)
    with prob.inflated_noise(phi):
        fitted = final_fit(prob)
        checks = check(prob, baseline, names, fitted)
        worst = failed([c for cs in checks.values() for c in cs])
        where = None
        if worst is not None and gains is not None and gains.get(worst.effect, 0.0) > 0.0:
            where = locate(prob, names.index(worst.effect), worst, gains[worst.effect], table, fitted)
    return checks, (rejection(worst) if worst is not None else None), where


#: A part (axis, segment kind) holding at least this share of a rejected finding's signal energy is where it is.
LOCATE_SHARE = 0.1


def locate(prob: SensorProblem, j: int, c: Check, gain: float, table: dict[str, list[float]],
           fitted: Fitted | None = None) -> Unexplained:
    """Where the structure of accepted term ``j``, rejected by check ``c``, lies: the axes and segment kinds
    holding at least :data:`LOCATE_SHARE` of its whitened fitted signal energy; ``gain``: its chi^2 gain;
    ``fitted``: :func:`final_fit` where the caller has it."""
    _, _, x0, nbase, beta = final_fit(prob) if fitted is None else fitted
    col = nbase + sum(a.shape[2] for a in prob.accepted[:j])
    p = prob.accepted[j].shape[2]
    energy = ((x0[:, col:col + p] @ beta[col:col + p]).reshape(3, prob.m) ** 2).T  # (m, 3)
    total = max(float(energy.sum()), 1e-300)
    axes = tuple(AX[k] for k in range(3) if energy[:, k].sum() / total >= LOCATE_SHARE)
    kinds = tuple(sorted(Kind(k).label for k in np.unique(prob.sd.kind)
                         if energy[prob.sd.kind == k].sum() / total >= LOCATE_SHARE))
    a, b = PARTS[c.split or ""]
    what = f"what the {c.effect} model fits, but {a} and {b} disagree on it"
    if c.part_a and c.part_b:
        def fmt(v: dict[str, Any]) -> str:
            return ", ".join(f"{x:.3g}+-{e:.2g}" for x, e in zip(v["value"], v["std"], strict=False)) + f" {v['unit']}"
        what += f" ({a} {fmt(c.part_a)}; {b} {fmt(c.part_b)})"
    return Unexplained(c.sensor, axes, kinds, what, table, float(gain))


def failed(checks: list[Check]) -> Check | None:
    """The worst failed check (largest chi2 over its critical value), None when all pass."""
    bad = [c for c in checks if not c.passes]
    return max(bad, key=lambda c: c.chi2 / c.critical) if bad else None


def rejection(c: Check) -> Rejection:
    """The rejection of a finding by check ``c``."""
    a, b = PARTS[c.split or ""]
    return Rejection(c.effect, c.sensor, f"inconsistent between {a} and {b} (chi2 {c.chi2:.1f} > {c.critical:.1f} "
                     f"for {c.dof} dof, {100 * TOLERANCE:g} % model tolerance): structure the parts disagree on is "
                     f"not this effect", {"consistency": c.entry().to_json()})


__all__ = [
    "ALPHA",
    "PARTS",
    "TOLERANCE",
    "Check",
    "check",
    "check_finding",
    "failed",
    "final_fit",
    "locate",
    "not_checked",
    "rejection",
    "review",
]
