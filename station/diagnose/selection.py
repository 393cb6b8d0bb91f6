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
the full model under the final model's dispersion and locates what stays unexplained.
"""

from __future__ import annotations

from collections.abc import Collection, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy import linalg

from station.diagnose import bootstrap, consistency, locator, retest, robust
from station.diagnose.candidates import MAX_DELAY_S, delay_regressor
from station.diagnose.likelihood import RCOND, WANDER_LIKE, SensorProblem, Test
from station.diagnose.registry import LIBRARY, REGISTRY, RIG_STEPS
from station.diagnose.reporting import AX, detectable_from, finding, outlier_test
from station.diagnose.residuals import SENSORS, Baseline, SensorData
from station.diagnose.results import Finding, Inseparable, Rejection
from station.session.model import Kind

#: Two candidates are inseparable when each one's fitted signal is explained this well (R^2) by the other.
COLLINEAR_R2 = 0.9
#: A temperature course that an exponential warm-up (eq. 3) explains to this R^2 (after the other base terms)
#: cannot be told from the warm-up in this recording.
TEMPERATURE_R2 = 0.98
#: The base model's part a temperature bias can be inseparable from (eq. 3's warm-up), as the registry names it.
WARMUP = REGISTRY["temperature_bias"].identifiability.base_twin
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


@dataclass(frozen=True)
class Decision:
    """All findings, rejected tests, inseparable pairs and unexplained locations of one diagnosis."""

    findings: tuple[Finding, ...]
    rejected: tuple[Rejection, ...]
    inseparable: tuple[Inseparable, ...]
    unexplained: tuple[robust.Unexplained | locator.Located, ...] = ()


def _r2(signal: np.ndarray, span: np.ndarray) -> float:
    if not np.any(signal):
        return 0.0
    coef, *_ = linalg.lstsq(span, signal, check_finite=False)
    res = signal - span @ coef
    return 1.0 - float(res @ res) / float(signal @ signal)


def _conditional(prob: SensorProblem, name: str, zb: np.ndarray, given: np.ndarray) -> Test:
    """Test of candidate ``name`` with the block regressors ``given`` taken into the model first."""
    prob.accepted.append(given)
    try:
        return prob.test_mean(name, zb)
    finally:
        prob.accepted.pop()


def _unique(prob: SensorProblem, best: Test, twin: Test, regs: dict[str, np.ndarray]) -> bool:
    """Whether ``best`` is significant given ``twin`` while ``twin`` is not significant given ``best``."""
    b = _conditional(prob, best.effect, regs[best.effect], regs[twin.effect])
    if not b.passes:
        return False
    t = _conditional(prob, twin.effect, regs[twin.effect], regs[best.effect])
    return not t.passes



def select(baseline: Baseline, *, max_effects: int = 4,
           candidates: Mapping[str, Collection[str]] | None = None, resamples: int = bootstrap.RESAMPLES,
           seed: int = bootstrap.SEED) -> Decision:
    """Forward selection of candidate effects per sensor (see the module docstring).

    ``candidates``: per sensor, the mean candidates to test (None: every one of the library); a recording that
    cannot test some (e.g. a rig-free one, :mod:`station.diagnose.rigfree`) says so itself. ``bias_random_walk``
    and ``outliers`` are always tested. ``resamples``: the bootstrap's over segments for each finding's
    confidence (:mod:`station.diagnose.bootstrap`, seeded with ``seed``; 0: none).
    """
    findings: list[dict[str, Any]] = []
    rejected: list[dict[str, Any]] = []
    inseparable: list[dict[str, Any]] = []
    unexplained: list[robust.Unexplained | locator.Located] = []
    for sensor in SENSORS:
        sd = baseline.sensor(sensor)
        prob = SensorProblem(baseline, sd)
        regs: dict[str, np.ndarray] = {}
        for name, cand in LIBRARY.items():
            if sensor in cand.sensors and (candidates is None or name in candidates.get(sensor, ())):
                z = cand.build(baseline, sd)
                if z is not None and np.any(z):
                    regs[name] = sd.block_mean(z)
                else:
                    why = "no data for it" if z is None else "the recording never excites it (all regressors 0)"
                    rejected.append({"effect": name, "sensor": sensor, "reason": f"not testable: {why}"})
                del z  # per-sample (n, 3, p): not kept alive while the next candidate's are built
        if "time_offset" in regs:
            regs["time_offset"], tau = _refine_delay(prob, baseline, sd, regs["time_offset"])
        else:
            tau = 0.0
        pool = set(regs) | {"bias_random_walk"}
        last: dict[str, Test] = {}
        names: list[str] = []
        walk: Test | None = None
        mine: list[dict[str, Any]] = []
        for _step in range(max_effects):
            before = prob.quality()
            tests = {name: prob.test_mean(name, regs[name]) for name in sorted(pool - {"bias_random_walk"})}
            ok = [t for t in tests.values() if t.passes and t.validates]
            if not ok and "bias_random_walk" in pool:
                # the wander is tested once the mean effects are in: an unmodelled mean signal is a wander too
                tests["bias_random_walk"] = prob.test_random_walk()
                ok = [tests["bias_random_walk"]] if tests["bias_random_walk"].passes else []
            last.update(tests)
            if not ok:
                break
            best = max(ok, key=lambda t: t.bic_gain)
            # identifiability: a competitor that explains the same signal about as well
            twins = []
            if best.effect != "bias_random_walk":
                for t in ok:
                    if t is best or t.effect == "bias_random_walk":
                        continue
                    if _r2(best.signal, t.span) > COLLINEAR_R2 and _r2(t.signal, best.span) > COLLINEAR_R2:
                        twins.append(t)
                # nearly collinear is not the same as inseparable: the best stays when what it alone
                # explains (given the twin) is significant while what the twin alone explains is not
                twins = [t for t in twins if not _unique(prob, best, t, regs)]
            # forms of one physics (registry family): the effect is found, only its form is not told apart
            family = REGISTRY[best.effect].identifiability.family
            forms = [t for t in twins if family and REGISTRY[t.effect].identifiability.family == family]
            if forms and len(forms) == len(twins):
                twins = []
            else:
                forms = []
            if best.effect == "temperature_bias" and prob.temperature_unique(best.theta) < best.critical:
                # significant, but what only a temperature bias explains is not: the warm-up (eq. 3) with
                # another T_c could take it over
                pool.discard(best.effect)
                last.pop(best.effect, None)
                r2, t_like = prob.temperature_collinearity()
                inseparable.append({
                    "effects": ["temperature_bias", WARMUP], "sensor": sensor,
                    "evidence": {"gain": round(best.gain, 2), "bic_gain": round(best.bic_gain, 2),
                                 "chi2_only_temperature": round(prob.temperature_unique(best.theta), 2),
                                 "r2_temperature_vs_warmup": round(r2, 4), "warmup_time_constant_s": round(t_like, 1)},
                    "rig_step": RIG_STEPS["temperature_bias"],
                })
                continue
            if twins:
                for t in (best, *twins):
                    pool.discard(t.effect)
                    last.pop(t.effect, None)
                # the signal is real, only its name is not: it stays in the model as a nuisance term, so that
                # what it explains does not pass another candidate's test
                prob.accepted.append(regs[best.effect])
                names.append(NUISANCE + best.effect)
                prob.refit_drift()
                inseparable.append({
                    "effects": [best.effect, *[t.effect for t in twins]], "sensor": sensor,
                    "evidence": {t.effect: {"gain": round(t.gain, 2), "bic_gain": round(t.bic_gain, 2)}
                                 for t in (best, *twins)},
                    "rig_step": "; ".join(RIG_STEPS.get(t.effect, "") for t in (best, *twins) if t.effect in RIG_STEPS),
                })
                continue
            if best.effect == "bias_random_walk":
                # its held-out check: the held-out blocks' prediction error under the covariance without and
                # with the walk (the mean model is the same; a walk that is there makes the kriging from the
                # training segments predict better and the errors' spread match, 1 = as expected)
                e0 = prob._heldout_errors(prob.accepted, prob._heldout_folds())
                prob.k2 = float(best.theta[0] ** 2)
                prob._fit_q()
                e1 = prob._heldout_errors(prob.accepted, prob._heldout_folds())
                if len(e0) == len(e1) and len(e0) > 1:
                    best.heldout_before, best.heldout_after = float(e0.mean()), float(e1.mean())
                    best.heldout_change_se = float(np.std(e1 - e0, ddof=1) / np.sqrt(len(e0)))
                walk = best
            else:
                prob.accepted.append(regs[best.effect])
                names.append(best.effect)
                prob.refit_drift()
            after = prob.quality()
            pool.discard(best.effect)
            last.pop(best.effect, None)
            mine.append(finding(sd, best, before, after))
            if best.effect != "bias_random_walk" and forms:
                for t in forms:
                    pool.discard(t.effect)
                    last.pop(t.effect, None)
                mine[-1]["evidence"]["form_inseparable_from"] = {
                    "family": family, "effects": {t.effect: {"gain": round(t.gain, 2)} for t in forms},
                    "rig_step": RIG_STEPS[best.effect]}
        # checks that hold when the model is wrong (robust.py): drop-one under the dispersion, stand-ins,
        # what stays unexplained; rounds until nothing more is rejected
        confidence: dict[str, dict[str, Any]] = {}
        checks: dict[str, list[consistency.Check]] = {}
        for _round in range(AUDIT_ROUNDS):
            audit = robust.audit(prob, baseline, names, regs, walk, _fitted_samples(prob, baseline, sd, names, tau))
            confidence = audit.confidence
            gone = {r["effect"] for r in audit.rejected}
            rejected.extend(audit.rejected)
            if not gone:  # effect-specific consistency (consistency.py): the worst failing finding goes
                checks, bad, where = consistency.review(
                    prob, baseline, [n if n in confidence else NUISANCE + n for n in names],
                    {n: c["quasi_gain_chi2"] for n, c in confidence.items()})
                if bad is not None:
                    gone = {bad["effect"]}
                    rejected.append(bad)
                if where is not None:  # its structure stays, and no candidate explains it
                    unexplained.append(where)
            unexplained.extend(audit.unexplained if not gone else [])
            if not gone:
                break
            keep = [i for i, n in enumerate(names) if n not in gone]
            prob.accepted = [prob.accepted[i] for i in keep]
            names = [names[i] for i in keep]
            if "bias_random_walk" in gone:
                walk = None
                prob.k2 = 0.0
            prob.refit_drift()
            mine = [f for f in mine if f["effect"] not in gone]
            if _round == AUDIT_ROUNDS - 1:
                unexplained.extend(robust.audit(prob, baseline, names, regs, walk,
                                                _fitted_samples(prob, baseline, sd, names, tau)).unexplained)
        # the locator (locator.py): the final model with the stochastic terms at the sensor class's values; an
        # effect standing in for what it locates is rejected, then the location is taken again without it
        for _round in range(2):
            mine_cells = {(int(k), "xyz".index(a)) for u in unexplained if u.sensor == sensor
                          for a in u.axes for k in _kind_codes(u.segment_kinds)}
            located = locator.locate(prob, baseline, names, extra_cells=mine_cells,
                                     fitted=_fitted_samples(prob, baseline, sd, names, tau))
            if located is None:
                break
            unexplained = [u for u in unexplained if u.sensor != sensor] + [located]
            gone = set(located.stand_ins)
            if not gone:
                break
            for name in sorted(gone):
                rejected.append({"effect": name, "sensor": sensor, "reason": "a stand-in: most of its fitted signal "
                                 "lies where the class-frozen model locates structure (see unexplained)"})
            keep = [i for i, n in enumerate(names) if n not in gone]
            prob.accepted = [prob.accepted[i] for i in keep]
            names = [names[i] for i in keep]
            mine = [f for f in mine if f["effect"] not in gone]
            prob.refit_drift()
        fitted_final = _fitted_samples(prob, baseline, sd, names, tau)
        size_checks = retest.sizes(prob, names, {f["effect"]: (f["_theta"], f.get("_theta_std")) for f in mine
                                                  if "_theta" in f})
        boot = (bootstrap.bootstrap(prob, names, {n: c["threshold"] for n, c in confidence.items()},
                                    robust.dispersion(prob)[0], resamples=resamples, seed=seed)
                if names and resamples else {})
        for f in mine:
            f["confidence"] = conf = dict(confidence.get(f["effect"], {"level": "low"}))
            if f["effect"] in boot:  # the level the report states is the bootstrap's (bootstrap.py)
                conf["drop_one_level"] = conf.get("level")
                conf["level"] = boot[f["effect"]].level
                conf["bootstrap_accepted_fraction"] = boot[f["effect"]].accepted_fraction
                f["bootstrap"] = boot[f["effect"]]
            f["consistency"] = checks.get(f["effect"]) or consistency.not_checked(f["effect"], sensor)
            size = size_checks.get(f["effect"])
            if size is not None:  # its size under the final model (retest.py): a spread beyond its std caps it
                f["evidence"]["retest"] = size.to_dict()
                if size.change_over_std > retest.SPREAD_STD and conf.get("level") == "high":
                    conf["level"] = "medium"
                    conf["capped_by"] = "retest: its size changes by more than its uncertainty between fits"
        findings.extend(mine)
        for t in last.values():
            entry: dict[str, Any] = {"effect": t.effect, "sensor": sensor, "gain": round(t.gain, 3),
                                     "bic_gain": round(t.bic_gain, 3), "params": t.params}
            if t.params == 0:
                entry["reason"] = "not identifiable with this recording (absorbed by the base model)"
                entry["rig_step"] = RIG_STEPS[t.effect]
            elif t.walk_explains:
                entry["reason"] = WALK_EXPLAINS
                entry["gain_given_walk"] = round(t.gain_given_walk, 3)
            elif not t.passes:
                entry["reason"] = "no significant improvement"
                if t.effect in LIBRARY:
                    entry["detectable_from"] = detectable_from(t)
            else:
                entry["reason"] = "worse on held-out segments"
            rejected.append(entry)
        twin = _wander_or_temperature(last, walk)
        if twin is not None:
            inseparable.append({"sensor": sensor, **twin})
        if "temperature_bias" in pool and np.any(baseline.d_temp):
            r2, t_like = prob.temperature_collinearity()
            if r2 > TEMPERATURE_R2:
                inseparable.append({
                    "effects": ["temperature_bias", WARMUP], "sensor": sensor,
                    "evidence": {"r2_temperature_vs_warmup": round(r2, 4), "warmup_time_constant_s": round(t_like, 1),
                                 "note": "the temperature course has the shape of a warm-up exp(-t/T_c) here"},
                    "rig_step": RIG_STEPS["temperature_bias"],
                })
        # counted again on the residual of the final model (retest.py), not the base fit's
        out = outlier_test(retest.recount_outliers(baseline.session, sd, fitted_final))
        if any(u.sensor == sensor for u in unexplained):
            # structure no candidate explains: effects named for it are stand-ins (robust.py)
            for item in [i for i in inseparable
                         if i["sensor"] == sensor and WARMUP not in i["effects"]]:
                inseparable.remove(item)
                rejected.append({"effect": " / ".join(item["effects"]), "sensor": sensor,
                                 "reason": "inseparable stand-ins for structure that stays unexplained"})
            if out["accepted"]:
                out["accepted"] = False
                out["reason"] = "more outliers than allowed, but where structure stays unexplained"
        if out.pop("accepted"):
            findings.append({
                "effect": "outliers", "sensor": sensor, "axes": [AX[k] for k in out.pop("axes")] or list(AX),
                "parameters": {"rate_per_sample": {"value": out["rate"], "std": out["rate_std"], "unit": "1"}},
                "evidence": {k: out[k] for k in ("count", "samples", "allowance", "p_value")},
                "fit": {}, "consistency": consistency.not_checked("outliers", sensor),
            })
        else:
            rejected.append({"effect": "outliers", "sensor": sensor,
                             "reason": out.get("reason", "no more outliers than allowed"),
                             "count": out["count"], "p_value": out["p_value"]})
    # the selection works on report entries; its result is typed
    return Decision(tuple(Finding.from_entry(f) for f in findings), tuple(Rejection.from_entry(r) for r in rejected),
                    tuple(Inseparable.from_entry(i) for i in inseparable), tuple(unexplained))


def _kind_codes(labels: Collection[str]) -> list[int]:
    """Segment-kind codes of the labels (rest, pose, rate, move)."""
    return [int(k) for k in Kind if k.label in labels]


def _wander_or_temperature(last: Mapping[str, Test], walk: Test | None) -> dict[str, Any] | None:
    """A slow course that is significant as a wander-like candidate (a temperature bias) while no random walk is
    allowed, and not as a random walk while the temperature course is a nuisance term (each test holds the other):
    the recording holds the structure but cannot name it. The pair's entry (without the sensor), or None."""
    wander = last.get(WALK)
    if walk is not None or wander is None or wander.passes:
        return None
    for name in WANDER_LIKE:
        course = last.get(name)
        if course is None or not course.walk_explains:
            continue
        return {"effects": [name, WALK],
                "evidence": {name: {"gain": round(course.gain, 2), "gain_given_walk": round(course.gain_given_walk, 2),
                                    "threshold": round(course.threshold, 2)},
                             WALK: {"gain_given_temperature": round(wander.gain, 2),
                                    "threshold": round(wander.threshold, 2)},
                             "note": "a slow wander: significant as a temperature bias without a random walk, and "
                                     "not significant as either given the other"},
                "rig_step": RIG_STEPS[name]}
    return None


