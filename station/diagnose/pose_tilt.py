"""Candidate effect ``pose_tilt``: the rig's actual attitude in a still pose is not the nominal one.

A rig (or a hand) that puts the unit in the six gravity poses states the nominal
specific force ``f_ref = +-g`` along one sensor axis in its reference columns; the unit's
actual attitude is off by a small rotation ``phi`` (sensor frame, perpendicular to the
pose's up axis; a rotation about up does not change what the accelerometer feels). Its
true input is then ``exp(-[phi]x) f_ref ~ f_ref + f_ref x phi``, so the accelerometer output
changes by (eq. 1 with the tilted input)

    dy = M (f_ref x phi) = sum_j phi_j M (f_ref x a_j)

with ``a_1, a_2`` the two rotation axes of the pose (for the six standard poses the two
other sensor axes) and M the base fit's misalignment matrix. Poses are told apart by the
direction of their reference vector (within ``ALIGN_COS``). Where the tilt acts is one of two
:data:`VARIANTS`, the one that explains more of the block residual is taken (same parameters):

* ``rig``: a real rig's pose error belongs to the orientation it holds: every still sample in that
  orientation of a rest or pose segment (the power-on rest, the settling, every visit) is tilted, and
  along the rig's moves the tilt, a fixed direction in the world, is carried with the sensor
  (``phi(t) = D(t)^T phi_P`` with ``D`` the reference rotation since the pose, integrated from the
  reference rate) and handed over from the pose before to the pose after in proportion to the angle
  turned (the independent generator's rig, ``tests/indepgen.py``, moves between the tilted poses);
* ``segment``: pose segments only (a power-on rest or a rate step in the same orientation is taken as
  un-tilted, as in the station simulator's ``pose_tilt`` effect).

Identifiability, and the parameters. Six pose means give 6 x 3 = 18 numbers; the base model
re-fits 12 of them (M's 9 entries and b's 3), so at most 6 of the 12 tilts can be told from
the base model by the poses alone. For a pair of opposite poses +k/-k and a rotation axis j:

* the half-difference ``d = (phi_j(+k) - phi_j(-k)) / 2`` shifts the output the same way in
  both poses, like a bias seen in those two poses only: identifiable against the bias of the
  other poses (6 parameters, one per pair and axis);
* the half-sum ``s = (phi_j(+k) + phi_j(-k)) / 2``, the same body rotation in both poses, turns
  gravity the opposite way in the two poses, exactly like a cross-axis entry of M (one per
  off-diagonal entry): the base fit absorbs it, unless segments outside the poses (rest, rate
  steps) see gravity along axis k without the tilt and so pin M's column k.

:func:`build` therefore fits ``d`` and ``s`` per pair and axis (``phi(+-k) = s +- d``) rather
than the per-pose tilts, and leaves a half-sum out (zero column) where the recording cannot
determine it; the rank gain of :mod:`station.diagnose.likelihood` counts the rest. What separates
the half-sums from the misalignment is :data:`RIG_STEP`.

Units: specific force m/s^2, tilt rad inside and deg in :func:`engineering`.
"""

from __future__ import annotations

import math
import weakref
from collections.abc import Callable, Mapping

import numpy as np

from station.diagnose.candidates import Rows, whole
from station.diagnose.residuals import Baseline, SensorData
from station.kernel.geometry import up_vector
from station.physics.effects import POSES
from station.session.model import Kind

#: A regressor column of one pose and rotation axis for the samples lo:hi: ``column(pose index, axis (3,), lo, hi)``
#: -> (hi - lo, 3).
Column = Callable[[int, np.ndarray, int, int], np.ndarray]

