"""``station diagnose SESSION.csv [--json] [--plot OUT.png] [--resamples N]``: the CLI front of :mod:`station.diagnose`.

Wire it into ``station/cli.py`` with ``app.command()(diagnose)``. The text report reads the typed
:class:`~station.diagnose.results.DiagnosisReport`; ``--json`` prints its ``to_json()``.
"""

from __future__ import annotations

import json
import sys
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import numpy as np
import typer

from station.kernel.errors import StationError

if TYPE_CHECKING:
    from station.diagnose.results import DiagnosisReport, Finding, RerunSummary
    from station.diagnose.results import RerunError as RerunErrorType


def _fmt_value(params: Mapping[str, Any]) -> tuple[str, str]:
    """A finding's parameters as 'value +- std' text and its unit (numbers rounded for people)."""
    if "pairs" in params:  # pose_tilt: per pose pair; the summary here, the pairs in --json
        d = [v["half_difference"] for v in params["pairs"].values() if v.get("half_difference")]
        text = "; ".join(f"{k.split(':')[0]} {v['half_difference']['value']:+.3f}+-{v['half_difference']['std']:.3f}"
                         for k, v in params["pairs"].items() if v.get("half_difference"))
        rms = params.get("rms_half_difference_deg")
        unit = "deg (tilt half-differences)" if d else ""
        return (f"rms {rms:.3f} ({text})" if rms is not None else text or "-"), unit
    if "value" not in params:  # outliers: one named parameter
        name, p = next(iter(params.items()))
        return f"{p['value']:.3g} +- {p['std']:.2g}", f"{p['unit']} ({name})"
    v = np.asarray(params["value"], dtype=float).ravel()
    sd = np.asarray(params["std"], dtype=float).ravel()
    text = ", ".join(f"{a:.3g}+-{b:.2g}" for a, b in zip(v, sd, strict=False))
    return text, str(params.get("unit", ""))


def _print_text(report: DiagnosisReport) -> None:
    findings, unexplained, untestable = report.findings, report.unexplained, report.untestable
    method = f" ({report.method}: tested on the still poses)" if report.method else ""
    typer.echo(f"diagnosis of {report.serial}{method}: {len(findings)} finding(s), {len(unexplained)} unexplained"
               + (f", {len(untestable)} untestable here" if untestable else ""))
    if (rf := report.rig_free) is not None and rf.accel_norm_rms_mps2 is not None:
        typer.echo(f"  base: rig-free fit, {rf.still_segments} still segments, {rf.moves} moves; gravity-norm "
                   f"RMS {rf.accel_norm_rms_mps2 * 1e3:.2f} mm/s^2, direction after each move "
                   f"{rf.gyro_direction_rms_deg:.3f} deg RMS")
        if (timing := rf.read_timing) and timing.get("selected"):
            # found and modelled by the base fit (station.fit.readtiming): the logger's, not the sensor's physics
            typer.echo(f"  base fit found in the gyro's read timing: {timing['reason']}")
    if findings:
        typer.echo(f"  {'effect':24s} {'sensor':6s} {'axes':4s} {'confidence':10s} value (unit)")
    for f in findings:
        _print_finding(f)
    for u in unexplained:
        if (c := u.censored) is not None:
            typer.echo(f"  UNEXPLAINED ({u.sensor}, axis {c.axis}, in {'/'.join(u.segment_kinds)} segments): "
                       f"{u.covariate}; {c.samples_excluded} samples in {len(c.segments)} segment(s) censored. "
                       f"{c.statement}.")
            if c.not_determined:
                typer.echo(f"    not determined: {'; '.join(c.not_determined)} ({c.reason})")
            continue
        typer.echo(f"  UNEXPLAINED ({u.sensor}, axes {''.join(u.axes)}, in {'/'.join(u.segment_kinds)} "
                   f"segments): {u.covariate}; excess chi2 {round(u.excess_chi2, 1):.0f}. No candidate of the library "
                   "explains it.")
    if untestable:
        typer.echo("  not testable on this recording:")
        by_reason: dict[tuple[str, str], list[str]] = {}
        for item in untestable:
            by_reason.setdefault((item.sensor, item.reason), []).append(item.effect)
        for (sensor, reason), effects in by_reason.items():
            typer.echo(f"    {', '.join(effects)} ({sensor}): {reason}")
    for pair in report.inseparable:
        typer.echo(f"  inseparable ({pair.sensor}): {' / '.join(pair.effects)}; rig step: {pair.rig_step}")
    if report.warmup_tc_range_s:
        ranges = ", ".join(f"{k} {lo:g}-{hi:g} s" for k, (lo, hi) in report.warmup_tc_range_s.items())
        typer.echo(f"  warm-up T_c kept in the sensor class's range: {ranges}")
    if not findings and not report.inseparable and not unexplained:
        typer.echo("  the base model (eq. 1 + eq. 3) explains this recording")
    sizes = [(r, r.detectable_from) for r in report.rejected
             if r.detectable_from is not None and r.detectable_from.determined]
    if sizes:
        typer.echo(f"  not found; this recording would show them ({100 * sizes[0][1].power:.0f} % power, "
                   "one parameter at a time) from:")
        for r, d in sizes:
            v = np.abs(np.asarray(d.value, dtype=float)).ravel()
            v = v[v > 0]
            if not v.size:
                continue
            span = f"{v.min():.3g}" if v.min() == v.max() else f"{v.min():.3g}-{v.max():.3g}"
            typer.echo(f"    {r.effect} ({r.sensor}): {span} {d.unit}")
    _print_rerun(report.rerun)


