"""Which covariate an ``unexplained`` axis follows, said so that the words match the physics, or "none".

The locator (:mod:`station.diagnose.locator`) tests one dictionary term at a time on a flagged axis's whitened
residual; a term is *eligible* when it takes :data:`~station.diagnose.locator.COVARIATE_SHARE` of the axis's excess
chi^2 in its located cells at :data:`~station.diagnose.locator.ALPHA_LOCATED`. This module adds, in order:

1. **Inseparable proxies** (:func:`inseparable`). Physical covariates are correlated on a recording (the temperature
   and the time since power-on during a warm-up, ``|rate|`` and ``rate^2`` on a plan with few rates, a rate step's
   decay and the temperature's rate). The strongest term is not the physics when a correlated one explains the same
   structure: for every other strong term ``C`` the best term ``B`` is refitted beside it; when ``B`` adds nothing
   significant given ``C`` (its chi^2 given ``C``, over the dispersion the pair leaves, at least 1, beyond the chi^2(1)
   tail :data:`~station.diagnose.locator.ALPHA_LOCATED`: the level the term was chosen at), the recording cannot tell
   them apart and both are said: "X or Y (inseparable on this recording)". A term that ``B`` does improve on is
   separable and not said.
2. **The family** of the named term(s) (:func:`families`): temperature, rate, specific force, angular acceleration,
   time since a rate step, time since power-on, sample clock, rotation history; said after the term.
3. **Terms of several parameters** where no single term is eligible, each a physical covariate of the issue's
   dictionary that one column cannot carry (tested with its own degrees of freedom, Bonferroni over its variants):
   - :func:`heading_columns`: a direction fixed in the *world* (horizontal; a field like the Earth's magnetic one)
     seen along a body axis, through the attitude integrated from the rig's rate reference (2 parameters: the
     field's two horizontal components); in poses it follows the heading, in table spins the spin phase;
   - :func:`oscillation_columns`: a slow oscillation in time (a cos/sin pair at one period, scanned over periods
     from :data:`OSC_MIN_PERIOD_S` to 2/3 of the recording, half-bin steps): a limit cycle, a periodic disturbance,
     periodic in the time since power-on, not in any rig or climate covariate.
   An eligible one is named with its family (the locator runs these after the sample-level spin test and the jump
   test, before "none").

What the text means (docs/diagnosis-locator.md): "follows X (family)" = X alone takes at least half the located
excess and no tested correlated term explains the same; "follows X or Y (inseparable on this recording)" = both do,
and neither adds significantly to the other; "none: ..." = no term or family of the dictionary takes half of it.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from scipy import linalg, stats

from station.session.model import Kind

#: How many of the strongest other terms are refitted beside the best one for the inseparability test.
TIE_CANDIDATES = 8
#: At most this many inseparable alternatives are said beside the best term (the strongest first).
TIE_SAY = 3
#: Shortest period (s) of the slow-oscillation test: the block means (about a second) and the holds (5-25 s) resolve it.
OSC_MIN_PERIOD_S = 30.0
#: The longest period is this share of the recording (at least 1.5 cycles).
OSC_MAX_SHARE = 2.0 / 3.0

#: Rate setpoints are told apart to this (deg/s) for the level-per-rate test.
RATE_LEVEL_DPS = 1.0

#: Families by the words a dictionary term's name holds (first match of each family; a product has two).
_FAMILY_WORDS: tuple[tuple[str, str], ...] = (
    ("delay growing with time (sample clock rate)", "sample clock"),
    ("time since power-on", "time (since power-on)"),
    ("time since the last rate step", "time since a rate step"),
    ("creep since the last step", "time since a step (creep)"),
    ("settling since the last rate step", "time since a rate step (settling)"),
    ("direction of the last rotation", "rotation history"),
    ("angular acceleration", "angular acceleration"),
    ("temperature rate dT/dt", "temperature (its rate of change)"),
    ("temperature", "temperature"),
    ("specific force", "specific force"),
    ("rate", "rate"),
)


def families(name: str) -> list[str]:
    """The physical families a dictionary term's ``name`` belongs to (e.g. ``rate z * temperature``: rate,
    temperature); the sample clock's term is of that family only (its name holds "rate" and "time" as words)."""
    out: list[str] = []
    rest = name
    for word, fam in _FAMILY_WORDS:
        if word in rest and fam not in out:
            out.append(fam)
            rest = rest.replace(word, " ")
    return out


