"""Which candidate effects the recording supports: forward selection on block means.


Mean model per axis: the base model's linear terms are re-fitted together with the
candidate (corrections to the row of M and b_stat; the warm-up ``b_drift exp(-t/T_c)`` of
eq. 3 in full, its T_c re-fitted, see :func:`base_drift`), so a candidate only counts
with what the base model cannot absorb. Decision (forward selection, one effect at a
time): twice the log-likelihood gain must exceed the BIC penalty ``p ln N`` and the
chi^2 critical value at ``ALPHA``, and the error on held-out segments (4-fold by segment)
must not rise by more than ``HELDOUT_SE`` standard errors of its paired change. Where the
best candidate's fitted signal and a competitor's are nearly collinear with this recording,
both are reported as inseparable, unless the best one stays significant given the
competitor while the competitor does not given the best.


``temperature_bias`` is tested like the other mean candidates (the drift's ``T_c``
re-fitted with it). When it is not found and the temperature course, after the other base
terms, is an exponential ``exp(-t/T)`` to ``R^2 > TEMPERATURE_R2`` (self-heating usually is),
the recording cannot tell a temperature bias from the warm-up drift of eq. 3: that pair is
listed as inseparable with the rig step that separates them.


After the forward selection, :mod:`station.diagnose.robust` re-tests every accepted effect against
the full model under the final model's dispersion and locates what stays unexplained;
:mod:`station.diagnose.locator` then locates structure with the stochastic terms held at the sensor class
(rejecting effects that stand in for it), and :mod:`station.diagnose.retest` re-fits each finding's size and
recounts the outliers under the final model.
"""

from __future__ import annotations

from collections.abc import Collection, Iterable, Mapping
from dataclasses import dataclass, field, replace

import numpy as np
from scipy import linalg

from station.diagnose import bootstrap, finding_consistency, locator, retest, rivals, robust
from station.diagnose.bootstrap import Bootstrap
from station.diagnose.candidates import MAX_DELAY_S, Rows, delay_rows
from station.diagnose.effect_registry import LIBRARY, REGISTRY, RIG_STEPS, engineering
from station.diagnose.likelihood import RCOND, WANDER_LIKE, SensorProblem, Test
from station.diagnose.reporting import detectable_from, finding, outlier_test
from station.diagnose.residuals import SENSORS, Baseline, SensorData
from station.diagnose.results import (
    Confidence,
    DetectableSize,
    Evidence,
    Finding,
    FormInseparable,
    Inseparable,
    Rejection,
    Unexplained,
)
from station.session.model import Kind

#: Two candidates are inseparable when each one's fitted signal is explained this well (R^2) by the other.
COLLINEAR_R2 = 0.9
#: A temperature course that an exponential warm-up (eq. 3) explains to this R^2 (after the other base terms)
#: cannot be told from the warm-up in this recording.
TEMPERATURE_R2 = 0.98
#: The base model's part a temperature bias can be inseparable from (eq. 3's warm-up), as the registry names it.
WARMUP = REGISTRY["temperature_bias"].identifiability.base_twin or "bias_drift"
#: Prefix of an accepted term that is in the model but named by no finding (an inseparable pair's signal).
NUISANCE = "~"
#: Rounds of the checks after the forward selection (robust.py, consistency.py); each may reject effects.
AUDIT_ROUNDS = 4
#: The candidate that is a wander of the bias (block covariance, not a mean term).
WALK = "bias_random_walk"
#: Why a wander-like candidate (a temperature bias) significant without a random walk is not a finding.
WALK_EXPLAINS = ("significant only while no bias random walk is allowed: with one (K^2 and the drift noise profiled "
                 "in both hypotheses) its gain is below the threshold, a slow wander explains its signal as well")
#: Fixed-point rounds of the exact-delay fit (:func:`_refine_delay`).
DELAY_ROUNDS = 6
#: Rounds of the locator (:func:`_locate`): after stand-ins are rejected, the location is taken once more.
LOCATOR_ROUNDS = 2
#: Why an effect the locator finds standing in for located structure is rejected.
STAND_IN = ("a stand-in: most of its fitted signal lies where the class-frozen model locates structure "
            "(see unexplained)")
