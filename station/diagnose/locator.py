"""Where the final model and the recording disagree, with the base model's stochastic terms held at their class.

The forward selection (:mod:`station.diagnose.selection`) and its checks (:mod:`station.diagnose.robust`) fit
eq. 3's drift noise ``q`` per axis by maximum likelihood without an upper bound. A flexible ``q`` takes up
structure that a deterministic or physical explanation would leave: a bias that jumps between two levels has
the exponential autocorrelation of eq. 3 (eq. 4), a bias that follows the rate or the temperature becomes
"drift noise"; after such a fit the dispersion of the rest and rate blocks is far *below* 1, which nothing
else treats as a symptom. Here, per sensor, after the selection:

1. **Stochastic terms frozen at the sensor class.** ``q`` is bounded by the drift noise of the class of the
   recording's sensor (:class:`DriftClass`: from the limits file in use, :meth:`DriftClass.from_limits`, else the
   station's :data:`station.kernel.sensor_class.TABLE1`): the class's stationary std of eq. 3's noise where it
   gives one, else ``drift_noise_rel`` of ``|b_drift|``, the unit's own warm-up between :data:`B_DRIFT_FLOOR` of
   the class's largest and the largest; :data:`CLASS_MARGIN` times that), T_c stays
   in the class range the selection kept it in, a bias random walk found by the selection stays. The final
   mean model (base terms and the accepted effects) is re-fitted by GLS under that covariance.
2. **Located by segment kind.** Its innovations per block (whitened residual, 1 = noise) are grouped by
   segment kind and axis; a cell whose mean square exceeds :data:`PHI_LOCATED` with a chi^2 tail below
   :data:`ALPHA_LOCATED` holds structure the model cannot explain. ``q`` fitted above the class bound is
   reported with it (``q_over_class``): the free fit had to stretch the drift noise for it. A small effect in a few
   blocks of a kind does not lift the cell's dispersion to :data:`PHI_LOCATED`; so each covariate's own test
   locates too (:func:`_targeted_cells`): the strongest covariate of an axis, its chi^2 over the dispersion left
   beyond the chi^2(1) tail :data:`ALPHA_LOCATED` shared by all covariates of the three axes, locates the kinds
   where the chi^2 it takes is itself significant at :data:`ALPHA_LOCATED`.
3. **The covariate it follows, or none.** Each flagged axis's whitened residual is regressed on one physical
   covariate at a time (:func:`covariates_by_axis`: the rate and its magnitude, powers, angular acceleration, specific
   force, its square, size and sign, temperature, its direction and rate, time since the last rate step, the force and
   the rate through first-order lags (creep, settling after a step), the direction of the last rotation, a delay
   growing with time, the products of a rate component with a specific-force component and with the temperature,
   of the force with the temperature, of the force and the rate with the temperature's rate); one that takes at least
   :data:`COVARIATE_SHARE` of the axis's excess chi^2 in its flagged cells, significant at :data:`ALPHA_LOCATED`, is
   named; otherwise a term periodic at the rate table's spin frequency when a cos/sin of the table's angle takes
   that share of the structure inside the rate holds (sample level, :func:`_spin_periodic`); otherwise a test of the
   drift model's own consequence: its increments are Gaussian; a bias that jumps between levels (telegraph) has a
   few increments of the 0.5 s window means in the still and rate-hold segments beyond 6 robust sigmas
   (:func:`_jumps`); otherwise "none". How the chosen covariate is said (its family, the correlated terms the
   recording cannot tell from it), the scatter test before the jumps and the several-parameter families after them
   (a world-fixed direction, a slow oscillation in time, a level per table rate):
   :mod:`station.diagnose.covariate_choice`.
4. **Empirical model** per flagged axis (:mod:`station.diagnose.empirical`): a sparse model over the covariate
   dictionary chosen on held-out segments, reported as "empirical, not in the library".
5. **Stand-ins.** An accepted effect whose fitted signal lies mostly (:data:`STAND_IN_SHARE`) in the
   located cells of its sensor stands in for that structure: the selection rejects it.

The result is an :class:`station.diagnose.results.Unexplained` entry (the same keys as robust.py's) carrying the
locator's evidence (:class:`~station.diagnose.results.LocatorEvidence`: ``locator`` in the JSON) and the empirical
models (:class:`~station.diagnose.results.EmpiricalModel`: ``empirical``).
"""

from __future__ import annotations

import math
import weakref
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy import linalg, stats
from scipy.ndimage import uniform_filter1d
from scipy.signal import lfilter

from station.diagnose import covariate_choice, empirical, robust
from station.diagnose.reporting import OUTLIER_ALLOWANCE
from station.diagnose.residuals import OUTLIER_SIGMA
from station.diagnose.results import CovariateTest, EmpiricalModel, LocatorEvidence, Unexplained
from station.fit.goodness import Rows
from station.kernel.limits_file import LimitsFile
from station.kernel.sensor_class import TABLE1, SensorClass
from station.session.model import Kind

