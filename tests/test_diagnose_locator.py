"""The mismatch locator, the empirical models and the re-tests of findings (locator, empirical, retest)."""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path

import numpy as np
import pytest

from station.diagnose import empirical, locator
from station.diagnose.results import load_report
from station.kernel.sensor_class import TABLE1
from station.session.model import Kind, Session

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))


def _still_session(n: int, fs: float, seg_len: int) -> Session:
    t = np.arange(n) / fs
    seg = np.arange(n) // seg_len
    kind = np.where(seg == 0, int(Kind.REST), int(Kind.POSE))
    z = np.zeros((n, 3))
    return Session(metadata={"serial": "T", "sample_rate_hz": str(fs), "gravity_mps2": "9.81"}, t_s=t, segment=seg,
                   kind=kind, accel_mps2=z, gyro_radps=z, temp_degc=np.full(n, 25.0), ref_accel_mps2=z,
                   ref_gyro_radps=z)


def test_class_drift_noise_is_the_class_share_of_the_warmup() -> None:
    top = max(abs(v) for v in TABLE1.gyro_bias_drift_dps) * math.pi / 180.0
    q = locator.class_drift_noise("gyro", np.array([top, 0.0, 2.0 * top]))
    rel = locator.CLASS_MARGIN * TABLE1.drift_noise_rel
    # own warm-up, floored at B_DRIFT_FLOOR of the class's largest, capped at the largest
    assert q == pytest.approx([(rel * top) ** 2, (rel * locator.B_DRIFT_FLOOR * top) ** 2, (rel * top) ** 2])
    assert locator.class_drift_noise("accel")[0] == pytest.approx((rel * 0.018) ** 2)


def test_jumps_tell_a_two_level_bias_from_gaussian_drift() -> None:
    fs, n = 100.0, 60_000
    rng = np.random.default_rng(3)
    session = _still_session(n, fs, 6000)
    noise = rng.standard_normal((n, 3)) * 0.01
    # Gauss-Markov drift (T_c 300 s) of the same size as the levels: increments Gaussian, no jumps
    phi = math.exp(-1.0 / (fs * 300.0))
    gm = np.zeros(n)
    e = rng.standard_normal(n) * 0.02 * math.sqrt(1 - phi**2)
    for i in range(1, n):
        gm[i] = phi * gm[i - 1] + e[i]
    smooth = noise.copy()
    smooth[:, 1] += gm
    jumps, total = locator._jumps(session, smooth, 1)
    assert jumps <= 1 and total > 1000
    # a telegraph bias +-0.02 with a dwell of 20 s
    flips = np.cumsum(rng.exponential(20.0 * fs, size=100)).astype(int)
    level = np.where(np.searchsorted(flips, np.arange(n)) % 2 == 0, 0.02, -0.02)
    tele = noise.copy()
    tele[:, 1] += level
    jumps, total = locator._jumps(session, tele, 1)
    assert jumps >= locator.JUMP_MIN and jumps >= locator.JUMP_MIN_SHARE * total


def test_empirical_model_finds_the_planted_covariate_on_held_out_segments() -> None:
    rng = np.random.default_rng(5)
    m = 300
    seg = np.repeat(np.arange(60), 5)
    d = {"a": rng.standard_normal(m), "b": rng.standard_normal(m), "c": rng.standard_normal(m)}
    r = 0.7 * d["b"] + rng.standard_normal(m) * 0.1
    model = empirical.fit("gyro", "x", r, np.ones(m), seg, d)
    assert model.terms == ("b",)
    assert model.coefficients[0] == pytest.approx(0.7, abs=0.02)
    assert model.heldout_improvement > 0.95
    assert model.to_json()["status"] == "empirical, not in the library"
    # pure noise: no term survives the held-out test
    noise = empirical.fit("gyro", "x", rng.standard_normal(m), np.ones(m), seg, d)
    assert noise.terms == () and noise.heldout_improvement == 0.0


