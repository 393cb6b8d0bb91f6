"""Physics of the simulated IMU (station.sim): unit draws, eq. (1)/(3), ADC, temperature, effects."""

from __future__ import annotations

import itertools
import math
from dataclasses import replace

import numpy as np
import pytest

from station.kernel.errors import StationError
from station.kernel.plan import RigPlan
from station.kernel.sensor_class import TABLE1, SensorClass
from station.physics.effects import EARTH_RATE_RADPS, GYRO_PER_ACCEL, STANDARD_GRAVITY, Effects
from station.physics.imu import Environment, ImuModel
from station.physics.trajectory import build_trajectory
from station.physics.unit import draw_unit
from station.session.model import Kind, Session
from station.sim.session_sim import SimResult, simulate_session

DEG = math.pi / 180.0

SHORT = RigPlan(
    rest_s=60.0,
    poses=("+z", "+x", "-y"),
    pose_hold_s=10.0,
    rate_steps=(("x", 200.0), ("x", -200.0)),
    rate_hold_s=5.0,
)

ALL_EFFECTS = Effects(
    temperature_bias=0.003,
    temperature_scale=300.0,
    g_sensitivity=0.1,
    scale_nonlinearity=0.005,
    scale_asymmetry=0.004,
    lever_arm=30.0,
    earth_rotation=1.0,
    time_offset=7.0,
    bias_random_walk=1e-4,
    outliers=1e-3,
)


def _pair(
    effects: Effects, *, seed: int = 5, plan: RigPlan = SHORT, noiseless: bool = False
) -> tuple[SimResult, SimResult]:
    """The same unit, seed and plan without and with ``effects`` (identical random streams)."""
    unit = draw_unit(TABLE1, np.random.default_rng(seed))
    if noiseless:
        unit = unit.noiseless()
    return (
        simulate_session(seed, plan=plan, unit=unit),
        simulate_session(seed, plan=plan, unit=unit, effects=effects),
    )


def _segments(s: Session, kind: Kind) -> list[slice]:
    return [seg.slice for seg in s.segments_of(kind)]


# --- unit draws --------------------------------------------------------------------------


def test_draw_unit_lies_in_table1_ranges() -> None:
    rng = np.random.default_rng(11)
    units = [draw_unit(TABLE1, rng) for _ in range(300)]
    off = ~np.eye(3, dtype=bool)

    def check(values: np.ndarray, lo: float, hi: float) -> None:
        assert values.min() >= lo and values.max() <= hi
        # the draws cover the range (uniform): something in each outer tenth
        assert values.min() < lo + 0.1 * (hi - lo) and values.max() > hi - 0.1 * (hi - lo)

    a = [u.accel for u in units]
    g = [u.gyro for u in units]
    check(np.array([x.bias_static for x in a]), -0.17, 0.026)
    check(np.array([x.bias_drift for x in a]), -0.002, 0.018)
    check(np.array([x.correlation_time_s for x in a]), 50.0, 167.0)
    check(np.array([np.diag(x.misalignment) for x in a]), 0.998, 1.02)
    check(np.array([x.misalignment[off] for x in a]), -0.03, 0.02)
    check(np.array([x.noise_std for x in a]), 0.017, 0.028)
    check(np.array([x.bias_static for x in g]) / DEG, -0.726, 2.739)
    check(np.array([x.bias_drift for x in g]) / DEG, -0.115, 0.347)
    check(np.array([x.correlation_time_s for x in g]), 1030.0, 3760.0)
    check(np.array([np.diag(x.misalignment) for x in g]), 0.97, 1.003)
    check(np.array([x.misalignment[off] for x in g]), -0.001, 0.001)
    check(np.array([x.noise_std for x in g]) / DEG, 0.01, 0.013)
    for u in units:
        np.testing.assert_allclose(u.accel.drift_noise, 0.01 * np.abs(u.accel.bias_drift))
        np.testing.assert_allclose(u.gyro.drift_noise, 0.01 * np.abs(u.gyro.bias_drift))
        assert 3.0 <= u.self_heating_k <= 8.0 and 200.0 <= u.self_heating_tau_s <= 600.0
        # quantization finer than the noise
        assert u.accel.lsb / math.sqrt(12) < 0.1 * u.accel.noise_std.min()
        assert u.gyro.lsb / math.sqrt(12) < 0.15 * u.gyro.noise_std.min()
        shapes = u.shapes
        for v in (shapes.accel_temp_bias, shapes.gyro_nonlinearity, shapes.g_sensitivity):
            assert np.all((np.abs(v) >= 0.5) & (np.abs(v) <= 1.0))
        assert np.linalg.norm(shapes.lever_arm) == pytest.approx(1.0)
    assert len({u.serial for u in units}) > 290


