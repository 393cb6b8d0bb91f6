"""Typed results of a diagnosis, built where they are decided, and their one JSON form.

:class:`DiagnosisReport` holds one diagnosis: its :class:`Finding` (each carrying its re-run and calibration
results), :class:`Rejection`, :class:`Inseparable` and :class:`Unexplained` entries,
the base fit's location section (:class:`~station.diagnose.residuals.SensorLocation` per sensor) and the
simulator re-run (:class:`RerunSummary`, or :class:`RerunError` where the recording cannot drive it).
:meth:`DiagnosisReport.to_json` is the one path to the ``station-diagnosis/1`` JSON object (``station diagnose
--json``, the web API, the web worker's file); :func:`load_report` reads it back into these types and refuses
another format.

Where an entry's content depends on the effect (a finding's ``parameters``, an inseparable pair's
``evidence``, a rejection's test numbers) it is kept as a JSON-ready mapping in the effect's engineering units
(:func:`station.diagnose.effect_registry.engineering`): the registry, not this module, says its shape.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from station.diagnose.bootstrap import Bootstrap
from station.diagnose.compensation_gain import CompensationGain
from station.diagnose.residuals import SENSORS, BaseFitNoise, SensorLocation
from station.kernel.errors import StationError

#: Format tag of the report (:meth:`DiagnosisReport.to_json`); :func:`load_report` refuses any other than these.
FORMAT = "station-diagnosis/1"
#: The tag of a report that censored a saturated axis (:class:`Censored` entries, ``base_fit`` null where the
#: censored recording determines no base fit): /1 plus those; written only where they occur, so a report
#: without them stays the /1 object it was, and a reader of /1 alone refuses one it would misread.
FORMAT_CENSORED = "station-diagnosis/2"
FORMATS = (FORMAT, FORMAT_CENSORED)

Json = dict[str, Any]


class ReportFormatError(StationError):
    """A diagnosis JSON object of another format (or not one at all)."""


# --- the parts of a finding --------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Compensation:
    """Whether the calibration compensates one finding, and why (not): the finding's ``calibration`` entry."""

    effect: str
    compensated: bool
    note: str
    gain: CompensationGain | None = None  # the corrected error on held-out segments, with and without it

    def to_json(self) -> Json:
        out: Json = {"compensated": self.compensated, "note": self.note}
        if self.gain is not None:
            out["held_out"] = self.gain.to_json()
        return out

    @classmethod
    def from_json(cls, effect: str, d: Mapping[str, Any]) -> Compensation:
        held = d.get("held_out")
        return cls(effect, bool(d["compensated"]), str(d["note"]),
                   None if held is None else CompensationGain.from_json(held))


@dataclass(frozen=True)
class CheckEntry:
    """One consistency check of a finding as reported (:meth:`station.diagnose.finding_consistency.Check.entry`):
    ``check`` None for an effect the registry gives no check; the numbers only where the check ran."""

    check: str | None
    result: str
    parts: tuple[str, str] | None = None
    chi2: float | None = None
    dof: int | None = None
    critical_chi2: float | None = None
    p_value: float | None = None
    power_chi2: float | None = None
    tolerance: float | None = None
    reason: str | None = None
    part_a: Mapping[str, Any] | None = None
    part_b: Mapping[str, Any] | None = None

    def to_json(self) -> Json:
        out: Json = {"check": self.check}
        if self.parts is not None:
            out["parts"] = list(self.parts)
        out["result"] = self.result
        if self.chi2 is not None:
            out.update({"chi2": self.chi2, "dof": self.dof, "critical_chi2": self.critical_chi2,
                        "p_value": self.p_value, "power_chi2": self.power_chi2, "tolerance": self.tolerance})
        if self.reason is not None:
            out["reason"] = self.reason
        if self.part_a is not None:
            out["part_a"], out["part_b"] = self.part_a, self.part_b
        return out

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> CheckEntry:
        parts = d.get("parts")
        return cls(check=d["check"], result=d["result"], parts=None if parts is None else (parts[0], parts[1]),
                   chi2=d.get("chi2"), dof=d.get("dof"), critical_chi2=d.get("critical_chi2"),
                   p_value=d.get("p_value"), power_chi2=d.get("power_chi2"), tolerance=d.get("tolerance"),
                   reason=d.get("reason"), part_a=d.get("part_a"), part_b=d.get("part_b"))


