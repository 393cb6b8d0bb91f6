"""One fit over a unit's soak-rack rest and its rig recording, on the sensor's own time base.

In a calibration line the warm-up of eq. 3 is observed in a powered soak rack: a long rest from
power-on in a fixed orientation nobody measured, no reference. The rig then records the poses and
rate steps of the same power-on. Both recordings carry the sensor's time since power-on (its sample
counter), so one model of eq. 1 with the drift of eq. 3 explains both:

* rig samples: ``y = M ref + b_stat + b_drift exp(-t/T_c) + s(t) + e`` as in :mod:`station.fit.calibrate`;
* rack samples: ``y = M c + b_stat + b_drift exp(-t/T_c) + s(t) + e`` with ``c`` the unknown, constant
  specific force (gravity in the slot's orientation) or angular rate (Earth's rate in it).

``M c`` is constant over the rack's rest, so per output axis it is one nuisance offset ``o_k`` (a
regressor that is 1 on the rack's samples, 0 on the rig's): the rack then says nothing about M and
b_stat (they come from the rig) but everything about the shape of the warm-up, ``b_drift``, ``T_c``
and the stochastic drift ``s``. This is the rig-free fit's treatment of unknown gravity directions
(:mod:`station.fit.rigfree_fit`: one direction per still segment) without its norm constraint ``|c| = g``,
which would add one equation against three offsets and couple the axes into a non-linear problem;
the constraint is instead checked afterwards (``quality["line"]["rack_gravity_mps2"]``: ``|M^-1 (o -
b_stat)|`` must be local gravity). The per-axis maximum-likelihood fit (:func:`station.fit.axis_ml.fit_axis`,
the Gauss-Markov drift started at 0 at power-on) is used unchanged over the block means of both
recordings (:func:`station.fit.blocks.make_blocks`); the rack's rest is cut into runs that double in
length from power-on so the fast accelerometer warm-up (T_c 50-167 s) gets short blocks.

A rack that holds its units in one known orientation (``rack_orientation``, e.g. ``"+z"``: every slot holds
its unit lying on its base, tilted by a small unknown angle) lets the norm tie one offset back in. After the fit
above, the rack's specific force ``c = M^-1 o`` gives the slot's tilt; a second pass takes the rack's rest as a
reference ``c'`` whose components across the nominal up axis are those of ``c`` and whose component along it is
``sqrt(g^2 - |c_across|^2)`` (``g`` the rig recording's local gravity), and fits the output
axis along up without a free offset. The rack's level on that axis is then ``M c' + b_stat + b_drift
exp(-t/T_c)``, as a rest in that orientation on the rig would be: the error of ``c'`` along up is
``|c_across| d|c_across| / g``, second order in the tilt's error (0.03 mm/s^2 for a 5 deg tilt known to 0.3 mm/s^2;
not in the stated uncertainties). The two axes across up keep their free offsets: they carry the tilt, which
nothing measures. A rest whose ``c`` is farther than ``rack_tilt_tolerance_deg`` from the nominal orientation
is refused (:class:`~station.kernel.errors.RackOrientationError`: the unit was put in its slot another way).

A rack of any orientation (``"any"``, the default) uses the same tie when the first pass finds the rest within
``rack_tilt_tolerance_deg`` of one of the six faces up (:func:`nearest_face`: a box-shaped unit put down in a tray
lies on a face), and keeps the free offsets otherwise (no refusal: any orientation is allowed); the face found is
recorded (``rack_face``, ``rack_face_angle_deg``). ``"free"`` (:data:`FREE_OFFSETS`) keeps the free offsets always
(the fit of ``"any"`` before this tie; for comparisons). The tie helps the first minute after a power-on in the
rack's own orientation, on the axis along gravity; it cannot help across gravity (above), nor the warm-up's shape,
which is the rack's first minutes' white noise whatever the tie (docs/line.md, *The first minute after power-on*).

A power interruption between rack and rig (:func:`check_power`) breaks the shared time base: the fit
is refused, and the line gives the unit the full rig plan or sends it back to the rack.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from threadpoolctl import threadpool_limits

from station import __version__
from station.fit.axis_ml import fit_axis
from station.fit.blocks import Blocks, make_blocks
from station.fit.boundary import numerics
from station.fit.calibrate import (
    FitOptions,
    NoiseEstimate,
    TriadLinear,
    mean_model,
    residual_allan,
    residual_figures,
    settled_runs,
    unpack_triad,
    white_noise,
)
from station.fit.checks import check_finite, check_session, check_time
from station.fit.determinability import assess
from station.fit.joint_found import joint_polynomial, with_found_terms
from station.kernel.errors import FitError, RackOrientationError
from station.kernel.geometry import AXIS_INDEX, POSE_ANGLES_DEG, up_vector
from station.kernel.line_plan import ANY_ORIENTATION, RACK_TILT_TOLERANCE_DEG
from station.kernel.parameters import FitQuality, ParameterSet, TriadParams
from station.session.model import Kind, Session

#: Metadata keys the line's recordings carry (see :func:`check_power`).
WALL_KEY = "wall_clock_at_start_s"
BOOT_KEY = "boot_count"
OFFSET_KEY = "clock_offset_s"
#: Offset added to the rig's segment indices in the merged recording (rack segments keep theirs).
_RIG_SEGMENT_OFFSET = 1_000_000
#: ``rack_orientation`` of :func:`fit_joint` that keeps the rack's free offsets on every axis whatever the rest's
#: orientation (the fit of ``"any"`` before it tied a rest found on a face; for comparisons).
FREE_OFFSETS = "free"
#: First rack run length (s); each later run is twice as long (see the module docstring).
_FIRST_RUN_S = 10.0


@dataclass(frozen=True)
class PowerContinuity:
    """Whether the rack's and the rig's recordings belong to one power-on of the unit.

    Attributes:
        continuous: one power-on: the joint fit may use both.
        reason: why not (empty when continuous).
        sensor_gap_s: rig's first sample time minus rack's last (sensor time, s).
        wall_gap_s: the same on the station's clock (s), NaN when a recording lacks it.
    """

    continuous: bool
    reason: str
    sensor_gap_s: float
    wall_gap_s: float


def _meta(session: Session, key: str) -> str | None:
    value = session.metadata.get(key)
    return None if value is None or str(value).strip() == "" else str(value).strip()


def _wall_start(session: Session) -> float:
    """Station clock at the first sample: ``wall_clock_at_start_s``, or ``clock_offset_s`` (station clock minus
    sensor time, what the sequence's clock sync measures) plus the first sample's sensor time; NaN if neither."""
    for key, plus in ((WALL_KEY, 0.0), (OFFSET_KEY, float(session.t_s[0]) if len(session) else math.nan)):
        text = _meta(session, key)
        try:
            value = float(text) + plus if text is not None else math.nan
        except ValueError:
            value = math.nan
        if math.isfinite(value):
            return value
    return math.nan


def power_continuity(
    *, rack_serial: str, rig_serial: str, rack_boot: str | None, rig_boot: str | None, rack_end_s: float,
    rack_end_clock_s: float, rig_start_s: float, rig_start_clock_s: float, max_transfer_s: float = 1800.0,
    clock_tolerance: float = 1e-3, clock_slack_s: float = 2.0,
) -> PowerContinuity:
    """The rules of :func:`check_power` on plain numbers: the rack's last sample (sensor time ``rack_end_s``,
    station clock ``rack_end_clock_s``) and the rig's first (``rig_start_s``, ``rig_start_clock_s``; NaN clock
    values skip the clock comparison), the power-on counters (None: unknown). The rig role also uses it
    before it runs anything: the unit's current uptime and boot count against its rack recording."""
    gap = float(rig_start_s - rack_end_s)
    wall_gap = float(rig_start_clock_s - rack_end_clock_s)

    def broken(reason: str) -> PowerContinuity:
        return PowerContinuity(False, reason, gap, wall_gap)

    if rack_serial != rig_serial:
        return broken(f"the recordings are of two units ({rack_serial!r} in the rack, {rig_serial!r} on the rig)")
    if rack_boot is not None and rig_boot is not None and rack_boot != rig_boot:
        return broken(f"power-on counter changed between rack and rig ({rack_boot} -> {rig_boot}): the unit lost power")
    if not gap > 0:
        return broken(f"sensor time restarted: the rig's first sample ({rig_start_s:.3f} s since power-on) is not "
                      f"after the rack's last ({rack_end_s:.3f} s): the unit lost power")
    if math.isfinite(wall_gap):
        allowed = clock_slack_s + clock_tolerance * abs(wall_gap)
        if abs(gap - wall_gap) > allowed:
            return broken(f"sensor time and station clock disagree between rack and rig (sensor {gap:.1f} s, "
                          f"station {wall_gap:.1f} s, allowed +-{allowed:.1f} s): the unit lost power or its "
                          "counter jumped")
    if gap > max_transfer_s:
        return broken(f"transfer from rack to rig took {gap:.0f} s (limit {max_transfer_s:.0f} s)")
    return PowerContinuity(True, "", gap, wall_gap)