#: Why an effect that an empirical term explains is rejected (rivals.py).
RIVAL = ("a stand-in for physics outside the library: a term of the empirical dictionary explains its signal "
         "(it is not significant given the term, the term is given it; see unexplained)")
#: Why a finding's confidence is capped by the size re-test (retest.py).
RETEST_CAP = "retest: its size changes by more than its uncertainty between fits"


@dataclass(frozen=True)
class Decision:
    """All findings, rejected tests, inseparable pairs and unexplained locations of one diagnosis."""

    findings: tuple[Finding, ...]
    rejected: tuple[Rejection, ...]
    inseparable: tuple[Inseparable, ...]
    unexplained: tuple[Unexplained, ...] = ()

    @classmethod
    def join(cls, parts: Iterable[Decision]) -> Decision:
        """One decision of several (e.g. per sensor), the entries in the order of ``parts``."""
        parts = list(parts)
        return cls(tuple(f for p in parts for f in p.findings), tuple(r for p in parts for r in p.rejected),
                   tuple(i for p in parts for i in p.inseparable), tuple(u for p in parts for u in p.unexplained))


@dataclass
class _Entries:
    """The report entries of one sensor as they are decided."""

    findings: list[Finding] = field(default_factory=list)
    rejected: list[Rejection] = field(default_factory=list)
    inseparable: list[Inseparable] = field(default_factory=list)
    unexplained: list[Unexplained] = field(default_factory=list)

    def decision(self) -> Decision:
        return Decision(tuple(self.findings), tuple(self.rejected), tuple(self.inseparable), tuple(self.unexplained))


@dataclass
class _Forward:
    """The forward selection's bookkeeping for one sensor (the model itself is the :class:`SensorProblem`'s).

    ``regs``: block regressors per testable mean candidate; ``pool``: candidates still to test; ``last``: each
    candidate's latest test that was not accepted; ``names``: the accepted terms in the order of
    ``SensorProblem.accepted`` (``NUISANCE`` + name for an inseparable pair's signal); ``walk``: the accepted bias
    random walk's test; ``found``: the findings accepted so far (confidence and checks come later)."""

    sensor: str
    regs: dict[str, np.ndarray]
    tau: float
    pool: set[str]
    last: dict[str, Test] = field(default_factory=dict)
    names: list[str] = field(default_factory=list)
    walk: Test | None = None
    found: list[Finding] = field(default_factory=list)

    def retire(self, *effects: str) -> None:
        """``effects`` are decided: no more tests, and no rejection entry from their last test."""
        for e in effects:
            self.pool.discard(e)
            self.last.pop(e, None)


def _r2(signal: np.ndarray, span: np.ndarray) -> float:
    if not np.any(signal):
        return 0.0
    coef, *_ = linalg.lstsq(span, signal, check_finite=False)
    res = signal - span @ coef
    return 1.0 - float(res @ res) / float(signal @ signal)


def _conditional(prob: SensorProblem, name: str, zb: np.ndarray, given: np.ndarray) -> Test:
    """Test of candidate ``name`` with the block regressors ``given`` taken into the model first."""
    with prob.given(given):
        return prob.test_mean(name, zb)


def _unique(prob: SensorProblem, best: Test, twin: Test, regs: Mapping[str, np.ndarray]) -> bool:
    """Whether ``best`` is significant given ``twin`` while ``twin`` is not significant given ``best``."""
    b = _conditional(prob, best.effect, regs[best.effect], regs[twin.effect])
    if not b.passes:
        return False
    t = _conditional(prob, twin.effect, regs[twin.effect], regs[best.effect])
    return not t.passes


