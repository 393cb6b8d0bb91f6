"""What :func:`station.diagnose.report.diagnose` returns: the typed report and the numbers behind its figure."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

from station.diagnose.rerun import Rerun
from station.diagnose.residuals import Baseline
from station.diagnose.results import DiagnosisReport


class ResidualCurve(NamedTuple):
    """One finding's block residual, before and after it was taken into the model (m, 3), sensor units (SI).

    ``labels`` name the two panels where they are not the block residual (None): a recording whose censored data
    determine no base fit has no residual, and its curves are the recording itself and what censoring leaves of it
    (NaN where censored)."""

    title: str  # "SENSOR EFFECT", e.g. "accel lever_arm"
    t_s: np.ndarray  # block times (s)
    before: np.ndarray
    after: np.ndarray
    labels: tuple[str, str] | None = None


@dataclass(frozen=True, eq=False)
class Diagnosis:
    """Result of :func:`station.diagnose.report.diagnose`.

    Attributes:
        report: the typed report (:class:`~station.diagnose.results.DiagnosisReport`; ``report.to_json()`` is the
            ``station-diagnosis/1`` object).
        baseline: the base fit and residuals; None where the recording, its saturated segments censored, determines
            no base fit (:mod:`station.diagnose.censoring`).
        curves: per finding, its block residual before and after; where no base fit is determined, per censored
            sensor its recording and what censoring leaves of it.
        rerun: the simulator re-runs (base and extended), None when the recording cannot drive it.
    """

    report: DiagnosisReport
    baseline: Baseline | None
    curves: list[ResidualCurve] = field(default_factory=list)
    rerun: Rerun | None = None

    @property
    def effects(self) -> list[tuple[str, str]]:
        """(effect, sensor) of every finding."""
        return self.report.effects

    def to_json(self) -> dict[str, object]:
        """The ``station-diagnosis/1`` object (:meth:`DiagnosisReport.to_json`)."""
        return self.report.to_json()


__all__ = ["Diagnosis", "ResidualCurve"]
