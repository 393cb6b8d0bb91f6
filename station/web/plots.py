"""Server-rendered SVG plots of a unit for the engineer's page (matplotlib, no pyplot state).

* ``raw_corrected``: raw versus corrected (Algorithm 1 applied with the fitted parameter
  set) specific force (mg) and angular rate (deg/s) per axis over the session;
* ``drift``: the gyro output during the power-on rest (deg/s) with the fitted bias of
  eq. (1) and (3), b_stat + b_drift * exp(-t / T_c);
* ``acf``: normalised autocorrelation of the low-passed rest record with the e^-1 point
  and the fitted T_c;
* ``residuals``: RMS of the fit residual per segment and axis (accel mg, gyro deg/s);
* ``allan``: overlapping Allan deviation of the gyro (deg/s) and accelerometer (mg)
  during the rest against the cluster time tau (s);
* ``histogram``: a population histogram of one parameter with its limits;
* ``diagnosis``: block-mean residual before and after each finding of a diagnosis
  (accel m/s^2, gyro deg/s), or the base model's residual when nothing is missing.

Each function returns the SVG text. Figures are built with :class:`matplotlib.figure.Figure`
directly (no global pyplot state), so they can be rendered from several threads.
"""

from __future__ import annotations

import io
import math

import numpy as np
from matplotlib.figure import Figure

from station.correct.session_correct import correct_session
from station.fit.acf import finite_record_acf, lowpass_record
from station.fit.allan import overlapping_allan_deviation
from station.kernel.display import display_for
from station.kernel.errors import FitError
from station.kernel.parameters import ParameterSet
from station.session.model import Kind, Session
from station.web.diagnosis_worker import Curve

AXES = "xyz"
_DEG = 180.0 / math.pi
_MG = display_for("acceleration")  # accelerometer quantities in mg (the display convention)
_MAX_POINTS = 4000


def _svg(fig: Figure) -> str:
    buf = io.StringIO()
    fig.savefig(buf, format="svg", bbox_inches="tight")
    return buf.getvalue()


def _stride(n: int) -> int:
    return max(1, n // _MAX_POINTS)


def raw_corrected_svg(session: Session, params: ParameterSet) -> str:
    """Raw versus corrected accelerometer (m/s^2) and gyro (deg/s) per axis over time (s)."""
    corrected = correct_session(session, params)
    k = _stride(len(session.t_s))
    t = session.t_s[::k]
    fig = Figure(figsize=(10, 7))
    axs = fig.subplots(3, 2, sharex=True)
    for i, a in enumerate(AXES):
        for col, (raw, cor, scale, unit, what) in enumerate((
            (session.accel_mps2, corrected.accel_mps2, _MG.scale, _MG.unit, "accel"),
            (session.gyro_radps, corrected.gyro_radps, _DEG, "deg/s", "gyro"),
        )):
            ax = axs[i, col]
            ax.plot(t, raw[::k, i] * scale, lw=0.6, color="#999999", label="raw")
            ax.plot(t, cor[::k, i] * scale, lw=0.6, color="#1f77b4", label="corrected")
            ax.set_ylabel(f"{what} {a} ({unit})")
            ax.grid(alpha=0.3)
    axs[0, 0].legend(loc="upper right", fontsize=8)
    axs[2, 0].set_xlabel("t (s)")
    axs[2, 1].set_xlabel("t (s)")
    fig.suptitle(f"{params.serial}: raw and corrected output")
    return _svg(fig)


def _rest(session: Session) -> np.ndarray:
    idx = np.flatnonzero(np.asarray(session.kind) == int(Kind.REST))
    if idx.size == 0:
        return np.arange(min(len(session.t_s), 1000))
    # the first contiguous rest block (the power-on rest)
    breaks = np.flatnonzero(np.diff(idx) > 1)
    return idx[: breaks[0] + 1] if breaks.size else idx


def drift_svg(session: Session, params: ParameterSet) -> str:
    """Gyro output during the power-on rest (deg/s) with the fitted b_stat + b_drift exp(-t/T_c) (eq. 1, 3)."""
    idx = _rest(session)
    t = session.t_s[idx]
    k = _stride(len(t))
    fig = Figure(figsize=(10, 3.2))
    axs = fig.subplots(1, 3)
    g = params.gyro
    for i, a in enumerate(AXES):
        ax = axs[i]
        ax.plot(t[::k], session.gyro_radps[idx[::k], i] * _DEG, lw=0.4, color="#999999", label="gyro output")
        tc = float(g.correlation_time_s[i])
        drift = float(g.bias_drift[i]) if math.isfinite(float(g.bias_drift[i])) else 0.0
        model = g.bias_static[i] + (drift * np.exp(-(t - t[0]) / tc) if math.isfinite(tc) and tc > 0 else 0.0)
        ax.plot(t, np.broadcast_to(model, t.shape) * _DEG, color="#d62728", lw=1.2, label="fit")
        ax.set_title(f"gyro {a}", fontsize=9)
        ax.set_xlabel("t (s)")
        ax.grid(alpha=0.3)
    axs[0].set_ylabel("rate (deg/s)")
    axs[0].legend(fontsize=8)
    fig.suptitle(f"{params.serial}: power-on drift")
    return _svg(fig)


def allan_svg(session: Session, params: ParameterSet) -> str:
    """Overlapping Allan deviation during the rest: gyro (deg/s) and accelerometer (m/s^2) versus tau (s)."""
    idx = _rest(session)
    rate = 1.0 / float(params.sample_period_s)
    fig = Figure(figsize=(10, 3.6))
    axs = fig.subplots(1, 2)
    for ax, data, scale, unit, what in ((axs[0], session.gyro_radps, _DEG, "deg/s", "gyro"),
                                        (axs[1], session.accel_mps2, _MG.scale, _MG.unit, "accel")):
        for i, a in enumerate(AXES):
            x = data[idx, i]
            x = x[np.isfinite(x)]
            if x.size < 20:
                continue
            curve = overlapping_allan_deviation(x * scale, rate)
            ax.loglog(curve.taus_s, curve.adev, marker=".", lw=0.8, label=a)
        ax.set_xlabel("τ (s)")
        ax.set_ylabel(f"Allan deviation ({unit})")
        ax.set_title(what, fontsize=9)
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize=8)
    fig.suptitle(f"{params.serial}: Allan deviation at rest")
    return _svg(fig)


