"""The diagnosis of one session as a JSON-ready object, and an optional figure.

:func:`diagnose` runs the whole chain (base fit, residuals, candidate selection) and
returns a :class:`Diagnosis`; ``Diagnosis.report`` is the object ``station diagnose --json``
prints::

    {"format": "station-diagnosis/1", "findings": [...], "rejected": [...], "inseparable": [...],
     "location": {...}, "base_fit": {...}}

Each finding has ``effect``, ``sensor`` (accel|gyro), ``axes``, ``parameters`` (value, std,
unit in engineering units), ``evidence`` (likelihood gain, BIC gain, held-out error) and
``fit`` (before/after: BIC, block chi^2 per axis, block residual RMS). Pure numerics:
only :func:`save_figure` writes a file.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from threadpoolctl import threadpool_limits

from station.diagnose.residuals import Baseline, fit_baseline, locate
from station.diagnose.select import select
from station.session.model import Session

FORMAT = "station-diagnosis/1"


@dataclass(frozen=True, eq=False)
class Diagnosis:
    """Result of :func:`diagnose`.

    Attributes:
        report: the JSON-ready object (see the module docstring).
        baseline: the base fit and residuals.
        curves: per finding, (block times s, block residual before, after), sensor units (SI).
    """

    report: dict[str, Any]
    baseline: Baseline
    curves: list[tuple[str, np.ndarray, np.ndarray, np.ndarray]] = field(default_factory=list)

    @property
    def effects(self) -> list[tuple[str, str]]:
        """(effect, sensor) of every finding."""
        return [(f["effect"], f["sensor"]) for f in self.report["findings"]]


def diagnose(session: Session) -> Diagnosis:
    """Diagnose ``session``: which physics the base model (eq. 1 + eq. 3) is missing.

    Raises :class:`station.errors.FitError` when the base fit refuses the recording.
    """
    # the linear algebra is on a few hundred blocks: BLAS threads only spin
    with threadpool_limits(limits=1, user_api="blas"):
        baseline = fit_baseline(session)
        decision = select(baseline)
    curves = []
    findings = []
    for f in decision.findings:
        res = f.pop("_block_residual", None)
        if res is not None:
            sd = baseline.sensor(f["sensor"])
            curves.append((f"{f['sensor']} {f['effect']}", sd.t_s, res[0], res[1]))
        findings.append(f)
    p = baseline.params
    report = {
        "format": FORMAT,
        "serial": session.serial,
        "findings": findings,
        "rejected": decision.rejected,
        "inseparable": decision.inseparable,
        "location": locate(baseline),
        "base_fit": {
            "accel_residual_rms_mps2": np.round(p.accel.residual_rms, 9).tolist(),
            "gyro_residual_rms_dps": np.round(np.degrees(p.gyro.residual_rms), 9).tolist(),
            "accel_noise_std_mps2": np.round(p.accel.noise_std, 9).tolist(),
            "gyro_noise_std_dps": np.round(np.degrees(p.gyro.noise_std), 9).tolist(),
        },
    }
    return Diagnosis(report=report, baseline=baseline, curves=curves)


def save_figure(diagnosis: Diagnosis, path: str | os.PathLike[str]) -> None:
    """Write a PNG of the block residual before and after each finding (needs matplotlib).

    Without findings, the base model's block residuals of both sensors are shown.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    curves = diagnosis.curves
    if not curves:
        b = diagnosis.baseline
        curves = [(f"{sd.sensor} base model", sd.t_s, sd.y, sd.y) for sd in (b.accel, b.gyro)]
    fig, axes = plt.subplots(len(curves), 2, figsize=(11, 2.8 * len(curves)), squeeze=False, sharex=True)
    for row, (title, t, before, after) in enumerate(curves):
        gyro = title.startswith("gyro")
        scale, unit = (np.degrees(1.0), "deg/s") if gyro else (1.0, "m/s^2")
        for col, (data, label) in enumerate(((before, "before"), (after, "after"))):
            ax = axes[row][col]
            for k, name in enumerate("xyz"):
                ax.plot(t, data[:, k] * scale, ".", ms=2, label=name)
            ax.set_title(f"{title}: block residual {label}", fontsize=9)
            ax.set_ylabel(unit)
            ax.grid(alpha=0.3)
        axes[row][0].legend(fontsize=7, markerscale=4)
    for ax in axes[-1]:
        ax.set_xlabel("time since power-on (s)")
    fig.tight_layout()
    fig.savefig(os.fspath(path), dpi=110)
    plt.close(fig)


__all__ = ["FORMAT", "Diagnosis", "diagnose", "save_figure"]