@dataclass(frozen=True)
class Confidence:
    """How sure the diagnosis is of a finding: the drop-one test's (:mod:`station.diagnose.robust`) and, where the
    bootstrap ran, the bootstrap's level (which is then ``level``; the drop-one one is ``drop_one_level``)."""

    level: str
    quasi_gain_chi2: float | None = None
    threshold: float | None = None
    #: a bias random walk's self-consistency z-scores (:meth:`SensorProblem.walk_consistency`)
    walk_consistency: Mapping[str, float] | None = None
    drop_one_level: str | None = None
    bootstrap_accepted_fraction: float | None = None
    #: why the level was lowered after the checks (e.g. the size re-test, :mod:`station.diagnose.retest`)
    capped_by: str | None = None

    @property
    def gain(self) -> float:
        """The drop-one quasi-likelihood chi^2 gain (0 where not tested)."""
        return 0.0 if self.quasi_gain_chi2 is None else self.quasi_gain_chi2

    @property
    def limit(self) -> float:
        """The threshold that gain is compared with (0 where not tested)."""
        return 0.0 if self.threshold is None else self.threshold

    @property
    def bootstrapped(self) -> bool:
        return self.bootstrap_accepted_fraction is not None

    def with_bootstrap(self, boot: Bootstrap) -> Confidence:
        """The confidence stated by the bootstrap ``boot``, the drop-one level kept beside it."""
        return Confidence(boot.level, self.quasi_gain_chi2, self.threshold, self.walk_consistency, self.level,
                          boot.accepted_fraction)

    def capped(self, level: str, reason: str) -> Confidence:
        """This confidence stated at ``level`` at most, ``reason`` saying why."""
        return replace(self, level=level, capped_by=reason)

    def to_json(self) -> Json:
        out: Json = {"level": self.level}
        if self.quasi_gain_chi2 is not None:
            out["quasi_gain_chi2"] = self.quasi_gain_chi2
            out["threshold"] = self.threshold
        if self.walk_consistency is not None:
            out["consistency"] = dict(self.walk_consistency)
        if self.bootstrapped:
            out["drop_one_level"] = self.drop_one_level
            out["bootstrap_accepted_fraction"] = self.bootstrap_accepted_fraction
        if self.capped_by is not None:
            out["capped_by"] = self.capped_by
        return out

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> Confidence:
        return cls(level=d["level"], quasi_gain_chi2=d.get("quasi_gain_chi2"), threshold=d.get("threshold"),
                   walk_consistency=d.get("consistency"), drop_one_level=d.get("drop_one_level"),
                   bootstrap_accepted_fraction=d.get("bootstrap_accepted_fraction"), capped_by=d.get("capped_by"))


@dataclass(frozen=True)
class FormInseparable:
    """Forms of one physics (a registry family) the recording names together: the effect is found, its form not."""

    family: str
    gains: Mapping[str, float]
    rig_step: str

    def to_json(self) -> Json:
        return {"family": self.family, "effects": {e: {"gain": g} for e, g in self.gains.items()},
                "rig_step": self.rig_step}

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> FormInseparable:
        return cls(d["family"], {e: v["gain"] for e, v in d["effects"].items()}, d["rig_step"])


@dataclass(frozen=True)
class Evidence:
    """The forward selection's test of a mean effect (or the random walk): likelihood and BIC gain, the critical
    chi^2, the held-out error before/after and the standard error of its change."""

    likelihood_gain_chi2: float
    params: int
    bic_gain: float
    critical_chi2: float
    heldout_before: float
    heldout_after: float
    heldout_change_se: float
    form_inseparable_from: FormInseparable | None = None
    #: its size re-fitted under the final model (:mod:`station.diagnose.retest`); None where not re-tested
    retest: SizeRetest | None = None

    def to_json(self) -> Json:
        out: Json = {"likelihood_gain_chi2": self.likelihood_gain_chi2, "params": self.params,
                     "bic_gain": self.bic_gain, "critical_chi2": self.critical_chi2,
                     "heldout_before": self.heldout_before, "heldout_after": self.heldout_after,
                     "heldout_change_se": self.heldout_change_se}
        if self.form_inseparable_from is not None:
            out["form_inseparable_from"] = self.form_inseparable_from.to_json()
        if self.retest is not None:
            out["retest"] = self.retest.to_json()
        return out

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> Evidence:
        form, retest = d.get("form_inseparable_from"), d.get("retest")
        return cls(d["likelihood_gain_chi2"], d["params"], d["bic_gain"], d["critical_chi2"], d["heldout_before"],
                   d["heldout_after"], d["heldout_change_se"],
                   None if form is None else FormInseparable.from_json(form),
                   None if retest is None else SizeRetest.from_json(retest))