def acf_svg(session: Session, params: ParameterSet) -> str:
    """Normalised autocorrelation of the low-passed rest record minus b_stat (eq. 4) per gyro and accel axis,
    against the lag (s), with the e^-1 level, its first crossing and the fitted T_c."""
    idx = _rest(session)
    rate = 1.0 / float(params.sample_period_s)
    fig = Figure(figsize=(10, 3.6))
    axs = fig.subplots(1, 2)
    for ax, data, tri, what in ((axs[0], session.gyro_radps, params.gyro, "gyro"),
                                (axs[1], session.accel_mps2, params.accel, "accel")):
        for i, a in enumerate(AXES):
            x = data[idx, i]
            rec = None
            for lowpass_s in (10.0, 2.0):  # a short rest cannot hold the 10 s low-pass
                try:
                    rec = lowpass_record(x[np.isfinite(x)], rate, lowpass_s=lowpass_s)
                    break
                except FitError:
                    continue
            if rec is None:
                ax.text(0.5, 0.5, "rest record too short", transform=ax.transAxes, ha="center")
                break
            y = np.asarray(rec.values) - float(tri.bias_static[i])
            s = finite_record_acf(y)
            if not s[0] > 0:
                continue
            rho = s / s[0]
            lag = np.arange(rho.size) / rec.rate_hz
            half = int(0.9 * rho.size)  # eq. 4 is a finite sum: the lags near the record length hold few terms
            line = ax.plot(lag[:half], rho[:half], lw=0.9, label=a)[0]
            below = np.flatnonzero(rho[:half] < math.exp(-1.0))
            if below.size:
                ax.plot(lag[below[0]], rho[below[0]], "o", color=line.get_color(), ms=5)
            tc = float(tri.correlation_time_s[i])
            if math.isfinite(tc) and tc < lag[half - 1]:
                ax.axvline(tc, color=line.get_color(), ls=":", lw=1.0)
        ax.axhline(math.exp(-1.0), color="#d62728", lw=1.0, ls="--", label="e⁻¹")
        ax.set_xlabel("lag (s)")
        ax.set_ylabel("normalised autocorrelation (1)")
        ax.set_title(f"{what}: dots = e⁻¹ crossing, dotted = fitted T_c", fontsize=9)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    fig.suptitle(f"{params.serial}: autocorrelation of the power-on drift")
    return _svg(fig)