NAME = "pose_tilt"
SENSORS = ("accel",)
DESCRIPTION = "actual attitude in each still pose tilted from the nominal one (two small angles per pose)"
#: A reference direction within this cosine of a pose's (about 2.6 deg) belongs to that pose.
ALIGN_COS = 0.999
#: The rig step that separates the tilt from the misalignment M (the half-sums, see the module docstring).
RIG_STEP = ("each pose measured at two headings, the fixture turned 180 deg about the vertical between them "
            "(a tilt of the fixture changes sign in the sensor frame, a misalignment does not), or the poses "
            "taken on a levelled precision cube or surface plate (tilt < 0.01 deg)")

_AXES = "xyz"
_PAIR_AXES = "zxy"  # pairs in the order of POSES: +-z, +-x, +-y
_DEG = math.pi / 180.0


def _rotation_axes(up: np.ndarray) -> np.ndarray:
    """The two rotation axes (2, 3) perpendicular to ``up``: the two sensor axes least along it, orthogonalized."""
    axes = []
    for k in sorted(np.argsort(np.abs(up), kind="stable")[:2]):
        a = np.zeros(3)
        a[k] = 1.0
        a = a - (a @ up) * up
        axes.append(a / np.linalg.norm(a))
    return np.array(axes)


def pose_groups(baseline: Baseline) -> tuple[np.ndarray, list[tuple[str, np.ndarray]]]:
    """Pose of each sample and the pose list: (index (n,) into the list, -1 outside pose segments;
    [(label, up unit vector (3,))]). The six standard poses come first, always, in the order of
    :data:`station.physics.effects.POSES`; other reference directions follow in order of first appearance.
    """
    session = baseline.session
    ref = np.asarray(session.ref_accel_mps2, dtype=float)
    norm = np.linalg.norm(np.nan_to_num(ref), axis=1)
    in_pose = (session.kind == int(Kind.POSE)) & np.all(np.isfinite(ref), axis=1) & (norm > 0)
    return _group_directions(ref, norm, np.flatnonzero(in_pose))


def _group_directions(ref: np.ndarray, norm: np.ndarray, rows: np.ndarray
                      ) -> tuple[np.ndarray, list[tuple[str, np.ndarray]]]:
    """The samples ``rows`` grouped by reference direction (within ALIGN_COS): the six standard poses first,
    other directions in order of first appearance; (index (n,), -1 outside ``rows``; [(label, up (3,))])."""
    poses: list[tuple[str, np.ndarray]] = [(p, up_vector(p)) for p in POSES]
    index = np.full(len(ref), -1, dtype=np.int64)
    if not len(rows):
        return index, poses
    unit = ref[rows] / norm[rows, None]
    for i, p in enumerate(POSES):
        index[rows[unit @ up_vector(p) > ALIGN_COS]] = i
    rest = rows[index[rows] < 0]
    while len(rest):
        u = ref[rest[0]] / norm[rest[0]]
        match = (ref[rest] / norm[rest, None]) @ u > ALIGN_COS
        index[rest[match]] = len(poses)
        poses.append((f"pose ({u[0]:+.3f}, {u[1]:+.3f}, {u[2]:+.3f})", u))
        rest = rest[~match]
    return index, poses


def _segment_ends(session_kind: np.ndarray, segment: np.ndarray) -> list[tuple[int, int, int]]:
    """Contiguous runs of equal (segment, kind): (start, stop, kind)."""
    n = len(segment)
    if n == 0:
        return []
    change = np.flatnonzero((np.diff(segment) != 0) | (np.diff(session_kind) != 0)) + 1
    starts = np.concatenate(([0], change))
    stops = np.concatenate((change, [n]))
    return [(int(a), int(b), int(session_kind[a])) for a, b in zip(starts, stops, strict=True)]