def _print_finding(f: Finding) -> None:
    """One finding: its value, the evidence, confidence and checks, calibration and re-run."""
    text, unit = _fmt_value(f.parameters)
    conf = f.confidence.level if f.confidence is not None else "-"
    typer.echo(f"  {f.effect:24s} {f.sensor:6s} {''.join(f.axes):4s} {conf:10s} {text} {unit}")
    ev = f.selection_test
    if ev is not None:
        typer.echo(f"    evidence: chi2 gain {ev.likelihood_gain_chi2:.1f} for {ev.params} parameter(s), "
                   f"BIC gain {ev.bic_gain:.1f}, held-out error {ev.heldout_before:.3f} -> "
                   f"{ev.heldout_after:.3f}"
                   + (" (1 = as expected)" if f.effect == "bias_random_walk" else ""))
        q = f.confidence
        if q is not None and q.quasi_gain_chi2 is not None:
            typer.echo(f"    against the full model, noise inflated by its dispersion: chi2 gain "
                       f"{q.quasi_gain_chi2:.1f} (threshold {q.limit:.1f})")
        if f.fit is not None:
            typer.echo(f"    block chi2 per axis {list(f.fit.before.block_chi2)} -> {list(f.fit.after.block_chi2)}")
    else:
        typer.echo(f"    evidence: {json.dumps(f.evidence.to_json())}")
    _print_confidence(f)
    if f.calibration is not None:
        typer.echo(f"    calibration: {'compensates it' if f.calibration.compensated else 'does not compensate it'}: "
                   f"{f.calibration.note}")
        if f.calibration.gain is not None:
            typer.echo(f"    {f.calibration.gain.describe()}")
    if f.rerun is not None:
        r = f.rerun
        typer.echo(f"    simulator re-run, block RMS per axis: {list(r.rms_base)} -> {list(r.rms_with_this_effect)} "
                   f"{r.unit} with this effect")


def _print_confidence(f: Finding) -> None:
    """A finding's bootstrap and consistency checks, one line each."""
    b = f.bootstrap
    if b is not None:
        spread = ""
        if b.median is not None:
            values = ", ".join(f"{m:.3g}+-{s:.2g}" for m, s in zip(b.median, b.std or (), strict=False))
            spread = f"; over the resamples {values} {b.unit}"
        typer.echo(f"    bootstrap over segments ({b.resamples} resamples, seed {b.seed}): named in "
                   f"{100 * b.accepted_fraction:.0f} %, spread {b.std_ratio:.2g} x the stated std{spread}")
    if f.consistency:
        parts = []
        for c in f.consistency:
            if c.check is None or c.parts is None:
                parts.append(f"not checked: {c.reason}")
                continue
            label = f"{c.parts[0]} vs {c.parts[1]}"
            if c.result == "not checked":
                parts.append(f"{label}: not checked, {c.reason}")
            else:
                parts.append(f"{label}: {c.result} (p {c.p_value:.2g})")
        typer.echo(f"    consistency: {'; '.join(parts)}")