def select(baseline: Baseline, *, max_effects: int = 4,
           candidates: Mapping[str, Collection[str]] | None = None, resamples: int = bootstrap.RESAMPLES,
           seed: int = bootstrap.SEED, locate: bool = True,
           drift_class: locator.DriftClass = locator.TABLE1_DRIFT, rig_moves: bool = True) -> Decision:
    """Forward selection of candidate effects per sensor (see the module docstring).

    ``candidates``: per sensor, the mean candidates to test (None: every one of the library); a recording that
    cannot test some (e.g. a rig-free one, :mod:`station.diagnose.rigfree_diagnosis`) says so itself.
    ``bias_random_walk`` and ``outliers`` are always tested. ``resamples``: the bootstrap's over segments for each
    finding's confidence (:mod:`station.diagnose.bootstrap`, seeded with ``seed``; 0: none). ``locate``: run the
    locator, its stochastic terms bounded by ``drift_class`` (the class of the recording's sensor); ``rig_moves``:
    the moves carry a rig's reference (False for a rig-free recording: no far-sample test in the moves).
    """
    return Decision.join(
        select_sensor(baseline, sensor, max_effects=max_effects,
                      candidates=None if candidates is None else candidates.get(sensor, ()),
                      resamples=resamples, seed=seed, locate=locate, drift_class=drift_class, rig_moves=rig_moves)
        for sensor in SENSORS)


def select_sensor(baseline: Baseline, sensor: str, *, max_effects: int = 4, candidates: Collection[str] | None = None,
                  resamples: int = bootstrap.RESAMPLES, seed: int = bootstrap.SEED, locate: bool = True,
                  drift_class: locator.DriftClass = locator.TABLE1_DRIFT, rig_moves: bool = True) -> Decision:
    """:func:`select` for one sensor, in its steps: the candidates' regressors; the forward selection; the checks
    that hold when the model is wrong (robust.py, consistency.py); the locator (locator.py) and the findings'
    sizes re-fitted under the final model (retest.py); the bootstrap's confidence; the candidates' rejections; the
    pairs the recording cannot tell apart; the outlier count under the final model."""
    sd = baseline.sensor(sensor)
    prob = SensorProblem(baseline, sd)
    prob.q_class = locator.class_drift_noise(sensor, sd.params.bias_drift, drift_class)
    out = _Entries()
    regs = _regressors(baseline, sd, candidates, out)
    tau = 0.0
    if "time_offset" in regs:
        regs["time_offset"], tau = _refine_delay(prob, baseline, sd, regs["time_offset"])
    fwd = _Forward(sensor, regs, tau, set(regs) | {WALK})
    for _step in range(max_effects):
        if not _forward_step(prob, fwd, out):
            break
    if locate:
        _rivals(prob, baseline, fwd, out)
    confidence, checks = _audit(prob, baseline, fwd, out)
    if locate and _locate(prob, baseline, fwd, out, drift_class, rig_moves) and _offer_walk(prob, fwd):
        # a stand-in had taken the place of a wander: with the walk in, the checks and the location once more
        out.unexplained.clear()
        confidence, checks = _audit(prob, baseline, fwd, out)
        _locate(prob, baseline, fwd, out, drift_class, rig_moves)
    fitted_final = _fitted_samples(prob, baseline, fwd)
    sizes = retest.sizes(prob, fwd.names, {f.effect: (f.theta, f.theta_std) for f in fwd.found
                                           if f.theta is not None})
    boot = (bootstrap.bootstrap(prob, fwd.names, {n: c.limit for n, c in confidence.items()},
                                robust.dispersion(prob)[0], resamples=resamples, seed=seed)
            if fwd.names and resamples else {})
    out.findings.extend(_retested(_checked(f, confidence, boot, checks), sizes.get(f.effect)) for f in fwd.found)
    out.rejected.extend(_not_named(t) for t in fwd.last.values())
    twin = _wander_or_temperature(fwd.last, fwd.walk)
    if twin is not None:
        out.inseparable.append(twin)
    if "temperature_bias" in fwd.pool and np.any(baseline.d_temp):
        _warmup_shaped_temperature(prob, out)
    # counted again on the residual of the final model (retest.py), not the base fit's
    _outliers(retest.recount_outliers(baseline.session, sd, fitted_final), out)
    return out.decision()


# --- the steps of select_sensor ----------------------------------------------------------------------------------
def _regressors(baseline: Baseline, sd: SensorData, candidates: Collection[str] | None,
                out: _Entries) -> dict[str, np.ndarray]:
    """Block regressors of every mean candidate of the library this sensor can test (``candidates``: only those);
    the ones the recording gives no data for, or never excites, are rejected as not testable."""
    regs: dict[str, np.ndarray] = {}
    for name, cand in LIBRARY.items():
        if sd.sensor in cand.sensors and (candidates is None or name in candidates):
            rows = cand.regressor_rows(baseline, sd)
            zb, excited = _block_regressors(sd, rows) if rows is not None else (None, False)
            if zb is not None and excited:
                regs[name] = zb
            else:
                why = "no data for it" if rows is None else "the recording never excites it (all regressors 0)"
                out.rejected.append(Rejection(name, sd.sensor, f"not testable: {why}"))
    return regs