def check_power(
    rack: Session, rig: Session, *, max_transfer_s: float = 1800.0, clock_tolerance: float = 1e-3,
    clock_slack_s: float = 2.0,
) -> PowerContinuity:
    """Did the unit stay powered from the rack's first sample to the rig's last?

    Interrupted when the serials differ, the sensor's power-on counter (``boot_count``) changed, the
    sensor time restarted (the rig's first sample is not after the rack's last: a counter reset), the
    sensor time between the two recordings disagrees with the station's clock (``wall_clock_at_start_s``
    of both; allowed: ``clock_slack_s`` plus ``clock_tolerance`` of the gap, the sensor's clock error),
    or the transfer took longer than ``max_transfer_s``.
    """
    if not len(rack) or not len(rig):
        return PowerContinuity(False, "an empty recording", math.nan, math.nan)
    return power_continuity(
        rack_serial=rack.serial, rig_serial=rig.serial, rack_boot=_meta(rack, BOOT_KEY), rig_boot=_meta(rig, BOOT_KEY),
        rack_end_s=float(rack.t_s[-1]), rack_end_clock_s=_wall_start(rack) + float(rack.t_s[-1] - rack.t_s[0]),
        rig_start_s=float(rig.t_s[0]), rig_start_clock_s=_wall_start(rig), max_transfer_s=max_transfer_s,
        clock_tolerance=clock_tolerance, clock_slack_s=clock_slack_s)