def _transport(w: np.ndarray, dt: float) -> np.ndarray:
    """Body-frame rotation accumulated from the first sample, (n, 3, 3): ``D_0 = I``,
    ``D_{i+1} = D_i exp([w_i dt]x)`` (``R(t) = R(t_0) D(t)`` for a sensor-to-world attitude ``R``)."""
    out = np.empty((len(w), 3, 3))
    d = np.eye(3)
    for i in range(len(w)):
        out[i] = d
        v = w[i] * dt
        ang = math.sqrt(float(v @ v))
        if ang > 0.0:
            k = v / ang
            kx = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
            d = d @ (np.eye(3) + math.sin(ang) * kx + (1.0 - math.cos(ang)) * (kx @ kx))
    return out


def rig_places(baseline: Baseline) -> tuple[np.ndarray, list[tuple[str, np.ndarray]], list[tuple[int, int, int, int]]]:
    """Where a rig's pose error acts (the ``rig`` variant of :func:`build`): (pose of each still sample (n,), -1
    elsewhere; the pose list; the moves next to a pose as (start, stop, pose before or -1, pose after or -1)).

    Still samples: every sample of a rest or pose segment *and* of the settling run labelled with the same
    segment number, whose reference direction is a pose's (the rig's error belongs to the orientation it holds,
    every time it holds it, the power-on rest too). Moves: the rig's moves (kind ``move``, a segment number of
    their own) that start or end in such a pose; along them the tilt goes over from the pose before to the pose
    after (the rig moves between the poses where they really are).
    """
    session = baseline.session
    ref = np.asarray(session.ref_accel_mps2, dtype=float)
    norm = np.linalg.norm(np.nan_to_num(ref), axis=1)
    ok = np.all(np.isfinite(ref), axis=1) & (norm > 0)
    kind = np.asarray(session.kind)
    seg = np.asarray(session.segment)
    held = np.isin(kind, [int(Kind.POSE), int(Kind.REST)])
    still_segs = np.unique(seg[held])
    still = np.isin(seg, still_segs) & ok & np.isin(kind, [int(Kind.POSE), int(Kind.REST), int(Kind.MOVE)])
    index, poses = _group_directions(ref, norm, np.flatnonzero(still))
    moves = []
    for a, b, k in _segment_ends(kind, seg):
        if k != int(Kind.MOVE) or seg[a] in still_segs:
            continue
        before = int(index[a - 1]) if a > 0 else -1
        after = int(index[b]) if b < len(index) else -1
        if before >= 0 or after >= 0:
            moves.append((a, b, before, after))
    return index, poses, moves


def _rig_columns(baseline: Baseline, f: np.ndarray) -> tuple[list[tuple[str, np.ndarray]], Column]:
    """(pose list, column(p, a, lo, hi)) of the ``rig`` variant: the body-frame tilt ``a`` (rad) of pose ``p``, in
    ``f x a`` (specific force m/s^2 per rad) wherever the rig holds or leaves/approaches that pose (see
    :func:`rig_places`), for the samples lo:hi."""
    index, poses, moves = rig_places(baseline)
    w_ref = baseline.session.ref_gyro_radps
    dt = 1.0 / baseline.session.sample_rate_hz
    paths = []
    for a, b, before, after in moves:
        w = np.nan_to_num(np.asarray(w_ref[a:b], dtype=float))
        d = _transport(w, dt)
        ang = np.concatenate(([0.0], np.cumsum(np.linalg.norm(w[:-1], axis=1)) * dt))
        s = ang / ang[-1] if ang[-1] > 0 else np.linspace(0.0, 1.0, b - a)
        # a world-fixed tilt seen in the body frame along the move: D^T a (pose before), D^T D_end a (pose after)
        d_end = d[-1]
        paths.append((a, b, before, after, d, d_end, s))

    def column(p: int, axis: np.ndarray, lo: int, hi: int) -> np.ndarray:
        out = np.zeros((hi - lo, 3))
        sel = index[lo:hi] == p
        out[sel] = np.cross(f[lo:hi][sel], axis)
        for a, b, before, after, d, d_end, s in paths:
            r0, r1 = max(a, lo), min(b, hi)
            if r0 >= r1:
                continue
            dm, sm = d[r0 - a:r1 - a], s[r0 - a:r1 - a]
            if before == p:
                out[r0 - lo:r1 - lo] += (1.0 - sm)[:, None] * np.cross(f[r0:r1], np.einsum("nji,j->ni", dm, axis))
            if after == p:
                out[r0 - lo:r1 - lo] += sm[:, None] * np.cross(f[r0:r1], np.einsum("nji,j->ni", dm, d_end @ axis))
        return out

    return poses, column


