"""The temperature terms of the fit: bias and scale polynomials in the unit's temperature (beyond eq. 1).

Per triad and output axis k, with ``dT = T - T_ref`` the unit's temperature (its own temperature
column) minus the reference temperature:

    x~_k = (M x)_k (1 + s_k1 dT + s_k2 dT^2 + s_k3 dT^3) + b_stat,k + c_k1 dT + c_k2 dT^2 + c_k3 dT^3
           + b_drift,k g(t) + n                                                   (eq. 1 with eq. 3)

The temperature terms are linear regressors of the axis fit (:func:`station.fit.axis_ml.fit_axis`), fitted
jointly with the row of M, b_stat and the warm-up drift of eq. 3: ``dT^j`` for the bias and
``(M^_k . x_ref) dT^j`` for the scale, with M^ the row from a previous pass (the scale term is linear in
s once M is known; the error of using M^ is of second order in ``s (M^ - M)``).

**When the temperature course can be told from the warm-up** (:func:`assess_temperature`): a warm-up
drift ``b_drift exp(-t/T_c)`` and a temperature coefficient times a temperature course that is itself
warm-up shaped (self-heating ``h (1 - exp(-t/tau))``, a slow ramp) are the same regressor, and no fit can
split them. The terms are fitted only when the plan moves the temperature: the settled data's
block-mean temperature spans at least ``min_temperature_span_k``, and what is left of it after the
best warm-up shape ``a + b exp(-t/tau)`` over any tau (2 s to 50 record spans; a ramp is the long-tau
limit) is taken out has an RMS of at least ``min_temperature_independent_k``. Otherwise the result says
so (:class:`~station.kernel.parameters.ThermalFit`, status ``not_separable``) and the fit is eq. 1 as before.

**Order** (:data:`ORDER_RULE`): backward elimination by Wald tests at the full model's (T_c, q).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from station.fit.axis_ml import AxisFit, AxisProblem, information_inverse
from station.fit.blocks import Blocks, block_exp_mean, make_blocks
from station.kernel.parameters import MAX_TEMP_ORDER, ThermalFit
from station.session.model import Session

ORDER_RULE = (
    "per output axis, bias and scale polynomials start at order thermal_max_order, capped at the number of "
    "temperature levels the polynomial's data hold minus one (levels: clusters of the blocks' temperatures "
    "apart by more than 3 K, a cluster spanning s K counting 1 + floor(s / 5 K); for the scale only the blocks "
    "with a reference input count); at the full model's "
    "(T_c, q) the highest order of a polynomial is dropped while its coefficient's Wald statistic z^2 is "
    "below thermal_order_wald (9: 3 sigma), never below order 1; then the axis is refitted at the chosen orders"
)

#: Seconds of the recording's start whose mean temperature is T_ref when none is given.
POWER_ON_WINDOW_S = 1.0


@dataclass(frozen=True, eq=False)
class TemperatureCourse:
    """The assessment of a recording's temperature.

    Attributes:
        note: the typed note (status ``fitted`` means: to be fitted; orders are filled in later).
        reference_degc: T_ref (degC); NaN without a temperature column.
        dt: ``T - T_ref`` per sample (K), (n,); None unless the terms are to be fitted.
    """

    note: ThermalFit
    reference_degc: float
    dt: np.ndarray | None

    @property
    def fit(self) -> bool:
        return self.dt is not None


def _warmup_residual_k(t: np.ndarray, h: np.ndarray, temp: np.ndarray, w: np.ndarray) -> float:
    """RMS (K, weights ``w``) of the block temperatures after the best ``a + b exp(-t/tau)``, any tau."""
    span_t = float(t.max() + 0.5 * h.max())
    best = float(np.sqrt(np.average((temp - np.average(temp, weights=w)) ** 2, weights=w)))
    sw = np.sqrt(w)
    for tau in np.geomspace(2.0, max(50.0 * span_t, 100.0), 120):
        x = np.column_stack([np.ones_like(t), block_exp_mean(t, h, tau)]) * sw[:, None]
        beta, *_ = np.linalg.lstsq(x, temp * sw, rcond=None)
        r = temp * sw - x @ beta
        best = min(best, float(np.sqrt(np.sum(r**2) / np.sum(w))))
    return best


def assess_temperature(
    session: Session,
    runs: list[tuple[int, int, int]],
    *,
    mode: str,
    min_span_k: float,
    min_independent_k: float,
    reference_degc: float | None,
    max_blocks: int = 200,
) -> TemperatureCourse:
    """Whether the recording's temperature separates temperature terms from the warm-up (module doc).

    ``runs``: the settled runs ``(segment, start, stop)`` the fits use (all triads' union).
    """
    temp = np.asarray(session.temp_degc, dtype=np.float64)
    if mode == "off":
        return TemperatureCourse(ThermalFit("disabled", "the fit was told not to fit temperature terms"),
                                 float("nan"), None)
    if not session.has_temperature:
        return TemperatureCourse(ThermalFit("no_temperature", "the recording has no temperature column"),
                                 float("nan"), None)
    sel = np.zeros(len(session), dtype=bool)
    for _, a, b in runs:
        sel[a:b] = True
    missing = int(np.count_nonzero(sel & ~np.isfinite(temp)))
    head = session.t_s <= session.t_s[0] + POWER_ON_WINDOW_S
    t_ref = float(reference_degc) if reference_degc is not None else float(np.nanmean(temp[head]))
    if missing or not np.isfinite(t_ref):
        return TemperatureCourse(
            ThermalFit("no_temperature", f"the temperature is missing in {missing} settled samples"), t_ref, None
        )
    ts = 1.0 / session.sample_rate_hz
    blocks = make_blocks(session.t_s, np.repeat(temp[:, None], 3, axis=1), np.zeros((len(session), 3)),
                         np.zeros((len(session), 3)), np.ones(len(session), dtype=bool), runs, ts, max_blocks)
    tb = blocks.y[:, 0]
    span = float(tb.max() - tb.min())
    indep = _warmup_residual_k(blocks.t_s, blocks.width_s, tb, blocks.count)
    if span < min_span_k:
        why = f"the temperature spans {span:.2f} K of the settled data (< {min_span_k:g} K)"
    elif indep < min_independent_k:
        why = (f"the temperature course is warm-up shaped: {indep:.2f} K RMS of it is left after the best "
               f"a + b exp(-t/tau) (< {min_independent_k:g} K)")
    else:
        return TemperatureCourse(ThermalFit("fitted", "", span, indep, {}, ORDER_RULE), t_ref, temp - t_ref)
    return TemperatureCourse(
        ThermalFit("not_separable", f"temperature terms not fitted: {why}; they cannot be told from the "
                                    "warm-up drift of eq. 3 without a plan that moves the temperature", span, indep),
        t_ref, None,
    )


def temperature_columns(dt: np.ndarray, ref: np.ndarray | None, order: int = MAX_TEMP_ORDER) -> np.ndarray:
    """Per-sample columns whose block means make the regressors: ``dT^j`` (j = 1..order), then, with a
    reference, ``ref_i dT^j`` (i = x, y, z for each j), (n, order (1 + 3))."""
    powers = np.column_stack([dt**j for j in range(1, order + 1)])
    if ref is None:
        return powers
    r = np.nan_to_num(ref)
    return np.column_stack([powers, *[r * powers[:, [j]] for j in range(order)]])


def axis_regressors(blocks: Blocks, m_row: np.ndarray | None, bias_order: int, scale_order: int) -> np.ndarray:
    """Block regressors of one axis: ``dT^j`` (j <= bias_order), then ``(M^_k . ref) dT^j`` (j <= scale_order)."""
    ex = blocks.extra
    assert ex is not None
    cols = [ex[:, j] for j in range(bias_order)]
    if m_row is not None:
        base = MAX_TEMP_ORDER
        for j in range(scale_order):
            cols.append(ex[:, base + 3 * j: base + 3 * j + 3] @ m_row)
    return np.column_stack(cols) if cols else np.zeros((len(blocks), 0))


#: Block temperatures further apart than this (K) are separate levels; a cluster spanning s K counts
#: 1 + floor(s / LEVEL_SPAN_K) levels (a ramp holds many, a plateau with its self-heating one).
LEVEL_GAP_K = 3.0
LEVEL_SPAN_K = 5.0


def temperature_levels(dt: np.ndarray) -> int:
    """How many distinct temperature levels the values ``dt`` (K) hold (see :data:`LEVEL_GAP_K`)."""
    x = np.sort(np.asarray(dt, dtype=float)[np.isfinite(dt)])
    if not x.size:
        return 0
    cuts = np.flatnonzero(np.diff(x) > LEVEL_GAP_K)
    levels = 0
    for part in np.split(x, cuts + 1):
        levels += 1 + int((part[-1] - part[0]) // LEVEL_SPAN_K)
    return levels


def order_caps(blocks: Blocks, m_row: np.ndarray | None, top: int) -> tuple[int, int]:
    """Highest (bias, scale) orders the blocks can identify: the temperature levels minus one, at least 1 and at
    most ``top``; the scale counts only blocks with a reference input (5 % of the largest or more)."""
    ex = blocks.extra
    assert ex is not None
    dt = ex[:, 0]
    cap_b = max(1, min(top, temperature_levels(dt) - 1))
    if m_row is None:
        return cap_b, 0
    u = np.abs(blocks.ref @ m_row)
    live = u > 0.05 * float(u.max()) if u.size and u.max() > 0 else np.zeros(len(u), dtype=bool)
    cap_s = max(1, min(top, temperature_levels(dt[live]) - 1))
    return cap_b, cap_s


def select_orders(
    blocks: Blocks, axis: int, base: np.ndarray, m_row: np.ndarray | None, sigma_w: float, full: AxisFit,
    max_order: int, wald: float, start: tuple[int, int] | None = None,
) -> tuple[int, int]:
    """(bias order, scale order) of one axis by backward elimination (:data:`ORDER_RULE`).

    ``base``: the axis design without temperature columns; ``full``: the fit at ``max_order`` for both.
    """
    tc = full.tc_s if np.isfinite(full.tc_s) else float(blocks.t_s.max() + blocks.width_s.max())
    y = blocks.y[:, axis]
    nb, ns = start if start is not None else (max_order, (max_order if m_row is not None else 0))
    while True:
        design = np.column_stack([base, axis_regressors(blocks, m_row, nb, ns)])
        prob = AxisProblem(blocks, y, design, sigma_w, with_drift=full.drift_resolved)
        _, beta, xw, _ = prob.solve(tc, max(full.drift_noise, 1e-300) ** 2)
        var = np.diag(information_inverse(xw.T @ xw))
        p0 = base.shape[1]
        top_b, top_s = p0 + nb - 1, p0 + nb + ns - 1
        drop_b = nb > 1 and beta[top_b] ** 2 < wald * var[top_b]
        drop_s = ns > 1 and beta[top_s] ** 2 < wald * var[top_s]
        if not (drop_b or drop_s):
            return nb, ns
        nb, ns = nb - int(drop_b), ns - int(drop_s)