def _rack_runs(rack: Session, offset: int) -> list[tuple[int, int, int]]:
    """The rack's still segments cut into runs doubling in length from power-on (indices into the merged
    recording, ``offset`` = the rack's first sample there)."""
    runs: list[tuple[int, int, int]] = []
    for seg in rack.segments_of(Kind.REST, Kind.POSE):
        t = rack.t_s[seg.start:seg.stop]
        edges = [0]
        length = _FIRST_RUN_S
        boundary = float(t[0]) + length
        while boundary < float(t[-1]):
            i = int(np.searchsorted(t, boundary))
            if i - edges[-1] >= 2:
                edges.append(i)
            length *= 2.0
            boundary += length
        edges.append(len(t))
        runs.extend((seg.index, offset + seg.start + a, offset + seg.start + b)
                    for a, b in itertools.pairwise(edges) if b > a)
    return runs


def _merge(rack: Session, rig: Session) -> Session:
    """One recording on the sensor's time base: the rack's samples, then the rig's (segments renumbered)."""
    def cat(name: str) -> np.ndarray:
        return np.concatenate([getattr(rack, name), getattr(rig, name)])

    return Session(
        metadata={**rig.metadata},
        t_s=cat("t_s"),
        segment=np.concatenate([rack.segment, rig.segment + _RIG_SEGMENT_OFFSET]),
        kind=cat("kind"),
        accel_mps2=cat("accel_mps2"),
        gyro_radps=cat("gyro_radps"),
        temp_degc=cat("temp_degc"),
        ref_accel_mps2=np.concatenate([np.full((len(rack), 3), np.nan), rig.ref_accel_mps2]),
        ref_gyro_radps=np.concatenate([np.full((len(rack), 3), np.nan), rig.ref_gyro_radps]),
    )