def _segment_columns(baseline: Baseline, f: np.ndarray) -> tuple[list[tuple[str, np.ndarray]], Column]:
    """(pose list, column(p, a, lo, hi)) of the ``segment`` variant: the tilt in pose segments only (as the
    station's simulator has it)."""
    index, poses = pose_groups(baseline)

    def column(p: int, axis: np.ndarray, lo: int, hi: int) -> np.ndarray:
        out = np.zeros((hi - lo, 3))
        sel = index[lo:hi] == p
        out[sel] = np.cross(f[lo:hi][sel], axis)
        return out

    return poses, column


def _pieces(n: int) -> list[tuple[int, int]]:
    return [(lo, min(lo + _ROWS, n)) for lo in range(0, n, _ROWS)]


def _assemble(sd: SensorData, poses: list, column: Column, free_of: Callable[[int], bool]) -> Rows:
    """The regressors' rows, M (f x a) per column: which half-sums are free is decided here, over all samples
    (a piece at a time); the rows are made when asked."""
    m = np.nan_to_num(np.asarray(sd.params.misalignment, dtype=float))
    n = len(sd.label)
    pairs = [(k, _rotation_axes(up_vector("+" + k))) for k in _PAIR_AXES]
    others = [_rotation_axes(poses[p][1]) for p in range(len(POSES), len(poses))]
    width = sum(2 * len(ax) for _, ax in pairs) + sum(len(ax) for ax in others)
    free = []
    for k, _axes in pairs:
        ip, im = POSES.index("+" + k), POSES.index("-" + k)
        both = all(any(np.any(column(i, _rotation_axes(up_vector(POSES[i]))[0], lo, hi)) for lo, hi in _pieces(n))
                   for i in (ip, im))
        free.append(both and free_of(_AXES.index(k)))

    def of(lo: int, hi: int) -> np.ndarray:
        z = np.zeros((hi - lo, 3, width))
        col = 0
        for (k, axes), fr in zip(pairs, free, strict=True):
            ip, im = POSES.index("+" + k), POSES.index("-" + k)
            for a in axes:
                plus, minus = column(ip, a, lo, hi), column(im, a, lo, hi)
                z[:, :, col] = (plus - minus) @ m.T  # d
                if fr:  # s, else zero
                    z[:, :, col + 1] = (plus + minus) @ m.T
                col += 2
        for p, axes in zip(range(len(POSES), len(poses)), others, strict=True):
            for a in axes:
                z[:, :, col] = column(p, a, lo, hi) @ m.T
                col += 1
        return z

    return Rows(n, of)


#: Samples per piece where the pose-tilt columns are scanned over the whole recording.
_ROWS = 1 << 16


def _sees_gravity_along(sd: SensorData, other: Callable[[int, int], np.ndarray], k: int) -> bool:
    """Whether the samples ``other(lo, hi)`` (a mask of rows lo:hi) see gravity along sensor axis ``k``: more than
    a tenth of the largest reference component among them (a piece at a time)."""
    n = len(sd.label)
    top, peak_k = 0.0, 0.0
    for lo, hi in _pieces(n):
        r = sd.ref[lo:hi][other(lo, hi)]
        if len(r):
            a = np.abs(r)
            top = max(top, float(a.max()))
            peak_k = max(peak_k, float(a[:, k].max()))
    return peak_k > 0.1 * top