def residuals_svg(params: ParameterSet) -> str:
    """RMS of the fit residual per segment and axis (accel mg, gyro deg/s), from the parameter set's quality."""
    fig = Figure(figsize=(10, 3.4))
    axs = fig.subplots(1, 2)
    for ax, what, scale, unit in ((axs[0], "accel", _MG.scale, _MG.unit), (axs[1], "gyro", _DEG, "deg/s")):
        figures = params.quality.residual(what)
        segs = (figures.segments if figures is not None else None) or {}
        keys = sorted(segs, key=lambda k: int(k) if str(k).isdigit() else 0)
        if keys:
            vals = np.array([[np.nan if v is None else float(v) for v in segs[k]] for k in keys]) * scale
            pos = np.arange(len(keys))
            for i, a in enumerate(AXES):
                ax.bar(pos + (i - 1) * 0.27, vals[:, i], width=0.27, label=a)
            ax.set_xticks(pos, [str(k) for k in keys], fontsize=7)
            ax.legend(fontsize=8)
        ax.set_xlabel("segment")
        ax.set_ylabel(f"residual RMS ({unit})")
        ax.set_title(what, fontsize=9)
        ax.grid(alpha=0.3, axis="y")
    fig.suptitle(f"{params.serial}: fit residual per segment")
    return _svg(fig)


def histogram_svg(name: str, unit: str, values: tuple[float, ...], low: float | None, high: float | None) -> str:
    """Histogram of ``values`` (``unit``) with the limits as red lines."""
    fig = Figure(figsize=(4.2, 2.6))
    ax = fig.subplots()
    if values:
        ax.hist(values, bins=max(5, min(30, int(math.sqrt(len(values))) + 3)), color="#1f77b4", alpha=0.8)
    for lim in (low, high):
        if lim is not None and math.isfinite(lim):
            ax.axvline(lim, color="#d62728", lw=1.5)
    ax.set_title(f"{name} ({unit}), n={len(values)}", fontsize=9)
    ax.tick_params(labelsize=7)
    ax.grid(alpha=0.3)
    return _svg(fig)


def message_svg(text: str) -> str:
    """A small SVG saying ``text`` (a plot that cannot be drawn)."""
    safe = text.replace("&", "&amp;").replace("<", "&lt;").replace(">", "&gt;")
    return (f'<svg xmlns="http://www.w3.org/2000/svg" width="480" height="60"><text x="10" y="35" '
            f'font-family="sans-serif" font-size="14">{safe}</text></svg>')


def _rms(a: np.ndarray) -> np.ndarray:
    with np.errstate(invalid="ignore"):
        return np.sqrt(np.nanmean(a * a, axis=0)) if a.size else np.full(a.shape[-1], np.nan)


def diagnosis_svg(curves: tuple[Curve, ...], title: str) -> str:
    """Block-mean residual (accel m/s^2, gyro deg/s) against time since power-on (s): per finding a row with the
    base model's residual and the residual with the finding modelled, on one y scale; RMS per axis in the titles."""
    if not curves:
        return message_svg("no residuals to show")
    two = any(c.after is not None for c in curves)
    fig = Figure(figsize=(10, 2.9 * len(curves) + 0.4))
    axs = fig.subplots(len(curves), 2 if two else 1, squeeze=False, sharex=True)
    for row, c in enumerate(curves):
        scale, unit = (_DEG, "deg/s") if c.unit == "rad/s" else (1.0, "m/s²")
        panels = [(c.before, c.labels[0] if c.after is not None else "block residual")]
        if c.after is not None:
            panels.append((c.after, c.labels[1]))
        for col, (data, label) in enumerate(panels):
            ax = axs[row, col]
            y = data * scale
            for i, a in enumerate(AXES):
                ax.plot(c.t_s, y[:, i], ".", ms=2.5, label=a)
            rms = ", ".join(f"{v:.3g}" for v in _rms(y))
            ax.set_title(f"{c.title}: {label}\nRMS x, y, z: {rms} {unit}", fontsize=9)
            ax.set_ylabel(unit)
            ax.grid(alpha=0.3)
        if len(panels) == 2:  # one y scale per row: the improvement is what the eye sees
            lo = min(axs[row, k].get_ylim()[0] for k in range(2))
            hi = max(axs[row, k].get_ylim()[1] for k in range(2))
            for k in range(2):
                axs[row, k].set_ylim(lo, hi)
        elif two:
            axs[row, 1].set_visible(False)
        axs[row, 0].legend(fontsize=7, markerscale=3, loc="upper right")
    for ax in axs[-1]:
        ax.set_xlabel("time since power-on (s)")
    fig.suptitle(title)
    return _svg(fig)