def _block_regressors(sd: SensorData, rows: Rows) -> tuple[np.ndarray, bool]:
    """Block means of a candidate's regressors, made a piece of samples at a time (no (n, 3, p) array), and
    whether any sample's regressor is not zero."""
    excited = False

    def piece(lo: int, hi: int) -> np.ndarray:
        nonlocal excited
        z = rows.of(lo, hi)
        excited = excited or bool(np.any(z))
        return z

    return sd.block_mean_of(piece), excited


def _forward_step(prob: SensorProblem, fwd: _Forward, out: _Entries) -> bool:
    """One step of the forward selection: test every candidate left, decide on the best one (a finding, a pair the
    recording cannot tell apart, or a temperature course the warm-up could take). False: none passes, stop."""
    before = prob.quality()
    tests = {name: prob.test_mean(name, fwd.regs[name]) for name in sorted(fwd.pool - {WALK})}
    ok = [t for t in tests.values() if t.passes and t.validates]
    if not ok and WALK in fwd.pool:
        # the wander is tested once the mean effects are in: an unmodelled mean signal is a wander too
        tests[WALK] = prob.test_random_walk()
        ok = [tests[WALK]] if tests[WALK].passes else []
    fwd.last.update(tests)
    if not ok:
        return False
    best = max(ok, key=lambda t: t.bic_gain)
    twins, forms = _twins(prob, best, ok, fwd.regs)
    if best.effect == "temperature_bias" and prob.temperature_unique(best.theta) < best.critical:
        # significant, but what only a temperature bias explains is not: the warm-up (eq. 3) with
        # another T_c could take it over
        fwd.retire(best.effect)
        out.inseparable.append(_temperature_or_warmup(prob, best))
        return True
    if twins:
        fwd.retire(best.effect, *(t.effect for t in twins))
        # the signal is real, only its name is not: it stays in the model as a nuisance term, so that
        # what it explains does not pass another candidate's test
        prob.accept(fwd.regs[best.effect])
        fwd.names.append(NUISANCE + best.effect)
        out.inseparable.append(_inseparable(best, twins))
        return True
    if best.effect == WALK:
        _accept_walk(prob, best)
        fwd.walk = best
    else:
        prob.accept(fwd.regs[best.effect])
        fwd.names.append(best.effect)
    after = prob.quality()
    fwd.retire(best.effect)
    form = None
    if best.effect != WALK and forms:
        fwd.retire(*(t.effect for t in forms))
        form = FormInseparable(REGISTRY[best.effect].identifiability.family or "",
                               {t.effect: round(t.gain, 2) for t in forms}, RIG_STEPS[best.effect])
    fwd.found.append(finding(prob.sd, best, before, after, form=form))
    return True


def _twins(prob: SensorProblem, best: Test, ok: list[Test], regs: Mapping[str, np.ndarray]
           ) -> tuple[list[Test], list[Test]]:
    """Identifiability of ``best`` among the passing tests ``ok``: the competitors that explain the same signal
    about as well (twins), or, when every twin is a form of the same physics (registry family), those forms (the
    effect is found, only its form is not told apart). Returns (twins, forms), at most one of them non-empty."""
    twins = []
    if best.effect != WALK:
        for t in ok:
            if t is best or t.effect == WALK:
                continue
            if _r2(best.signal, t.span) > COLLINEAR_R2 and _r2(t.signal, best.span) > COLLINEAR_R2:
                twins.append(t)
        # nearly collinear is not the same as inseparable: the best stays when what it alone
        # explains (given the twin) is significant while what the twin alone explains is not
        twins = [t for t in twins if not _unique(prob, best, t, regs)]
    family = REGISTRY[best.effect].identifiability.family
    forms = [t for t in twins if family and REGISTRY[t.effect].identifiability.family == family]
    if forms and len(forms) == len(twins):
        return [], forms
    return twins, []