def with_family(names: Sequence[str]) -> str:
    """``names`` (the best term first, then its inseparable alternatives) as the covariate's words."""
    fams: list[str] = []
    for n in names:
        fams += [f for f in families(n) if f not in fams]
    fam = f" [{' / '.join(fams)}]" if fams else ""
    if len(names) == 1:
        return f"{names[0]}{fam}"
    return (f"{' or '.join(names)} (inseparable on this recording: the first adds nothing significant to the others)"
            f"{fam}")


def inseparable(best: tuple[str, np.ndarray, float, float], tests: Sequence[tuple[str, np.ndarray, float, float]],
                rk: np.ndarray, alpha: float) -> list[str]:
    """Terms of ``tests`` (name, whitened residualized column, coefficient, chi^2 gain) that the ``best`` one does not
    improve on given them: ``B | C``'s chi^2 over the pair's residual dispersion (at least 1) not beyond the chi^2(1)
    tail ``alpha``. The :data:`TIE_CANDIDATES` strongest others are tried; returned by gain, at most :data:`TIE_SAY`."""
    name_b, cb, _, _ = best
    others = sorted((t for t in tests if t[0] != name_b), key=lambda t: -t[3])[:TIE_CANDIDATES]
    nb = float(cb @ cb)
    thr = float(stats.chi2.isf(alpha, 1))
    out: list[str] = []
    for name_c, cc, _, gain_c in others:
        if gain_c <= 0.0:
            continue
        nc = float(cc @ cc)
        if nb <= 0.0 or nc <= 0.0:
            continue
        x = np.column_stack([cb / math.sqrt(nb), cc / math.sqrt(nc)])  # unit columns: the test is scale-free
        g = x.T @ x
        if np.linalg.cond(g) > 1e12:  # the same column: inseparable by construction
            out.append(name_c)
            continue
        beta = np.linalg.solve(g, x.T @ rk)
        both = float(beta @ (x.T @ rk))
        phi = max(1.0, float(np.mean((rk - x @ beta) ** 2)))
        if (both - gain_c) / phi < thr:
            out.append(name_c)
    return out[:TIE_SAY]


def group_gain(cols: np.ndarray, chol: np.ndarray, qk: np.ndarray, rk: np.ndarray) -> tuple[float, np.ndarray]:
    """The chi^2 a group of block covariates ``cols`` (m, d) takes from the axis's whitened residual ``rk`` (m,) once
    whitened by ``chol`` and residualized against the axis's design (orthonormal ``qk``): (gain, the fitted part)."""
    cw = linalg.solve_triangular(chol, cols, lower=True, check_finite=False)
    cw = cw - qk @ (qk.T @ cw)
    beta, *_ = np.linalg.lstsq(cw, rk, rcond=None)
    fitted = cw @ beta
    return float(fitted @ fitted), fitted