#: The two places a pose error can act (:func:`build`): ``rig`` (every time the rig holds the pose, rest included,
#: and along its moves to and from it) and ``segment`` (in pose segments only).
VARIANTS = ("rig", "segment")


def variant_rows(baseline: Baseline, sd: SensorData, variant: str) -> Rows | None:
    """The regressors' rows (:class:`~station.diagnose.candidates.Rows`) of :func:`build` for one of
    :data:`VARIANTS`; None without pose segments."""
    if sd.sensor != "accel":
        return None
    index, _ = pose_groups(baseline)
    if not np.any(index >= 0):
        return None
    del index
    f = sd.ref  # accelerometer reference, NaN -> 0 (m/s^2)
    kind = baseline.session.kind
    if variant == "segment":
        poses, column = _segment_columns(baseline, f)
        return _assemble(sd, poses, column, lambda k: _sees_gravity_along(
            sd, lambda lo, hi: (sd.label[lo:hi] >= 0) & (kind[lo:hi] != int(Kind.POSE)), k))
    poses, column = _rig_columns(baseline, f)
    touched = np.zeros(len(f), dtype=bool)
    for lo, hi in _pieces(len(f)):
        for p in range(len(poses)):
            for a in _rotation_axes(poses[p][1]):
                touched[lo:hi] |= np.any(column(p, a, lo, hi) != 0, axis=1)
    return _assemble(sd, poses, column, lambda k: _sees_gravity_along(
        sd, lambda lo, hi: (sd.label[lo:hi] >= 0) & ~touched[lo:hi], k))


def build_variant(baseline: Baseline, sd: SensorData, variant: str) -> np.ndarray | None:
    """The regressors (n, 3, p) of :func:`build` for one of :data:`VARIANTS`; None without pose segments."""
    rows = variant_rows(baseline, sd, variant)
    return None if rows is None else rows.whole()


def _explained(sd: SensorData, zb: np.ndarray) -> float:
    """Weighted block chi^2 the block regressors ``zb`` (m, 3, p) explain beyond the base terms (rows of M,
    b_stat, eq. 3's warm-up at the base fit's T_c), white block noise: the variant choice of :func:`build`."""
    ref_b = sd.block_mean(sd.ref)
    t = sd.t_s
    gain = 0.0
    for k in range(3):
        tc = float(sd.params.correlation_time_s[k])
        tc = tc if math.isfinite(tc) and tc > 0 else float(t.max() + 1.0)
        base = np.column_stack([ref_b, np.ones(len(t)), np.exp(-t / tc)])
        w = np.sqrt(sd.count) / sd.sigma[k]
        y = sd.y[:, k] * w
        rss = []
        for x in (base, np.column_stack([base, zb[:, k, :]])):
            xw = x * w[:, None]
            beta, *_ = np.linalg.lstsq(xw, y, rcond=1e-10)
            r = y - xw @ beta
            rss.append(float(r @ r))
        gain += rss[0] - rss[1]
    return gain


def choose_variant(baseline: Baseline, sd: SensorData) -> tuple[str, Rows | None]:
    """The variant (:data:`VARIANTS`) whose regressors explain more of the block residual (the first of
    :data:`VARIANTS` on a tie), and its regressors' rows.

    Each variant's block means are summed a piece of samples at a time: no (n, 3, p) array (the largest arrays of
    a long recording's diagnosis) is made.
    """
    gains: dict[str, float] = {}
    rows: dict[str, Rows | None] = {}
    for v in reversed(VARIANTS):
        rows[v] = r = variant_rows(baseline, sd, v)
        gains[v] = _explained(sd, sd.block_mean_of(r.of)) if r is not None else -math.inf
    best = max(VARIANTS, key=lambda v: gains[v])
    return best, rows[best]