@dataclass(frozen=True)
class SizeRetest:
    """A finding's size fitted again in the final model, with eq. 3's drift noise free and bounded by the sensor
    class (engineering units, as the effect registry gives them), and the largest change between the three fits
    over the finding's standard deviation (:mod:`station.diagnose.retest`)."""

    final_model: Mapping[str, Any]
    final_model_drift_noise_at_class: Mapping[str, Any]
    change_over_std: float
    note: str

    def to_json(self) -> Json:
        return {"final_model": dict(self.final_model),
                "final_model_drift_noise_at_class": dict(self.final_model_drift_noise_at_class),
                "change_over_std": self.change_over_std, "note": self.note}

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> SizeRetest:
        return cls(d["final_model"], d["final_model_drift_noise_at_class"], d["change_over_std"], d["note"])


@dataclass(frozen=True)
class OutlierEvidence:
    """The outlier count against the sensor class's allowance (Poisson tail)."""

    count: int
    samples: int
    allowance: float
    p_value: float

    def to_json(self) -> Json:
        return {"count": self.count, "samples": self.samples, "allowance": self.allowance, "p_value": self.p_value}

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> OutlierEvidence:
        return cls(d["count"], d["samples"], d["allowance"], d["p_value"])


@dataclass(frozen=True)
class BlockFit:
    """The sensor's model before or after a finding: BIC, block chi^2 and block residual RMS per axis."""

    bic: float
    block_chi2: tuple[float, ...]
    block_rms: tuple[float, ...]
    unit: str

    def to_json(self) -> Json:
        return {"bic": self.bic, "block_chi2": list(self.block_chi2), "block_rms": list(self.block_rms),
                "unit": self.unit}

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> BlockFit:
        return cls(d["bic"], tuple(d["block_chi2"]), tuple(d["block_rms"]), d["unit"])


@dataclass(frozen=True)
class FitChange:
    """The sensor's fit before and after the finding was taken into the model."""

    before: BlockFit
    after: BlockFit

    def to_json(self) -> Json:
        return {"before": self.before.to_json(), "after": self.after.to_json()}

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> FitChange | None:
        return cls(BlockFit.from_json(d["before"]), BlockFit.from_json(d["after"])) if d else None


@dataclass(frozen=True)
class FindingRerun:
    """A simulated finding's re-run: block RMS per axis of its sensor for the base model, the base model with this
    effect alone, and with all accepted effects (:meth:`station.diagnose.rerun.Rerun.finding_part`)."""

    unit: str
    rms_base: tuple[float, ...]
    rms_with_this_effect: tuple[float, ...]
    rms_extended: tuple[float, ...]

    def to_json(self) -> Json:
        return {"unit": self.unit, "rms_base": list(self.rms_base), "rms_with_this_effect": list(
            self.rms_with_this_effect), "rms_extended": list(self.rms_extended)}

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> FindingRerun:
        return cls(d["unit"], tuple(d["rms_base"]), tuple(d["rms_with_this_effect"]), tuple(d["rms_extended"]))