def test_draw_unit_is_deterministic_and_names_fields_like_params() -> None:
    a = draw_unit(TABLE1, np.random.default_rng(3))
    b = draw_unit(TABLE1, np.random.default_rng(3))
    assert a.serial == b.serial and a.serial.startswith("SIM-")
    np.testing.assert_array_equal(a.gyro.misalignment, b.gyro.misalignment)
    d = a.as_parameter_set_dict()
    assert set(d) == {"accel", "gyro"}
    names = {"misalignment", "bias_static", "bias_drift", "correlation_time_s", "drift_noise", "noise_std"}
    assert set(d["accel"]) == names
    ps = a.as_parameter_set(0.01)
    np.testing.assert_array_equal(ps.gyro.bias_static, a.gyro.bias_static)
    assert ps.to_json()  # serialisable (NaN Allan figures become null)
    assert draw_unit(TABLE1, np.random.default_rng(3), serial="SN-1").serial == "SN-1"


# --- the renderer ---------------------------------------------------------------------------


def test_chunked_render_is_bit_identical_to_one_shot() -> None:
    unit = draw_unit(TABLE1, np.random.default_rng(8))
    traj = build_trajectory(SHORT)
    t = traj.sample_times()[:6000]
    one = ImuModel(unit, effects=ALL_EFFECTS, seed=99, latitude_deg=52.0, heading_deg=30.0)
    kin = traj.kinematics(t, time_offset_s=one.time_offset_s)
    whole = one.render(kin, 9.81)
    chunked = ImuModel(unit, effects=ALL_EFFECTS, seed=99, latitude_deg=52.0, heading_deg=30.0)
    random_cuts = np.random.default_rng(1).integers(0, len(t), 20)
    cuts = np.unique(np.concatenate(([0, 1, 2, 3, 700, 701], random_cuts, [len(t)])))
    parts = []
    for a, b in itertools.pairwise(cuts):
        sub = traj.kinematics(t[a:b], time_offset_s=chunked.time_offset_s)
        parts.append(chunked.render(sub, 9.81))
    for name in ("accel_mps2", "gyro_radps", "temp_degc", "t_s"):
        np.testing.assert_array_equal(getattr(whole, name), np.concatenate([getattr(p, name) for p in parts]))
    assert chunked.samples_rendered == len(t) and chunked.t_last_s == t[-1]


def test_render_is_seeded() -> None:
    unit = draw_unit(TABLE1, np.random.default_rng(8))
    traj = build_trajectory(SHORT)
    kin = traj.kinematics(traj.sample_times()[:500])
    a = ImuModel(unit, seed=1).render(kin, 9.81)
    b = ImuModel(unit, seed=1).render(kin, 9.81)
    c = ImuModel(unit, seed=2).render(kin, 9.81)
    np.testing.assert_array_equal(a.accel_mps2, b.accel_mps2)
    assert not np.array_equal(a.accel_mps2, c.accel_mps2)
    seq = np.random.SeedSequence(7)
    np.testing.assert_array_equal(
        ImuModel(unit, seed=seq).render(kin, 9.81).gyro_radps, ImuModel(unit, seed=seq).render(kin, 9.81).gyro_radps
    )