def rows(baseline: Baseline, sd: SensorData) -> Rows | None:
    """Per-sample regressors (n, 3, p) of the pose tilts (rad), as rows (the chosen variant's, kept per
    baseline: they hold only the pose of each sample and the moves' rotations); None without pose segments.

    Accelerometer only (``sd.sensor == "accel"``); M is ``sd.params.misalignment``. A tilt
    ``phi_j`` of pose ``P`` (rotation axis ``a_j``) adds ``M (f_ref x a_j) phi_j`` where the rig holds
    ``P``. Where that is (:data:`VARIANTS`, the one that explains more of the block residual is taken, the
    same parameters either way):

    * ``rig``: every still sample in ``P``'s orientation that belongs to a rest or pose segment (the power-on
      rest, the settling, every visit), and along the rig's moves from and to ``P``: the tilt, a fixed
      direction in the world, carried along the reference rotation (integrated reference rate) and handed
      over from the pose before to the pose after in proportion to the angle turned;
    * ``segment``: pose segments only (the station's simulator).

    Parameters, in this order (see :data:`PARAMETERS`):

    * for each opposite pair +k/-k of the standard poses (z, x, y) and each of its two rotation
      axes: the half-difference ``d = (phi(+k) - phi(-k)) / 2`` and the half-sum
      ``s = (phi(+k) + phi(-k)) / 2`` (so ``phi(+-k) = s +- d``): 12 parameters. The column of
      ``s`` is zero (not fitted) when no block the tilt does not reach sees gravity along
      axis k (then M's column k absorbs it exactly), or when only one pose of the pair is
      present (then ``d`` alone is that pose's tilt);
    * two per-pose tilts for every other reference direction, in order of first appearance.
    """
    if sd.sensor != "accel":
        return None
    hit = _CACHE.get(baseline)
    if hit is not None and hit[0] is sd:
        return hit[1]
    _best, r = choose_variant(baseline, sd)
    _CACHE[baseline] = (sd, r)
    return r


build = whole(rows)

#: The chosen variant's rows of :func:`rows` per baseline (selection, the fitted signal, the re-run and the
#: compensation ask for the same ones); entries go with their baseline.
_CACHE: weakref.WeakKeyDictionary[Baseline, tuple[SensorData, Rows | None]] = weakref.WeakKeyDictionary()


def release(baseline: Baseline) -> None:
    """Drop what :func:`rows` keeps for ``baseline`` (the pose of each sample, the moves' rotations): for a caller
    that needs no more of them; a later :func:`rows` makes them again."""
    _CACHE.pop(baseline, None)


def specific_force_change(baseline: Baseline, sd: SensorData, theta: np.ndarray) -> np.ndarray:
    """What fitted tilts ``theta`` (rad, order of :func:`build`) change in the true specific force,
    sensor frame (m/s^2), (n, 3): ``f_ref x phi`` in each pose's samples, zero elsewhere. Adding it to
    the reference gives the input a simulator re-run of the recording needs (``M^-1`` of the regressors).
    """
    r = rows(baseline, sd)
    out = np.zeros((len(baseline.session), 3))
    if r is None:
        return out
    m = np.nan_to_num(np.asarray(sd.params.misalignment, dtype=float))
    th = np.asarray(theta, dtype=float)
    for lo, hi in _pieces(r.n):  # a piece at a time: no (n, 3, p) regressors
        out[lo:hi] = np.linalg.solve(m, (r.of(lo, hi) @ th).T).T
    return out


def _parameter_names() -> tuple[str, ...]:
    names = []
    for k in _PAIR_AXES:
        for j in _rotation_axes(up_vector("+" + k)).argmax(axis=1):
            names += [f"+-{k} about {_AXES[j]}: half-difference", f"+-{k} about {_AXES[j]}: half-sum"]
    return tuple(names)