#: The class's drift-noise std is taken this many times larger (a unit at the edge of its class is still in it).
CLASS_MARGIN = 3.0
#: The warm-up that bounds a unit's drift noise is taken at least this share of the class's largest.
B_DRIFT_FLOOR = 0.1
#: A cell's dispersion under the class-frozen model above this ...
PHI_LOCATED = 2.0
#: ... with a chi^2 tail below this is located structure.
ALPHA_LOCATED = 1e-6
#: A covariate is named when it takes at least this share of the axis's excess chi^2 in its located cells.
COVARIATE_SHARE = 0.5
#: Jumps: increments of the residual's window means (this long, s) inside still and rate-hold segments ...
JUMP_WINDOW_S = 0.5
#: ... further than this many robust sigmas (a Gaussian increment: 2e-9) ...
JUMP_SIGMAS = 6.0
#: ... at least this many, and this share of the increments, make the bias one that jumps between levels.
JUMP_MIN = 4
JUMP_MIN_SHARE = 0.004
#: An accepted effect with at least this share of its whitened fitted signal's energy in located cells is a
#: stand-in for the located structure (the robust checks' rule, :func:`station.diagnose.robust.stand_ins`).
STAND_IN_SHARE = robust.STAND_IN_SHARE
AX = "xyz"
#: Sample-level faults in the moves: the library's outlier rule (a sample further than ``OUTLIER_SIGMA`` noise sigmas
#: from its local mean, :mod:`station.diagnose.residuals`) counts only settled segments; the block means of a move
#: do not see a few bad samples either (they are left out of the blocks). Counted here on the final model's
#: residual in the moves, against the library's allowance (:data:`station.diagnose.reporting.OUTLIER_ALLOWANCE`).
MOVE_SAMPLES = "isolated samples far from the model in the moves"
#: Time constants (s) of the decay after a rate step that the ``since the last rate step`` covariate tries.
KICK_TAU_S = (4.0, 10.0, 25.0, 60.0)
#: Time constants (s) of the first-order lags through which the specific force and the rate pass: ``x - L_tau[x]``
#: is an anelastic creep or a settling after every step of ``x`` (a tumble, a rate step), gone once settled.
LAG_TAU_S = (1.0, 3.0, 10.0)
#: The temperature's rate of change is taken over this window (s): the sensor's temperature is slow and quantized.
TEMP_RATE_WINDOW_S = 10.0
#: The rate's magnitude changing faster than this (rad/s^2, 2 deg/s^2) is a rate step (a ramp or a tumble).
STEP_MIN_RADPS2 = 2.0 * math.pi / 180.0
#: A rotation about an axis faster than this (rad/s, 2 deg/s) sets the axis's direction of the last rotation.
DIRECTION_MIN_RADPS = 2.0 * math.pi / 180.0
#: The sign of a specific-force component is taken smoothly over this share of ``g`` (tanh(f / (share g))).
FORCE_SIGN_SHARE = 0.2


@dataclass(frozen=True)
class DriftClass:
    """The eq. 3 drift of the sensor class a recording is judged against: per sensor (``accel``, ``gyro``) the
    range of ``b_drift`` (SI), the stationary std of the drift noise where the class states it (SI), else
    ``drift_noise_rel`` of ``|b_drift|`` (Table 1's rule)."""

    name: str
    bias_drift: Mapping[str, tuple[float, float]]
    drift_noise_rel: float = TABLE1.drift_noise_rel
    drift_noise: Mapping[str, float] = field(default_factory=dict)

    @classmethod
    def of(cls, sc: SensorClass = TABLE1) -> DriftClass:
        deg = math.pi / 180.0
        lo, hi = sc.gyro_bias_drift_dps
        return cls(sc.name, {"accel": sc.accel_bias_drift_mps2, "gyro": (lo * deg, hi * deg)}, sc.drift_noise_rel)

    @classmethod
    def from_limits(cls, lim: LimitsFile) -> DriftClass:
        """The class of a limits file: its product ``bias_drift`` ranges and its ``drift_noise`` where given."""
        p = lim.product
        return cls(lim.name, {"accel": p.accel.bias_drift, "gyro": p.gyro.bias_drift}, TABLE1.drift_noise_rel,
                   dict(lim.drift_noise))


#: The station's own class (the paper's Table 1).
TABLE1_DRIFT = DriftClass.of(TABLE1)


def class_drift_noise(sensor: str, b_drift: np.ndarray | None = None, cls: DriftClass = TABLE1_DRIFT) -> np.ndarray:
    """Largest stationary variance of eq. 3's drift noise per axis (SI unit^2) the sensor class grants a unit
    whose warm-up is ``b_drift`` (3,): :data:`CLASS_MARGIN` times the class's drift-noise std where it states
    one, else times ``drift_noise_rel`` of ``|b_drift|``, the warm-up taken at least :data:`B_DRIFT_FLOOR` of the
    class's largest and at most that largest (None: the largest)."""
    if sensor in cls.drift_noise:
        return np.full(3, (CLASS_MARGIN * cls.drift_noise[sensor]) ** 2)
    lo, hi = cls.bias_drift[sensor]
    top = max(abs(lo), abs(hi))
    b = np.full(3, top) if b_drift is None else np.clip(np.abs(np.nan_to_num(b_drift, nan=top)),
                                                        B_DRIFT_FLOOR * top, top)
    return np.asarray((CLASS_MARGIN * cls.drift_noise_rel * b) ** 2, dtype=float)


