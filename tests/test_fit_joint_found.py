"""The found terms in the line's joint fit (station.fit.joint_found): the gyro's IEEE 952 polynomial and the time
offset recovered from a line unit's rack and rig recordings against known truth, on the station's simulator and on
the independent line generator (benchmarks/gen_line_indep.py); not kept without them; flagged where the line's rig
plan or capture cannot determine them.

Seeds: development used 901-902 (simulator) and 911-913 (independent generator); these tests use 3101-3107.
"""

from __future__ import annotations

import hashlib
from dataclasses import replace
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from benchmark_modules import load_benchmark

from station.eeprom.image import decode_image, encode_image, run_image
from station.fit.calibrate import FitOptions
from station.fit.joint import fit_joint
from station.kernel.found_terms import found_terms
from station.kernel.line_plan import LinePlan, line_rig_plan
from station.kernel.parameters import ParameterSet
from station.physics.effects import Effects, EffectShapes, EffectTruth
from station.session.model import Kind, Session
from station.sim.line_sim import simulate_line

W200 = float(np.radians(200.0))
PRIOR = {"accel": (50.0, 167.0), "gyro": (1030.0, 3760.0)}
AUTO = FitOptions(tc_range_s=PRIOR, scale_nonlinearity="auto", time_offset="auto")
OFF = FitOptions(tc_range_s=PRIOR)
TAU_S = 3e-3
K2 = np.array([1.0, -0.7, 0.6]) * 1e-3 / W200  # 0.1 % and less at 200 deg/s
K3 = np.array([-0.5, 0.8, 1.0]) * 1e-3 / W200**2
#: the line's rig part with two rate magnitudes and both signs about each axis: both terms identifiable
TWO_RATES = replace(line_rig_plan(), rate_steps=tuple((a, s * r) for a in "zxy" for r in (50.0, 200.0)
                                                      for s in (1.0, -1.0)))


def _truth(seed: int, tau_s: float, k2: np.ndarray, k3: np.ndarray) -> EffectTruth:
    et = Effects(time_offset=tau_s * 1e3).realize(EffectShapes.draw(np.random.default_rng(seed)))
    return replace(et, gyro_quadratic=k2, gyro_cubic=k3)


def _assert_recovered(params: ParameterSet, tau_s: float, k2: np.ndarray, k3: np.ndarray) -> None:
    note = params.quality.time_offset
    assert note is not None and note.status == "fitted", note
    assert params.time_offset_std_s > 0
    assert abs(params.time_offset_s - tau_s) <= 3.0 * params.time_offset_std_s, (params.time_offset_s,
                                                                                   params.time_offset_std_s)
    poly = params.quality.scale_nonlinearity
    assert poly is not None and poly.status == "fitted" and poly.axes == ("x", "y", "z"), poly
    for name, true in (("scale_quadratic", k2), ("scale_cubic", k3)):
        k, k_std = getattr(params.gyro, name), getattr(params.gyro, f"{name}_std")
        assert np.all(k_std > 0), (name, k_std)
        assert np.all(np.abs(k - true) <= 3.0 * k_std), (name, k, true, (k - true) / k_std)


@pytest.mark.parametrize("seed", [3101, 3102])
def test_simulated_line_unit_time_offset_and_polynomial_recovered(seed: int) -> None:
    line = simulate_line(seed, plan=LinePlan(rig=TWO_RATES), effect_truth=_truth(seed, TAU_S, K2, K3))
    params = fit_joint(line.rack, line.rig, AUTO)
    _assert_recovered(params, TAU_S, K2, K3)
    assert params.format == "station-params/3"
    # the summary and the EEPROM image carry what the set keeps
    summary = {t.name: t for t in found_terms(params).terms}
    assert summary["time_offset"].applied and summary["time_offset"].value == params.time_offset_s
    assert all(summary[f"gyro.{t}.{a}"].applied for t in ("k2", "k3") for a in "xyz")
    image = decode_image(encode_image(run_image(params, "ST", datetime(2026, 11, 28, tzinfo=UTC))))
    assert image.layout_version == 3 and image.effects is not None
    assert image.effects.time_offset_s == pytest.approx(params.time_offset_s, rel=1e-6)
    assert np.allclose(image.effects.quadratic[1], params.gyro.scale_quadratic, rtol=1e-6)
    assert np.allclose(image.effects.cubic[1], params.gyro.scale_cubic, rtol=1e-6)
    # the joint fit without the terms (as before) leaves them out: 0 in the set, no note
    off = fit_joint(line.rack, line.rig, OFF)
    assert off.time_offset_s == 0.0 and not off.has_nonlinearity
    assert off.quality.time_offset is None and off.quality.scale_nonlinearity is None


def test_independent_line_unit_time_offset_and_polynomial_recovered() -> None:
    gen = load_benchmark("gen_line_indep")
    u = gen.generate_unit(3103, rack_s=1800.0, hour_s=10.0, rig=replace(TWO_RATES, rest_s=2.0), time_offset_s=TAU_S,
                          gyro_k2=K2, gyro_k3=K3)
    _assert_recovered(fit_joint(u.rack, u.rig, AUTO), TAU_S, K2, K3)


def test_without_them_nothing_is_kept() -> None:
    line = simulate_line(3104, plan=LinePlan(rig=TWO_RATES))
    params = fit_joint(line.rack, line.rig, AUTO)
    note = params.quality.time_offset
    assert note is not None and note.status == "not_significant", note  # estimated, and not kept
    assert params.time_offset_s == 0.0
    poly = params.quality.scale_nonlinearity
    assert poly is not None and poly.status == "not_significant", poly
    assert not params.has_nonlinearity and params.format == "station-params/2"