@dataclass(frozen=True, eq=False)
class Finding:
    """An effect the recording supports, with its parameters in engineering units.

    ``parameters``: per the effect (:func:`station.diagnose.effect_registry.engineering`), JSON-ready;
    ``evidence``: the selection's test (:class:`Evidence`) or, for ``outliers``, the count (:class:`OutlierEvidence`);
    ``fit``: the sensor's fit before/after (None for ``outliers``); ``confidence``: None where not assessed;
    ``consistency``: the effect-specific checks (:mod:`station.diagnose.finding_consistency`; a ``not checked``
    entry with the reason where none could run); ``bootstrap``: None where not run; ``rerun``: the simulator
    re-run's part (None where not simulated); ``calibration``: whether the station's calibration compensates it
    (None before that is assessed). ``theta`` (the fitted SI parameters, for the simulator re-run) and
    ``block_residual`` (the block residual before and after the effect, (m, 3), sensor units) and ``theta_std``
    (the stated standard deviations of ``theta``, for the size re-test) are not part of the JSON entry.
    """

    effect: str
    sensor: str
    axes: tuple[str, ...]
    parameters: Mapping[str, Any]
    evidence: Evidence | OutlierEvidence
    fit: FitChange | None = None
    confidence: Confidence | None = None
    consistency: tuple[CheckEntry, ...] = ()
    bootstrap: Bootstrap | None = None
    rerun: FindingRerun | None = None
    calibration: Compensation | None = None
    theta: np.ndarray | None = field(default=None, repr=False)
    block_residual: tuple[np.ndarray, np.ndarray] | None = field(default=None, repr=False)
    theta_std: np.ndarray | None = field(default=None, repr=False)

    @property
    def selection_test(self) -> Evidence | None:
        """The forward selection's test of it (None for an outlier count, which is no model term)."""
        return self.evidence if isinstance(self.evidence, Evidence) else None

    def to_json(self) -> Json:
        out: Json = {"effect": self.effect, "sensor": self.sensor, "axes": list(self.axes),
                     "parameters": dict(self.parameters), "evidence": self.evidence.to_json(),
                     "fit": {} if self.fit is None else self.fit.to_json()}
        if self.confidence is not None:
            out["confidence"] = self.confidence.to_json()
        if self.consistency:
            out["consistency"] = [c.to_json() for c in self.consistency]
        if self.bootstrap is not None:
            out["bootstrap"] = self.bootstrap.to_json()
        if self.rerun is not None:
            out["rerun"] = self.rerun.to_json()
        if self.calibration is not None:
            out["calibration"] = self.calibration.to_json()
        return out

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> Finding:
        ev = d["evidence"]
        conf, boot, rr, cal = d.get("confidence"), d.get("bootstrap"), d.get("rerun"), d.get("calibration")
        return cls(
            effect=d["effect"], sensor=d["sensor"], axes=tuple(d["axes"]), parameters=d["parameters"],
            evidence=OutlierEvidence.from_json(ev) if "likelihood_gain_chi2" not in ev else Evidence.from_json(ev),
            fit=FitChange.from_json(d.get("fit") or {}),
            confidence=None if conf is None else Confidence.from_json(conf),
            consistency=tuple(CheckEntry.from_json(c) for c in d.get("consistency", ())),
            bootstrap=None if boot is None else Bootstrap.from_json(boot),
            rerun=None if rr is None else FindingRerun.from_json(rr),
            calibration=None if cal is None else Compensation.from_json(d["effect"], cal))


# --- the other entries -----------------------------------------------------------------------------------------
@dataclass(frozen=True)
class DetectableSize:
    """How large each parameter of a rejected candidate would have had to be for this recording to show it
    (:func:`station.diagnose.reporting.detectable_from`); ``value`` None: the recording does not determine every
    parameter (the base model absorbs some), so no size is quoted."""

    value: Any = None
    unit: str = ""
    power: float = 0.0
    noncentrality: float = 0.0

    @property
    def determined(self) -> bool:
        return self.value is not None

    def to_json(self) -> Json | None:
        if not self.determined:
            return None
        return {"value": self.value, "unit": self.unit, "power": self.power, "noncentrality": self.noncentrality}

    @classmethod
    def from_json(cls, d: Mapping[str, Any] | None) -> DetectableSize:
        return cls() if d is None else cls(d["value"], d["unit"], d["power"], d["noncentrality"])


@dataclass(frozen=True)
class Rejection:
    """A candidate tested and not named, and why.

    ``details``: its test numbers (gain, BIC gain, threshold, counts, a failed consistency check, ...), JSON-ready
    and in the order reported; ``rig_step``: the rig step that would make it identifiable, where the recording
    cannot; ``detectable_from``: where no significant improvement was the reason, the size this recording would
    have shown (None: not a mean candidate that was short of significance)."""

    effect: str
    sensor: str
    reason: str
    details: Mapping[str, Any] = field(default_factory=dict)
    rig_step: str | None = None
    detectable_from: DetectableSize | None = None

    def to_json(self) -> Json:
        out: Json = {"effect": self.effect, "sensor": self.sensor, **self.details}
        if self.rig_step is not None:
            out["rig_step"] = self.rig_step
        if self.detectable_from is not None:
            out["detectable_from"] = self.detectable_from.to_json()
        out["reason"] = self.reason
        return out

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> Rejection:
        typed = ("effect", "sensor", "reason", "rig_step", "detectable_from")
        return cls(effect=d["effect"], sensor=d["sensor"], reason=d["reason"],
                   details={k: v for k, v in d.items() if k not in typed}, rig_step=d.get("rig_step"),
                   detectable_from=DetectableSize.from_json(d["detectable_from"]) if "detectable_from" in d else None)


@dataclass(frozen=True)
class Inseparable:
    """Effects this recording cannot tell apart, and the rig step that would (``evidence``: per the pair)."""

    effects: tuple[str, ...]
    sensor: str
    evidence: Mapping[str, Any]
    rig_step: str

    def to_json(self) -> Json:
        return {"effects": list(self.effects), "sensor": self.sensor, "evidence": dict(self.evidence),
                "rig_step": self.rig_step}

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> Inseparable:
        return cls(effects=tuple(d["effects"]), sensor=d["sensor"], evidence=d.get("evidence", {}),
                   rig_step=d["rig_step"])