@dataclass(frozen=True, eq=False)
class _JointTriad:
    p: dict[str, np.ndarray]
    tri: TriadLinear
    blocks: Blocks
    offsets: np.ndarray  # (3, n_rack_segments) nuisance offsets M c (+ nothing else)
    offsets_std: np.ndarray
    noise: NoiseEstimate
    runs: list[tuple[int, int, int]]
    polynomial: dict[str, Any] | None = None  # the gyro's IEEE 952 note (station.fit.joint_found)


def _fit_triad(
    merged: Session, data: np.ndarray, ref: np.ndarray, rig_runs: list[tuple[int, int, int]],
    rack_runs: list[tuple[int, int, int]], indicator: np.ndarray, options: FitOptions, triad: str,
    tied_axis: int | None = None,
) -> _JointTriad:
    """``tied_axis``: the output axis fitted without the rack's free offsets (its rack samples' reference in
    ``ref`` is the rack's tied specific force, see the module docstring); its offsets are 0."""
    runs = sorted(rig_runs + rack_runs, key=lambda r: r[1])
    noise = white_noise(merged, data, runs, options.outlier_sigma)
    blocks = make_blocks(merged.t_s, data, np.nan_to_num(ref), np.nan_to_num(merged.ref_accel_mps2), noise.keep,
                         runs, 1.0 / merged.sample_rate_hz, options.max_blocks, extra=indicator)
    assert blocks.extra is not None
    design = np.column_stack([blocks.ref, np.ones((len(blocks), 1)), blocks.extra])
    tc_range = options.tc_range_s.get(triad)
    n_off = indicator.shape[1]
    fits = [fit_axis(blocks, k, design[:, :4] if k == tied_axis else design, float(noise.sigma[k]),
                     lr_threshold=options.drift_lr_threshold, tc_range_s=tc_range) for k in range(3)]
    tri = TriadLinear(fits=fits, n_ref=3, extra=0)
    note = None
    if triad == "gyro":  # the scale polynomial's columns after the rack's offsets (station.fit.joint_found)
        assert tied_axis is None  # the norm tie is the accelerometer's
        tri, note = joint_polynomial(blocks, design, noise.sigma, options, tri, tc_range)
        fits = tri.fits
    offsets = np.array([np.zeros(n_off) if k == tied_axis else f.beta[4:4 + n_off] for k, f in enumerate(fits)])
    offsets_std = np.array([np.zeros(n_off) if k == tied_axis else
                            np.sqrt(np.clip(np.diag(f.beta_cov)[4:4 + n_off], 0.0, None))
                            for k, f in enumerate(fits)])
    return _JointTriad(unpack_triad(tri), tri, blocks, offsets, offsets_std, noise, runs, note)


def tied_rack_force(force: np.ndarray, up: str, gravity_mps2: float, tolerance_deg: float) -> tuple[np.ndarray, float]:
    """The rack rest's reference for the second pass: ``force`` (the first pass's ``M^-1 o``, m/s^2) with its
    component along the nominal ``up`` (a pose name) replaced by ``sqrt(g^2 - |force across up|^2)``; and the
    angle (deg) between ``force`` and ``up``. Refuses (:class:`RackOrientationError`) an angle above
    ``tolerance_deg``."""
    u = up_vector(up)
    norm = float(np.linalg.norm(force))
    angle = math.degrees(math.acos(float(np.clip(force @ u / norm, -1.0, 1.0)))) if norm > 0 else 180.0
    if not angle <= tolerance_deg:
        raise RackOrientationError(
            f"the unit rested {angle:.1f} deg from {up} up in the rack (the plan holds units {up} up within "
            f"{tolerance_deg:g} deg): it was put in its slot another way; soak it again as the plan says or give "
            "it the full rig plan")
    k = AXIS_INDEX[up[1]]
    tied = force.copy()
    tied[k] = 0.0  # across up: the first pass's; along up: from the norm
    tied[k] = u[k] * math.sqrt(max(gravity_mps2**2 - float(tied @ tied), 0.0))
    return tied, angle