def world_directions(session: Any) -> np.ndarray | None:
    """Body components of two horizontal directions fixed in the world, per sample (n, 2, 3): the attitude
    integrated from the rig's rate reference (``ref_gyro_radps``; the exponential map of each step's mean rate, the
    steps composed by a prefix product), the vertical from the reference's specific force at the start. None
    without a rate reference or a still start."""
    rate = np.nan_to_num(np.asarray(session.ref_gyro_radps, dtype=float))
    force = np.nan_to_num(np.asarray(session.ref_accel_mps2, dtype=float))
    t = np.asarray(session.t_s, dtype=float)
    n = len(t)
    if n < 3 or not np.any(rate) or not np.any(force):
        return None
    up = force[: max(1, min(n, 10))].mean(axis=0)
    if np.linalg.norm(up) < 1.0:
        return None
    up = up / np.linalg.norm(up)
    e1 = np.eye(3)[int(np.argmin(np.abs(up)))]
    e1 = e1 - up * (e1 @ up)
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(up, e1)
    # step quaternions exp(0.5 w dt) of each interval's mean rate; Q_i = q_0 (x) ... (x) q_{i-1} (body -> world)
    w = 0.5 * (rate[1:] + rate[:-1]) * np.diff(t)[:, None]
    ang = np.linalg.norm(w, axis=1)
    half = 0.5 * ang
    s = np.where(ang > 1e-12, np.sin(half) / np.where(ang > 1e-12, ang, 1.0), 0.5)
    q = np.concatenate([np.cos(half)[:, None], w * s[:, None]], axis=1)
    q = np.concatenate([[[1.0, 0.0, 0.0, 0.0]], q], axis=0)
    step = 1
    while step < n:  # Hillis-Steele scan: associative, order kept (earlier on the left)
        q[step:] = _qmul(q[:-step], q[step:])
        q[step:] /= np.linalg.norm(q[step:], axis=1, keepdims=True)
        step *= 2
    return np.stack([_rotate_inverse(q, e1), _rotate_inverse(q, e2)], axis=1)


