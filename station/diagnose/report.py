"""The diagnosis of one session, and an optional figure.

:func:`diagnose` runs the whole chain (base fit, residuals, candidate selection, simulator re-run, calibration
check) and returns a :class:`~station.diagnose.outcome.Diagnosis`; its ``report`` is the typed
:class:`~station.diagnose.results.DiagnosisReport`, whose ``to_json()`` is the object ``station diagnose --json``
prints::

    {"format": "station-diagnosis/1", "findings": [...], "rejected": [...], "inseparable": [...],
     "location": {...}, "warmup_tc_range_s": {...} | null, "base_fit": {...}, "rerun": {...}}

Each finding has ``effect``, ``sensor`` (accel|gyro), ``axes``, ``parameters`` (value, std,
unit in engineering units), ``evidence`` (likelihood gain, BIC gain, held-out error) and
``fit`` (before/after: BIC, block chi^2 per axis, block residual RMS); a simulated finding also
has ``rerun`` (block RMS of its sensor per axis: base, base + this effect, all effects).
Each mean finding also has ``confidence`` (``level`` high/medium/low: the bootstrap's where it ran, else the
drop-one test's against the full model), ``consistency`` (its effect-specific checks,
:mod:`station.diagnose.finding_consistency`: per check ``check``, ``parts``, ``result`` passed/failed/not
informative/not checked, ``reason`` where not checked, chi^2 and the parameters per part) and ``bootstrap``
(:mod:`station.diagnose.bootstrap`: ``accepted_fraction``, ``std_ratio``, parameters' median and spread). A
finding failing a check is in ``rejected`` with the check under ``consistency``.
Each ``rejected`` entry has ``effect``, ``sensor`` and ``reason``; a mean candidate that brought no
significant improvement also has ``detectable_from`` (per parameter, in its engineering unit, the size
this recording would have shown with the quoted ``power``; :func:`station.diagnose.reporting.detectable_from`).

``rerun`` (:mod:`station.diagnose.rerun`): the simulator re-run on the recording's own motion
with the base model and with the accepted effects, compared with the recording per block:
``{"method", "effects", "not_simulated", "base": {SENSOR: STATS}, "extended": {SENSOR: STATS},
"improvement": {SENSOR: {"rms_ratio", "chi2_ratio"}}}`` where STATS holds ``unit``, ``blocks``,
``rms``, ``noise_rms``, ``chi2`` per axis and the same ``per_kind`` (rest/pose/rate/move);
``{"error": ...}`` when the recording cannot drive the simulator. ``warmup_tc_range_s``: the
sensor class's T_c range per sensor the diagnosis kept eq. 3's warm-up in (null: none given). Pure numerics: only
:func:`save_figure` writes a file.

A rig-free recording (:mod:`station.diagnose.rigfree_diagnosis`) adds ``"method": "rig-free"``, ``untestable``
(``effect``, ``sensor``, ``reason`` per candidate it cannot test) and ``rig_free`` (the base fit's still segments,
moves, gravity-norm and move-direction RMS, the Earth rate handling); its ``rerun`` is ``{"error": ...}``.
"""

from __future__ import annotations

import os
import time
from collections.abc import Mapping
from dataclasses import replace

import numpy as np
from threadpoolctl import threadpool_limits

from station.diagnose import noise_variance
from station.diagnose.bootstrap import RESAMPLES, SEED
from station.diagnose.censoring import Censoring, censor
from station.diagnose.diagnosis_progress import DONE, STAGES, Progress, Stage
from station.diagnose.finding_compensation import compensation
from station.diagnose.locator import TABLE1_DRIFT, DriftClass
from station.diagnose.outcome import Diagnosis, ResidualCurve
from station.diagnose.rerun import FittedEffect, Rerun, rerun
from station.diagnose.residuals import BaseFitNoise, fit_baseline, locate, warmup_ranges
from station.diagnose.results import FORMAT, DiagnosisReport, FindingRerun, RerunError, RerunSummary
from station.diagnose.rigfree_diagnosis import diagnose_rig_free
from station.diagnose.selection import select
from station.fit.rigfree_fit import is_rig_free
from station.kernel.errors import FitError
from station.session.model import Session