def _temperature_or_warmup(prob: SensorProblem, best: Test) -> Inseparable:
    """A significant temperature bias whose own part (what the warm-up cannot take) is not significant."""
    r2, t_like = prob.temperature_collinearity()
    return Inseparable(
        ("temperature_bias", WARMUP), best.sensor,
        {"gain": round(best.gain, 2), "bic_gain": round(best.bic_gain, 2),
         "chi2_only_temperature": round(prob.temperature_unique(best.theta), 2),
         "r2_temperature_vs_warmup": round(r2, 4), "warmup_time_constant_s": round(t_like, 1)},
        RIG_STEPS["temperature_bias"])


def _inseparable(best: Test, twins: list[Test]) -> Inseparable:
    tests = (best, *twins)
    return Inseparable(
        tuple(t.effect for t in tests), best.sensor,
        {t.effect: {"gain": round(t.gain, 2), "bic_gain": round(t.bic_gain, 2)} for t in tests},
        "; ".join(RIG_STEPS.get(t.effect, "") for t in tests if t.effect in RIG_STEPS))


def _accept_walk(prob: SensorProblem, best: Test) -> None:
    """Take the bias random walk of ``best`` into the block covariance, with its held-out check: the held-out
    blocks' prediction error under the covariance without and with the walk (the mean model is the same; a walk
    that is there makes the kriging from the training segments predict better and the errors' spread match,
    1 = as expected)."""
    e0 = prob.heldout_errors()
    prob.set_random_walk(float(best.theta[0] ** 2))
    e1 = prob.heldout_errors()
    if len(e0) == len(e1) and len(e0) > 1:
        best.heldout_before, best.heldout_after = float(e0.mean()), float(e1.mean())
        best.heldout_change_se = float(np.std(e1 - e0, ddof=1) / np.sqrt(len(e0)))


def _audit(prob: SensorProblem, baseline: Baseline, fwd: _Forward, out: _Entries
           ) -> tuple[dict[str, Confidence], dict[str, list[finding_consistency.Check]]]:
    """The checks that hold when the model is wrong (robust.py: drop-one under the dispersion, stand-ins, what
    stays unexplained) and the effect-specific consistency (consistency.py: the worst failing finding goes), in
    rounds until nothing more is rejected. Returns the confidence and the checks of the effects kept."""
    confidence: dict[str, Confidence] = {}
    checks: dict[str, list[finding_consistency.Check]] = {}
    for round_ in range(AUDIT_ROUNDS):
        audit = robust.audit(prob, baseline, fwd.names, fwd.regs, fwd.walk, _fitted_samples(prob, baseline, fwd))
        confidence = audit.confidence
        gone = {r.effect for r in audit.rejected}
        out.rejected.extend(audit.rejected)
        if not gone:
            checks, bad, where = finding_consistency.review(
                prob, baseline, [n if n in confidence else NUISANCE + n for n in fwd.names],
                {n: c.gain for n, c in confidence.items()})
            if bad is not None:
                gone = {bad.effect}
                out.rejected.append(bad)
            if where is not None:  # its structure stays, and no candidate explains it
                out.unexplained.append(where)
        out.unexplained.extend(audit.unexplained if not gone else [])
        if not gone:
            break
        _drop(prob, fwd, gone)
        if round_ == AUDIT_ROUNDS - 1:
            out.unexplained.extend(robust.audit(prob, baseline, fwd.names, fwd.regs, fwd.walk,
                                                _fitted_samples(prob, baseline, fwd)).unexplained)
    return confidence, checks


def _locate(prob: SensorProblem, baseline: Baseline, fwd: _Forward, out: _Entries,
            drift_class: locator.DriftClass, rig_moves: bool = True) -> bool:
    """The locator (locator.py): the final model with the stochastic terms at the sensor class's values. Its entry
    replaces the sensor's unexplained entries (their cells are located with it); an effect standing in for what it
    locates is rejected, then the location is taken again without it. True when it rejected stand-ins."""
    rejected = False
    for _round in range(LOCATOR_ROUNDS):
        cells = {(k, "xyz".index(a)) for u in out.unexplained for a in u.axes for k in _kind_codes(u.segment_kinds)}
        located = locator.locate(prob, baseline, fwd.names, extra_cells=cells,
                                 fitted=_fitted_samples(prob, baseline, fwd), drift_class=drift_class,
                                 move_samples=rig_moves)
        if located is None:
            return rejected
        out.unexplained[:] = [located]
        gone = set(located.locator.stand_ins) if located.locator is not None else set()
        if not gone:
            return rejected
        out.rejected.extend(Rejection(name, fwd.sensor, STAND_IN) for name in sorted(gone))
        _drop(prob, fwd, gone)
        rejected = True
    return rejected


