"""The trajectory a rig plan drives: the three axis motions and the segment table.

:func:`build_trajectory` turns a :class:`~station.kernel.plan.RigPlan` into the three axis
trajectories (roll, pitch, yaw; :mod:`station.physics.motion`) and a segment table with
the rig's reference (spec session-csv-v1: what the rig knows). Angles in rad, rates in
rad/s, accelerations in rad/s^2 inside the trajectory.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field, replace

import numpy as np

from station.kernel.geometry import (
    AXIS_INDEX,
    POSE_ANGLES_DEG,
    Kinematics,
    kinematics_from_angles,
    rotation_vector_matrix,
    up_vector,
)
from station.kernel.plan import PlanError, RigPlan
from station.physics.motion import AxisTrajectory
from station.session.model import Kind

_DEG = math.pi / 180.0


@dataclass(frozen=True)
class PlanSegment:
    """One rig step: a segment of the session.

    Attributes:
        index: segment number (the CSV ``segment`` column).
        kind: rest, pose, rate or move.
        t_start_s, t_stop_s: rig time range [start, stop) (s).
        up: for rest/pose/rate, the pose whose axis points up ('+x', ...); None for moves.
        rate_axis: for rate, the nominal sensor axis 'x'|'y'|'z'; else None.
        rate_dps: for rate, the commanded rate about ``+rate_axis`` (deg/s); else 0.
    """

    index: int
    kind: Kind
    t_start_s: float
    t_stop_s: float
    up: str | None = None
    rate_axis: str | None = None
    rate_dps: float = 0.0


@dataclass(frozen=True, eq=False)
class RigTrajectory:
    """The rig's axes over time and its segment table; evaluate it at sample times."""

    plan: RigPlan
    roll: AxisTrajectory = field(repr=False)
    pitch: AxisTrajectory = field(repr=False)
    yaw: AxisTrajectory = field(repr=False)
    segments: tuple[PlanSegment, ...]
    duration_s: float

    def sample_times(self) -> np.ndarray:
        """Sample times ``k / sample_rate_hz`` from 0 (power-on) up to the end of the plan (s)."""
        fs = self.plan.sample_rate_hz
        n = math.floor(self.duration_s * fs - 1e-9) + 1
        return np.arange(n) / fs

    def axis_states(self, t_rig_s: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(angle rad, rate rad/s, accel rad/s^2), each (n, 3) with columns roll, pitch, yaw."""
        t = np.asarray(t_rig_s, dtype=float)
        states = [ax.state(t) for ax in (self.roll, self.pitch, self.yaw)]
        angle, rate, accel = (np.stack([s[i] for s in states], axis=1) for i in range(3))
        return angle, rate, accel

    def kinematics(
        self, t_s: np.ndarray, time_offset_s: float = 0.0, pose_tilt_rad: Mapping[str, np.ndarray] | None = None,
        rest_tilt: tuple[np.ndarray, float] | None = None,
    ) -> Kinematics:
        """Sensor kinematics at rig time ``t_s - time_offset_s``, stamped with ``t_s`` (sensor time).

        ``pose_tilt_rad`` (the ``pose_tilt`` effect, :meth:`station.physics.effects.EffectTruth.pose_tilts`):
        pose name -> rotation vector ``phi`` (rad, sensor frame); in every ``pose`` segment of that
        pose the sensor's attitude is ``R exp([phi]x)`` instead of the commanded ``R`` (the rig
        stands still there, so body rate and angular acceleration stay as commanded: zero). Rest,
        rate and move segments keep the commanded attitude. Without tilts (None or all zero) the
        result is the commanded kinematics, bit for bit.

        ``rest_tilt`` = ``(phi, until_s)``: the same for the ``rest`` segments' samples before rig time
        ``until_s`` (a unit held still somewhere other than the rig, e.g. a soak rack's slot that is not level).
        """
        t = np.asarray(t_s, dtype=float)
        angle, rate, accel = self.axis_states(t - time_offset_s)
        kin = kinematics_from_angles(t, angle, rate, accel)
        tilts = {p: np.asarray(v, dtype=float) for p, v in (pose_tilt_rad or {}).items() if np.any(v)}
        rest_phi = None if rest_tilt is None or not np.any(rest_tilt[0]) else np.asarray(rest_tilt[0], dtype=float)
        if not tilts and rest_phi is None:
            return kin
        idx = self.segment_of(t - time_offset_s)
        rotation = kin.rotation.copy()
        if rest_tilt is not None and rest_phi is not None:
            kinds = np.array([int(s.kind) for s in self.segments])[idx]
            sel = (kinds == int(Kind.REST)) & (t - time_offset_s < float(rest_tilt[1]))
            rotation[sel] = rotation[sel] @ rotation_vector_matrix(rest_phi)
        for i, seg in enumerate(self.segments):
            if seg.kind != Kind.POSE or seg.up not in tilts:
                continue
            sel = idx == i
            if np.any(sel):
                rotation[sel] = rotation[sel] @ rotation_vector_matrix(tilts[seg.up])
        return replace(kin, rotation=rotation)

    def segment_of(self, t_s: np.ndarray) -> np.ndarray:
        """Index into :attr:`segments` of each time (rig time, s); the last segment extends to the end."""
        starts = np.array([s.t_start_s for s in self.segments])
        return np.clip(np.searchsorted(starts, np.asarray(t_s, dtype=float), side="right") - 1, 0, len(starts) - 1)

    def labels(self, t_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(segment index, :class:`Kind` code) per time: the CSV ``segment`` and ``kind`` columns."""
        idx = self.segment_of(t_s)
        seg_index = np.array([s.index for s in self.segments], dtype=np.int64)
        kinds = np.array([int(s.kind) for s in self.segments], dtype=np.int8)
        return seg_index[idx], kinds[idx]

    def reference(self, t_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """What the rig knows at rig time ``t_s``: (specific force m/s^2, angular rate rad/s), (n, 3) each.

        rest/pose: gravity times the commanded up axis, zero rate; rate: gravity times the
        up axis and the commanded rate about the nominal axis; move: from the rig's encoders
        (up vector and body rates of the gimbal and table angles). No centripetal, Earth rate
        or other physics the rig does not know.
        """
        t = np.asarray(t_s, dtype=float)
        g = self.plan.gravity_mps2
        idx = self.segment_of(t)
        ref_f = np.empty((len(t), 3))
        ref_w = np.zeros((len(t), 3))
        kinds = np.array([int(s.kind) for s in self.segments])[idx]
        moving = kinds == int(Kind.MOVE)
        if np.any(moving):
            enc = self.kinematics(t[moving])
            ref_f[moving] = enc.specific_force(g)
            ref_w[moving] = enc.omega_radps
        for i, seg in enumerate(self.segments):
            if seg.kind == Kind.MOVE:
                continue
            sel = idx == i
            if not np.any(sel):
                continue
            assert seg.up is not None  # every segment but a move has a pose
            ref_f[sel] = g * up_vector(seg.up)
            if seg.kind == Kind.RATE:
                assert seg.rate_axis is not None  # a rate segment has its axis
                w = np.zeros(3)
                w[AXIS_INDEX[seg.rate_axis]] = seg.rate_dps * _DEG
                ref_w[sel] = w
        return ref_f, ref_w


class _Builder:
    """Drives the three axes in lockstep and records the segment table."""

    def __init__(self, plan: RigPlan) -> None:
        self.plan = plan
        roll0, pitch0 = POSE_ANGLES_DEG[plan.rest_pose]
        self.axes = (
            AxisTrajectory(p0=roll0 * _DEG),
            AxisTrajectory(p0=pitch0 * _DEG),
            AxisTrajectory(p0=0.0),
        )
        self.t = 0.0
        self.pose = plan.rest_pose
        self.table_rate = 0.0  # rad/s
        self.segments: list[PlanSegment] = []
        self._move_start: float | None = None

    def _sync(self, t_end: float) -> None:
        for ax in self.axes:
            ax.hold_until(t_end)
        self.t = t_end

    def _begin_move(self) -> None:
        if self._move_start is None:
            self._move_start = self.t

    def _end_move(self) -> None:
        if self._move_start is not None and self.t > self._move_start:
            self._add(Kind.MOVE, self._move_start, self.t)
        self._move_start = None

    def _add(self, kind: Kind, t0: float, t1: float, *, up: str | None = None, rate_axis: str | None = None,
             rate_dps: float = 0.0) -> None:
        self.segments.append(PlanSegment(len(self.segments), kind, t0, t1, up=up, rate_axis=rate_axis,
                                         rate_dps=rate_dps))

    def hold(self, kind: Kind, duration: float, *, up: str | None = None, rate_axis: str | None = None,
             rate_dps: float = 0.0) -> None:
        self._end_move()
        if duration <= 0:
            return
        t0 = self.t
        self._sync(t0 + duration)
        self._add(kind, t0, self.t, up=up, rate_axis=rate_axis, rate_dps=rate_dps)

    def tumble(self, pose: str) -> None:
        """Move the gimbal (roll, pitch) to ``pose``, then settle; the table must be still."""
        if pose == self.pose:
            return
        self._begin_move()
        p = self.plan
        roll, pitch = POSE_ANGLES_DEG[pose]
        rate, acc = p.tumble_rate_dps * _DEG, p.tumble_accel_dps2 * _DEG
        d_roll = self.axes[0].move_to(roll * _DEG, rate, acc)
        d_pitch = self.axes[1].move_to(pitch * _DEG, rate, acc)
        self._sync(self.t + max(d_roll, d_pitch) + p.settle_s)
        self.pose = pose

    def ramp(self, rate_radps: float) -> None:
        """Ramp the table to ``rate_radps``, then settle."""
        if rate_radps == self.table_rate:
            return
        self._begin_move()
        duration = self.axes[2].ramp_rate(rate_radps, self.plan.table_accel_dps2 * _DEG)
        self.table_rate = rate_radps
        self._sync(self.t + duration + self.plan.settle_s)


def _plan_block(b: _Builder, plan: RigPlan, rest_s: float) -> None:
    """The rest (``rest_s``, in the rest pose), the poses and the rate steps of ``plan``."""
    b.ramp(0.0)
    b.tumble(plan.rest_pose)
    b.hold(Kind.REST, rest_s, up=plan.rest_pose)
    for pose in plan.poses:
        b.tumble(pose)
        b.hold(Kind.POSE, plan.pose_hold_s, up=pose)
    current_axis: str | None = None
    for axis, rate_dps in plan.rate_steps:
        sign = -1.0 if axis in plan.rate_flip else 1.0
        if axis != current_axis:
            b.ramp(0.0)
            b.tumble(("-" if sign < 0 else "+") + axis)
            current_axis = axis
        b.ramp(sign * rate_dps * _DEG)
        b.hold(Kind.RATE, plan.rate_hold_s, up=b.pose, rate_axis=axis, rate_dps=rate_dps)


def build_trajectory(plan: RigPlan) -> RigTrajectory:
    """The trajectory and segment table of ``plan`` (see the module docstring)."""
    return build_plateau_trajectory(plan, 1, 0.0)[0]


def build_plateau_trajectory(plan: RigPlan, plateaus: int, soak_s: float) -> tuple[RigTrajectory, tuple[float, ...]]:
    """``plan`` run ``plateaus`` times in a row, as at the temperature plateaus of a climate chamber.

    Block 0 is ``plan`` itself (its power-on rest of ``rest_s``); every later block first returns the
    rig to ``rest_pose`` and holds a still ``rest`` segment of ``soak_s`` (the soak while the unit
    settles at the next temperature), then the poses and rate steps again. Returns the trajectory
    and the rig time (s) at which each block starts (its soak; 0 for block 0). ``plateaus`` = 1 is
    :func:`build_trajectory`, segment for segment.
    """
    if plateaus < 1:
        raise PlanError(f"plateaus must be >= 1, got {plateaus}")
    if not soak_s >= 0:
        raise PlanError(f"soak_s must be >= 0, got {soak_s!r}")
    b = _Builder(plan)
    starts = []
    for k in range(plateaus):
        starts.append(b.t)
        _plan_block(b, plan, plan.rest_s if k == 0 else soak_s)
    b.ramp(0.0)
    b._end_move()
    if not b.segments:
        raise PlanError("plan: nothing to do (all durations are zero)")
    return RigTrajectory(plan, b.axes[0], b.axes[1], b.axes[2], tuple(b.segments), b.t), tuple(starts)
