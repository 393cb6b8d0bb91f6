"""Capture quality gates: is one unit's capture of one step good enough to fit?

Each gate measures one value of the samples captured in a step window and
compares it with its limits (:class:`~station.sequence.options.SequenceOptions`):

* ``sample_fraction``: received / expected samples (the link delivered the window);
* ``dropped_fraction``: frames lost to sequence-counter gaps inside the window;
* ``stillness_gyro`` / ``stillness_accel``: rest and poses, the largest per-axis std of
  the linearly detrended samples (a slow drift, eq. 3, is not motion);
* ``gravity_ratio``: rest and poses, ``|mean specific force| / g``;
* ``rate_error`` / ``rate_steadiness``: rate steps, the mean gyro rate about the commanded
  axis minus the command, and its detrended std.

and the station's own timing and the rig's own report of the window (:func:`timing_gates`, :func:`rig_gate`):

* ``sensor_clock_rate``: station clock seconds per sensor second from the run's first clock sync to the
  one after the window (the sensor's sample time base against the station clock; 1 when both keep time);
* ``frame_lateness``: how far (station s) the stream ran behind the station clock when the sample that
  closes the window arrived (the station or the link did not keep up; the clock sync that placed the
  window queued behind those frames);
* ``rig_settled_fraction``: the fraction of the rig's own readings from its confirmation to the end of the capture
  that reported the step's pose and table rate settled (status bits and readbacks).

A failed link or timing gate (sample count, dropped frames, clock rate, late frames, a rig that did
not report itself settled) is a station fault: ERROR, which the retest policy does not count. A failed
physics gate (stillness, gravity, rate) says the unit measures nonsense in a step the rig confirmed: the
unit FAILs. Every gate is a :class:`~station.kernel.measurement.Measurement` (``link`` set for the
station's gates). Units: m/s^2, rad/s, s, 1.
"""

from __future__ import annotations

import math

import numpy as np

from station.kernel.geometry import AXIS_INDEX, POSE_ANGLES_DEG
from station.kernel.measurement import Measurement
from station.rig.protocol import RigState
from station.rig.registers import angle_error_deg
from station.sensor.protocol import SampleBlock
from station.sequence.options import SequenceOptions
from station.session.model import Kind

SEQ_MODULUS = 1 << 16


