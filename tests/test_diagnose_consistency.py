"""Effect-specific consistency checks and the segment bootstrap of the diagnosis.

Recordings of the independent generator (tests/indepgen.py), development seeds (0-999) only.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))

import indepgen

from station.diagnose import bootstrap, robust
from station.diagnose import finding_consistency as consistency
from station.diagnose.effect_registry import EFFECTS, LIBRARY
from station.diagnose.likelihood import SensorProblem
from station.diagnose.residuals import fit_baseline
from station.diagnose.results import CheckEntry

TC = {"accel": (50.0, 167.0), "gyro": (1030.0, 3760.0)}  # Table 1, as the station's default limits file


def _accepted(seed: int, effects: dict[str, float], sensor: str, names: list[str]):
    """The base fit of an independent recording and one sensor's problem with ``names`` accepted."""
    rec = indepgen.generate(seed, effects)
    base = fit_baseline(rec.session, warmup_tc_s=TC)
    sd = base.sensor(sensor)
    prob = SensorProblem(base, sd)
    for n in names:
        prob.accept(sd.block_mean(LIBRARY[n].build(base, sd)), refit=False)
    prob.refit_drift()
    return base, prob


def test_every_effect_has_checks_or_says_why_not() -> None:
    for e in EFFECTS:
        assert set(e.consistency) <= set(consistency.PARTS), e.name
        assert bool(e.consistency) != bool(e.not_checked), e.name


@pytest.fixture(scope="module")
def delayed():
    return {s: _accepted(5, {"time_offset": 10.0}, s, ["time_offset"]) for s in ("accel", "gyro")}


def test_a_true_delay_agrees_between_tumbles_and_ramps(delayed) -> None:
    base, prob = delayed["gyro"]
    checks, bad, where = consistency.review(prob, base, ["time_offset"], {"time_offset": 100.0})
    (c,) = checks["time_offset"]
    assert c.split == "tumbles_vs_ramps" and c.informative and c.passes and c.result == "passed"
    assert bad is None and where is None
    # both parts see the 10 ms the generator put in
    assert abs(c.part_a["value"][0] - 10.0) < 0.5 and abs(c.part_b["value"][0] - 10.0) < 0.5
    assert c.part_a["unit"] == "ms"


def test_a_check_the_recording_cannot_run_says_why(delayed) -> None:
    # the accelerometer's reference changes only where gravity turns: no ramps reach its delay
    base, prob = delayed["accel"]
    (c,) = consistency.check(prob, base, ["time_offset"])["time_offset"]
    assert c.result == "not checked" and not c.checked and c.passes
    assert "does not reach the rate ramps" in c.reason
    assert c.entry().to_json()["reason"] == c.reason
    # an effect the registry gives no check: its reason
    (n,) = consistency.not_checked("bias_random_walk", "gyro")
    assert n.split is None and "covariance" in n.reason and n.entry().to_json()["result"] == "not checked"


def test_an_even_scale_term_fitted_as_asymmetry_is_rejected_and_located() -> None:
    # k2 w^2 (even) against the asymmetry's (a/2)|w|: the rates' two signs disagree on the fitted a
    base, prob = _accepted(7, {"scale_nonlinearity_even": 3e-3}, "gyro", ["scale_asymmetry"])
    checks, bad, where = consistency.review(prob, base, ["scale_asymmetry"], {"scale_asymmetry": 100.0})
    failed = [c for c in checks["scale_asymmetry"] if c.result == "failed"]
    assert failed and failed[0].chi2 > failed[0].critical
    assert bad is not None and bad.effect == "scale_asymmetry" and "inconsistent between" in bad.reason
    assert isinstance(where, robust.Unexplained)
    assert where.sensor == "gyro" and "rate" in where.segment_kinds and where.excess_chi2 == 100.0
    assert "scale_asymmetry" in where.covariate


@pytest.fixture(scope="module")
def asymmetric():
    return _accepted(7, {"scale_asymmetry": 3e-3}, "gyro", ["scale_asymmetry"])