def _rivals(prob: SensorProblem, baseline: Baseline, fwd: _Forward, out: _Entries) -> None:
    """Each finding re-tested against the empirical alternative (rivals.py): one that a term of the locator's
    dictionary (no library effect) explains, while it explains nothing given that term, is rejected; what it took
    up is left to the locator."""
    found = rivals.stand_ins(prob, baseline, fwd.names)
    for s in found:
        out.rejected.append(Rejection(s.effect, fwd.sensor, RIVAL, s.details()))
    if found:
        _drop(prob, fwd, {s.effect for s in found})


def _offer_walk(prob: SensorProblem, fwd: _Forward) -> bool:
    """After the locator rejected stand-ins: the bias random walk, if it was not accepted, tested once more on the
    model without them (a mean effect accepted before the walk's turn, e.g. a temperature bias, takes up a wander's
    slow course and then stands in for it). True when it passes and is taken in (its checks follow)."""
    if WALK not in fwd.pool or fwd.walk is not None:
        return False
    before = prob.quality()
    t = prob.test_random_walk()
    fwd.last[WALK] = t
    if not t.passes:
        return False
    _accept_walk(prob, t)
    fwd.walk = t
    fwd.retire(WALK)
    fwd.found.append(finding(prob.sd, t, before, prob.quality()))
    return True


def _retested(f: Finding, size: retest.SizeCheck | None) -> Finding:
    """Finding ``f`` with its size under the final model (retest.py) in its evidence and the spread of the sizes in
    its stated standard deviation (:meth:`retest.SizeCheck.stated_std`); a spread beyond its standard deviation
    caps a high confidence at medium."""
    if size is None or not isinstance(f.evidence, Evidence):
        return f
    conf = f.confidence
    if size.change_over_std > retest.SPREAD_STD and conf is not None and conf.level == "high":
        conf = conf.capped("medium", RETEST_CAP)
    f = replace(f, evidence=replace(f.evidence, retest=size.result()), confidence=conf)
    if f.theta is None or f.theta_std is None or REGISTRY[f.effect].engineering is not None:
        return f  # (pose_tilt: its entry per pose pair is made from the full covariance, left as fitted)
    spread = size.spread
    if not np.any(spread > 0) and not size.integrated:
        return f
    # an effect sized with the warm-up's T_c integrated out (retest.py) states that value and its uncertainty; the
    # bootstrap's spread over segments was taken at the one T_c of the re-fit, where the misfit of a wrong T_c
    # widens it (it stays in the finding's bootstrap entry)
    theta = size.final if size.integrated else f.theta
    std = size.stated_std(size.std if size.integrated else f.theta_std)
    params = dict(f.parameters)
    params.setdefault("std_fit", params.get("std"))  # the fit's own (the bootstrap's step keeps it where it widened)
    if size.integrated:
        params["value"] = engineering(f.effect, f.sensor, theta, np.diag(std**2))["value"]
        params["value_selection_step"] = engineering(f.effect, f.sensor, f.theta, np.diag(std**2))["value"]
        params["std_from"] = ["fit, T_c integrated"] * len(theta)
    params["std"] = engineering(f.effect, f.sensor, theta, np.diag(std**2))["std"]
    params["std_spread"] = engineering(f.effect, f.sensor, theta, np.diag(spread**2))["std"]
    return replace(f, parameters=params, theta=np.asarray(theta, dtype=float), theta_std=std)


def _kind_codes(labels: Collection[str]) -> list[int]:
    """Segment-kind codes of the labels (rest, pose, rate, move)."""
    return [int(k) for k in Kind if k.label in labels]