def test_recount_outliers_under_the_final_model() -> None:
    import gen_outside

    from station.diagnose.residuals import fit_baseline
    from station.diagnose.retest import recount_outliers

    rec = gen_outside.generate(0, "none")
    b = fit_baseline(rec.session)
    sd = b.gyro
    # a signal the base model lacks, 20 noise sigmas in one still segment: outliers against the base model ...
    seg = next(s for s in rec.session.segments() if s.kind == Kind.POSE)
    extra = np.zeros_like(sd.residual[:])
    extra[seg.start + (seg.stop - seg.start) // 2:seg.stop, 0] = 20.0 * sd.sigma[0]
    from dataclasses import replace

    bad = replace(sd, residual=sd.residual[:] + extra)
    assert recount_outliers(rec.session, bad, np.zeros_like(extra)).outlier_count[0] > 0
    # ... none once the accepted effects' fitted signal (here: exactly that signal) is taken out
    assert recount_outliers(rec.session, bad, extra).outlier_count[0] == sd.outlier_count[0]


@pytest.mark.parametrize(("seed", "kind", "sensor", "words"), [
    (2, "telegraph", "gyro", "two-level"),
    (4, "rate_norm_bias", "gyro", "|rate|"),
])
def test_outside_physics_is_located_not_named(seed: int, kind: str, sensor: str, words: str) -> None:
    import gen_outside

    from station.diagnose import diagnose
    from station.kernel.limits_file import DEFAULT_LIMITS_PATH, load_limits

    rec = gen_outside.generate(seed, kind)
    report = diagnose(rec.session, warmup_tc_s=dict(load_limits(DEFAULT_LIMITS_PATH).correlation_time_s),
                      resamples=0).report
    rep = report.to_json()
    # the locator's entries read back into the types give the same JSON
    assert json.dumps(load_report(json.loads(json.dumps(rep))).to_json()) == json.dumps(rep)
    assert rep["findings"] == []
    mine = [u for u in rep["unexplained"] if u["sensor"] == sensor]
    assert mine and "xyz"[rec.axis] in mine[0]["axes"]
    assert words in mine[0]["covariate"]
    assert mine[0]["empirical"] and mine[0]["empirical"][0]["status"] == "empirical, not in the library"


@pytest.mark.parametrize(("seed", "kind", "kinds", "words"), [
    (120006, "temp_hysteresis", {"rest", "pose", "rate"}, "temperature"),
    (120013, "sample_hold", {"move"}, "held samples"),
])
def test_hysteresis_and_held_samples_are_located_not_named(seed: int, kind: str, kinds: set[str], words: str) -> None:
    """Development seeds the locator missed before: a bias with a play in temperature on one gyro axis was taken for a
    temperature bias plus a random walk shared by the axes (the walk's K^2 is now tested for being the same on each
    axis); bursts of held samples were left out of the move blocks as outliers and seen by nothing (the far samples in
    the moves are now counted against the library's outlier allowance)."""
    import gen_outside

    from station.diagnose import diagnose
    from station.kernel.limits_file import DEFAULT_LIMITS_PATH, load_limits

    rec = gen_outside.generate(seed, kind)
    rep = diagnose(rec.session, warmup_tc_s=dict(load_limits(DEFAULT_LIMITS_PATH).correlation_time_s),
                   resamples=0).report.to_json()
    assert rep["findings"] == []
    mine = [u for u in rep["unexplained"] if u["sensor"] == "gyro" and set(u["segment_kinds"]) & kinds]
    assert mine and "xyz"[rec.axis] in mine[0]["axes"]
    assert words in mine[0]["locator"]["covariate_per_axis"]["xyz"[rec.axis]] or words in mine[0]["covariate"]


def test_far_samples_in_the_moves_are_counted_and_told_held() -> None:
    fs, n = 100.0, 3000
    rng = np.random.default_rng(7)
    t = np.arange(n) / fs
    seg = np.arange(n) // 500
    kind = np.where(seg % 2 == 0, int(Kind.POSE), int(Kind.MOVE))
    ramp = np.zeros((n, 3))
    ramp[:, 0] = np.where(kind == int(Kind.MOVE), 0.1 * np.sin(t), 0.0)  # rad/s, changing in the moves
    gyro = ramp + rng.standard_normal((n, 3)) * 1e-3
    held = np.arange(n)
    for i0 in (600, 1100, 1700, 2700):  # four bursts of 20 held samples, all in moves
        held[i0:i0 + 20] = i0
    gyro_h = gyro[held]
    z = np.zeros((n, 3))
    session = Session(metadata={"serial": "T", "sample_rate_hz": str(fs), "gravity_mps2": "9.81"}, t_s=t,
                      segment=seg, kind=kind, accel_mps2=z, gyro_radps=gyro_h, temp_degc=np.full(n, 25.0),
                      ref_accel_mps2=z, ref_gyro_radps=ramp)

    class _Sd:
        sensor = "gyro"
        sigma = np.full(3, 1e-3)
        censored = None  # no saturated segment

    count, total, rep = locator._move_samples(session, _Sd(), gyro_h - ramp)
    assert total[0] == 1500
    assert count[0] >= 10 and rep[0] >= 0.9 * count[0]  # the held samples on the moving axis: repeats of the one before
    assert count[1] == 0 and count[2] == 0  # nothing changes on the still axes: nothing far
    assert set(locator._move_sample_cells(session, _Sd(), gyro_h - ramp)) == {0}
    # no held samples: nothing
    count0, _, _ = locator._move_samples(session, _Sd(), gyro - ramp)
    assert count0.sum() == 0


@pytest.mark.parametrize(("seed", "kind", "words"), [(176041, "g_scale", "specific force"),
                                                     (176054, "temp_misalign", "temperature")])
def test_products_of_rate_are_located_and_a_stand_in_rejected(seed: int, kind: str, words: str) -> None:
    """Development seeds of two kinds the locator missed: a gyro scale that depends on the force along its axis was
    named a ``temperature_scale`` (the scale differs between rate holds and tumbles, which happen at other
    temperatures); a cross-axis coupling that changes with temperature (5e-5/K at 50 Hz) was not seen. Now the
    dictionary has the products of rate with force and with temperature, a covariate's own test locates cells the
    dispersion rule misses, and a finding that such a term explains is rejected as its stand-in."""
    import gen_outside

    from station.diagnose import diagnose
    from station.kernel.limits_file import DEFAULT_LIMITS_PATH, load_limits

    rec = gen_outside.generate(seed, kind)
    rep = diagnose(rec.session, warmup_tc_s=dict(load_limits(DEFAULT_LIMITS_PATH).correlation_time_s),
                   resamples=0).report.to_json()
    assert rep["findings"] == []
    mine = [u for u in rep["unexplained"] if u["sensor"] == "gyro"]
    ax = "xyz"[rec.axis]
    assert mine and ax in mine[0]["axes"]
    text = dict(mine[0]["locator"]["covariate_per_axis"])[ax]
    assert f"rate {ax} * {words}" in text if kind == "g_scale" else f"* {words}" in text
    if kind == "g_scale":  # the temperature scale it was named before is rejected as a stand-in for the product
        stand = [r for r in rep["rejected"]
                 if r["effect"] == "temperature_scale" and "stand-in for physics" in r["reason"]]
        assert stand and stand[0]["rival"] == f"rate {ax} * specific force {ax} on {ax}"