def _smooth_derivative(x: np.ndarray, fs: float) -> np.ndarray:
    """d/dt of per-sample x (n, ...) over a ~50 ms window (the reference's sample noise)."""
    w = max(3, round(0.05 * fs) | 1)
    return np.gradient(uniform_filter1d(x, size=w, axis=0, mode="nearest"), 1.0 / fs, axis=0)


def _lag_excess(x: np.ndarray, fs: float, tau: float) -> np.ndarray:
    """``x - L[x]`` per column of ``x`` (n, 3), ``L`` a first-order lag of time constant ``tau`` (s) started settled
    at ``x[0]``: zero while ``x`` holds, after each step of ``x`` the step decaying with ``tau`` (a creep or a
    settling that follows the step)."""
    a = math.exp(-1.0 / (fs * tau))
    lagged = lfilter([1.0 - a], [1.0, -a], np.ascontiguousarray((x - x[0]).T), axis=-1).T + x[0]
    return np.asarray(x - lagged)


def _last_direction(rate: np.ndarray) -> np.ndarray:
    """Per axis the sign of the last rotation about it faster than :data:`DIRECTION_MIN_RADPS` (held while still;
    0 before the first), (n, 3)."""
    n = len(rate)
    out = np.zeros_like(rate)
    for j in range(rate.shape[1]):
        moving = np.abs(rate[:, j]) > DIRECTION_MIN_RADPS
        last = np.maximum.accumulate(np.where(moving, np.arange(n), -1))
        out[:, j] = np.where(last >= 0, np.sign(rate[np.maximum(last, 0), j]), 0.0)
    return out


#: The dictionary of a sensor's blocks, made once per (sensor data, baseline, extended): the rivals and the locator
#: ask for the same one; held weakly by the sensor data (gone with the diagnosis).
_MADE: weakref.WeakKeyDictionary[Any, dict[tuple[int, bool], list[dict[str, np.ndarray]]]] = (
    weakref.WeakKeyDictionary())


def covariates_by_axis(baseline: Any, sd: Any, *, extended: bool = False) -> list[dict[str, np.ndarray]]:
    """Per axis of ``sd`` its block-mean physical covariates (m,), by name (the covariates the axes share made
    once); ``extended``: also the rate components' products, the time since power-on and the table's spin phase
    (the empirical models'). Made once per ``sd``, ``baseline`` and ``extended`` (the arrays are not to be changed)."""
    made = _MADE.setdefault(sd, {})
    key = (id(baseline), extended)
    if key not in made:
        made[key] = _covariates_by_axis(baseline, sd, extended)
    return made[key]