@dataclass(frozen=True)
class Untestable:
    """A candidate this kind of recording (rig-free) cannot test, and why."""

    effect: str
    sensor: str
    reason: str

    def to_json(self) -> Json:
        return {"effect": self.effect, "sensor": self.sensor, "reason": self.reason}

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> Untestable:
        return cls(d["effect"], d["sensor"], d["reason"])


@dataclass(frozen=True)
class Censored:
    """A saturated (clipped) axis the diagnosis censored (:mod:`station.diagnose.censoring`): the rails its output
    sits at, the samples at them and the segments taken out of its triad's data, and what that leaves undetermined.

    ``levels`` (one per rail, the minimum before the maximum) are in the display convention (``unit``: deg/s for
    the gyro's rate, mg for the accelerometer's specific force, :mod:`station.kernel.display`), ``levels_si`` in
    the sensor's SI unit. ``samples_at_level``: samples at or beyond a rail; ``samples_excluded``: the samples of
    the censored segments (``segments``: their indices in the recording). ``not_determined``: the parameters the
    censored recording cannot determine (empty: the rest is diagnosed as usual), with ``reason``.
    """

    sensor: str
    axis: str
    levels_si: tuple[float, ...]
    levels: tuple[float, ...]
    unit: str
    samples_at_level: int
    samples_excluded: int
    segments: tuple[int, ...]
    statement: str
    not_determined: tuple[str, ...] = ()
    reason: str = ""

    def to_json(self) -> Json:
        out: Json = {"axis": self.axis, "levels": list(self.levels), "unit": self.unit,
                     "levels_si": list(self.levels_si), "samples_at_level": self.samples_at_level,
                     "samples_excluded": self.samples_excluded, "segments": list(self.segments),
                     "statement": self.statement, "not_determined": list(self.not_determined)}
        if self.reason:
            out["reason"] = self.reason
        return out

    @classmethod
    def from_json(cls, sensor: str, d: Mapping[str, Any]) -> Censored:
        return cls(sensor, d["axis"], tuple(d["levels_si"]), tuple(d["levels"]), d["unit"], d["samples_at_level"],
                   d["samples_excluded"], tuple(d["segments"]), d["statement"], tuple(d["not_determined"]),
                   d.get("reason", ""))


@dataclass(frozen=True)
class Unexplained:
    """Where the final model leaves structure that no candidate explains (:mod:`station.diagnose.robust`), or a
    saturated axis the diagnosis censored (``censored``; its ``excess_chi2`` is NaN, written null: censored samples
    are not fitted)."""

    sensor: str
    axes: tuple[str, ...]
    segment_kinds: tuple[str, ...]
    covariate: str
    dispersion: dict[str, list[float]]  # kind -> mean square innovation per axis (1 = noise)
    excess_chi2: float
    periodic: dict[str, Any] | None = None
    #: the mismatch locator's evidence (:mod:`station.diagnose.locator`); None where the entry is robust.py's
    locator: LocatorEvidence | None = None
    #: empirical models of the located axes (:mod:`station.diagnose.empirical`); None where none were fitted
    empirical: tuple[EmpiricalModel, ...] | None = None
    #: a saturated axis censored from the diagnosis's data (:mod:`station.diagnose.censoring`); None otherwise
    censored: Censored | None = None

    def to_json(self) -> Json:
        if self.censored is not None:
            return {"sensor": self.sensor, "axes": list(self.axes), "segment_kinds": list(self.segment_kinds),
                    "covariate": self.covariate, "dispersion": self.dispersion, "excess_chi2": None,
                    "explained_by": None, "note": self.censored.statement, "censored": self.censored.to_json()}
        out: Json = {"sensor": self.sensor, "axes": list(self.axes), "segment_kinds": list(self.segment_kinds),
                     "covariate": self.covariate, "dispersion": self.dispersion,
                     "excess_chi2": round(self.excess_chi2, 1), "explained_by": None,
                     "note": "no candidate of the library explains this: physics outside the model"}
        if self.locator is not None:
            out["locator"] = self.locator.to_json()
        if self.empirical is not None:
            out["empirical"] = [e.to_json() for e in self.empirical]
        if self.periodic:
            out["periodic"] = self.periodic
        return out

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> Unexplained:
        loc, emp, cen = d.get("locator"), d.get("empirical"), d.get("censored")
        chi2 = d["excess_chi2"]
        return cls(d["sensor"], tuple(d["axes"]), tuple(d["segment_kinds"]), d["covariate"], d["dispersion"],
                   float("nan") if chi2 is None else chi2, d.get("periodic"),
                   None if loc is None else LocatorEvidence.from_json(loc),
                   None if emp is None else tuple(EmpiricalModel.from_json(e) for e in emp),
                   None if cen is None else Censored.from_json(d["sensor"], cen))


