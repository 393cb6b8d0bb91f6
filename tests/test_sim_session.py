"""Whole simulated sessions (station.sim.session_sim, station.kernel.plan): determinism, plan, reference columns."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from station.kernel.errors import StationError
from station.kernel.geometry import AXIS_INDEX, up_vector
from station.kernel.plan import RigPlan, default_plan, random_plan
from station.kernel.sensor_class import TABLE1
from station.physics.effects import Effects
from station.physics.trajectory import build_trajectory
from station.physics.unit import draw_unit
from station.session.model import Kind, Session
from station.sim.session_sim import SimResult, simulate_session

DEG = math.pi / 180.0

SHORT = RigPlan(
    rest_s=30.0, poses=("+x", "-z"), pose_hold_s=5.0, rate_steps=(("y", 100.0), ("z", -50.0)), rate_hold_s=3.0
)


@pytest.fixture(scope="module")
def default_result() -> SimResult:
    return simulate_session(123)


def _arrays(s: Session) -> dict[str, np.ndarray]:
    names = ("t_s", "segment", "kind", "accel_mps2", "gyro_radps", "temp_degc", "ref_accel_mps2", "ref_gyro_radps")
    return {n: getattr(s, n) for n in names}


def test_same_seed_same_session_and_bytes(default_result: SimResult) -> None:
    again = simulate_session(123)
    for name, value in _arrays(default_result.session).items():
        np.testing.assert_array_equal(value, getattr(again.session, name), err_msg=name)
    assert dict(again.session.metadata) == dict(default_result.session.metadata)
    other = simulate_session(124)
    assert not np.array_equal(other.session.accel_mps2, default_result.session.accel_mps2)
    assert other.truth.serial != default_result.truth.serial
    csv_v1 = pytest.importorskip("station.session.csv_v1")
    a = csv_v1.format_session(simulate_session(7, plan=SHORT, effects=Effects(lever_arm=20)).session)
    b = csv_v1.format_session(simulate_session(7, plan=SHORT, effects=Effects(lever_arm=20)).session)
    assert a.encode() == b.encode()
    back = csv_v1.parse_session(a)
    assert back.metadata["sim_effects"] == "lever_arm=20.0"
    assert Effects.parse(back.metadata["sim_effects"]) == Effects(lever_arm=20)


def test_metadata(default_result: SimResult) -> None:
    md = dict(default_result.session.metadata)
    assert md == {
        "serial": default_result.truth.serial,
        "sample_rate_hz": "100",
        "gravity_mps2": "9.8128",
        "latitude_deg": "52.61",
        "heading_deg": "0",
        "station": "sim",
        "rig": "sim",
        "sim_seed": "123",
        "sim_class": "table1",
        "sim_effects": "none",
    }
    plan = replace(default_plan(), serial="SN-000123", rest_s=10.0, poses=(), rate_steps=())
    assert simulate_session(1, plan=plan).session.serial == "SN-000123"


def test_default_plan_is_a_realistic_session(default_result: SimResult) -> None:
    s = default_result.session
    assert s.t_s[0] == 0.0
    np.testing.assert_allclose(np.diff(s.t_s), 0.01, rtol=1e-9)
    assert 12 * 60 <= s.duration_s <= 15 * 60
    segs = s.segments()
    assert [seg.index for seg in segs] == list(range(len(segs)))  # one run per rig step
    assert segs[0].kind == Kind.REST and segs[0].start == 0 and len(segs[0]) == 30000
    kinds = [seg.kind for seg in segs]
    assert kinds.count(Kind.REST) == 1 and kinds.count(Kind.POSE) == 6 and kinds.count(Kind.RATE) == 18
    # the plan's segment table is what the session shows
    plan_segs = default_result.trajectory.segments
    assert [(p.index, p.kind) for p in plan_segs] == [(g.index, g.kind) for g in segs]
    for p, g in zip(plan_segs, segs, strict=True):
        assert s.t_s[g.start] >= p.t_start_s - 1e-9 and s.t_s[g.stop - 1] < p.t_stop_s
    # poses cover every axis up and down; rates +-50/100/200 about each axis
    ups = {tuple(s.ref_accel_mps2[g.start] / s.gravity_mps2) for g in segs if g.kind == Kind.POSE}
    assert ups == {tuple(up_vector(p)) for p in ("+x", "-x", "+y", "-y", "+z", "-z")}
    rates = sorted(tuple(np.round(s.ref_gyro_radps[g.start] / DEG, 9)) for g in segs if g.kind == Kind.RATE)
    expected = sorted(
        tuple(float(r) if i == k else 0.0 for i in range(3)) for k in range(3) for r in (50, -50, 100, -100, 200, -200)
    )
    assert rates == expected
    for g in segs:
        if g.kind == Kind.RATE:
            assert 11.9 <= len(g) / 100 <= 12.1
        if g.kind == Kind.POSE:
            assert len(g) == 3000


def _check_reference(res: SimResult) -> None:
    """The reference columns obey the spec: rig knowledge only, gravity up, commanded rates."""
    s, traj = res.session, res.trajectory
    g = s.gravity_mps2
    assert np.all(np.isfinite(s.ref_accel_mps2)) and np.all(np.isfinite(s.ref_gyro_radps))
    np.testing.assert_allclose(np.linalg.norm(s.ref_accel_mps2, axis=1), g, rtol=1e-12)
    for seg in s.segments():
        ref_f, ref_w = s.ref_accel_mps2[seg.slice], s.ref_gyro_radps[seg.slice]
        kin = traj.kinematics(s.t_s[seg.slice])  # the rig's own encoders (no time offset)
        if seg.kind in (Kind.REST, Kind.POSE, Kind.RATE):
            up = ref_f[0] / g
            assert np.count_nonzero(up) == 1 and abs(up).max() == 1.0  # exactly one axis up
            assert np.all(ref_f == ref_f[0])
            np.testing.assert_allclose(kin.up_in_sensor(), np.broadcast_to(up, kin.omega_radps.shape), atol=1e-12)
            # physically settled: the rig really does what the reference says
            np.testing.assert_allclose(kin.omega_radps, ref_w, atol=1e-9)
            np.testing.assert_allclose(kin.alpha_radps2, 0.0, atol=1e-9)
        if seg.kind in (Kind.REST, Kind.POSE):
            assert np.all(ref_w == 0.0)
        elif seg.kind == Kind.RATE:
            w = ref_w[0]
            assert np.count_nonzero(w) == 1 and np.all(ref_w == w)
        else:
            np.testing.assert_allclose(ref_f, kin.specific_force(g), atol=1e-12)
            np.testing.assert_allclose(ref_w, kin.omega_radps, atol=1e-12)


def test_reference_columns_default_plan(default_result: SimResult) -> None:
    _check_reference(default_result)


@pytest.mark.parametrize("plan_seed", [0, 1, 2])
def test_random_plans_simulate_and_obey_the_spec(plan_seed: int) -> None:
    plan = random_plan(np.random.default_rng(plan_seed))
    again = random_plan(np.random.default_rng(plan_seed))
    assert plan == again
    plan = replace(plan, rest_s=min(plan.rest_s, 60.0))  # keep the test quick
    res = simulate_session(plan_seed, plan=plan, effects=Effects(earth_rotation=1.0, lever_arm=10.0))
    s = res.session
    assert s.sample_rate_hz == plan.sample_rate_hz
    np.testing.assert_allclose(np.diff(s.t_s), 1.0 / plan.sample_rate_hz, rtol=1e-9)
    _check_reference(res)
    rate_segs = [seg for seg in res.trajectory.segments if seg.kind == Kind.RATE]
    assert [(seg.rate_axis, seg.rate_dps) for seg in rate_segs] == list(plan.rate_steps)
    for seg in rate_segs:  # negative axis up for flipped axes, and the reference is still about +axis
        assert seg.up == ("-" if seg.rate_axis in plan.rate_flip else "+") + seg.rate_axis
    tr = res.truth.gyro
    earth_up = 7.292115e-5 * math.sin(math.radians(plan.latitude_deg))  # the horizontal part averages out
    for seg in s.segments_of(Kind.RATE):
        w = s.ref_gyro_radps[seg.start]
        up = s.ref_accel_mps2[seg.start] / s.gravity_mps2
        measured = s.gyro_radps[seg.slice].mean(axis=0)
        expected = tr.misalignment @ (w + earth_up * up) + tr.bias_at(s.t_s[seg.slice]).mean(axis=0)
        np.testing.assert_array_less(np.abs(measured - expected), 0.005 * DEG + 5 * tr.drift_noise)


def test_random_plans_vary() -> None:
    plans = [random_plan(np.random.default_rng(i)) for i in range(12)]
    assert len({p.poses for p in plans}) > 6
    assert len({p.sample_rate_hz for p in plans}) > 1
    assert len({p.rate_steps for p in plans}) > 6
    assert all(set(p.poses) == {"+x", "-x", "+y", "-y", "+z", "-z"} for p in plans)


def test_given_unit_and_effects_truth() -> None:
    unit = draw_unit(TABLE1, np.random.default_rng(77))
    res = simulate_session(3, plan=SHORT, unit=unit, effects=Effects(lever_arm=25.0, time_offset=-4.0))
    assert res.truth is unit and res.session.serial == unit.serial
    assert np.linalg.norm(res.effect_truth.lever_arm_m) == pytest.approx(0.025)
    assert res.effect_truth.time_offset_s == pytest.approx(-0.004)
    assert res.session.metadata["sim_effects"] == "lever_arm=25.0,time_offset=-4.0"
    # the same unit with another seed: same parameters, other noise
    other = simulate_session(4, plan=SHORT, unit=unit)
    assert not np.array_equal(other.session.accel_mps2, res.session.accel_mps2)


def test_flipped_rate_axis_spins_the_table_the_other_way() -> None:
    plan = replace(SHORT, rate_flip=("y",))
    traj = build_trajectory(plan)
    seg = next(s for s in traj.segments if s.kind == Kind.RATE and s.rate_axis == "y")
    assert seg.up == "-y" and seg.rate_dps == 100.0
    t = np.array([(seg.t_start_s + seg.t_stop_s) / 2])
    _, rate, _ = traj.axis_states(t)
    assert rate[0, 2] == pytest.approx(-100.0 * DEG)  # table yaw rate
    kin = traj.kinematics(t)
    assert kin.omega_radps[0, AXIS_INDEX["y"]] == pytest.approx(100.0 * DEG)


def test_plan_validation() -> None:
    for bad in (
        {"poses": ("+w",)},
        {"rate_steps": (("q", 10.0),)},
        {"sample_rate_hz": 0.0},
        {"rest_s": -1.0},
        {"rate_flip": ("k",)},
    ):
        with pytest.raises(StationError):
            RigPlan(**bad)  # type: ignore[arg-type]