def _covariates_by_axis(baseline: Any, sd: Any, extended: bool) -> list[dict[str, np.ndarray]]:
    """:func:`covariates_by_axis`, made."""
    session = baseline.session
    fs = session.sample_rate_hz
    rate = np.nan_to_num(session.ref_gyro_radps)
    force = np.nan_to_num(session.ref_accel_mps2)
    t = session.t_s
    mag = np.linalg.norm(rate, axis=1)
    out: dict[str, np.ndarray] = {"|rate|": mag}
    for j in range(3):
        out[f"rate {AX[j]}"] = rate[:, j]
        out[f"|rate {AX[j]}|"] = np.abs(rate[:, j])
        out[f"rate^2 {AX[j]}"] = rate[:, j] ** 2
        out[f"rate^3 {AX[j]}"] = rate[:, j] ** 3
        out[f"specific force {AX[j]}"] = force[:, j]
    alpha = _smooth_derivative(rate, fs)
    for j in range(3):
        out[f"angular acceleration {AX[j]}"] = alpha[:, j]
    temp = baseline.d_temp
    if np.ptp(temp) > 0:
        out["temperature"] = temp
        dtemp = _smooth_derivative(temp, fs)
        scale = max(float(np.percentile(np.abs(dtemp), 90)), 1e-12)
        out["temperature direction (heating vs cooling: hysteresis)"] = np.tanh(dtemp / (0.2 * scale))
        # the temperature's rate of change (a thermal gradient while the temperature moves): a bias following it, and
        # a scale of the force or the rate following it
        tw = max(3, round(TEMP_RATE_WINDOW_S * fs) | 1)
        trate = np.gradient(uniform_filter1d(np.asarray(temp, dtype=float), size=tw, mode="nearest"), 1.0 / fs)
        if np.ptp(trate) > 0:
            out["temperature rate dT/dt"] = trate
            for j in range(3):
                out[f"specific force {AX[j]} * temperature rate dT/dt"] = force[:, j] * trate
                out[f"rate {AX[j]} * temperature rate dT/dt"] = rate[:, j] * trate
        for j in range(3):
            out[f"specific force {AX[j]} * temperature"] = force[:, j] * temp
    # a kick after each rate step, by the step's size, decaying: |d|w|/dt| through a first-order lag
    step = np.abs(_smooth_derivative(mag, fs))
    if np.any(step > 0):
        for tau in KICK_TAU_S:
            out[f"time since the last rate step (decay {tau:g} s, by the step's size)"] = lfilter(
                [1.0 / fs], [1.0, -math.exp(-1.0 / (fs * tau))], step)
    # products of a rate component with a specific-force component and with the temperature: a scale or a
    # cross-axis coupling that depends on the force along an axis or on the temperature (the library's are one
    # form each: temperature_scale on the own axis, g_sensitivity a bias)
    for i in range(3):
        for j in range(3):
            out[f"rate {AX[i]} * specific force {AX[j]}"] = rate[:, i] * force[:, j]
        if "temperature" in out:
            out[f"rate {AX[i]} * temperature"] = rate[:, i] * temp
    # even functions of the force (a bias by the force's size, not its sign), a bias by the direction of the last
    # rotation about an axis or by the sign of a force component (direction-dependent), and the force and the rate
    # through first-order lags (a creep after each tumble, a scale settling after each rate step)
    g = max(float(np.median(np.linalg.norm(force, axis=1))), 1e-9)
    direction = _last_direction(rate)
    for j in range(3):
        out[f"specific force^2 {AX[j]} (even in the force)"] = force[:, j] ** 2
        out[f"|specific force {AX[j]}| (even in the force)"] = np.abs(force[:, j])
        out[f"direction of the last rotation about {AX[j]} (sign of rate {AX[j]}, held)"] = direction[:, j]
        out[f"sign of specific force {AX[j]} (direction-dependent)"] = np.tanh(force[:, j] / (FORCE_SIGN_SHARE * g))
    # and a scale settling after each rate step: the rate times a decay of the time since the last step ended
    ramping = np.abs(step) > STEP_MIN_RADPS2
    ended = ramping & ~np.append(ramping[1:], False)
    last = np.maximum.accumulate(np.where(ended, np.arange(len(t)), -1))
    since = np.where(last >= 0, t - t[np.maximum(last, 0)], np.inf)
    for tau in LAG_TAU_S:
        creep = _lag_excess(force, fs, tau)
        settle = _lag_excess(rate, fs, tau)
        decay = np.exp(-since / tau)
        for j in range(3):
            out[f"specific force {AX[j]} creep since the last step (first-order lag {tau:g} s)"] = creep[:, j]
            out[f"rate {AX[j]} settling since the last rate step (first-order lag {tau:g} s)"] = settle[:, j]
            out[f"rate {AX[j]} * time since the last rate step (a scale settling, decay {tau:g} s)"] = (
                rate[:, j] * decay)
    if extended:
        for i, j in ((0, 1), (0, 2), (1, 2)):
            out[f"rate {AX[i]} * rate {AX[j]}"] = rate[:, i] * rate[:, j]
        out["time since power-on"] = t
        angle = np.concatenate([[0.0], np.cumsum(0.5 * (mag[1:] + mag[:-1]) * np.diff(t))])
        out["spin phase cos"] = np.cos(angle)
        out["spin phase sin"] = np.sin(angle)
    shared = {name: sd.block_mean(v) for name, v in out.items() if np.ptp(v) > 0}
    du = _smooth_derivative(sd.u, fs)
    delay = "delay growing with time (sample clock rate)"
    per_axis: list[dict[str, np.ndarray]] = []
    for k in range(3):
        own = dict(shared)
        if np.ptp(du[:, k]) > 0:
            own[delay] = sd.block_mean(-du[:, k] * t)
        per_axis.append(own)
    return per_axis


def _spin_periodic(session: Any, sd: Any, residual: Rows | np.ndarray, k: int) -> tuple[float, int, float, float]:
    """Axis ``k``'s ``residual`` (n, 3) in the rate-table holds against the table's angle (integrated from the
    rate reference): per hold of at least one turn, the least-squares cos/sin part beside a mean and a trend.
    Returns (its chi^2 in white-noise units, dof, its share of the holds' structure above the white noise, its
    rms amplitude over the holds in the sensor's SI unit): a term periodic at the spin frequency takes most of
    the structure; slow or jumping structure leaves most outside it."""
    rate = np.nan_to_num(session.ref_gyro_radps)
    chi = excess = amp2 = 0.0
    dof = n_all = 0
    for seg in session.segments():
        if seg.kind != Kind.RATE or len(seg) < 50:
            continue
        sl = seg.slice
        w = np.linalg.norm(rate[sl], axis=1)
        t = session.t_s[sl]
        ang = np.concatenate([[0.0], np.cumsum(0.5 * (w[1:] + w[:-1]) * np.diff(t))])
        if ang[-1] < 2.0 * math.pi:
            continue
        keep = sd.keep[sl]
        r = residual[sl, k][keep]
        tt = t[keep] - t[keep].mean()
        x = np.column_stack([np.ones(len(r)), tt, np.cos(ang[keep]), np.sin(ang[keep])])
        beta, *_ = np.linalg.lstsq(x, r, rcond=None)
        left = r - x[:, :2] @ np.linalg.lstsq(x[:, :2], r, rcond=None)[0]
        per = x[:, 2:] @ beta[2:]
        var = float(sd.sigma[k]) ** 2
        chi += float(per @ per) / var
        excess += max(float(left @ left) - len(r) * var, 0.0) / var
        dof += 2
        amp2 += float(np.sum(beta[2:] ** 2)) * len(seg)
        n_all += len(seg)
    return chi, dof, (chi / excess if excess > 0 else 0.0), math.sqrt(amp2 / max(n_all, 1))