def diagnose(session: Session, *, warmup_tc_s: Mapping[str, tuple[float, float]] | None = None,
             resamples: int = RESAMPLES, seed: int = SEED, progress: Progress | None = None,
             drift_class: DriftClass = TABLE1_DRIFT) -> Diagnosis:
    """Diagnose ``session``: which physics the base model (eq. 1 + eq. 3) is missing.

    ``warmup_tc_s``: the sensor class's range of eq. 3's T_c (s) per sensor, e.g.
    ``LimitsFile.correlation_time_s``; see :func:`station.diagnose.residuals.fit_baseline`. None: the
    recording alone decides T_c (a temperature bias then often cannot be told from the warm-up).

    A rig-free recording (hand-held poses without references, :func:`station.fit.rigfree_fit.is_rig_free`) is
    diagnosed by :func:`station.diagnose.rigfree_diagnosis.diagnose_rig_free` (its report adds ``untestable``).

    ``resamples``: the bootstrap over segments that states each finding's confidence
    (:mod:`station.diagnose.bootstrap`, seeded with ``seed``: same recording, same numbers); 0 leaves it out.

    ``drift_class``: the class of the recording's sensor, whose drift noise bounds eq. 3's ``q`` in the locator
    (:class:`station.diagnose.locator.DriftClass`, e.g. ``DriftClass.from_limits(limits)``; default: Table 1).

    ``progress``: called with a :class:`~station.diagnose.diagnosis_progress.Stage` as each stage starts and once
    more when done (see :mod:`station.diagnose.diagnosis_progress`; a rig-free recording's diagnosis tells only its
    start and its end); None: nothing is told.

    Raises :class:`station.kernel.errors.FitError` when the base fit refuses the recording.
    """
    t0 = time.perf_counter()
    n = len(session)

    def tell(index: int) -> None:
        if progress is not None:
            name = STAGES[index] if index < len(STAGES) else DONE
            progress(Stage(index, len(STAGES), name, time.perf_counter() - t0, n))

    if is_rig_free(session):
        tell(0)
        out = diagnose_rig_free(session, warmup_tc_s=warmup_tc_s, resamples=resamples, seed=seed,
                                drift_class=drift_class)
        tell(len(STAGES))
        return out
    censoring = censor(session)  # a saturated axis: censored here, refused by station fit
    if not censoring.determined:
        tell(len(STAGES))
        return _not_determined(session, censoring)
    censored = bool(censoring.entries)
    session = censoring.session
    # the linear algebra is on a few hundred blocks: BLAS threads only spin
    with threadpool_limits(limits=1, user_api="blas"):
        tell(0)
        baseline = censoring.apply(fit_baseline(session, warmup_tc_s=warmup_tc_s, censored=censored))
        tell(1)
        decision = select(baseline, resamples=resamples, seed=seed, drift_class=drift_class)
        curves = [ResidualCurve(f"{f.sensor} {f.effect}", baseline.sensor(f.sensor).t_s, *f.block_residual)
                  for f in decision.findings if f.block_residual is not None]
        fitted = [FittedEffect(f.effect, f.sensor, np.zeros(0) if f.theta is None else f.theta)
                  for f in decision.findings if f.theta is not None or f.effect == "outliers"]
        tell(2)
        runs: Rerun | None
        section: RerunSummary | RerunError
        parts: list[FindingRerun | None]
        try:
            runs = rerun(baseline, fitted)
        except FitError as exc:
            runs, section, parts = None, RerunError(str(exc)), [None] * len(decision.findings)
        else:
            section = runs.summary()
            parts = [runs.finding_part(f.effect, f.sensor) for f in decision.findings]
        tell(3)
        calibration = compensation(session, [(f.effect, f.sensor) for f in decision.findings], warmup_tc_s=warmup_tc_s,
                                   censored=censored)
    findings = tuple(replace(f, rerun=part, calibration=c)
                     for f, part, c in zip(decision.findings, parts, calibration, strict=True))
    report = DiagnosisReport(
        serial=session.serial, findings=findings, rejected=decision.rejected, inseparable=decision.inseparable,
        unexplained=decision.unexplained + noise_variance.unexplained(session) + censoring.unexplained(),
        location=locate(baseline),
        warmup_tc_range_s=warmup_ranges(baseline),
        base_fit=BaseFitNoise.of(baseline), rerun=section)
    tell(len(STAGES))
    return Diagnosis(report=report, baseline=baseline, curves=curves, rerun=runs)