def _refine_delay(
    prob: SensorProblem, baseline: Baseline, sd: SensorData, first: np.ndarray
) -> tuple[np.ndarray, float]:
    """The time offset as an exact delay: start from the first-order estimate (coefficient of ``-du/dt``),
    then evaluate the reference at ``t - tau`` (:func:`delay_regressor`) and take the coefficient as the
    next ``tau`` until it is a fixed point (the coefficient equals the delay the regressor was built with:
    the least-squares delay of ``y = u(t - tau)``). Returns the block regressor and tau (s), |tau| <= 50 ms."""
    tau = float(np.clip(prob.test_mean("time_offset", first).theta[0], -MAX_DELAY_S, MAX_DELAY_S))
    zb = first
    for _ in range(DELAY_ROUNDS):
        if abs(tau) < 1e-5:
            return first, tau
        zb = sd.block_mean(delay_regressor(baseline, sd, tau))
        new = float(np.clip(prob.test_mean("time_offset", zb).theta[0], -MAX_DELAY_S, MAX_DELAY_S))
        done = abs(new - tau) < 1e-6 + 1e-3 * abs(tau)
        tau = new
        if done:
            break
    return zb, tau


def _fitted_samples(prob: SensorProblem, baseline: Baseline, sd: SensorData, names: list[str],
                    tau: float) -> np.ndarray:
    """The accepted mean effects' fitted signal per sample (n, 3), at the joint fit's coefficients."""
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
        z = delay_regressor(baseline, sd, tau) if name == "time_offset" else LIBRARY[name].build(baseline, sd)
        if z is not None:
            out += np.einsum("nkp,p->nk", z, theta)
    return out


__all__ = ["COLLINEAR_R2", "NUISANCE", "TEMPERATURE_R2", "WALK_EXPLAINS", "Decision", "select"]