def _jumps(session: Any, residual: Rows | np.ndarray, k: int, censored: np.ndarray | None = None) -> tuple[int, int]:
    """Jumps of axis ``k``'s ``residual`` (n, 3) inside the still and rate-hold segments: (number of increments
    between adjacent :data:`JUMP_WINDOW_S` window means further than :data:`JUMP_SIGMAS` robust sigmas, number
    of increments). Eq. 3's drift, a random walk and short-correlated noise have Gaussian increments; a bias
    that jumps between levels has a few very large ones."""
    fs = session.sample_rate_hz
    w = max(10, round(JUMP_WINDOW_S * fs))
    inc: list[np.ndarray] = []
    for seg in session.segments():
        if seg.kind == Kind.MOVE or len(seg) < 3 * w or (censored is not None and censored[seg.start]):
            continue
        x = residual[seg.start:seg.stop, k]
        nwin = len(x) // w
        means = x[:nwin * w].reshape(nwin, w).mean(axis=1)
        inc.append(np.diff(means))
    if not inc:
        return 0, 0
    d = np.concatenate(inc)
    scale = 1.4826 * float(np.median(np.abs(d - np.median(d))))
    if scale <= 0:
        return 0, len(d)
    return int(np.sum(np.abs(d) > JUMP_SIGMAS * scale)), len(d)


