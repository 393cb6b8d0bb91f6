"""Checks of the forward selection that hold when the model is wrong, and what stays unexplained.

The nested tests of :mod:`station.diagnose.likelihood` assume the extended model is right. When it is
not (an effect whose shape a candidate only approximates, or physics outside the library), the
structure it leaves passes other candidates' tests. After the forward selection, per sensor:

1. **Dispersion of the final model per segment kind** (quasi-likelihood): the block innovations
   (the GLS residual whitened by the Cholesky factor of the block covariance, one per block) are
   grouped by segment kind (rest, pose, rate, move) and axis; their mean square ``phi`` is the
   dispersion (1 when the model is right).
2. **Drop-one re-test under the dispersion**: every accepted effect is tested again against the
   full final model without it, with the white block noise inflated by ``max(1, phi)`` of its
   block's kind and axis, and the drift's T_c and q re-fitted for both models (a drift noise fitted
   with the effect in would make its absence look worse than it is). An effect that only lives on
   structure another effect's imperfect model (or unexplained physics) left behind loses its
   significance there and is rejected.
3. **Unexplained**: where the final model's innovations stay above the noise (per kind and axis,
   chi^2 tail below :data:`ALPHA_UNEXPLAINED` and ``phi`` above :data:`PHI_UNEXPLAINED`), or where
   the sample residual in the rate-table holds follows the table's angle (a term periodic at the
   spin frequency: no candidate of the library is), the location is reported. An accepted effect
   whose fitted signal lies mostly (:data:`STAND_IN_SHARE`) in unexplained cells of its sensor is
   taken for a stand-in of that physics and rejected.

Confidence of a finding: the drop-one quasi-likelihood gain over its threshold
(``high`` at 4x or more, ``medium`` at 1.5x, else ``low``). A ``low`` one next to an effect
:data:`DOMINANT` times stronger on the same sensor is rejected (the dominant model's imperfection).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy import linalg, stats

from station.diagnose.likelihood import SensorProblem, Test, WalkConsistency
from station.diagnose.residuals import Baseline, SensorData
from station.diagnose.results import Confidence, Rejection, Unexplained
from station.session.model import Kind

#: Tail probability below which a cell's excess chi^2 counts as unexplained.
ALPHA_UNEXPLAINED = 1e-6
#: ... and its dispersion must exceed this (model imperfections of a few per cent are not physics).
PHI_UNEXPLAINED = 1.5
#: An accepted effect with at least this share of its whitened fitted signal's energy in unexplained cells
#: is a stand-in for the unexplained physics.
STAND_IN_SHARE = 0.5
#: A finding whose drop-one gain is below ``MARGINAL`` times its threshold while another finding of the sensor
#: is ``DOMINANT`` times stronger is rejected: a model that fits a signal of chi^2 G to 99.99 % leaves G / 1e4.
MARGINAL = 1.5
DOMINANT = 100.0
AX = "xyz"
def stand_ins(names: Sequence[str], accepted: Sequence[np.ndarray], x: np.ndarray, beta: np.ndarray, nbase: int,
              rows: np.ndarray) -> list[str]:
    """The accepted effects (``names``, regressor blocks ``accepted`` after the ``nbase`` base columns of the
    whitened design ``x``, coefficients ``beta``) whose fitted signal lies mostly (:data:`STAND_IN_SHARE` of its
    energy) in the design rows ``rows`` (a boolean mask): stand-ins for structure located there. Nuisance terms
    are never one."""
    out: list[str] = []
    col = nbase
    for name, zb in zip(names, accepted, strict=True):
        p = zb.shape[2]
        sig = x[:, col:col + p] @ beta[col:col + p]
        col += p
        if name.startswith(NUISANCE):
            continue
        e = float(sig @ sig)
        if e > 0 and float(sig[rows] @ sig[rows]) / e >= STAND_IN_SHARE:
            out.append(name)
    return out


#: Prefix of an accepted term that no finding names (see :data:`station.diagnose.selection.NUISANCE`).
NUISANCE = "~"


@dataclass
class Audit:
    """What the checks keep: confidence per kept effect, rejections, unexplained locations."""

    confidence: dict[str, Confidence] = field(default_factory=dict)
    rejected: list[Rejection] = field(default_factory=list)
    unexplained: list[Unexplained] = field(default_factory=list)


def innovations(prob: SensorProblem) -> np.ndarray:
    """Whitened GLS residual of the current model per block and axis, (m, 3) (1 = noise)."""
    chols, yw = prob.whitened()
    x, _ = prob.design(chols, prob.accepted)
    beta, *_ = linalg.lstsq(x, yw, check_finite=False)
    return (yw - x @ beta).reshape(3, prob.m).T


def dispersion(prob: SensorProblem) -> tuple[np.ndarray, dict[str, list[float]]]:
    """Per block and axis the dispersion of its kind (>= 1), and the table kind -> per-axis mean square."""
    z = innovations(prob)
    phi = np.ones_like(z)
    table: dict[str, list[float]] = {}
    for kind in Kind:
        sel = prob.sd.kind == int(kind)
        if sel.sum() < 3:
            continue
        ms = np.mean(z[sel] ** 2, axis=0)
        table[kind.label] = [float(v) for v in np.round(np.asarray(ms, dtype=float), 3)]
        phi[sel] = np.maximum(ms, 1.0)[None, :]
    return phi, table


def _walk_summary(cons: WalkConsistency) -> dict[str, float]:
    """The z-scores of :meth:`station.diagnose.likelihood.SensorProblem.walk_consistency` for the report."""
    return dict(cons.z)


def _confidence(gain: float, threshold: float) -> str:
    r = gain / threshold if threshold > 0 else math.inf
    return "high" if r >= 4.0 else "medium" if r >= 1.5 else "low"


@dataclass(frozen=True, eq=False)
class SpinPeriodic:
    """:func:`periodic_in_spin`: chi^2 per axis of the cos/sin terms of the rate table's angle, its degrees of
    freedom (2 per hold) and the rms amplitude per axis (sensor units, SI)."""

    chi2: np.ndarray
    dof: int
    amplitude: np.ndarray


def periodic_in_spin(baseline: Baseline, sd: SensorData, fitted: np.ndarray) -> SpinPeriodic | None:
    """Sample residual (minus the accepted effects' ``fitted`` signal, (n, 3)) in the rate-table holds against
    the table's angle: per hold and axis the least-squares cos/sin amplitude of the angle integrated from the
    rate reference, summed to a chi^2 per axis (2 per hold). None without rate holds."""
    session = baseline.session
    rate = session.ref_gyro_radps  # NaN -> 0 a segment at a time (no (n, 3) copy)
    chi = np.zeros(3)
    amp2 = np.zeros(3)
    dof = 0
    for seg in session.segments():
        if seg.kind != Kind.RATE or len(seg) < 50:
            continue
        sl = seg.slice
        w = np.linalg.norm(np.nan_to_num(rate[sl]), axis=1)
        if np.median(w) < 1e-3:
            continue
        t = session.t_s[sl]
        ang = np.concatenate([[0.0], np.cumsum(0.5 * (w[1:] + w[:-1]) * np.diff(t))])
        if ang[-1] < 2.0 * math.pi:
            continue
        keep = sd.keep[sl]
        r = (sd.residual[sl] - fitted[sl])[keep]
        x = np.column_stack([np.ones(keep.sum()), np.cos(ang[keep]), np.sin(ang[keep]), t[keep] - t[keep].mean()])
        beta, *_ = np.linalg.lstsq(x, r, rcond=None)
        fit = x[:, 1:3] @ beta[1:3]
        chi += np.sum(fit**2, axis=0) / sd.sigma**2
        amp2 += np.sum(beta[1:3] ** 2, axis=0) * len(seg)
        dof += 2
    if dof == 0:
        return None
    n_all = sum(len(s) for s in session.segments() if s.kind == Kind.RATE)
    return SpinPeriodic(chi, dof, np.sqrt(amp2 / max(n_all, 1)))


def audit(prob: SensorProblem, baseline: Baseline, names: list[str], regs: dict[str, np.ndarray],
          random_walk: Test | None, fitted_samples: np.ndarray) -> Audit:
    """Run the checks of the module docstring on the final model of one sensor.

    ``prob``: the :class:`station.diagnose.likelihood.SensorProblem` with the accepted mean effects (block
    regressors ``regs[name]`` in the order of ``names``) and, with ``random_walk`` (its Test), the walk;
    ``fitted_samples``: the accepted mean effects' fitted signal per sample (n, 3) for the periodic check.
    """
    sd = prob.sd
    out = Audit()
    gyro = sd.sensor == "gyro"
    factor, unit = (180.0 / math.pi, "deg/s") if gyro else (1.0, "m/s^2")
    # --- unexplained cells of the final model ---
    phi, table = dispersion(prob)
    z = innovations(prob)
    bad_cells: set[tuple[int, int]] = set()
    for kind in Kind:
        sel = sd.kind == int(kind)
        if sel.sum() < 3:
            continue
        for k in range(3):
            chi = float(np.sum(z[sel, k] ** 2))
            if chi / sel.sum() > PHI_UNEXPLAINED and stats.chi2.sf(chi, int(sel.sum())) < ALPHA_UNEXPLAINED:
                bad_cells.add((int(kind), k))
    per = periodic_in_spin(baseline, sd, fitted_samples)
    periodic_axes = []
    if per is not None:
        for k in range(3):
            if stats.chi2.sf(per.chi2[k], per.dof) < ALPHA_UNEXPLAINED and per.chi2[k] > 3.0 * per.dof:
                periodic_axes.append(k)
                bad_cells.add((int(Kind.RATE), k))
                bad_cells.add((int(Kind.MOVE), k))
    # --- stand-ins: accepted effects living in the unexplained cells ---
    stand_in: set[str] = set()
    if bad_cells and names:
        chols, _ = prob.whitened()
        x, nbase = prob.design(chols, prob.accepted)
        yw = prob.whitened()[1]
        beta, *_ = linalg.lstsq(x, yw, check_finite=False)
        cell_of_row = np.concatenate([[(int(sd.kind[i]), k) for i in range(prob.m)] for k in range(3)])
        in_bad = np.array([(int(a), int(b)) in bad_cells for a, b in cell_of_row])
        stand_in.update(stand_ins(names, prob.accepted, x, beta, nbase, in_bad))
    # --- drop-one re-test of every accepted effect under the dispersion ---
    with prob.inflated_noise(phi):
        for i, name in enumerate(names):
            if name.startswith(NUISANCE):  # an inseparable pair's signal: part of the model, named by no finding
                continue
            with prob.without(i) as zb:
                t = prob.test_mean(name, zb, profile=True)
            if name in stand_in:
                out.rejected.append(Rejection(name, sd.sensor, "a stand-in: most of its fitted signal lies where "
                                              "structure stays unexplained (see unexplained)",
                                              {"gain": round(t.gain, 3)}))
            elif not t.passes:  # (the held-out gate was the forward selection's; here only the significance)
                why = ("not significant against the full model with the noise inflated by the final model's "
                       "dispersion per segment kind (misspecification)")
                if t.walk_explains:
                    why += (f"; with a bias random walk allowed its gain is {t.gain_given_walk:.3g}: a slow wander "
                            "explains it as well")
                out.rejected.append(Rejection(name, sd.sensor, why, {"gain": round(t.gain, 3),
                                                                     "threshold": round(t.threshold, 3)}))
            else:
                out.confidence[name] = Confidence(_confidence(t.gain, t.threshold), round(t.gain, 2),
                                                  round(t.threshold, 2))
        if random_walk is not None:
            with prob.random_walk_off():
                t = prob.test_random_walk(size=False)  # the decision and its gain only
            cons = prob.walk_consistency()
            if t.passes and not bad_cells and cons.consistent:
                out.confidence["bias_random_walk"] = Confidence(_confidence(t.gain, t.threshold), round(t.gain, 2),
                                                                round(t.threshold, 2), _walk_summary(cons))
            elif t.passes and not bad_cells:
                out.rejected.append(Rejection(
                    "bias_random_walk", sd.sensor, "not the same wander throughout the record (its K^2 differs "
                    "between the halves, between increments inside and across segments, while the temperature "
                    "rises and falls, or between the axes): structure of a mean effect, not a random walk",
                    {"gain": round(t.gain, 3), "consistency": _walk_summary(cons)}))
            else:
                out.rejected.append(Rejection(
                    "bias_random_walk", sd.sensor, "not significant under the final model's dispersion, or a wander "
                    "that stands in for unexplained structure", {"gain": round(t.gain, 3)}))
    # --- a marginal effect next to a dominant one: the dominant model's imperfection can leave that much ---
    gains = {n: c.gain for n, c in out.confidence.items()}
    for name, c in list(out.confidence.items()):
        dominant = max((g for n, g in gains.items() if n != name), default=0.0)
        if c.gain < MARGINAL * c.limit and dominant >= DOMINANT * c.gain:
            del out.confidence[name]
            out.rejected.append(Rejection(
                name, sd.sensor, f"marginal (chi2 gain below {MARGINAL:g}x its threshold) next to an effect "
                f"{DOMINANT:g}x stronger, whose model's imperfection can leave that much",
                {"gain": c.quasi_gain_chi2, "threshold": c.threshold}))
    # --- locate what stays unexplained ---
    if bad_cells:
        kinds = sorted({Kind(cell).label for cell, _ in bad_cells})
        axes = sorted({k for _, k in bad_cells})
        excess = 0.0
        for cell, k in bad_cells:
            sel = sd.kind == cell
            excess += float(np.sum(z[sel, k] ** 2)) - float(sel.sum())
        if periodic_axes and per is not None:
            amp = ", ".join(f"{AX[k]} {per.amplitude[k] * factor:.3g}" for k in periodic_axes)
            cov = f"periodic at the rate table's spin frequency (amplitude {amp} {unit})"
            periodic = {"axes": [AX[k] for k in periodic_axes], "chi2": np.round(per.chi2, 1).tolist(),
                        "dof": per.dof, "amplitude": np.round(per.amplitude * factor, 6).tolist(),
                        "unit": unit}
        else:
            cov = _covariate(prob, baseline, z, bad_cells)
            periodic = None
        out.unexplained.append(Unexplained(sd.sensor, tuple(AX[k] for k in axes), tuple(kinds), cov, table,
                                           max(excess, 0.0), periodic))
    return out


def _covariate(prob: SensorProblem, baseline: Baseline, z: np.ndarray, cells: set[tuple[int, int]]) -> str:
    """The block covariate the unexplained innovations follow most closely (|correlation|)."""
    sd = prob.sd
    rate = sd.block_mean(np.nan_to_num(baseline.session.ref_gyro_radps))
    force = sd.block_mean(np.nan_to_num(baseline.session.ref_accel_mps2))
    temp = sd.block_mean(baseline.d_temp)
    best = ("no simple covariate (time, temperature, rate, |rate|, specific force)", 0.0)
    for c, k in cells:
        sel = sd.kind == c
        if sel.sum() < 4:
            continue
        cols = {"time": sd.t_s, "temperature": temp, "rate": rate[:, k], "|rate|": np.abs(rate[:, k]),
                "rate^2 (other axes)": np.sum(rate**2, axis=1) - rate[:, k] ** 2, "specific force": force[:, k]}
        for name, v in cols.items():
            a, b = z[sel, k], v[sel]
            if np.ptp(b) == 0:
                continue
            r = float(np.corrcoef(a, b)[0, 1])
            if abs(r) > abs(best[1]) and abs(r) > 0.5:
                best = (f"follows {name} (correlation {r:+.2f})", r)
    return best[0]


__all__ = ["ALPHA_UNEXPLAINED", "PHI_UNEXPLAINED", "Audit", "Unexplained", "audit", "dispersion", "innovations"]