def nearest_face(force: np.ndarray) -> tuple[str, float]:
    """The pose (``"+z"``, ``"-x"``, ...) whose up axis is nearest the direction of ``force`` (a rest's specific
    force in the sensor frame, m/s^2), and the angle between them (deg)."""
    norm = float(np.linalg.norm(force))
    if not norm > 0:
        return "+z", 180.0
    k = int(np.argmax(np.abs(force)))
    pose = ("+" if force[k] > 0 else "-") + "xyz"[k]
    return pose, math.degrees(math.acos(float(np.clip(abs(force[k]) / norm, -1.0, 1.0))))


def fit_joint(
    rack: Session, rig: Session, options: FitOptions | None = None, *, max_transfer_s: float = 1800.0,
    max_blocks: int = 140, clock_slack_s: float = 2.0, rack_orientation: str = ANY_ORIENTATION,
    rack_tilt_tolerance_deg: float = RACK_TILT_TOLERANCE_DEG,
) -> ParameterSet:
    """Fit eq. 1 with eq. 3's drift to a unit's rack rest and rig recording together.

    ``rack``: rest from power-on, references NaN (any orientation, constant); ``rig``: poses and rate
    steps (and optionally a rest) with references, its ``t_s`` the same sensor time since power-on.
    ``options.max_blocks`` is replaced by ``max_blocks`` (the long rack rest needs more blocks than a rig
    session); thermal terms and g-sensitivity are not fitted here; the gyro's IEEE 952 scale polynomial and the
    time offset are, as ``options.scale_nonlinearity`` and ``options.time_offset`` ask
    (:mod:`station.fit.joint_found`).
    ``rack_orientation``: ``"any"`` (the rack's rest has free offsets, but a rest found within
    ``rack_tilt_tolerance_deg`` of a face up gets the norm tie along it), ``"free"`` (free offsets always), or the
    pose the rack holds its units in (``"+z"``...), within ``rack_tilt_tolerance_deg``: the accelerometer's rack
    level along up is then tied to the norm of gravity (module docstring); a rest farther from it raises
    :class:`~station.kernel.errors.RackOrientationError`.

    Raises :class:`~station.kernel.errors.FitError` with a one-line reason when the recordings cannot
    give a trustworthy result, including a power interruption between them (:func:`check_power`).
    """
    opts = options or FitOptions()
    with threadpool_limits(limits=1, user_api="blas"), numerics(f"joint fit of {rig.serial!r}"):
        return _fit_joint(rack, rig, opts, max_transfer_s, max_blocks, clock_slack_s, rack_orientation,
                          rack_tilt_tolerance_deg)


