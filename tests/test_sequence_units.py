"""The sequence's pure parts, without peers: plan steps, capture gates, session assembly, limits, outcomes."""

from __future__ import annotations

import math
import threading
from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pytest

from station.kernel.clock import SimClock
from station.kernel.limits import table1_limits
from station.kernel.plan import RigPlan, default_plan
from station.kernel.sensor_class import TABLE1
from station.physics.unit import draw_unit
from station.rig import rig_client_options
from station.sensor.client import SampleBlock, SensorTimeout
from station.sequence.capture import UnitChannel, Window, build_session
from station.sequence.gates import detrended_std, dropped_frames, evaluate, link_gates, rate_gates, still_gates
from station.sequence.limits import check_limits
from station.sequence.options import SequenceOptions
from station.sequence.records import Outcome, worst
from station.sequence.steps import plan_steps
from station.session.model import Kind

G = 9.8128
OPT = SequenceOptions()


def block(t: np.ndarray, accel: np.ndarray, gyro: np.ndarray, seq: np.ndarray | None = None) -> SampleBlock:
    n = len(t)
    s = np.arange(n, dtype=np.uint16) if seq is None else seq.astype(np.uint16)
    return SampleBlock(s, t, accel, gyro, np.full(n, 25.0), np.zeros(n, np.uint8))


def still(n: int = 1000, rate: float = 100.0, up: int = 2, noise: float = 0.02, seed: int = 0) -> SampleBlock:
    rng = np.random.default_rng(seed)
    t = 1.0 + np.arange(n) / rate
    a = noise * rng.standard_normal((n, 3))
    a[:, up] += G
    w = 2e-4 * rng.standard_normal((n, 3))
    return block(t, a, w)


# --- plan -> steps ---------------------------------------------------------------------------------


def test_default_plan_steps() -> None:
    steps = plan_steps(default_plan())
    assert len(steps) == 1 + 6 + 18
    assert steps[0].name == "rest" and steps[0].kind == Kind.REST and steps[0].hold_s == 300.0
    assert [s.name for s in steps[1:7]] == ["pose +z", "pose -z", "pose +x", "pose -x", "pose +y", "pose -y"]
    rate = steps[7]
    got = (rate.name, rate.pose, rate.table_rate_dps, rate.rate_axis, rate.hold_s)
    assert got == ("rate x +50", "+x", 50.0, "x", 12.0)
    f, w = rate.reference(G)
    np.testing.assert_allclose(f, [G, 0, 0])
    np.testing.assert_allclose(w, [math.radians(50.0), 0, 0])


def test_flipped_rate_axis_spins_upside_down() -> None:
    steps = plan_steps(RigPlan(rate_steps=(("y", 100.0),), rate_flip=("y",)))
    rate = steps[-1]
    assert rate.pose == "-y" and rate.table_rate_dps == -100.0 and rate.rate_dps == 100.0
    f, w = rate.reference(G)
    np.testing.assert_allclose(f, [0, -G, 0])
    np.testing.assert_allclose(w, [0, math.radians(100.0), 0])


# --- gates -----------------------------------------------------------------------------------------------


def test_detrended_std_ignores_a_drift() -> None:
    t = np.linspace(0.0, 10.0, 1001)
    x = np.column_stack([3.0 + 0.5 * t, np.sin(40 * t)])
    s = detrended_std(t, x)
    assert s[0] == pytest.approx(0.0, abs=1e-12)
    assert s[1] == pytest.approx(np.sqrt(0.5), rel=0.02)


def test_dropped_frames_counts_gaps_across_the_wrap() -> None:
    assert dropped_frames(np.array([65533, 65534, 65535, 0, 1], dtype=np.uint16)) == 0
    assert dropped_frames(np.array([65534, 1, 2, 5], dtype=np.uint16)) == 2 + 2