def _move_samples(session: Any, sd: Any, residual: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per axis, in the rig's moves: (samples of ``residual`` (n, 3) further than ``OUTLIER_SIGMA`` noise sigmas from
    their local mean, the moves' samples, those far samples whose raw reading repeats the one before on every axis:
    a converter that holds a sample). The rule of the library's outlier count (:mod:`station.diagnose.residuals`),
    applied where that count does not look."""
    count, total, held, _, _ = _far_samples(session, sd, residual)
    return count, total, held


def _far_samples(session: Any, sd: Any, residual: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, int]:
    """:func:`_move_samples` and, with the same rule, the far samples per axis in the settled segments and their
    number of samples."""
    data = session.accel_mps2 if sd.sensor == "accel" else session.gyro_radps
    count = np.zeros(3, dtype=int)
    held = np.zeros(3, dtype=int)
    settled = np.zeros(3, dtype=int)
    total = settled_n = 0
    censored = sd.censored  # saturated segments (censoring.py): not this triad's data
    for s in session.segments():
        if len(s) < 10 or (censored is not None and censored[s.start]):
            continue
        x = residual[s.start:s.stop]
        local = uniform_filter1d(x, size=max(3, min(len(s), 101)), axis=0, mode="nearest")
        bad = np.abs(x - local) > OUTLIER_SIGMA * sd.sigma
        if s.kind != Kind.MOVE:
            settled += bad.sum(axis=0)
            settled_n += len(s)
            continue
        raw = data[s.start:s.stop]
        same = np.concatenate([[False], np.all(raw[1:] == raw[:-1], axis=1)])
        count += bad.sum(axis=0)
        held += (bad & same[:, None]).sum(axis=0)
        total += len(s)
    return count, np.full(3, total), held, settled, settled_n


def _move_sample_cells(session: Any, sd: Any, residual: np.ndarray) -> dict[int, tuple[int, int, int]]:
    """Axes whose far samples in the moves (:func:`_move_samples`) exceed, with a Poisson tail below
    :data:`ALPHA_LOCATED`, the library's outlier allowance or, where more, the rate of far samples the settled
    segments show (spikes everywhere are the library's ``outliers``, not something of the moves): axis -> (count,
    samples, held)."""
    count, total, held, settled, settled_n = _far_samples(session, sd, residual)
    lam = np.maximum(OUTLIER_ALLOWANCE[sd.sensor], settled / max(settled_n, 1)) * total
    return {k: (int(count[k]), int(total[k]), int(held[k])) for k in range(3)
            if count[k] > 0 and stats.poisson.sf(count[k] - 1, lam[k]) < ALPHA_LOCATED}


def locate(prob: Any, baseline: Any, names: list[str], extra_cells: set[tuple[int, int]] | None = None,
           fitted: np.ndarray | None = None, drift_class: DriftClass = TABLE1_DRIFT,
           move_samples: bool = True) -> Unexplained | None:
    """Run the module's steps on the final model of one sensor (``prob``, a
    :class:`station.diagnose.likelihood.SensorProblem` with the accepted effects ``names``). ``extra_cells``:
    (kind code, axis) cells located by other checks (e.g. :mod:`station.diagnose.robust`'s) to name the
    covariate of as well; ``fitted``: the accepted effects' signal per sample (n, 3), for the jump test (None:
    not run); ``drift_class``: the class whose drift noise bounds ``q``. None when nothing is located."""
    sd = prob.sd
    q_cls = class_drift_noise(sd.sensor, sd.params.bias_drift, drift_class)
    q_fit = prob.q.copy()
    with prob.drift_noise_at_most(q_cls):
        fit = prob.whitened_fit()
        chols, x, nbase, beta, res = fit.chols, fit.x, fit.nbase, fit.beta, fit.res
        m = prob.m
        z = res.reshape(3, m).T
        cells: set[tuple[int, int]] = set()
        table: dict[str, list[float]] = {}
        for kind in Kind:
            sel = sd.kind == int(kind)
            if sel.sum() < 3:
                continue
            ms = np.mean(z[sel] ** 2, axis=0)
            table[kind.label] = [round(float(v), 3) for v in ms]
            for k in range(3):
                chi = float(np.sum(z[sel, k] ** 2))
                if chi / sel.sum() > PHI_LOCATED and stats.chi2.sf(chi, int(sel.sum())) < ALPHA_LOCATED:
                    cells.add((int(kind), k))
        cells |= set(extra_cells or ())
        # the covariate tests of every axis (whitened, each covariate residualized against the axis's mean model)
        values = covariates_by_axis(baseline, sd)
        gains = {k: covariate_gains(values[k], chols[k], x[k * m:(k + 1) * m], res[k * m:(k + 1) * m])
                 for k in range(3)}
        # a covariate's own test, where the cells' dispersion does not reach PHI_LOCATED (a small effect in few
        # blocks): located where it takes a significant part of the axis's chi^2 (module docstring, step 2)
        targeted = _targeted_cells(sd, gains, res, cells)
        block_cells = set(cells)  # by the cells' dispersion (and the other checks' cells)
        structure_cells = block_cells | set(targeted)  # and by a covariate's own test: the block-level structure
        cells |= structure_cells
        # the far samples in the moves (only where a rig's reference is there: not on a rig-free recording)
        samples = (_move_sample_cells(baseline.session, sd, sd.residual_less(fitted)[:])
                   if fitted is not None and move_samples else {})
        cells |= {(int(Kind.MOVE), k) for k in samples}
        if not cells:
            return None
        axes = sorted({k for _, k in cells})
        extended: list[dict[str, np.ndarray]] = []

        def dictionary(k: int) -> dict[str, np.ndarray]:
            """The empirical models' dictionary of axis k (made once)."""
            if not extended:
                extended.extend(covariates_by_axis(baseline, sd, extended=True))
            return extended[k]

        power_on = sd.block_mean(np.asarray(baseline.session.t_s, dtype=float))
        # the several-parameter families, in the order they are tried, each built once per sensor when first needed
        group_builders = (covariate_choice.heading_columns, covariate_choice.oscillation_columns,
                          covariate_choice.rate_level_columns)
        made_groups: dict[int, dict[str, np.ndarray]] = {}

        def group(i: int) -> dict[str, np.ndarray]:
            if i not in made_groups:
                made_groups[i] = group_builders[i](baseline.session, sd)
            return made_groups[i]

        # --- covariate per axis ---
        tests: list[CovariateTest] = []
        chosen: list[tuple[str, str]] = []
        models: list[EmpiricalModel] = []
        for k in axes:
            rows = slice(k * m, (k + 1) * m)
            rk = res[rows]
            if k in samples and not any(kk == k for _, kk in structure_cells):
                count, total, held = samples[k]  # seen only at the sample level
                tests.append(CovariateTest(AX[k], MOVE_SAMPLES, float(count), count / max(total, 1)))
                chosen.append((AX[k], _samples_text(count, total, held, OUTLIER_ALLOWANCE[sd.sensor])))
                models.append(empirical.fit(sd.sensor, AX[k], prob.y[:, k] - _mean_fit(prob, beta, nbase, k),
                                            1.0 / prob.white[:, k], sd.segment,
                                            dictionary(k)))
                continue
            kinds_k = [c for c, kk in cells if kk == k]
            in_cells = np.isin(sd.kind, kinds_k)
            excess = max(float(np.sum(rk[in_cells] ** 2)) - float(in_cells.sum()), 1e-9)
            best: tuple[str, float, float] = ("none", 0.0, 0.0)
            best_term = None
            for term in gains[k]:
                name, cw, coef, gain = term
                new_r = rk - coef * cw
                share = (float(np.sum(rk[in_cells] ** 2)) - float(np.sum(new_r[in_cells] ** 2))) / excess
                tests.append(CovariateTest(AX[k], name, gain, share))
                if share >= COVARIATE_SHARE and stats.chi2.sf(gain, 1) < ALPHA_LOCATED and gain > best[1]:
                    best = (name, gain, share)
                    best_term = term
            if best_term is not None:  # said with the correlated terms the recording cannot tell from it
                # the time since power-on only as a proxy said beside the term it cannot be told from (a proxy of
                # the temperature and the warm-up: never named alone, everything slow follows it)
                proxies = [*gains[k], *covariate_gains({"time since power-on": power_on}, chols[k], x[rows], rk)]
                ties = covariate_choice.inseparable(best_term, proxies, rk, ALPHA_LOCATED)
                best = (covariate_choice.with_family([best[0], *ties]), best[1], best[2])
            if best[0] == "none" and fitted is not None:
                chi, dof, share, _amp = _spin_periodic(baseline.session, sd, sd.residual_less(fitted), k)
                tests.append(CovariateTest(AX[k], "periodic at the spin frequency", chi, share))
                if dof and share >= COVARIATE_SHARE and stats.chi2.sf(chi, dof) < ALPHA_LOCATED:
                    best = ("periodic", chi, share)
            if best[0] == "none" and fitted is not None:  # the noise itself grows in a rate hold (before the jumps:
                # their increments assume the same noise in the holds as in the still segments)
                ratio, tail = covariate_choice.spin_scatter(baseline.session, sd.residual_less(fitted), k,
                                                            sd.censored)
                tests.append(CovariateTest(AX[k], "scatter in a rate hold over the still segments'", ratio, 0.0))
                if ratio >= PHI_LOCATED and tail < ALPHA_LOCATED:
                    best = (f"scatter {ratio:.1f}", ratio, 0.0)
            if best[0] == "none" and fitted is not None:
                count, total = _jumps(baseline.session, sd.residual_less(fitted), k, sd.censored)
                tests.append(CovariateTest(AX[k], "jumps (two-level)", float(count), count / max(total, 1)))
                if count >= JUMP_MIN and count >= JUMP_MIN_SHARE * total:
                    best = ("two-level", float(count), 0.0)
            if best[0] == "none":  # terms of several parameters: a world-fixed direction, a slow oscillation
                qk = _basis(x[rows])
                for i in range(len(group_builders)):
                    got = covariate_choice.best_group(group(i), chols[k], qk, rk, in_cells, excess, COVARIATE_SHARE,
                                                      ALPHA_LOCATED)
                    if got is not None:
                        tests.append(CovariateTest(AX[k], got[0], got[1], got[2]))
                        best = (covariate_choice.with_family([got[0]]), got[1], got[2])
                        break
            chosen.append((AX[k], best[0]))
            models.append(empirical.fit(sd.sensor, AX[k], prob.y[:, k] - _mean_fit(prob, beta, nbase, k),
                                        1.0 / prob.white[:, k], sd.segment,
                                        dictionary(k)))
        tests.sort(key=lambda t: (not t.name.startswith("jumps"), -t.gain_chi2))
        # --- stand-ins among the accepted effects ---
        stand: list[str] = []
        if names:
            # a block-level notion: the cells seen only at the sample level hold no block structure to stand in for
            cell_rows = np.concatenate([[(int(sd.kind[i]), k) in block_cells for i in range(m)] for k in range(3)])
            stand = robust.stand_ins(names, prob.accepted, x, beta, nbase, cell_rows)
        excess_all = 0.0
        for c, k in structure_cells:
            sel = sd.kind == c
            excess_all += float(np.sum(z[sel, k] ** 2)) - float(sel.sum())
        periodic = None
        if fitted is not None and any(c == "periodic" for _, c in chosen):
            per = [_spin_periodic(baseline.session, sd, sd.residual_less(fitted), k) for k in range(3)]
            factor, unit = (180.0 / math.pi, "deg/s") if sd.sensor == "gyro" else (1.0, "m/s^2")
            periodic = {"axes": [a for a, c in chosen if c == "periodic"], "chi2": [round(p[0], 1) for p in per],
                        "dof": per[0][1], "amplitude": [round(p[3] * factor, 6) for p in per], "unit": unit}
        names_used = {c for _, c in chosen}
        cov = _text(chosen[0][1]) if len(names_used) == 1 else "; ".join(f"{a}: {_text(c)}" for a, c in chosen)
        return Unexplained(
            sensor=sd.sensor, axes=tuple(AX[k] for k in axes),
            segment_kinds=tuple(sorted({Kind(c).label for c, _ in cells})), covariate=cov,
            dispersion=table, excess_chi2=excess_all, periodic=periodic,
            locator=LocatorEvidence(
                covariate_per_axis=tuple(chosen),
                q_over_class=tuple(float(v / c) for v, c in zip(q_fit, q_cls, strict=True)), tests=tuple(tests[:8]),
                stand_ins=tuple(stand)),
            empirical=tuple(models))