def theta_of(tilts: Mapping[str, np.ndarray]) -> np.ndarray:
    """The 12 pair parameters of :func:`build` (rad) of per-pose tilts: pose ('+x', ...) -> rotation
    vector (rad, sensor frame), e.g. :meth:`station.physics.effects.EffectTruth.pose_tilts`; missing poses are 0."""
    zero = np.zeros(3)
    out = []
    for k in _PAIR_AXES:
        plus, minus = tilts.get("+" + k, zero), tilts.get("-" + k, zero)
        for a in _rotation_axes(up_vector("+" + k)):
            out += [0.5 * (plus @ a - minus @ a), 0.5 * (plus @ a + minus @ a)]
    return np.array(out)


def engineering(theta: np.ndarray, cov: np.ndarray) -> dict[str, object]:
    """Fitted tilt parameters (rad, order of :func:`build`) and their covariance, in deg.

    Returns per opposite pose pair and rotation axis the ``half_difference`` (identifiable
    whenever both poses were taken) and the ``half_sum`` (None where this recording does not
    determine it: the base fit's M absorbs it), each ``{"value", "std"}`` in deg; the per-pose
    tilts ``s +- d`` where both are determined; ``rms_half_difference_deg``; and the tilts of
    poses outside the six standard ones (``other_poses``, [about a1, about a2] deg each).
    """
    theta = np.asarray(theta, dtype=float)
    cov = np.asarray(cov, dtype=float)
    std = np.sqrt(np.clip(np.diag(cov), 0.0, None))

    tiny = 1e-6 * float(std.max(initial=0.0))  # a zero column's variance from a pseudo-inverse is round-off

    def deg(i: int) -> dict[str, float] | None:
        if std[i] <= tiny:
            return None
        return {"value": round(float(theta[i]) / _DEG, 6), "std": round(float(std[i]) / _DEG, 6)}

    pairs: dict[str, dict[str, object]] = {}
    halves: list[float] = []  # the pairs' half-differences (deg), for their RMS
    per_pose: dict[str, dict[str, float]] = {}
    for i, name in enumerate(PARAMETERS[::2]):
        key = name.split(":")[0]
        d, s = deg(2 * i), deg(2 * i + 1)
        if d is None:
            continue  # neither pose of the pair, or a pair the base fit absorbs entirely
        pairs[key] = {"half_difference": d, "half_sum": s}
        halves.append(d["value"])
        if s is not None:
            axis = key.split()[0][2]
            about = key.split()[-1]
            for sign in (1.0, -1.0):
                a, b = 2 * i + 1, 2 * i
                var = cov[a, a] + cov[b, b] + 2.0 * sign * cov[a, b]
                per_pose[f"{'+' if sign > 0 else '-'}{axis} about {about}"] = {
                    "value": round(float(theta[a] + sign * theta[b]) / _DEG, 6),
                    "std": round(math.sqrt(max(float(var), 0.0)) / _DEG, 6),
                }
    out: dict[str, object] = {"unit": "deg", "pairs": pairs, "per_pose": per_pose}
    if pairs:
        vals = np.array(halves)
        out["rms_half_difference_deg"] = round(float(np.sqrt(np.mean(vals**2))), 6)
    extra = theta[len(PARAMETERS):]
    if len(extra):
        out["other_poses"] = {
            "value": np.round(extra.reshape(-1, 2) / _DEG, 6).tolist(),
            "std": np.round(std[len(PARAMETERS):].reshape(-1, 2) / _DEG, 6).tolist(),
        }
    return out


#: Names of the 12 pair parameters of :func:`build` (rad), in order.
PARAMETERS: tuple[str, ...] = _parameter_names()

__all__ = [
    "ALIGN_COS",
    "DESCRIPTION",
    "NAME",
    "PARAMETERS",
    "RIG_STEP",
    "SENSORS",
    "VARIANTS",
    "build",
    "build_variant",
    "choose_variant",
    "engineering",
    "pose_groups",
    "release",
    "rig_places",
    "rows",
    "specific_force_change",
    "theta_of",
    "variant_rows",
]