def test_render_refuses_time_going_backwards() -> None:
    unit = draw_unit(TABLE1, np.random.default_rng(8))
    traj = build_trajectory(SHORT)
    t = traj.sample_times()[:10]
    model = ImuModel(unit)
    model.render(traj.kinematics(t[:5]), 9.81)
    with pytest.raises(ValueError):
        model.render(traj.kinematics(t[4:]), 9.81)
    with pytest.raises(ValueError):
        ImuModel(unit).render(traj.kinematics(t[::-1]), 9.81)


def test_pose_and_rest_means_follow_eq1() -> None:
    """Mean accel per static segment = M_a (g up) + b_stat + b_drift exp(-t/T_c), within statistics."""
    res = simulate_session(21)
    s, tr = res.session, res.truth.accel
    g = s.gravity_mps2
    checked = 0
    for sl in _segments(s, Kind.REST) + _segments(s, Kind.POSE):
        n = sl.stop - sl.start
        up = s.ref_accel_mps2[sl][0] / g
        expected = (tr.misalignment @ (g * up)) + tr.bias_at(s.t_s[sl]).mean(axis=0)
        tol = 5 * np.sqrt(tr.noise_std**2 / n + tr.drift_noise**2 + tr.lsb**2 / 12 / n) + 2 * tr.outlier_size / n
        np.testing.assert_array_less(np.abs(s.accel_mps2[sl].mean(axis=0) - expected), tol)
        checked += 1
    assert checked == 7
    # the drift is visible: early rest minus late rest = b_drift (1 - exp(-...)) to within noise
    rest = _segments(s, Kind.REST)[0]
    early, late = slice(rest.start, rest.start + 500), slice(rest.stop - 500, rest.stop)
    diff = s.accel_mps2[early].mean(0) - s.accel_mps2[late].mean(0)
    expected = tr.bias_at(s.t_s[early]).mean(0) - tr.bias_at(s.t_s[late]).mean(0)
    tol = 5 * np.sqrt(2 * tr.noise_std**2 / 500 + 2 * tr.drift_noise**2)
    np.testing.assert_array_less(np.abs(diff - expected), tol)


def test_rate_means_follow_eq1() -> None:
    """Mean gyro per rate segment = M_w w + bias (Earth rate off), within statistics."""
    res = simulate_session(22)
    s, tr = res.session, res.truth.gyro
    segs = _segments(s, Kind.RATE)
    assert len(segs) == 18
    for sl in segs:
        n = sl.stop - sl.start
        w = s.ref_gyro_radps[sl][0]
        expected = tr.misalignment @ w + tr.bias_at(s.t_s[sl]).mean(axis=0)
        tol = 5 * np.sqrt(tr.noise_std**2 / n + tr.drift_noise**2 + tr.lsb**2 / 12 / n)
        np.testing.assert_array_less(np.abs(s.gyro_radps[sl].mean(axis=0) - expected), tol)


def test_gyro_sees_body_rates_during_tumbles() -> None:
    res = simulate_session(4, plan=SHORT, unit=draw_unit(TABLE1, np.random.default_rng(4)).noiseless())
    s, tr = res.session, res.truth
    moves = _segments(s, Kind.MOVE)
    assert moves
    for sl in moves:
        kin = res.trajectory.kinematics(s.t_s[sl])
        assert np.abs(kin.omega_radps).max() > 10 * DEG
        expected_w = kin.omega_radps @ tr.gyro.misalignment.T + tr.gyro.bias_at(s.t_s[sl])
        np.testing.assert_allclose(s.gyro_radps[sl], expected_w, atol=0.51 * tr.gyro.lsb + 1e-12)
        expected_f = kin.specific_force(s.gravity_mps2) @ tr.accel.misalignment.T + tr.accel.bias_at(s.t_s[sl])
        np.testing.assert_allclose(s.accel_mps2[sl], expected_f, atol=0.51 * tr.accel.lsb + 1e-12)