def _drop(prob: SensorProblem, fwd: _Forward, gone: set[str]) -> None:
    """The effects ``gone`` out of the model and out of the findings."""
    keep = [i for i, n in enumerate(fwd.names) if n not in gone]
    prob.retain(keep, random_walk=WALK not in gone)
    fwd.names = [fwd.names[i] for i in keep]
    if WALK in gone:
        fwd.walk = None
    fwd.found = [f for f in fwd.found if f.effect not in gone]


def _checked(f: Finding, confidence: Mapping[str, Confidence], boot: Mapping[str, Bootstrap],
             checks: Mapping[str, list[finding_consistency.Check]]) -> Finding:
    """Finding ``f`` with its confidence (the bootstrap's level where it ran), bootstrap and consistency checks."""
    conf = confidence.get(f.effect, Confidence("low"))
    b = boot.get(f.effect)
    if b is not None:  # the level the report states is the bootstrap's (bootstrap.py)
        conf = conf.with_bootstrap(b)
    found = checks.get(f.effect) or finding_consistency.not_checked(f.effect, f.sensor)
    return replace(_bootstrap_std(f, b), confidence=conf, bootstrap=b, consistency=tuple(c.entry() for c in found))


def _bootstrap_std(f: Finding, b: Bootstrap | None) -> Finding:
    """Finding ``f`` whose stated standard uncertainty is, per parameter, the larger of the fit's and the bootstrap's
    spread over segments (bootstrap.py): where the value depends on which segments are in more than the fit's
    noise model says (the model only approximates the physics, or the residual is correlated beyond it), the fit's
    own standard error understates it. The fit's is kept as ``std_fit``; ``std_from`` says which one is stated."""
    std = f.parameters.get("std")
    if b is None or b.std is None or not isinstance(std, list) or len(std) != len(b.std) \
            or any(isinstance(v, list) for v in std) or f.theta_std is None:
        return f
    fit = np.asarray(std, dtype=float)
    boot = np.nan_to_num(np.asarray(b.std, dtype=float))
    if not np.any(boot > fit):
        return f
    new = np.maximum(fit, boot)
    params = dict(f.parameters)
    params.update(std=[float(f"{v:.4g}") for v in new], std_fit=list(std),
                  std_from=["bootstrap" if bb > ff else "fit" for ff, bb in zip(fit, boot, strict=True)])
    scale = np.where(fit > 0, new / np.where(fit > 0, fit, 1.0), 1.0)
    return replace(f, parameters=params, theta_std=np.asarray(f.theta_std, dtype=float) * scale)


def _not_named(t: Test) -> Rejection:
    """The rejection of a candidate whose last test did not make it a finding, and why."""
    details = {"gain": round(t.gain, 3), "bic_gain": round(t.bic_gain, 3), "params": t.params}
    if t.params == 0:
        return Rejection(t.effect, t.sensor, "not identifiable with this recording (absorbed by the base model)",
                         details, rig_step=RIG_STEPS[t.effect])
    if t.walk_explains:
        return Rejection(t.effect, t.sensor, WALK_EXPLAINS, {**details, "gain_given_walk": round(t.gain_given_walk, 3)})
    if not t.passes:
        return Rejection(t.effect, t.sensor, "no significant improvement", details,
                         detectable_from=(detectable_from(t) or DetectableSize()) if t.effect in LIBRARY else None)
    return Rejection(t.effect, t.sensor, "worse on held-out segments", details)


def _warmup_shaped_temperature(prob: SensorProblem, out: _Entries) -> None:
    """A temperature bias not found, on a temperature course an exponential warm-up explains: inseparable."""
    r2, t_like = prob.temperature_collinearity()
    if r2 > TEMPERATURE_R2:
        out.inseparable.append(Inseparable(
            ("temperature_bias", WARMUP), prob.sd.sensor,
            {"r2_temperature_vs_warmup": round(r2, 4), "warmup_time_constant_s": round(t_like, 1),
             "note": "the temperature course has the shape of a warm-up exp(-t/T_c) here"},
            RIG_STEPS["temperature_bias"]))