@dataclass(frozen=True)
class CovariateTest:
    """One covariate the locator tried on one axis: its chi^2 gain (whitened, 1 dof) and its share of the
    excess."""

    axis: str
    name: str
    gain_chi2: float
    share_of_excess: float

    def to_json(self) -> Json:
        return {"axis": self.axis, "covariate": self.name, "gain_chi2": round(self.gain_chi2, 1),
                "share_of_excess": round(self.share_of_excess, 3)}

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> CovariateTest:
        return cls(d["axis"], d["covariate"], d["gain_chi2"], d["share_of_excess"])


@dataclass(frozen=True)
class LocatorEvidence:
    """How the locator located an :class:`Unexplained` entry: the covariate per axis (or ``none``), the fitted
    drift noise over the class bound per axis, the covariates tried, the accepted effects it rejected as
    stand-ins."""

    covariate_per_axis: tuple[tuple[str, str], ...]
    q_over_class: tuple[float, ...]
    tests: tuple[CovariateTest, ...]
    stand_ins: tuple[str, ...] = ()
    stochastic_terms: str = "drift noise q bounded by the sensor class"

    def to_json(self) -> Json:
        return {"stochastic_terms": self.stochastic_terms, "covariate_per_axis": dict(self.covariate_per_axis),
                "q_over_class": [round(v, 3) for v in self.q_over_class],
                "tests": [t.to_json() for t in self.tests], "stand_ins_rejected": list(self.stand_ins)}

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> LocatorEvidence:
        return cls(tuple(d["covariate_per_axis"].items()), tuple(d["q_over_class"]),
                   tuple(CovariateTest.from_json(t) for t in d["tests"]), tuple(d["stand_ins_rejected"]),
                   d["stochastic_terms"])


@dataclass(frozen=True)
class EmpiricalModel:
    """A sparse model of one axis's located structure, scored on held-out segments
    (:mod:`station.diagnose.empirical`): empirical, not in the library."""

    sensor: str
    axis: str
    terms: tuple[str, ...]
    coefficients: tuple[float, ...]  # sensor SI unit per covariate unit (covariates in SI: rad/s, m/s^2, K, s)
    heldout_improvement: float  # 1 - held-out error with the model / without it (0: nothing)
    folds: int

    def to_json(self) -> Json:
        return {"sensor": self.sensor, "axis": self.axis, "status": "empirical, not in the library",
                "terms": [{"covariate": t, "coefficient_si": float(f"{c:.6g}")}
                          for t, c in zip(self.terms, self.coefficients, strict=True)],
                "heldout_improvement": round(self.heldout_improvement, 3), "folds": self.folds}

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> EmpiricalModel:
        return cls(d["sensor"], d["axis"], tuple(t["covariate"] for t in d["terms"]),
                   tuple(t["coefficient_si"] for t in d["terms"]), d["heldout_improvement"], d["folds"])



# --- the simulator re-run ----------------------------------------------------------------------------------------
@dataclass(frozen=True)
class KindStatistics:
    """Block residual of one sensor over some blocks: count, RMS (weighted by block size), its white-noise floor
    and the block chi^2, per axis (gyro in deg/s)."""

    blocks: int
    rms: tuple[float, ...]
    noise_rms: tuple[float, ...]
    chi2: tuple[float, ...]

    def to_json(self) -> Json:
        return {"blocks": self.blocks, "rms": list(self.rms), "noise_rms": list(self.noise_rms),
                "chi2": list(self.chi2)}

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> KindStatistics:
        return cls(d["blocks"], tuple(d["rms"]), tuple(d["noise_rms"]), tuple(d["chi2"]))


@dataclass(frozen=True)
class BlockStatistics:
    """:class:`KindStatistics` over all blocks of a sensor and per kind of segment, with the unit."""

    unit: str
    overall: KindStatistics
    per_kind: Mapping[str, KindStatistics]

    def to_json(self) -> Json:
        return {"unit": self.unit, **self.overall.to_json(),
                "per_kind": {k: v.to_json() for k, v in self.per_kind.items()}}

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> BlockStatistics:
        return cls(d["unit"], KindStatistics.from_json(d),
                   {k: KindStatistics.from_json(v) for k, v in d["per_kind"].items()})