def test_link_gates() -> None:
    b = still(1000)
    assert all(g.passed for g in link_gates(b, 1.0, 11.0, 100.0, OPT))
    keep = np.ones(1000, bool)
    keep[500:520] = False
    short = SampleBlock(*(getattr(b, n)[keep] for n in SampleBlock.__dataclass_fields__))  # type: ignore[arg-type]
    sample, dropped = link_gates(short, 1.0, 11.0, 100.0, OPT)
    assert not sample.passed and sample.value == pytest.approx(0.98)
    assert not dropped.passed and dropped.value == pytest.approx(0.02) and dropped.link


def test_still_gates_pass_still_and_fail_moving_or_wrong_gravity() -> None:
    assert all(g.passed for g in still_gates(still(), G, OPT))
    b = still()
    shaking = replace(b, gyro_radps=b.gyro_radps + 0.05 * np.sin(30 * b.t_s)[:, None])
    names = {g.name for g in still_gates(shaking, G, OPT) if not g.passed}
    assert names == {"stillness_gyro"}
    half_g = replace(b, accel_mps2=0.5 * b.accel_mps2)
    bad = [g for g in still_gates(half_g, G, OPT) if not g.passed]
    assert [g.name for g in bad] == ["gravity_ratio"] and bad[0].value == pytest.approx(0.5, abs=0.01)
    assert not bad[0].link


def test_rate_gates() -> None:
    b = still()
    w = np.radians(100.0)
    spinning = replace(b, gyro_radps=b.gyro_radps + np.array([0.0, 0.0, 1.01 * w]))
    assert all(g.passed for g in rate_gates(spinning, "z", w, OPT))
    wrong_axis = [g for g in rate_gates(spinning, "x", w, OPT) if not g.passed]
    assert [g.name for g in wrong_axis] == ["rate_error"]
    kinds = {g.name for g in evaluate(spinning, Kind.RATE, 1.0, 11.0, 100.0, G, OPT, "z", w)}
    assert kinds == {"sample_fraction", "dropped_fraction", "rate_error", "rate_steadiness"}


# --- session assembly ------------------------------------------------------------------------------------


class FakeSensor:
    """Hands out prepared blocks on drain(), reports sensor uptime = clock - 100 s on status()."""

    def __init__(self, blocks: list[SampleBlock], clock: SimClock) -> None:
        self.blocks = list(blocks)
        self.clock = clock

    def drain(self) -> SampleBlock:
        return self.blocks.pop(0) if self.blocks else SampleBlock.empty()

    def status(self) -> SimpleNamespace:
        return SimpleNamespace(uptime_s=self.clock.now() - 100.0)


def test_sync_measures_the_sensor_clock_offset() -> None:
    clock = SimClock(1.0, start=500.0)
    ch = UnitChannel(0, "fake", FakeSensor([], clock), clock)  # type: ignore[arg-type]
    assert ch.sync(3) == pytest.approx(100.0, abs=1e-3)


class LateReplySensor(FakeSensor):
    """Reads its clock at once, but the reply arrives ``delay_s`` later (queued behind streamed frames)."""

    def __init__(self, clock: SimClock, delay_s: float) -> None:
        super().__init__([], clock)
        self.delay_s = delay_s

    def status(self) -> SimpleNamespace:
        reply = super().status()
        self.clock.sleep(self.delay_s)
        return reply


def test_window_start_bound_holds_for_a_one_sided_round_trip() -> None:
    clock = SimClock(1000.0, start=500.0)
    ch = UnitChannel(0, "fake", LateReplySensor(clock, 2.0), clock)  # type: ignore[arg-type]
    ch.sync(3)
    # the midpoint estimate is off by half the trip; the bound is not early
    assert ch.offset_s is not None and abs(ch.offset_s - 100.0) > 0.9
    t_station = clock.now()
    truth = t_station - 100.0
    assert truth <= ch.latest_sensor_time(t_station) <= truth + 2.0 * ch.sync_halfwidth_s + 1e-6