def test_gauss_markov_drift_noise_statistics() -> None:
    """The stochastic drift part: exact GM discretization, stationary std, correlation exp(-lag/T_c)."""
    base = draw_unit(TABLE1, np.random.default_rng(2)).noiseless()
    tau, std = np.array([20.0, 40.0, 60.0]), np.array([0.05, 0.1, 0.2])
    accel = replace(base.accel, correlation_time_s=tau, drift_noise=std, bias_drift=np.zeros(3), lsb=0.0)
    unit = replace(base, accel=accel)
    model = ImuModel(unit, seed=3, environment=Environment(23.0, 0.0))
    t = np.arange(0, 20000.0, 0.5)
    n = len(t)
    from station.kernel.geometry import Kinematics

    kin = Kinematics(t, np.broadcast_to(np.eye(3), (n, 3, 3)), np.zeros((n, 3)), np.zeros((n, 3)))
    x = model.render(kin, 0.0).accel_mps2 - accel.bias_static
    assert np.all(x[0] == 0.0)  # g(0) = 1 exactly at power-on: no stochastic part yet
    settled = x[t > 5 * tau.max()]
    np.testing.assert_allclose(settled.std(axis=0), std, rtol=0.2)
    for k in range(3):
        lag = int(tau[k] / 0.5)
        y = settled[:, k]
        rho = np.corrcoef(y[:-lag], y[lag:])[0, 1]
        assert rho == pytest.approx(math.exp(-1.0), abs=0.12)


def test_temperature_channel() -> None:
    res = simulate_session(6)
    s, u, env = res.session, res.truth, res.environment
    assert 21.0 <= env.ambient_degc <= 25.0 and abs(env.ambient_rate_k_per_s) <= 1.0 / 3600
    np.testing.assert_array_equal(np.rint(s.temp_degc * 256) / 256, s.temp_degc)
    t = s.t_s
    true = env.ambient_degc + env.ambient_rate_k_per_s * t + u.self_heating_k * (1 - np.exp(-t / u.self_heating_tau_s))
    resid = s.temp_degc - true
    assert abs(resid.mean()) < 0.005
    assert resid.std() == pytest.approx(math.hypot(0.05, (1 / 256) / math.sqrt(12)), rel=0.05)
    assert s.temp_degc[:100].mean() == pytest.approx(env.ambient_degc, abs=0.05)


def test_adc_quantizes_and_clips() -> None:
    base = draw_unit(TABLE1, np.random.default_rng(9))
    top = 2048 * base.accel.lsb  # ~4.9 m/s^2: the poses clip
    unit = replace(base, accel=replace(base.accel, full_scale=top))
    res = simulate_session(9, plan=SHORT, unit=unit)
    s = res.session
    for values, lsb in ((s.accel_mps2, unit.accel.lsb), (s.gyro_radps, unit.gyro.lsb)):
        counts = values / lsb
        np.testing.assert_allclose(counts, np.rint(counts), atol=1e-6)
    assert s.accel_mps2.max() == pytest.approx(top - unit.accel.lsb)
    assert s.accel_mps2.min() == pytest.approx(-top)
    # the 16-bit, +-8 g accelerometer and the 20-bit, +-2000 deg/s gyro of Table 1's class
    assert base.accel.lsb == pytest.approx(16 * STANDARD_GRAVITY / 65536)
    assert base.gyro.lsb == pytest.approx(4000 * DEG / 2**20)


def test_sensor_class_outliers_on_the_accelerometer_only() -> None:
    cls = replace(TABLE1, accel_outlier_probability=0.01)
    res = simulate_session(10, plan=SHORT, sensor_class=cls)
    assert res.truth.accel.outlier_probability == 0.01 and res.truth.gyro.outlier_probability == 0.0
    unit = res.truth
    clean = simulate_session(10, plan=SHORT, unit=replace(unit, accel=replace(unit.accel, outlier_probability=0.0)))
    np.testing.assert_array_equal(res.session.gyro_radps, clean.session.gyro_radps)
    diff = res.session.accel_mps2 - clean.session.accel_mps2
    hits = diff != 0
    expected = 0.01 * hits.size
    assert abs(hits.sum() - expected) < 5 * math.sqrt(expected)
    size = np.abs(diff[hits]) / np.broadcast_to(unit.accel.noise_std, diff.shape)[hits]
    assert size.min() > 0.5 * 8 - 0.5 and size.max() < 1.5 * 8 + 0.5  # 4..12 sigma
    assert len(_segments(res.session, Kind.RATE)) == 2