@dataclass(frozen=True)
class Improvement:
    """Base over extended re-run, per axis: RMS ratio and chi^2 ratio (1 where the extended one is 0)."""

    rms_ratio: tuple[float, ...]
    chi2_ratio: tuple[float, ...]

    def to_json(self) -> Json:
        return {"rms_ratio": list(self.rms_ratio), "chi2_ratio": list(self.chi2_ratio)}

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> Improvement:
        return cls(tuple(d["rms_ratio"]), tuple(d["chi2_ratio"]))


@dataclass(frozen=True)
class RerunSummary:
    """The report's ``rerun`` section (:mod:`station.diagnose.rerun`): the simulator on the recording's own
    motion with the base model and with the accepted effects, compared with the recording per block."""

    method: str
    effects: tuple[tuple[str, str], ...]  # (effect, sensor) simulated
    not_simulated: tuple[Mapping[str, str], ...]
    base: Mapping[str, BlockStatistics]
    extended: Mapping[str, BlockStatistics]
    improvement: Mapping[str, Improvement]

    def to_json(self) -> Json:
        return {"method": self.method, "effects": [{"effect": e, "sensor": s} for e, s in self.effects],
                "not_simulated": [dict(x) for x in self.not_simulated],
                "base": {s: v.to_json() for s, v in self.base.items()},
                "extended": {s: v.to_json() for s, v in self.extended.items()},
                "improvement": {s: v.to_json() for s, v in self.improvement.items()}}

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> RerunSummary:
        return cls(d["method"], tuple((e["effect"], e["sensor"]) for e in d["effects"]),
                   tuple(d["not_simulated"]),
                   {s: BlockStatistics.from_json(v) for s, v in d["base"].items()},
                   {s: BlockStatistics.from_json(v) for s, v in d["extended"].items()},
                   {s: Improvement.from_json(v) for s, v in d["improvement"].items()})


@dataclass(frozen=True)
class RerunError:
    """Why no simulator re-run: the recording cannot drive the simulator (or has no known motion)."""

    error: str

    def to_json(self) -> Json:
        return {"error": self.error}


# --- the rig-free section ----------------------------------------------------------------------------------------
@dataclass(frozen=True)
class RigFreeSection:
    """A rig-free recording's base fit (:mod:`station.fit.rigfree_fit`): still segments, moves, gravity-norm and
    move-direction RMS, the Earth rate taken out, the read timing, and which blocks the diagnosis uses."""

    still_segments: int | None
    moves: int | None
    accel_norm_rms_mps2: float | None
    gyro_direction_rms_deg: float | None
    earth_vertical_removed_dps: float | None
    read_timing: Any
    blocks: str

    def to_json(self) -> Json:
        return {"still_segments": self.still_segments, "moves": self.moves,
                "accel_norm_rms_mps2": self.accel_norm_rms_mps2, "gyro_direction_rms_deg": self.gyro_direction_rms_deg,
                "earth_vertical_removed_dps": self.earth_vertical_removed_dps, "read_timing": self.read_timing,
                "blocks": self.blocks}

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> RigFreeSection:
        return cls(d["still_segments"], d["moves"], d["accel_norm_rms_mps2"], d["gyro_direction_rms_deg"],
                   d["earth_vertical_removed_dps"], d["read_timing"], d["blocks"])