def _qmul(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    pw, px, py, pz = p.T
    qw, qx, qy, qz = q.T
    return np.stack([pw * qw - px * qx - py * qy - pz * qz, pw * qx + px * qw + py * qz - pz * qy,
                     pw * qy - px * qz + py * qw + pz * qx, pw * qz + px * qy - py * qx + pz * qw], axis=1)


def _rotate_inverse(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """R(q)^T v per row of q (body components of the world vector v)."""
    w = q[:, :1]
    u = -q[:, 1:]
    uv = np.cross(u, v)
    return np.asarray(v + 2.0 * w * uv + 2.0 * np.cross(u, uv))


def heading_columns(session: Any, sd: Any) -> dict[str, np.ndarray]:
    """Per body axis ``j`` the block means (m, 2) of the two world-horizontal directions' components along ``j``
    (:func:`world_directions`): a bias ``c (R^T m)_j`` of a world-fixed horizontal field ``m`` is their combination."""
    dirs = world_directions(session)
    if dirs is None:
        return {}
    means = sd.block_mean(dirs.reshape(len(dirs), 6)).reshape(-1, 2, 3)
    return {f"heading: a horizontal direction fixed in the world along body {'xyz'[j]} (attitude, spin phase)":
            means[:, :, j] for j in range(3) if np.ptp(means[:, :, j]) > 0}


def oscillation_columns(session: Any, sd: Any) -> dict[str, np.ndarray]:
    """Block means (m, 2) of cos/sin of ``2 pi t / P`` over the periods ``P`` of the slow-oscillation scan (half-bin
    steps in frequency, :data:`OSC_MIN_PERIOD_S` to :data:`OSC_MAX_SHARE` of the recording), by name."""
    t = np.asarray(session.t_s, dtype=float)
    span = float(t[-1] - t[0]) if len(t) > 1 else 0.0
    out: dict[str, np.ndarray] = {}
    if span <= 0.0:
        return out
    j = 1.5
    while True:
        period = 2.0 * span / (2.0 * j)
        if period < OSC_MIN_PERIOD_S:
            break
        if period <= OSC_MAX_SHARE * span:
            ph = 2.0 * math.pi * (t - t[0]) / period
            out[f"time: a slow oscillation, period {period:.0f} s (periodic in the time since power-on)"] = (
                sd.block_mean(np.column_stack([np.cos(ph), np.sin(ph)])))
        j += 0.5
    return out


def rate_level_columns(session: Any, sd: Any) -> dict[str, np.ndarray]:
    """Indicators (m, d) of the rate-hold blocks at each of the table's ``d`` rate setpoints (the rate reference's
    block mean to :data:`RATE_LEVEL_DPS`): a level per rate, a function of the rate that no power of it need fit (a
    converter's nonlinearity periodic in the output, a resonance at one rate). Empty with fewer than two setpoints."""

    rate = sd.block_mean(np.nan_to_num(np.asarray(session.ref_gyro_radps, dtype=float))) * (180.0 / math.pi)
    hold = sd.kind == int(Kind.RATE)
    if hold.sum() < 3:
        return {}
    keys = np.round(rate[hold] / RATE_LEVEL_DPS).astype(int)
    levels, which = np.unique(keys, axis=0, return_inverse=True)
    if len(levels) < 2:
        return {}
    cols = np.zeros((len(rate), len(levels)))
    cols[np.flatnonzero(hold), np.asarray(which).ravel()] = 1.0
    return {"the table rate, nonlinearly: one level per rate setpoint (a function of the rate no power of it fits)":
            cols}


def spin_scatter(session: Any, residual: Any, k: int, censored: np.ndarray | None = None) -> tuple[float, float]:
    """Axis ``k``'s scatter inside the rate holds against the still segments' (rest, pose): per segment the variance of
    ``residual`` (n, 3) about its own straight line (a bias and a slow drift gone); the largest hold's over the still
    segments' pooled one. Returns (that ratio, its F tail with the hold's and the still segments' degrees of freedom,
    times the number of holds: Bonferroni over the holds). A table's vibration (largest through a resonance, at one
    rate) or a noise that grows with the rate makes a hold's samples scatter more; white or coloured noise and a bias
    do not change the ratio. (nan, 1) without both kinds of segment."""
    still = [0.0, 0]
    holds: list[tuple[float, int]] = []
    for seg in session.segments():
        if seg.kind == Kind.MOVE or len(seg) < 10 or (censored is not None and censored[seg.start]):
            continue
        x = np.asarray(residual[seg.start:seg.stop, k], dtype=float)
        u = np.arange(len(x), dtype=float)
        u -= u.mean()
        e = x - x.mean() - u * (float(u @ x) / float(u @ u))
        if seg.kind == Kind.RATE:
            holds.append((float(e @ e), len(x) - 2))
        else:
            still[0] += float(e @ e)
            still[1] += len(x) - 2
    if not holds or still[1] < 10 or still[0] <= 0.0:
        return math.nan, 1.0
    ref = still[0] / still[1]
    ratio, dof = max(((v / n) / ref, n) for v, n in holds)
    return ratio, min(1.0, len(holds) * float(stats.f.sf(ratio, dof, still[1])))


def best_group(groups: Mapping[str, np.ndarray], chol: np.ndarray, qk: np.ndarray, rk: np.ndarray,
               in_cells: np.ndarray, excess: float, share_min: float, alpha: float) -> tuple[str, float, float] | None:
    """The group of ``groups`` (name -> (m, d) block covariates) with the largest chi^2 on ``rk``, when it is beyond
    the chi^2(d) tail ``alpha`` over the number of groups (Bonferroni over the variants) and takes ``share_min`` of
    the ``excess`` inside ``in_cells``: (name, gain, share); None otherwise."""
    if not groups:
        return None
    scored = []
    for name, cols in groups.items():
        gain, fitted = group_gain(np.asarray(cols, dtype=float).reshape(len(rk), -1), chol, qk, rk)
        scored.append((gain, name, fitted, np.asarray(cols).reshape(len(rk), -1).shape[1]))
    gain, name, fitted, dof = max(scored, key=lambda s: s[0])
    if stats.chi2.sf(gain, dof) >= alpha / len(groups):
        return None
    share = (float(np.sum(rk[in_cells] ** 2)) - float(np.sum((rk - fitted)[in_cells] ** 2))) / excess
    return (name, gain, share) if share >= share_min else None


__all__ = ["OSC_MIN_PERIOD_S", "RATE_LEVEL_DPS", "TIE_CANDIDATES", "TIE_SAY", "best_group", "families", "group_gain",
           "heading_columns", "inseparable", "oscillation_columns", "rate_level_columns", "spin_scatter", "with_family",
           "world_directions"]