def _fit_joint(rack: Session, rig: Session, options: FitOptions, max_transfer_s: float,
               max_blocks: int, clock_slack_s: float, rack_orientation: str,
               rack_tilt_tolerance_deg: float) -> ParameterSet:
    if rack_orientation not in (ANY_ORIENTATION, FREE_OFFSETS) and rack_orientation not in POSE_ANGLES_DEG:
        raise ValueError(f"rack_orientation must be 'any', 'free' or a pose name, got {rack_orientation!r}")
    check_time(rack)
    check_finite(rack)
    if not rack.segments_of(Kind.REST, Kind.POSE):
        raise FitError("the rack recording has no rest segment")
    power = check_power(rack, rig, max_transfer_s=max_transfer_s, clock_slack_s=clock_slack_s)
    if not power.continuous:
        raise FitError(f"rack and rig recordings are not one power-on: {power.reason}")
    gyro_method = check_session(rig, min_pose_samples=options.min_pose_samples)
    if gyro_method != "rate":
        raise FitError("the joint fit needs rate steps on the rig (M_w from known angles is not supported here)")
    options = replace(options, max_blocks=max_blocks)
    merged = _merge(rack, rig)
    n_rack = len(rack)
    rack_runs = _rack_runs(rack, 0)
    rack_segments = sorted({seg for seg, _, _ in rack_runs})
    indicator = np.zeros((len(merged), len(rack_segments)))
    for j, seg in enumerate(rack_segments):
        indicator[:n_rack, j] = rack.segment == seg
    shift = [(s + _RIG_SEGMENT_OFFSET, a + n_rack, b + n_rack) for s, a, b in
             settled_runs(rig, (Kind.REST, Kind.POSE), rig.ref_accel_mps2)]
    with numerics("accelerometer joint fit (rack rest, rig rest and poses)"):
        a = _fit_triad(merged, merged.accel_mps2, merged.ref_accel_mps2, shift, rack_runs, indicator, options, "accel")
    accel_ref = merged.ref_accel_mps2
    rule = "rack rest: M c + b_stat + b_drift exp(-t/T_c) with M c one free offset per axis and rack segment"
    tie: dict[str, Any] = {}
    up = "" if rack_orientation == FREE_OFFSETS else rack_orientation
    if rack_orientation == ANY_ORIENTATION:
        try:
            first = np.linalg.solve(a.p["misalignment"], a.offsets).T  # per rack segment: M^-1 o
        except np.linalg.LinAlgError:
            raise FitError("the accelerometer's M from the rig is singular: no rack orientation to check") from None
        found = [nearest_face(c) for c in first]
        faces = {f for f, _ in found}
        up = faces.pop() if len(faces) == 1 and all(angle <= rack_tilt_tolerance_deg for _, angle in found) else ""
        tie = {"rack_face": up or None, "rack_face_angle_deg": [round(angle, 4) for _, angle in found]}
        if not up:  # not on one face within the tolerance: the free offsets stand
            rule += (f" (the rest was not within {rack_tilt_tolerance_deg:g} deg of one face up: no tie to the norm "
                     "of gravity)")
    if up:
        gravity = rig.gravity_mps2  # the local gravity the rig's references are made with
        try:
            first = np.linalg.solve(a.p["misalignment"], a.offsets).T  # per rack segment: M^-1 o
        except np.linalg.LinAlgError:
            raise FitError("the accelerometer's M from the rig is singular: no rack orientation to check") from None
        accel_ref = merged.ref_accel_mps2.copy()
        angles = []
        for j, seg in enumerate(rack_segments):
            tied, angle = tied_rack_force(first[j], up, gravity, rack_tilt_tolerance_deg)
            accel_ref[:n_rack][rack.segment == seg] = tied
            angles.append(round(angle, 4))
        k_up = AXIS_INDEX[up[1]]
        with numerics("accelerometer joint fit, second pass (the rack's level along gravity tied to its norm)"):
            a = _fit_triad(merged, merged.accel_mps2, accel_ref, shift, rack_runs, indicator, options, "accel",
                           tied_axis=k_up)
        held = (f"held {up} up" if up == rack_orientation else
                f"in any orientation, found lying on a face ({up} up)")
        rule = (f"rack rest, {held} within {rack_tilt_tolerance_deg:g} deg: M c' + b_stat + "
                f"b_drift exp(-t/T_c), c' the first pass's M^-1 o across {up} and sqrt(g^2 - "
                f"|c' across|^2) along it (g = {gravity:.5f} m/s^2, the rig recording's gravity), free offsets on the "
                f"two axes across {up}; the gyro's rest one free offset per axis")
        tie = {**tie, "rack_orientation": rack_orientation, "rack_tilt_tolerance_deg": rack_tilt_tolerance_deg,
               "rack_tilt_deg": angles, "gravity_mps2": round(gravity, 9)}
    g_shift = [(s + _RIG_SEGMENT_OFFSET, a0 + n_rack, b0 + n_rack) for s, a0, b0 in
               settled_runs(rig, (Kind.REST, Kind.POSE, Kind.RATE), rig.ref_gyro_radps)]
    with numerics("gyroscope joint fit (rack rest, rig rest, poses and rate steps)"):
        g = _fit_triad(merged, merged.gyro_radps, merged.ref_gyro_radps, g_shift, rack_runs, indicator, options,
                       "gyro")

    def residual(j: _JointTriad, data: np.ndarray, ref: np.ndarray) -> np.ndarray:
        return data - mean_model(j.p, merged.t_s, ref, merged.ref_accel_mps2) - indicator @ j.offsets.T

    a_res = residual(a, merged.accel_mps2, accel_ref)
    g_res = residual(g, merged.gyro_radps, merged.ref_gyro_radps)

    def implied(j: _JointTriad, ref: np.ndarray) -> list[list[float]]:
        """The rack's constant input per rack segment, ``M^-1 (M c' + o)`` (``c'`` the rack's reference in the
        second pass, else 0: the offsets hold ``M c``)."""
        level = j.offsets + j.p["misalignment"] @ np.array(
            [np.nan_to_num(ref[:n_rack][rack.segment == seg][0]) for seg in rack_segments]).T
        try:
            return np.linalg.solve(j.p["misalignment"], level).T.round(9).tolist()
        except np.linalg.LinAlgError:
            return []

    rack_force = implied(a, accel_ref)
    line: dict[str, Any] = {
        "rack_samples": n_rack,
        "rack_span_s": round(float(rack.t_s[-1] - rack.t_s[0]), 6),
        "rig_start_s": round(float(rig.t_s[0]), 6),
        "transfer_s": round(power.sensor_gap_s, 6),
        "rack_segments": [int(s) for s in rack_segments],
        "rack_specific_force_mps2": rack_force,
        "rack_gravity_mps2": [round(float(np.linalg.norm(c)), 6) for c in rack_force],
        "rack_angular_rate_radps": implied(g, merged.ref_gyro_radps),
        "rule": rule,
        **tie,
    }
    quality = FitQuality(
        accel=residual_figures(a_res, a.runs, a.noise.keep),
        gyro=residual_figures(g_res, g.runs, g.noise.keep),
        gyro_scale_method=gyro_method,
        outliers={"accel": tuple(a.noise.outliers.tolist()), "gyro": tuple(g.noise.outliers.tolist())},
        drift_likelihood_ratio={"accel": tuple(round(f.lr, 3) for f in a.tri.fits),
                                "gyro": tuple(round(f.lr, 3) for f in g.tri.fits)},
        extra={"line": line},  # the line's section (read as quality.extra["line"])
    )

    def triad(j: _JointTriad, res: np.ndarray) -> TriadParams:
        mask = np.zeros(len(merged), dtype=bool)
        for _, s0, s1 in j.runs:
            mask[s0:s1] = True
        mask &= j.noise.keep
        return TriadParams(noise_std=j.noise.sigma, noise_std_std=j.noise.sigma_std,
                           allan=residual_allan(merged, res, j.noise.keep),
                           residual_rms=np.sqrt(np.mean(res[mask] ** 2, axis=0)), **j.p)

    params = ParameterSet(
        serial=rig.serial,
        sample_period_s=1.0 / rig.sample_rate_hz,
        moving_average_length=options.moving_average_length,
        accel=triad(a, a_res),
        gyro=triad(g, g_res),
        quality=quality,
        source={
            "software": f"station {__version__}",
            "fit": "joint (rack + rig)",
            "samples": len(merged),
            "rack_samples": n_rack,
            "duration_s": round(float(merged.t_s[-1] - merged.t_s[0]), 6),
            "sample_rate_hz": rig.sample_rate_hz,
            **({"tc_prior_s": {k: [float(v[0]), float(v[1])] for k, v in options.tc_range_s.items()}}
               if options.tc_range_s else {}),
        },
    )
    params = with_found_terms(params, rig, g.p, g.noise.sigma, options, g.polynomial)  # time offset on the rig part
    return assess(params, float(merged.t_s[-1]))


__all__ = ["BOOT_KEY", "FREE_OFFSETS", "OFFSET_KEY", "WALL_KEY", "PowerContinuity", "check_power", "fit_joint",
           "nearest_face", "power_continuity", "tied_rack_force"]