def covariate_gains(values: Mapping[str, np.ndarray], chol: np.ndarray, xk: np.ndarray, rk: np.ndarray
                    ) -> list[tuple[str, np.ndarray, float, float]]:
    """One axis's covariate tests: per covariate block values in ``values`` (name -> (m,), :func:`covariates_by_axis`)
    (name, its values whitened by the axis's Cholesky factor ``chol`` and residualized against the axis's whitened
    design ``xk`` (m, p), its least-squares coefficient on the whitened residual ``rk`` (m,), the chi^2 it takes)."""
    qk = _basis(xk)
    out: list[tuple[str, np.ndarray, float, float]] = []
    if not values:
        return out
    names = list(values)
    # all covariates at once: one triangular solve and one projection for the dictionary's matrix
    cws = linalg.solve_triangular(chol, np.column_stack([values[n] for n in names]), lower=True, check_finite=False)
    cws = cws - qk @ (qk.T @ cws)
    norms = np.einsum("ij,ij->j", cws, cws)
    dots = cws.T @ rk
    for i, name in enumerate(names):
        nn = float(norms[i])
        if nn <= 1e-300:
            continue
        coef = float(dots[i]) / nn
        out.append((name, cws[:, i], coef, coef**2 * nn))
    return out


def _basis(xk: np.ndarray) -> np.ndarray:
    """An orthonormal basis (m, r) of the non-zero columns of an axis's whitened design ``xk`` (m, p)."""
    xk = xk[:, np.any(xk != 0, axis=0)]
    return np.asarray(linalg.qr(xk, mode="economic", check_finite=False)[0] if xk.shape[1]
                      else np.zeros((len(xk), 0)))