def test_collect_until_and_silence() -> None:
    clock = SimClock(1.0)
    b = still(1000)
    first, second = b.split(600)
    ch = UnitChannel(0, "fake", FakeSensor([first, second], clock), clock)  # type: ignore[arg-type]
    stop = threading.Event()
    ch.collect_until(5.0, stop, 0.5)
    assert ch.t_first_s == 1.0 and ch.t_last_s >= 5.0
    ch.collect_until(10.99, stop, 0.5)
    assert len(ch.window_samples(2.0, 3.0)) == 100
    with pytest.raises(SensorTimeout, match="went silent"):
        ch.collect_until(20.0, stop, 0.05)


def test_build_session_labels_windows_and_moves() -> None:
    clock = SimClock(1.0)
    ch = UnitChannel(3, "fake", FakeSensor([still(1000)], clock), clock)  # type: ignore[arg-type]
    ch.rate_hz = 100
    ch.collect_until(10.0, threading.Event(), 0.5)
    up = np.array([0.0, 0.0, G])
    ch.windows = [
        Window("rest", Kind.REST, 1.0, 4.0, up, np.zeros(3)),
        Window("pose +z", Kind.POSE, 4.0, 5.0, up, np.zeros(3)),  # continues without a move
        Window("rate z +10", Kind.RATE, 6.5, 8.0, up, np.array([0, 0, math.radians(10.0)])),
    ]
    s = build_session(ch, G, {"station": "test"})
    assert s is not None
    assert s.serial == "slot3" and s.sample_rate_hz == 100.0 and s.metadata["station"] == "test"
    segs = [(seg.index, seg.kind, len(seg)) for seg in s.segments()]
    assert segs == [(0, Kind.REST, 300), (1, Kind.POSE, 100), (2, Kind.MOVE, 150), (3, Kind.RATE, 150),
                    (4, Kind.MOVE, 300)]
    assert np.isnan(s.ref_gyro_radps[s.segments()[2].start]).all()
    np.testing.assert_allclose(s.ref_gyro_radps[s.segments()[3].start], [0, 0, math.radians(10.0)])


# --- limits and outcomes -----------------------------------------------------------------------------------


def test_table1_truth_passes_and_an_outlier_fails() -> None:
    truth = draw_unit(TABLE1, np.random.default_rng(4))
    params = truth.as_parameter_set(0.01)
    checks = check_limits(params, table1_limits())
    assert checks and all(c.passed for c in checks)
    names = {c.name for c in checks}
    assert "accel.M.xy" in names and "gyro.bias_static.z" in names
    assert not any("correlation_time" in n for n in names)  # not checked by default
    assert any("correlation_time" in c.name for c in check_limits(params, table1_limits(check_correlation_time=True)))
    bad = replace(params, gyro=replace(params.gyro, bias_static=np.array([0.0, 0.0, math.radians(5.0)])))
    failed = [c for c in check_limits(bad, table1_limits()) if not c.passed]
    assert [c.name for c in failed] == ["gyro.bias_static.z"]
    # widened by k standard uncertainties
    unsure = replace(bad, gyro=replace(bad.gyro, bias_static_std=np.full(3, math.radians(1.0))))
    assert all(c.passed for c in check_limits(unsure, table1_limits()))


def test_worst_outcome_order() -> None:
    assert worst([]) == Outcome.PASS
    assert worst([Outcome.PASS, Outcome.FAIL]) == Outcome.FAIL
    assert worst([Outcome.ERROR, Outcome.FAIL, Outcome.PASS]) == Outcome.ERROR
    assert worst([Outcome.ERROR, Outcome.ABORTED]) == Outcome.ABORTED


def test_rig_client_options_scale() -> None:
    assert rig_client_options(1.0) == {
        "poll_s": 0.1, "heartbeat_period_s": 0.5, "ack_timeout_s": 2.0, "alive_timeout_s": 2.0, "watchdog_s": 2.0
    }
    fast = rig_client_options(100.0)
    assert fast["watchdog_s"] == 60.0 and fast["heartbeat_period_s"] == 4.0
    assert SequenceOptions().for_scale(100.0).supervise_period_s == 5.0