def test_a_true_asymmetry_passes_both_checks(asymmetric) -> None:
    base, prob = asymmetric
    checks, bad, _ = consistency.review(prob, base, ["scale_asymmetry"], {"scale_asymmetry": 100.0})
    assert [c.split for c in checks["scale_asymmetry"]] == ["negative_vs_positive_input", "low_vs_high_input"]
    assert all(c.result == "passed" for c in checks["scale_asymmetry"]) and bad is None
    for c in checks["scale_asymmetry"]:
        np.testing.assert_allclose(c.part_a["value"], -3e-3, atol=1e-4)  # the generator's sign convention
        np.testing.assert_allclose(c.part_b["value"], -3e-3, atol=1e-4)


def test_the_bootstrap_is_seeded_and_states_the_spread(asymmetric) -> None:
    _, prob = asymmetric
    phi = robust.dispersion(prob)[0]
    a = bootstrap.bootstrap(prob, ["scale_asymmetry"], {"scale_asymmetry": 20.0}, phi, resamples=20, seed=3)
    b = bootstrap.bootstrap(prob, ["scale_asymmetry"], {"scale_asymmetry": 20.0}, phi, resamples=20, seed=3)
    c = bootstrap.bootstrap(prob, ["scale_asymmetry"], {"scale_asymmetry": 20.0}, phi, resamples=20, seed=4)
    assert a == b and a != c
    r = a["scale_asymmetry"]
    assert r.resamples == 20 and r.accepted_fraction == 1.0 and r.level == "high"
    np.testing.assert_allclose(r.median, -3e-3, atol=1e-4)
    assert all(0 < s < 1e-4 for s in r.std) and r.unit.startswith("relative")
    # a threshold no resample reaches: never accepted, low confidence
    never = bootstrap.bootstrap(prob, ["scale_asymmetry"], {"scale_asymmetry": 1e12}, phi, resamples=5, seed=3)
    assert never["scale_asymmetry"].accepted_fraction == 0.0 and never["scale_asymmetry"].level == "low"


def test_findings_carry_their_checks_and_bootstrap_typed_and_in_the_report() -> None:
    from station.diagnose import diagnose
    from station.diagnose.selection import select

    rec = indepgen.generate(19, {"time_offset": 10.0})
    base = fit_baseline(rec.session, warmup_tc_s=TC)
    decision = select(base, resamples=10, seed=5)
    gyro = next(f for f in decision.findings if f.sensor == "gyro")
    assert gyro.effect == "time_offset"
    assert isinstance(gyro.bootstrap, bootstrap.Bootstrap) and gyro.bootstrap.resamples == 10
    assert gyro.bootstrap.seed == 5 and gyro.bootstrap.accepted_fraction == 1.0
    assert abs(gyro.bootstrap.median[0] - 10.0) < 0.5
    assert gyro.confidence is not None and gyro.confidence.level == "high"
    (c,) = gyro.consistency
    assert isinstance(c, CheckEntry) and c.result == "passed"
    entry = gyro.to_json()
    assert entry["consistency"][0]["check"] == "tumbles_vs_ramps" and entry["bootstrap"]["resamples"] == 10
    # resamples=0 leaves the bootstrap out; the checks stay
    report = diagnose(rec.session, warmup_tc_s=TC, resamples=0).to_json()
    for f in report["findings"]:
        assert "bootstrap" not in f and f["consistency"]


def test_cli_shows_the_checks_and_the_bootstrap(tmp_path: Path) -> None:
    from typer.testing import CliRunner

    from station.cli import app
    from station.kernel.limits_file import DEFAULT_LIMITS_PATH

    path = tmp_path / "delay.csv"
    indepgen.generate(19, {"time_offset": 10.0}).write(path)
    r = CliRunner().invoke(app, ["diagnose", str(path), "--limits", str(DEFAULT_LIMITS_PATH), "--resamples", "4"])
    assert r.exit_code == 0, r.output
    assert "bootstrap over segments (4 resamples, seed 16)" in r.output
    assert "consistency: tumbles (gravity turning) vs rate ramps and other moves: passed" in r.output
    assert "vs rate ramps and other moves: not checked, its signal does not reach the rate ramps" in r.output