def _targeted_cells(sd: Any, gains: Mapping[int, list[tuple[str, np.ndarray, float, float]]], res: np.ndarray,
                    cells: set[tuple[int, int]]) -> dict[tuple[int, int], str]:
    """Cells (kind code, axis) not located by their dispersion where one covariate's own test locates structure:
    the strongest covariate's chi^2 on the axis's whitened residual (``res``, the three axes stacked), over the
    dispersion the axis keeps without it (at least 1: a misstated noise does not pass as structure), beyond the
    chi^2(1) tail :data:`ALPHA_LOCATED` shared by the dictionary's tests on the three axes (Bonferroni), and in a
    segment kind the part of that chi^2 taken inside the kind's blocks significant at :data:`ALPHA_LOCATED`.
    Returns the cells with the covariate that located them."""
    out: dict[tuple[int, int], str] = {}
    n_tests = max(1, sum(len(g) for g in gains.values()))
    m = len(sd.kind)
    for k, tests in gains.items():
        if not tests:
            continue
        name, cw, coef, gain = max(tests, key=lambda t: t[3])
        rk = res[k * m:(k + 1) * m]
        new = rk - coef * cw
        phi = max(1.0, float(np.mean(new**2)))
        if stats.chi2.sf(gain / phi, 1) >= ALPHA_LOCATED / n_tests:
            continue
        for kind in Kind:
            sel = sd.kind == int(kind)
            if (int(kind), k) in cells or sel.sum() < 3:
                continue
            drop = float(np.sum(rk[sel] ** 2) - np.sum(new[sel] ** 2))
            if drop > 0 and stats.chi2.sf(drop / phi, 1) < ALPHA_LOCATED:
                out[(int(kind), k)] = name
    return out


def _mean_fit(prob: Any, beta: np.ndarray, nbase: int, k: int) -> np.ndarray:
    """The GLS mean fit of axis k (its base terms and the accepted effects) per block, unwhitened (m,)."""
    col = sum(b.shape[1] for b in prob.base[:k])
    nb = prob.base[k].shape[1]
    out = prob.base[k] @ beta[col:col + nb]
    c = nbase
    for zb in prob.accepted:
        p = zb.shape[2]
        out = out + zb[:, k, :] @ beta[c:c + p]
        c += p
    return np.asarray(out)


def _samples_text(count: int, total: int, held: int, allowance: float) -> str:
    """The covariate text of an axis located only by its far samples in the moves (:func:`_move_sample_cells`)."""
    # with noise above the LSB a reading equal to the one before on all three axes does not happen by chance: a few
    # such repeats among the far samples are a converter that holds (the rest are their neighbours: the local mean
    # of the library's rule is pulled by the held samples)
    what = (f"{held} of them repeat the sample before on every axis (held samples: a sample-and-hold, the converter "
            "repeats a reading)"
            if held >= JUMP_MIN else "no repeats of the sample before among them (glitches or sharp structure)")
    return (f"{MOVE_SAMPLES}: {count} of {total} samples beyond {OUTLIER_SIGMA:g} noise sigmas of their local mean "
            f"(the library's allowance {allowance:g} a sample); {what}; "
            "a sample-level fault the block means do not see")


def _text(name: str) -> str:
    if name == "none":
        return ("none: no covariate of the dictionary (rate, |rate|, rate^2, rate^3, angular acceleration, specific "
                "force and its square and size, temperature, its direction and rate, time since the last rate step, "
                "force and rate through lags, the direction of the last rotation, a delay growing with time, "
                "rate times force or temperature, force times temperature, time since power-on, a horizontal "
                "direction fixed in the world, a slow oscillation in time) "
                f"takes {COVARIATE_SHARE:.0%} of it, and it is not two-level")
    if name == "periodic":
        return ("periodic at the rate table's spin frequency: follows the spin phase (a cos/sin of the table's angle "
                "takes most of the structure inside the rate holds) [spin phase]")
    if name == "two-level":
        return ("two-level: the bias jumps between levels inside still segments (increments far from Gaussian), not "
                "eq. 3's Gaussian drift, and follows no covariate")
    if name.startswith("scatter "):
        return (f"noise that grows in the rate holds: the scatter in one is {name[8:]} times the still segments' (a "
                "vibration of the spinning table, or a noise that follows the rate) [rate / vibration]")
    if name.startswith(MOVE_SAMPLES):
        return name
    return f"follows {name}"


__all__ = ["ALPHA_LOCATED", "PHI_LOCATED", "TABLE1_DRIFT", "DriftClass", "class_drift_noise", "covariate_gains",
           "covariates_by_axis", "locate"]