# --- effects ---------------------------------------------------------------------------------


def test_effects_parse_describe_and_errors() -> None:
    e = Effects.parse(["lever_arm=30", "earth_rotation=1"])
    assert e.lever_arm == 30.0 and e.earth_rotation == 1.0 and e.time_offset == 0.0
    assert e.describe() == "lever_arm=30.0,earth_rotation=1.0"
    assert Effects.parse(e.describe()) == e
    assert Effects.parse("none") == Effects() and Effects().describe() == "none"
    assert Effects.parse("time_offset=-5, outliers=1e-3").time_offset == -5.0
    assert set(e.as_dict()) == set(Effects.names())
    assert len(Effects.names()) == 11  # the ten original effects plus pose_tilt
    for bad in ("warp=1", "lever_arm", "lever_arm=abc", "lever_arm=-1", "outliers=1.5", "g_sensitivity=nan"):
        with pytest.raises(StationError):
            Effects.parse(bad)


def test_effect_realization_units() -> None:
    unit = draw_unit(TABLE1, np.random.default_rng(1))
    off = Effects().realize(unit.shapes)
    assert not np.any(off.lever_arm_m) and not np.any(off.g_sensitivity) and off.time_offset_s == 0.0
    et = Effects(lever_arm=30, time_offset=12, temperature_bias=0.002, g_sensitivity=0.1).realize(unit.shapes)
    assert np.linalg.norm(et.lever_arm_m) == pytest.approx(0.030)
    assert et.time_offset_s == pytest.approx(0.012)
    np.testing.assert_allclose(et.accel_temp_bias, 0.002 * unit.shapes.accel_temp_bias)
    np.testing.assert_allclose(et.gyro_temp_bias, 0.002 * GYRO_PER_ACCEL * DEG * unit.shapes.gyro_temp_bias)
    assert np.abs(et.g_sensitivity).max() <= 0.1 * DEG / STANDARD_GRAVITY + 1e-15


def test_effects_off_leave_the_base_model_alone() -> None:
    """An effect only changes what it acts on: lever arm at rest changes nothing."""
    off, on = _pair(Effects(lever_arm=30.0))
    rest = _segments(off.session, Kind.REST)[0]
    np.testing.assert_array_equal(off.session.accel_mps2[rest], on.session.accel_mps2[rest])
    np.testing.assert_array_equal(off.session.gyro_radps, on.session.gyro_radps)
    np.testing.assert_array_equal(off.session.ref_accel_mps2, on.session.ref_accel_mps2)


def test_lever_arm_gives_centripetal_acceleration() -> None:
    off, on = _pair(Effects(lever_arm=30.0))
    r = on.effect_truth.lever_arm_m
    m = on.truth.accel.misalignment
    s = on.session
    for sl in _segments(s, Kind.RATE):
        w = s.ref_gyro_radps[sl][0]
        assert abs(w[0]) == pytest.approx(200 * DEG)
        diff = (s.accel_mps2[sl] - off.session.accel_mps2[sl]).mean(axis=0)
        centripetal = np.cross(w, np.cross(w, r))
        np.testing.assert_allclose(diff, m @ centripetal, atol=3e-4)
        r_perp = math.hypot(r[1], r[2])
        assert np.linalg.norm(centripetal) == pytest.approx(w[0] ** 2 * r_perp)
    # ~0.37 m/s^2 for the full 30 mm perpendicular to the axis at 200 deg/s
    assert pytest.approx(0.3655, abs=1e-3) == (200 * DEG) ** 2 * 0.030