def _print_rerun(rerun: RerunSummary | RerunErrorType) -> None:
    """The simulator re-run: recording minus simulation per block, base vs base + effects."""
    from station.diagnose.results import RerunError

    if isinstance(rerun, RerunError):
        typer.echo(f"  simulator re-run not possible: {rerun.error}")
        return
    n = len(rerun.effects)
    head = "simulator re-run on the recording's motion, recording minus simulation per block"
    typer.echo(f"  {head} (RMS x/y/z, chi2 x/y/z, 1 = noise):")
    for sensor in ("accel", "gyro"):
        b = rerun.base[sensor]
        line = f"    {sensor:5s} base {list(b.overall.rms)} {b.unit}, chi2 {list(b.overall.chi2)}"
        if n:
            e = rerun.extended[sensor]
            line += f" -> with {n} effect(s) {list(e.overall.rms)} {e.unit}, chi2 {list(e.overall.chi2)}"
        typer.echo(line + f" (noise {list(b.overall.noise_rms)})")
    for item in rerun.not_simulated:
        typer.echo(f"    not simulated: {item['effect']} ({item['sensor']}): {item['reason']}")


def diagnose(
    session_path: Annotated[Path, typer.Argument(metavar="SESSION.csv", help="session CSV v1 recording")],
    as_json: Annotated[bool, typer.Option("--json", help="print the diagnosis as one JSON object")] = False,
    plot: Annotated[Path | None, typer.Option("--plot", help="write a PNG of the residual before/after")] = None,
    limits: Annotated[Path | None, typer.Option(
        "--limits", help="limits file (e.g. fixtures/limits/default.toml) whose correlation_time_s ranges are the "
        "sensor class's T_c: a warm-up outside them is not taken for eq. 3's drift; its bias_drift ranges (and "
        "drift_noise where given) bound the drift noise in the locator. Default: the recording alone decides T_c, "
        "the locator takes Table 1's class")] = None,
    resamples: Annotated[int | None, typer.Option(
        "--resamples", min=0, help="bootstrap resamples over segments for each finding's confidence (0: none; "
        "default: station.diagnose.bootstrap.RESAMPLES)")] = None,
    progress: Annotated[bool | None, typer.Option(
        "--progress/--no-progress", help="print the diagnosis's stages to stderr (default: when stderr is a "
        "terminal); never into stdout")] = None,
) -> None:
    """Find the physics the base model misses in a recording, fit it and show the improvement."""
    import warnings

    from station.commands.output import check_output
    from station.commands.progress import stderr_progress
    from station.kernel.limits_file import load_limits
    from station.session import check_session_file, read_session

    try:
        if plot is not None:
            check_output(plot, inputs=[session_path], suffix=".png", what="--plot")
        check_session_file(session_path)  # a device, a huge or a foreign file: refused before the diagnosis's imports
        from station.diagnose.locator import TABLE1_DRIFT, DriftClass
        from station.diagnose.report import diagnose as run_diagnosis
        from station.diagnose.report import save_figure
        from station.fit.boundary import numerics

        limits_file = load_limits(limits) if limits is not None else None
        warmup_tc = limits_file.correlation_time_s if limits_file is not None else None
        drift = DriftClass.from_limits(limits_file) if limits_file is not None else TABLE1_DRIFT
        session = read_session(session_path)
        with warnings.catch_warnings(), numerics(f"diagnosis of {session.serial!r}"):
            warnings.simplefilter("ignore", RuntimeWarning)
            result = run_diagnosis(session, warmup_tc_s=warmup_tc, progress=stderr_progress(progress),
                                   drift_class=drift, **({} if resamples is None else {"resamples": resamples}))
        if plot is not None:
            save_figure(result, plot)
    except StationError as exc:
        typer.echo(f"error: {exc}", err=True)
        raise typer.Exit(2) from None
    except OSError as exc:
        typer.echo(f"error: cannot write {plot}: {exc.strerror or exc}", err=True)
        raise typer.Exit(2) from None
    if as_json:
        sys.stdout.write(json.dumps(result.report.to_json()) + "\n")
    else:
        _print_text(result.report)
        if plot is not None:
            typer.echo(f"wrote {plot}")


__all__ = ["diagnose"]