def detrended_std(t_s: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Per-column std of ``x`` (n, k) about its least-squares line in ``t_s`` (same unit as ``x``)."""
    if len(t_s) < 3:
        return np.full(x.shape[1], np.nan)
    tc = t_s - t_s.mean()
    xc = x - x.mean(axis=0)
    denom = float(tc @ tc)
    slope = (tc @ xc) / denom if denom > 0 else np.zeros(x.shape[1])
    return (xc - np.outer(tc, slope)).std(axis=0)


def dropped_frames(seq: np.ndarray) -> int:
    """Frames missing between consecutive sequence numbers (u16, wrapping)."""
    if len(seq) < 2:
        return 0
    d = np.mod(np.diff(seq.astype(np.int64)), SEQ_MODULUS)
    return int(np.sum(np.where(d > 0, d - 1, 0)))


def link_gates(block: SampleBlock, t0_s: float, t1_s: float, rate_hz: float, opt: SequenceOptions) -> list[Measurement]:
    """Sample count and dropped frames of the window [t0_s, t1_s) (sensor time, s)."""
    expected = max(math.floor((t1_s - t0_s) * rate_hz + 1e-6), 1)
    n = len(block)
    return [
        Measurement.in_range("sample_fraction", n / expected, opt.min_sample_fraction, math.inf, "1", link=True),
        Measurement.in_range("dropped_fraction", dropped_frames(block.seq) / expected, 0.0, opt.max_dropped_fraction,
                             "1", link=True),
    ]


def still_gates(block: SampleBlock, gravity_mps2: float, opt: SequenceOptions) -> list[Measurement]:
    """Stillness and gravity magnitude of a rest or pose window."""
    if len(block) < 3:
        return []
    g_std = float(np.max(detrended_std(block.t_s, block.gyro_radps)))
    a_std = float(np.max(detrended_std(block.t_s, block.accel_mps2)))
    ratio = float(np.linalg.norm(block.accel_mps2.mean(axis=0)) / gravity_mps2)
    return [
        Measurement.in_range("stillness_gyro", g_std, 0.0, opt.stillness_gyro_radps, "rad/s"),
        Measurement.in_range("stillness_accel", a_std, 0.0, opt.stillness_accel_mps2, "m/s^2"),
        Measurement.in_range("gravity_ratio", ratio, 1.0 - opt.gravity_tolerance, 1.0 + opt.gravity_tolerance, "1"),
    ]


def rate_gates(block: SampleBlock, axis: str, rate_radps: float, opt: SequenceOptions) -> list[Measurement]:
    """Mean rate error and steadiness about the commanded axis of a rate-step window."""
    if len(block) < 3:
        return []
    w = block.gyro_radps[:, AXIS_INDEX[axis]]
    tol = opt.rate_tolerance * abs(rate_radps) + opt.rate_offset_radps
    steady = float(detrended_std(block.t_s, w[:, None])[0])
    return [
        Measurement.in_range("rate_error", float(w.mean()) - rate_radps, -tol, tol, "rad/s"),
        Measurement.in_range("rate_steadiness", steady, 0.0, opt.rate_steadiness_radps, "rad/s"),
    ]


def evaluate(
    block: SampleBlock,
    kind: Kind,
    t0_s: float,
    t1_s: float,
    rate_hz: float,
    gravity_mps2: float,
    opt: SequenceOptions,
    rate_axis: str | None = None,
    rate_radps: float = 0.0,
) -> list[Measurement]:
    """Every gate that applies to a window of ``kind``: link gates first, then physics gates."""
    out = link_gates(block, t0_s, t1_s, rate_hz, opt)
    if kind in (Kind.REST, Kind.POSE):
        out += still_gates(block, gravity_mps2, opt)
    elif kind == Kind.RATE and rate_axis is not None:
        out += rate_gates(block, rate_axis, rate_radps, opt)
    return out


def clock_rate_gate(first: tuple[float, float, float], last: tuple[float, float, float],
                    opt: SequenceOptions) -> Measurement | None:
    """``sensor_clock_rate``: station seconds per sensor second between two clock syncs.

    ``first``, ``last``: (station time s, sensor time s, half round trip s) of the run's first sync and of
    this step's. The limits are ``1 +- max_clock_rate_error`` widened by what the two syncs cannot resolve
    (their half round trips over the sensor time between them). None while the syncs are less than
    ``clock_check_min_s`` of sensor time apart (nothing to judge yet).
    """
    d_sensor = last[1] - first[1]
    if not d_sensor >= opt.clock_check_min_s:
        return None
    ratio = (last[0] - first[0]) / d_sensor
    slack = opt.max_clock_rate_error + (first[2] + last[2]) / d_sensor
    return Measurement.in_range("sensor_clock_rate", ratio, 1.0 - slack, 1.0 + slack, "1", link=True)


def frame_lateness_gate(lateness_s: float, allowance_s: float, opt: SequenceOptions) -> Measurement:
    """``frame_lateness`` (station s): how far behind the station clock the stream was when the window's closing
    sample arrived; at most ``max_frame_lateness_s`` plus ``allowance_s`` (the capture passes twice the silence
    the station tolerates from a stream anyway, ``2 silence_floor_wall_s`` wall seconds on the station clock, so
    that a loaded host that merely polls late is not a fault)."""
    return Measurement.in_range("frame_lateness", lateness_s, -math.inf, opt.max_frame_lateness_s + allowance_s, "s",
                                link=True)


def settled_at(st: RigState, pose: str, table_rate_dps: float, opt: SequenceOptions) -> bool:
    """Whether a rig reading reports the step's pose in position and its table rate settled (status bits and
    readbacks within the capture tolerances)."""
    roll, pitch = POSE_ANGLES_DEG[pose]
    return (st.in_position and st.rate_settled and not st.fault
            and abs(angle_error_deg(st.roll_deg, roll)) <= opt.angle_tol_deg
            and abs(angle_error_deg(st.pitch_deg, pitch)) <= opt.angle_tol_deg
            and abs(st.rate_dps - table_rate_dps) <= opt.rate_tol_dps)


def rig_gate(readings: list[RigState], pose: str, table_rate_dps: float, opt: SequenceOptions) -> Measurement | None:
    """``rig_settled_fraction``: the fraction of the rig's readings during a capture that reported the step settled
    (:func:`settled_at`); must be 1. None without readings."""
    if not readings:
        return None
    ok = sum(settled_at(st, pose, table_rate_dps, opt) for st in readings)
    return Measurement.in_range("rig_settled_fraction", ok / len(readings), 1.0, 1.0, "1", link=True)


_WHY = {
    "sensor_clock_rate": "the station clock and the sensor's sample time base run at different rates",
    "frame_lateness": "the stream ran behind the station clock (the station or the link did not keep up)",
    "rig_settled_fraction": "the rig did not report the step's pose and table rate settled throughout the capture",
}


def station_fault_text(gate: Measurement) -> str:
    """A failed station gate for people: what it measured, and what that means where it is not obvious."""
    why = _WHY.get(gate.name)
    return gate.describe() if why is None else f"{why}: {gate.describe()}"