def test_earth_rotation_components() -> None:
    plan = replace(SHORT, latitude_deg=52.6, heading_deg=0.0)
    off, on = _pair(Effects(earth_rotation=1.0), plan=plan)
    rest = _segments(on.session, Kind.REST)[0]  # +z up, table at yaw 0: world = sensor frame
    diff = (on.session.gyro_radps[rest] - off.session.gyro_radps[rest]).mean(axis=0)
    lat = math.radians(52.6)
    earth = EARTH_RATE_RADPS * np.array([0.0, math.cos(lat), math.sin(lat)])
    np.testing.assert_allclose(diff, on.truth.gyro.misalignment @ earth, atol=2e-4 * DEG)
    assert np.linalg.norm(earth) / DEG * 3600 == pytest.approx(15.041, abs=0.001)
    # heading 90 deg: the rig's x axis points south, so north is -x
    plan90 = replace(plan, heading_deg=90.0)
    off90, on90 = _pair(Effects(earth_rotation=1.0), plan=plan90)
    d90 = (on90.session.gyro_radps[rest] - off90.session.gyro_radps[rest]).mean(axis=0)
    earth90 = EARTH_RATE_RADPS * np.array([-math.cos(lat), 0.0, math.sin(lat)])
    np.testing.assert_allclose(d90, on90.truth.gyro.misalignment @ earth90, atol=2e-4 * DEG)
    # the rig's reference does not know the Earth rate
    np.testing.assert_array_equal(on.session.ref_gyro_radps, off.session.ref_gyro_radps)


def test_time_offset_shifts_motion_edges() -> None:
    off, on = _pair(Effects(time_offset=50.0), noiseless=True)
    s = on.session
    move = _segments(s, Kind.MOVE)[0]

    def edge(session: Session) -> int:
        w = session.gyro_radps[move]
        return int(np.argmax(np.abs(w - w[0]).max(axis=1) > 1 * DEG))

    assert edge(on.session) - edge(off.session) == 5  # 50 ms at 100 Hz
    # the reference stays on rig time
    np.testing.assert_array_equal(on.session.ref_gyro_radps, off.session.ref_gyro_radps)
    # and the sensor matches the rig's motion 50 ms earlier
    kin = on.trajectory.kinematics(s.t_s[move] - 0.05)
    expected = kin.omega_radps @ on.truth.gyro.misalignment.T + on.truth.gyro.bias_at(s.t_s[move])
    np.testing.assert_allclose(s.gyro_radps[move], expected, atol=0.51 * on.truth.gyro.lsb + 1e-12)


def test_temperature_bias_follows_temperature() -> None:
    off, on = _pair(Effects(temperature_bias=0.01), plan=RigPlan(rate_steps=()))
    temp = on.session.temp_degc
    d_temp = temp - on.environment.ambient_degc
    et = on.effect_truth
    for sensor, coef in (("accel_mps2", et.accel_temp_bias), ("gyro_radps", et.gyro_temp_bias)):
        diff = getattr(on.session, sensor) - getattr(off.session, sensor)
        for k in range(3):
            slope = np.polyfit(d_temp, diff[:, k], 1)[0]
            assert slope == pytest.approx(coef[k], rel=0.03)
            assert np.corrcoef(temp, diff[:, k])[0, 1] * np.sign(coef[k]) > 0.9
    assert np.abs(et.accel_temp_bias).max() <= 0.01
    assert temp[-1] - temp[0] > 2.0  # self-heating gave it something to act on


def test_temperature_scale() -> None:
    off, on = _pair(Effects(temperature_scale=2000.0), plan=RigPlan(rest_s=600.0, rate_steps=()))
    s = on.session
    true_temp = ImuModel(on.truth, environment=on.environment).true_temperature(s.t_s)
    d_temp = true_temp - on.environment.ambient_degc
    sc = on.effect_truth.accel_temp_scale
    for sl in _segments(s, Kind.POSE):
        u = on.truth.accel.misalignment @ s.ref_accel_mps2[sl][0]
        expected = (sc * d_temp[sl, None] * u).mean(axis=0)
        diff = (s.accel_mps2[sl] - off.session.accel_mps2[sl]).mean(axis=0)
        np.testing.assert_allclose(diff, expected, atol=2e-4)