# --- the report ----------------------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class DiagnosisReport:
    """One diagnosis (``station-diagnosis/1``): every candidate of each sensor found, rejected (with why),
    inseparable or untestable; where structure stays unexplained; the base fit's location section and noise; the
    warm-up T_c range given (None: none); the simulator re-run. ``method`` "rig-free" (with ``untestable`` and
    ``rig_free``) for a hand-held recording, else None."""

    serial: str
    findings: tuple[Finding, ...]
    rejected: tuple[Rejection, ...]
    inseparable: tuple[Inseparable, ...]
    unexplained: tuple[Unexplained, ...]
    location: Mapping[str, SensorLocation]
    warmup_tc_range_s: Mapping[str, tuple[float, float]] | None
    base_fit: BaseFitNoise | None  # None: a censored recording that determines no base fit (``not_determined``)
    rerun: RerunSummary | RerunError
    method: str | None = None
    untestable: tuple[Untestable, ...] = ()
    rig_free: RigFreeSection | None = None

    def of_sensor(self, sensor: str) -> SensorReport:
        """The entries of one sensor."""
        return SensorReport(sensor, tuple(f for f in self.findings if f.sensor == sensor),
                            tuple(r for r in self.rejected if r.sensor == sensor),
                            tuple(i for i in self.inseparable if i.sensor == sensor),
                            tuple(u for u in self.unexplained if u.sensor == sensor), self.location.get(sensor))

    @property
    def sensors(self) -> Iterator[SensorReport]:
        return (self.of_sensor(s) for s in SENSORS)

    @property
    def effects(self) -> list[tuple[str, str]]:
        """(effect, sensor) of every finding."""
        return [(f.effect, f.sensor) for f in self.findings]

    def to_json(self) -> Json:
        """The ``station-diagnosis/1`` object (see :mod:`station.diagnose.report`)."""
        censored = self.base_fit is None or any(u.censored is not None for u in self.unexplained)
        out: Json = {"format": FORMAT_CENSORED if censored else FORMAT, "serial": self.serial}
        if self.method is not None:
            out["method"] = self.method
        out["findings"] = [f.to_json() for f in self.findings]
        out["rejected"] = [r.to_json() for r in self.rejected]
        if self.method is not None:
            out["untestable"] = [u.to_json() for u in self.untestable]
        out.update({
            "inseparable": [i.to_json() for i in self.inseparable],
            "unexplained": [u.to_json() for u in self.unexplained],
            "location": {s: loc.to_json() for s, loc in self.location.items()},
            "warmup_tc_range_s": None if self.warmup_tc_range_s is None else {
                s: list(r) for s, r in self.warmup_tc_range_s.items()},
            "base_fit": None if self.base_fit is None else self.base_fit.to_json(),
        })
        if self.rig_free is not None:
            out["rig_free"] = self.rig_free.to_json()
        out["rerun"] = self.rerun.to_json()
        return out


@dataclass(frozen=True)
class SensorReport:
    """The entries of one sensor of a :class:`DiagnosisReport`."""

    sensor: str
    findings: tuple[Finding, ...]
    rejected: tuple[Rejection, ...]
    inseparable: tuple[Inseparable, ...]
    unexplained: tuple[Unexplained, ...]
    location: SensorLocation | None


def load_report(d: Mapping[str, Any]) -> DiagnosisReport:
    """A :class:`DiagnosisReport` from its JSON object (:meth:`DiagnosisReport.to_json`, also after a round trip
    through strict JSON, NaN as null). Raises :class:`ReportFormatError` for another format or a malformed one."""
    if not isinstance(d, Mapping) or d.get("format") not in FORMATS:
        found = d.get("format") if isinstance(d, Mapping) else type(d).__name__
        raise ReportFormatError(f"not a {FORMAT} diagnosis (format {found!r}; known: {', '.join(FORMATS)})")
    try:
        rerun = d["rerun"]
        tc = d["warmup_tc_range_s"]
        return DiagnosisReport(
            serial=d["serial"],
            findings=tuple(Finding.from_json(f) for f in d["findings"]),
            rejected=tuple(Rejection.from_json(r) for r in d["rejected"]),
            inseparable=tuple(Inseparable.from_json(i) for i in d["inseparable"]),
            unexplained=tuple(Unexplained.from_json(u) for u in d["unexplained"]),
            location={s: SensorLocation.from_json(v) for s, v in d["location"].items()},
            warmup_tc_range_s=None if tc is None else {s: (r[0], r[1]) for s, r in tc.items()},
            base_fit=None if d["base_fit"] is None else BaseFitNoise.from_json(d["base_fit"]),
            rerun=RerunError(rerun["error"]) if "error" in rerun else RerunSummary.from_json(rerun),
            method=d.get("method"),
            untestable=tuple(Untestable.from_json(u) for u in d.get("untestable", ())),
            rig_free=None if d.get("rig_free") is None else RigFreeSection.from_json(d["rig_free"]))
    except (KeyError, TypeError, IndexError, AttributeError) as exc:
        raise ReportFormatError(f"a malformed {FORMAT} diagnosis: {type(exc).__name__}: {exc}") from None


__all__ = [
    "FORMAT",
    "FORMATS",
    "FORMAT_CENSORED",
    "BlockFit",
    "BlockStatistics",
    "Censored",
    "CheckEntry",
    "Compensation",
    "Confidence",
    "CovariateTest",
    "DetectableSize",
    "DiagnosisReport",
    "EmpiricalModel",
    "Evidence",
    "Finding",
    "FindingRerun",
    "FitChange",
    "FormInseparable",
    "Improvement",
    "Inseparable",
    "KindStatistics",
    "LocatorEvidence",
    "OutlierEvidence",
    "Rejection",
    "ReportFormatError",
    "RerunError",
    "RerunSummary",
    "RigFreeSection",
    "SensorReport",
    "SizeRetest",
    "Unexplained",
    "Untestable",
    "load_report",
]