def _outliers(sd: SensorData, out: _Entries) -> None:
    """The outlier count; where structure stays unexplained, the effects named for it are stand-ins
    (robust.py): their inseparable pairs become rejections, and more outliers than allowed are not a finding."""
    test = outlier_test(sd)
    reason = None
    if any(u.sensor == sd.sensor for u in out.unexplained):
        for item in [i for i in out.inseparable if i.sensor == sd.sensor and WARMUP not in i.effects]:
            out.inseparable.remove(item)
            out.rejected.append(Rejection(" / ".join(item.effects), sd.sensor,
                                          "inseparable stand-ins for structure that stays unexplained"))
        if test.significant:
            reason = "more outliers than allowed, but where structure stays unexplained"
    if test.significant and reason is None:
        out.findings.append(test.finding())
    else:
        out.rejected.append(test.rejection(reason or "no more outliers than allowed"))


def _wander_or_temperature(last: Mapping[str, Test], walk: Test | None) -> Inseparable | None:
    """A slow course that is significant as a wander-like candidate (a temperature bias) while no random walk is
    allowed, and not as a random walk while the temperature course is a nuisance term (each test holds the other):
    the recording holds the structure but cannot name it. The pair, or None."""
    wander = last.get(WALK)
    if walk is not None or wander is None or wander.passes:
        return None
    for name in WANDER_LIKE:
        course = last.get(name)
        if course is None or not course.walk_explains:
            continue
        return Inseparable(
            (name, WALK), wander.sensor,
            {name: {"gain": round(course.gain, 2), "gain_given_walk": round(course.gain_given_walk, 2),
                    "threshold": round(course.threshold, 2)},
             WALK: {"gain_given_temperature": round(wander.gain, 2), "threshold": round(wander.threshold, 2)},
             "note": "a slow wander: significant as a temperature bias without a random walk, and "
                     "not significant as either given the other"},
            RIG_STEPS[name])
    return None


def _refine_delay(
    prob: SensorProblem, baseline: Baseline, sd: SensorData, first: np.ndarray
) -> tuple[np.ndarray, float]:
    """The time offset as an exact delay: start from the first-order estimate (coefficient of ``-du/dt``),
    then evaluate the reference at ``t - tau`` (:func:`~station.diagnose.candidates.delay_regressor`) and take
    the coefficient as the next ``tau`` until it is a fixed point (the coefficient equals the delay the regressor
    was built with: the least-squares delay of ``y = u(t - tau)``). Returns the block regressor and tau (s),
    |tau| <= 50 ms."""
    tau = float(np.clip(prob.test_mean("time_offset", first).theta[0], -MAX_DELAY_S, MAX_DELAY_S))
    zb = first
    for _ in range(DELAY_ROUNDS):
        if abs(tau) < 1e-5:
            return first, tau
        zb = sd.block_mean_of(delay_rows(baseline, sd, tau).of)
        new = float(np.clip(prob.test_mean("time_offset", zb).theta[0], -MAX_DELAY_S, MAX_DELAY_S))
        done = abs(new - tau) < 1e-6 + 1e-3 * abs(tau)
        tau = new
        if done:
            break
    return zb, tau


def _fitted_samples(prob: SensorProblem, baseline: Baseline, fwd: _Forward) -> np.ndarray:
    """The accepted mean effects' fitted signal per sample (n, 3), at the joint fit's coefficients."""
    sd, names, tau = prob.sd, fwd.names, fwd.tau
    out = np.zeros((len(baseline.session), 3))
    if not names:
        return out
    chols, yw = prob.whitened()
    x, nbase = prob.design(chols, prob.accepted)
    beta, *_ = linalg.lstsq(x, yw, cond=RCOND, check_finite=False)
    col = nbase
    for name, zb in zip(names, prob.accepted, strict=True):
        p = zb.shape[2]
        theta = beta[col:col + p]
        col += p
        name = name.removeprefix(NUISANCE)
        rows = delay_rows(baseline, sd, tau) if name == "time_offset" else LIBRARY[name].regressor_rows(baseline, sd)
        if rows is not None:
            for lo, hi in sd.pieces:  # a piece at a time: no (n, 3, p) regressors
                out[lo:hi] += np.einsum("nkp,p->nk", rows.of(lo, hi), theta)
    return out


__all__ = ["COLLINEAR_R2", "NUISANCE", "TEMPERATURE_R2", "WALK_EXPLAINS", "Decision", "select", "select_sensor"]
