"""The diagnosis of a unit's recording in the JSON API (``GET /api/units/{serial}/diagnosis``).

One answer per state of the background diagnosis (see :mod:`station.web.diagnosis_worker`): ready
(200), pending (202), failed (422: the recording cannot be diagnosed), queue full (503).

A ready answer carries the ``station-diagnosis/1`` report as it is and its typed summary for people
(:class:`DiagnosisSummary`, what the diagnosis page shows): findings with engineering values, their
uncertainties and units and the confidence, what stays unexplained and where, effects the recording
cannot tell apart with the rig step that would, and the candidates tested and rejected. The summary is
read from the typed report (:class:`station.diagnose.results.DiagnosisReport`), attribute by attribute.
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping
from typing import TYPE_CHECKING, Annotated, Any, Literal

from pydantic import BaseModel, Field

from station.web.models.common import Serial

if TYPE_CHECKING:
    from station.diagnose.results import DiagnosisReport, Finding, Rejection, Unexplained

DiagnosedRun = Annotated[str, Field(description="the run whose recording is diagnosed")]
SessionSha256 = Annotated[str, Field(description="hex SHA-256 of the recording as the run stored it")]
Reason = Annotated[str, Field(description="why, one line")]


Number = float | None
#: A scalar, per-axis or matrix value (engineering units; null where not finite).
Values = Number | list[Number] | list[list[Number]]


class ParameterValue(BaseModel):
    """One fitted parameter of a finding (or a detectable size), in engineering units."""

    name: str = Field(description="what the value is: the effect's parameter vector, a derived figure (e.g. "
                                  "'length_mm') or one pose pair's tilt (e.g. '+-z about x: half-difference')")
    value: Values = Field(description="the value: scalar, per axis (x, y, z) or a 3x3 matrix, in ``unit``")
    std: Values = Field(default=None, description="its standard uncertainty, same shape and unit; null: none given")
    unit: str = Field(default="", description="engineering unit of value and std (e.g. 'mm', 'ms', 'ppm/K', 'deg')")


class FindingSummary(BaseModel):
    """An effect the recording supports."""

    effect: str = Field(description="the candidate effect's name (station.diagnose.effect_registry)")
    sensor: str = Field(description="'accel' or 'gyro'")
    axes: list[str] = Field(description="sensor axes the effect acts on")
    parameters: list[ParameterValue] = Field(description="fitted parameters with uncertainties and units")
    confidence: str | None = Field(default=None, description="how confident the diagnosis is ('high', 'medium', "
                                                             "'low'); null: not assessed (e.g. outliers)")
    quasi_gain_chi2: float | None = Field(default=None, description="chi^2 gain of the finding against the full "
                                                                    "model with the noise inflated by its "
                                                                    "dispersion (drop-one test)")
    threshold_chi2: float | None = Field(default=None, description="the critical chi^2 that gain is compared with")
    bic_gain: float | None = Field(default=None, description="BIC gain when the effect was added")
    heldout_before: float | None = Field(default=None, description="error on held-out segments without the effect")
    heldout_after: float | None = Field(default=None, description="... and with it")
    compensated: bool | None = Field(default=None, description="whether the station's calibration compensates it; "
                                                               "null: not checked")
    calibration_note: str | None = Field(default=None, description="why (not) compensated, one line")


class UnexplainedSummary(BaseModel):
    """Structure the accepted effects leave above the noise that no candidate of the library explains."""

    sensor: str = Field(description="'accel' or 'gyro'")
    axes: list[str] = Field(description="sensor axes where it is")
    segment_kinds: list[str] = Field(description="kinds of segment it is in (rest, pose, rate, move)")
    covariate: str = Field(description="what it follows: a covariate or frequency (e.g. periodic at the rate "
                                       "table's spin frequency, with amplitudes), or that none was found")
    excess_chi2: float | None = Field(default=None, description="chi^2 above the noise in those segments")
    amplitude: list[Number] | None = Field(default=None, description="per-axis amplitude of the periodic part "
                                                                     "at the spin frequency, in ``unit``")
    unit: str | None = Field(default=None, description="unit of ``amplitude`` (m/s^2 or deg/s)")


class InseparableSummary(BaseModel):
    """Effects this recording cannot tell apart."""

    effects: list[str] = Field(description="the effects (one of them, or the base model's warm-up, is there)")
    sensor: str = Field(description="'accel' or 'gyro'")
    rig_step: str = Field(description="the rig step that would separate them")


class RejectionSummary(BaseModel):
    """A candidate tested and not named."""

    effect: str = Field(description="the candidate (or the inseparable stand-ins, joined by ' / ')")
    sensor: str = Field(description="'accel' or 'gyro'")
    reason: str = Field(description="why it is not named, one line")
    rig_step: str | None = Field(default=None, description="the rig step that would make it identifiable, where "
                                                           "the recording cannot")
    detectable_from: ParameterValue | None = Field(
        default=None, description="the size per axis this recording would have shown (with the power named in "
                                  "its name), where no significant improvement was the reason")


class DiagnosisSummary(BaseModel):
    """What the diagnosis found, for people: the four lists of the report, typed."""

    findings: list[FindingSummary] = Field(description="effects the recording supports")
    unexplained: list[UnexplainedSummary] = Field(description="where residual structure stays that no candidate "
                                                              "explains (findings then do not name a stand-in)")
    inseparable: list[InseparableSummary] = Field(description="effects this recording cannot tell apart")
    rejected: list[RejectionSummary] = Field(description="candidates tested and not named")

    @classmethod
    def of(cls, report: DiagnosisReport | None) -> DiagnosisSummary:
        """The summary of a diagnosis report (empty lists for None)."""
        if report is None:
            return cls(findings=[], unexplained=[], inseparable=[], rejected=[])
        return cls(findings=[_finding(f) for f in report.findings],
                   unexplained=[_unexplained(u) for u in report.unexplained],
                   inseparable=[InseparableSummary(effects=list(i.effects), sensor=i.sensor, rig_step=i.rig_step)
                                for i in report.inseparable],
                   rejected=[_rejection(r) for r in report.rejected])


_UNIT_SUFFIX = re.compile(r"_(mm|ms|deg|dps|mps2|ppm|k|s|m)$", re.IGNORECASE)


def _num(v: Any) -> Any:
    """Finite floats kept, everything else (NaN, inf, strings) None; nested lists kept as lists."""
    if isinstance(v, list | tuple):
        return [_num(x) for x in v]
    if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(float(v)):
        return None
    return float(v)


def _value(name: str, d: Mapping[str, Any], unit: str = "") -> ParameterValue:
    return ParameterValue(name=name, value=_num(d.get("value")), std=_num(d.get("std")),
                          unit=str(d.get("unit") or unit))


def _parameters(effect: str, params: Mapping[str, Any]) -> list[ParameterValue]:
    """A finding's parameters (the effect's own shape, :func:`station.diagnose.effect_registry.engineering`) as a
    flat list: the parameter vector, derived figures, and nested groups (e.g. pose_tilt's pairs)."""
    out = []
    unit = str(params.get("unit") or "")
    if "value" in params:
        out.append(_value(effect, params))
    for key, v in params.items():
        if key in ("value", "std", "unit"):
            continue
        if isinstance(v, Mapping) and "value" in v:
            out.append(_value(key, v, unit))
        elif isinstance(v, Mapping):  # e.g. pose_tilt's pairs: name -> {half_difference: {value, std}, ...}
            for sub, w in v.items():
                for part, x in (w.items() if isinstance(w, Mapping) and "value" not in w else [("", w)]):
                    if isinstance(x, Mapping) and "value" in x:
                        label = f"{sub}: {part.replace('_', '-')}" if part else f"{key} {sub}"
                        out.append(_value(label, x, unit))
        elif isinstance(v, int | float) and not isinstance(v, bool):
            suffix = _UNIT_SUFFIX.search(key)
            out.append(ParameterValue(name=key, value=_num(v), unit=suffix.group(1) if suffix else unit))
    return out


def _finding(f: Finding) -> FindingSummary:
    conf, selected, cal = f.confidence, f.selection_test, f.calibration
    return FindingSummary(
        effect=f.effect, sensor=f.sensor, axes=list(f.axes), parameters=_parameters(f.effect, f.parameters),
        confidence=None if conf is None else conf.level,
        quasi_gain_chi2=None if conf is None else _num(conf.quasi_gain_chi2),
        threshold_chi2=None if conf is None else _num(conf.threshold),
        bic_gain=None if selected is None else _num(selected.bic_gain),
        heldout_before=None if selected is None else _num(selected.heldout_before),
        heldout_after=None if selected is None else _num(selected.heldout_after),
        compensated=None if cal is None else cal.compensated, calibration_note=None if cal is None else cal.note)


def _unexplained(u: Unexplained) -> UnexplainedSummary:
    periodic = u.periodic or {}
    amplitude = periodic.get("amplitude")
    return UnexplainedSummary(
        sensor=u.sensor, axes=list(u.axes), segment_kinds=list(u.segment_kinds), covariate=u.covariate,
        excess_chi2=_num(u.excess_chi2), amplitude=_num(amplitude) if isinstance(amplitude, list) else None,
        unit=periodic.get("unit"))


def _rejection(r: Rejection) -> RejectionSummary:
    d = r.detectable_from
    size = None
    if d is not None and d.determined:
        size = ParameterValue(name=f"detectable from ({100 * d.power:.0f} % power)", value=_num(d.value), std=None,
                              unit=d.unit)
    return RejectionSummary(effect=r.effect, sensor=r.sensor, reason=r.reason, rig_step=r.rig_step,
                            detectable_from=size)


class DiagnosisReady(BaseModel):
    """The diagnosis is ready."""

    status: Literal["ready"] = Field(description="'ready'")
    serial: Serial
    run_id: DiagnosedRun
    session_sha256: SessionSha256
    elapsed_s: float | None = Field(description="wall time the diagnosis took (s); null when not measured")
    report: dict[str, Any] = Field(description="the station-diagnosis/1 report of station.diagnose, as ``station "
                                               "diagnose --json`` prints it: findings with parameters and "
                                               "uncertainties (engineering units named in each), rejected and "
                                               "inseparable effects, where the residual is, the simulator re-run")
    summary: DiagnosisSummary = Field(description="the report's findings, unexplained structure, inseparable and "
                                                  "rejected effects, typed (what the diagnosis page shows)")


class DiagnosisPending(BaseModel):
    """The diagnosis is being computed: ask again after ``Retry-After`` seconds."""

    status: Literal["pending"] = Field(description="'pending'")
    serial: Serial
    run_id: DiagnosedRun
    session_sha256: SessionSha256


class DiagnosisFailed(BaseModel):
    """The recording cannot be diagnosed (the fit refuses it, it is not a session, it changed since its run)."""

    status: Literal["error"] = Field(description="'error'")
    detail: Reason
    serial: Serial
    run_id: DiagnosedRun
    session_sha256: SessionSha256


class DiagnosisQueueFull(BaseModel):
    """Too many recordings are waiting for a diagnosis: ask again after ``Retry-After`` seconds."""

    status: Literal["busy"] = Field(description="'busy'")
    detail: Reason
    serial: Serial
    run_id: DiagnosedRun
    session_sha256: SessionSha256


__all__ = [
    "DiagnosisFailed", "DiagnosisPending", "DiagnosisQueueFull", "DiagnosisReady", "DiagnosisSummary", "FindingSummary",
    "InseparableSummary", "ParameterValue", "RejectionSummary", "UnexplainedSummary",
]