def _not_determined(session: Session, censoring: Censoring) -> Diagnosis:
    """The diagnosis of a recording whose censored data cannot determine the base fit: the censored entries (with
    the parameters not determined) and nothing else; no number for what the data cannot give."""
    report = DiagnosisReport(
        serial=session.serial, findings=(), rejected=(), inseparable=(), unexplained=censoring.unexplained(),
        location={}, warmup_tc_range_s=None, base_fit=None,
        rerun=RerunError("not run: with the saturated segments censored the base fit is not determined "
                         "(see unexplained: not_determined)"))
    return Diagnosis(report=report, baseline=None, curves=censoring.curves(), rerun=None)


def save_figure(diagnosis: Diagnosis, path: str | os.PathLike[str]) -> None:
    """Write a PNG of the block residual before and after each finding (needs matplotlib).

    Without findings, the base model's block residuals of both sensors are shown. With a simulator
    re-run, one more row per sensor shows the recording minus the base simulation and minus the
    extended simulation (base + the accepted effects), per block.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows: list[tuple[str, str, str, np.ndarray, np.ndarray, np.ndarray]] = []
    curves = diagnosis.curves
    if not curves:
        b = diagnosis.baseline
        if b is None:
            raise FitError("no figure: the recording determines no base fit (see the report)")
        curves = [ResidualCurve(f"{sd.sensor} base model", sd.t_s, sd.y, sd.y) for sd in (b.accel, b.gyro)]
    for title, t, before, after, labels in curves:
        left, right = labels or ("block residual before", "block residual after")
        rows.append((title.split(" ")[0], f"{title}: {left}", f"{title}: {right}", t, before, after))
    runs = diagnosis.rerun
    if runs is not None:
        for sensor in ("accel", "gyro"):
            sd = runs.baseline.sensor(sensor)
            rows.append((sensor, f"{sensor}: recording - base simulation", f"{sensor}: recording - simulation "
                         f"with {len(runs.extended.effects)} effect(s)", sd.t_s, runs.base.block_residual[sensor],
                         runs.extended.block_residual[sensor]))
    fig, axes = plt.subplots(len(rows), 2, figsize=(11, 2.8 * len(rows)), squeeze=False, sharex=True)
    for row, (sensor, left, right, t, before, after) in enumerate(rows):
        scale, unit = (np.degrees(1.0), "deg/s") if sensor == "gyro" else (1.0, "m/s^2")
        for col, (data, label) in enumerate(((before, left), (after, right))):
            ax = axes[row][col]
            for k, name in enumerate("xyz"):
                ax.plot(t, data[:, k] * scale, ".", ms=2, label=name)
            ax.set_title(label, fontsize=9)
            ax.set_ylabel(unit)
            ax.grid(alpha=0.3)
        axes[row][0].legend(fontsize=7, markerscale=4)
        if row >= len(curves):  # the re-run rows: one scale for both, so the improvement shows
            lo = min(axes[row][0].get_ylim()[0], axes[row][1].get_ylim()[0])
            hi = max(axes[row][0].get_ylim()[1], axes[row][1].get_ylim()[1])
            for ax in axes[row]:
                ax.set_ylim(lo, hi)
    for ax in axes[-1]:
        ax.set_xlabel("time since power-on (s)")
    fig.tight_layout()
    fig.savefig(os.fspath(path), dpi=110)
    plt.close(fig)


__all__ = ["FORMAT", "Diagnosis", "diagnose", "save_figure"]