def test_the_default_line_plan_cannot_identify_the_polynomial_and_says_which_step_would() -> None:
    # the default line's rig part holds one magnitude (+-100 deg/s) per axis: neither term by the rig fit's rules
    line = simulate_line(3105, effect_truth=_truth(3105, TAU_S, K2, K3))
    params = fit_joint(line.rack, line.rig, AUTO)
    poly = params.quality.scale_nonlinearity
    assert poly is not None and poly.status == "not_identifiable", poly
    assert all("add a step at a second magnitude" in m for m in poly.detail["not_identifiable"])
    assert [m[:2] for m in poly.detail["not_identifiable"]] == ["x:", "y:", "z:"]
    assert not params.has_nonlinearity
    terms = {t.name: t for t in found_terms(params).terms}
    assert terms["gyro.k2.x"].status == "not_determined" and "second magnitude" in terms["gyro.k2.x"].reason
    # its transitions still determine the time offset
    assert params.quality.time_offset is not None and params.quality.time_offset.status == "fitted"
    assert abs(params.time_offset_s - TAU_S) <= 3.0 * params.time_offset_std_s


def _without_move_references(s: Session) -> Session:
    """The rig recording as the station's capture makes it: no reference in the moves."""
    move = s.kind == Kind.MOVE
    f, w = s.ref_accel_mps2.copy(), s.ref_gyro_radps.copy()
    f[move], w[move] = np.nan, np.nan
    return s.replace(ref_accel_mps2=f, ref_gyro_radps=w)


def test_one_sign_and_a_capture_without_move_references_are_flagged() -> None:
    one_sign = replace(line_rig_plan(), rate_steps=tuple((a, r) for a in "zxy" for r in (50.0, 200.0)))
    line = simulate_line(3106, plan=LinePlan(rig=one_sign), effect_truth=_truth(3106, TAU_S, K2, K3))
    params = fit_joint(line.rack, _without_move_references(line.rig), AUTO)
    poly = params.quality.scale_nonlinearity
    assert poly is not None and poly.detail["identifiable"] == {"k2": [], "k3": ["x", "y", "z"]}, poly
    assert all("add the same magnitudes in the other direction" in m for m in poly.detail["not_identifiable"])
    assert not np.any(params.gyro.scale_quadratic)
    note = params.quality.time_offset
    assert note is not None and note.status == "not_determined" and "no transitions" in note.reason
    assert params.time_offset_s == 0.0


def test_the_line_rig_role_writes_the_polynomial_and_its_verification_passes(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The line on its transports (virtual clock): a unit with a planted k2 and k3 soaks in the rack, is carried
    powered to the rig, runs a line rig part with two rate magnitudes, and the rig role's joint fit keeps both
    terms on every axis (within 3 sigma); the image is layout 3 holding them, the on-rig verification of the
    firmware's corrected output passes. The station's capture records no reference in the moves: the time offset
    is not determined and not written."""
    from station.compose import Station
    from station.eeprom.image import read_all_slots, select_image
    from station.kernel.line_plan import LinePlanFile, line_plan_to_json
    from station.kernel.virtual_clock import VirtualClock, acting
    from station.line.recordings import DatabaseArchive
    from station.sequence.records import Outcome
    from station.sim.line_station import SimLine
    from station.store.db import open_database

    monkeypatch.setenv("STATION_LOCK_DIR", str(tmp_path / "locks"))
    plan = LinePlan(rack_s=300.0, rig=TWO_RATES)
    line = LinePlanFile(plan, "two-rates.json", hashlib.sha256(line_plan_to_json(plan).encode()).hexdigest())
    clock = VirtualClock()
    records: dict[str, Any] = {}
    with acting(clock, name="test"), SimLine(1, 1.0, 3107, line.rig_plan(), clock=clock, effects=Effects(
            time_offset=TAU_S * 1e3), effect_change=lambda _, et: replace(et, gyro_quadratic=K2, gyro_cubic=K3)) as sim:
        db_url = f"sqlite:///{tmp_path / 'line.sqlite'}"
        with open_database(db_url) as database:
            sim.soak([0], 300.0, DatabaseArchive(database.sessions))
        sim.to_rig([0], 30.0)
        config = sim.rig_config([0], line, db_url=db_url, station_id="found-line")
        station = Station(config, clock=sim.clock, on_provision=lambda r: records.__setitem__(r.serial, r))
        result = station.run()
        eeprom = sim.sim.units[0].sensor.eeprom.image()
    unit = result.units[0]
    assert unit.outcome is Outcome.PASS, unit.message
    p = unit.params
    assert p is not None and p.source["fit"] == "joint (rack + rig)"
    for name, true in (("scale_quadratic", K2), ("scale_cubic", K3)):
        k, k_std = getattr(p.gyro, name), getattr(p.gyro, f"{name}_std")
        assert np.all(k_std > 0) and np.all(np.abs(k - true) <= 3.0 * k_std), (name, (k - true) / k_std)
    assert p.quality.time_offset is not None and p.quality.time_offset.status == "not_determined"
    assert p.time_offset_s == 0.0
    slot = select_image(read_all_slots(eeprom), p.serial)
    assert slot is not None and slot.image is not None and slot.image.layout_version == 3
    assert slot.image.effects is not None and np.array_equal(slot.image.effects.quadratic[1], p.gyro.scale_quadratic)
    rec = records[p.serial]
    assert rec.verification is not None and rec.verification.passed