def test_g_sensitivity() -> None:
    off, on = _pair(Effects(g_sensitivity=0.2))
    s = on.session
    big = on.effect_truth.g_sensitivity
    for sl in _segments(s, Kind.REST) + _segments(s, Kind.POSE):
        diff = (s.gyro_radps[sl] - off.session.gyro_radps[sl]).mean(axis=0)
        np.testing.assert_allclose(diff, big @ s.ref_accel_mps2[sl][0], atol=3e-4 * DEG)
    assert np.abs(big @ np.array([0, 0, STANDARD_GRAVITY])).max() / DEG <= 0.2 + 1e-12


def test_scale_nonlinearity_and_asymmetry() -> None:
    off, on = _pair(Effects(scale_nonlinearity=0.01))
    off2, asym = _pair(Effects(scale_asymmetry=0.01))
    k = on.effect_truth.gyro_nonlinearity[0]
    a = asym.effect_truth.gyro_asymmetry[0]
    m = on.truth.gyro.misalignment
    for sl in _segments(on.session, Kind.RATE):
        u = (m @ on.session.ref_gyro_radps[sl][0])[0]
        d_nl = (on.session.gyro_radps[sl, 0] - off.session.gyro_radps[sl, 0]).mean()
        assert d_nl == pytest.approx(k * u * abs(u), abs=2e-4 * DEG)
        # relative error k|u|: at 200 deg/s the effect value times the unit's shape
        assert abs(d_nl / u) == pytest.approx(abs(k) * abs(u), rel=0.01)
        d_as = (asym.session.gyro_radps[sl, 0] - off2.session.gyro_radps[sl, 0]).mean()
        assert d_as == pytest.approx(0.5 * a * abs(u), abs=2e-4 * DEG)
    assert abs(k) * 200 * DEG == pytest.approx(0.01 * abs(on.truth.shapes.gyro_nonlinearity[0]))


def test_bias_random_walk_grows_with_sqrt_time() -> None:
    off, on = _pair(Effects(bias_random_walk=5e-3), plan=RigPlan(rest_s=900.0, poses=(), rate_steps=()))
    et = on.effect_truth
    for sensor, k in (("accel_mps2", et.accel_random_walk), ("gyro_radps", et.gyro_random_walk)):
        walk = getattr(on.session, sensor) - getattr(off.session, sensor)
        steps = walk[::1000][1:] - walk[::1000][:-1]  # increments over 10 s
        assert steps.std() == pytest.approx(k * math.sqrt(10.0), rel=0.15)
        assert abs(walk[0]).max() <= 0.51 * (on.truth.accel.lsb if sensor == "accel_mps2" else on.truth.gyro.lsb)
    assert et.gyro_random_walk == pytest.approx(5e-3 * GYRO_PER_ACCEL * DEG)


def test_extra_outliers() -> None:
    off, on = _pair(Effects(outliers=0.01))
    n = len(on.session)
    for sensor in ("accel_mps2", "gyro_radps"):
        changed = (getattr(on.session, sensor) != getattr(off.session, sensor)).sum()
        expected = 0.01 * 3 * n
        assert abs(changed - expected) < 5 * math.sqrt(expected)
    gyro_jump = np.abs(on.session.gyro_radps - off.session.gyro_radps).max(axis=None)
    assert gyro_jump <= 1.5 * 8.0 * on.truth.gyro.noise_std.max() + on.truth.gyro.lsb


def test_custom_sensor_class_changes_the_draw() -> None:
    tight = SensorClass(name="tight", accel_bias_static_mps2=(0.01, 0.011))
    u = draw_unit(tight, np.random.default_rng(0))
    assert np.all((u.accel.bias_static >= 0.01) & (u.accel.bias_static <= 0.011))
