"""Re-run the simulator with the fitted models and compare it with the recording.

The diagnosis names effects from block regressions (:mod:`station.diagnose.selection`); this
module checks the result the other way round: the project's simulator
(:class:`station.physics.imu.ImuModel`) renders the unit twice on the *recording's own* rig motion
and temperature course,

* **base**: the fitted eq. (1) with the drift of eq. (3) (``baseline.params``),
* **extended**: the same plus every accepted mean effect with its fitted SI parameters
  (mapped onto the simulator's :class:`~station.physics.effects.EffectTruth` by each effect's entry in
  :mod:`station.diagnose.effect_registry`),

and both are compared with the recording per block of :mod:`station.diagnose.residuals`.

Rig motion: the simulator is driven by the recording's reference columns (specific force and
body rate, NaN -> 0), the angular acceleration as their time derivative and, for the Earth
rate only, the attitude integrated from the rate reference
(:func:`station.diagnose.candidates.attitude`); the sample times are the recording's. A fitted
``time_offset`` is applied as the simulator does it: the references are read at ``t - delta``.
Temperature: the smoothed recorded course (``baseline.d_temp``) replaces the simulator's
self-heating model, so the temperature effects see what the diagnosis saw.

Both runs are noise-free (no white noise, drift noise, outliers or ADC): the simulated output
is the model's expected output and the block statistic measures the model, not the noise;
the result is deterministic (no random draw reaches the output). The stochastic effects
(``bias_random_walk``, ``outliers``) do not change the expected output and are not simulated.

Both models then get the same re-fit of the base model's terms on the block means (per axis
the row of M, b_stat and the drift ``b_drift exp(-t/T_c)`` of eq. 3 with T_c from a grid around
the fitted one; weighted least squares) followed by a second render with the corrected
parameters: the accepted effects were fitted jointly with these terms, and doing the same for
both runs leaves the effects as the only difference.

Statistic per sensor, axis and kind of segment: the block means of recording minus simulation,
their RMS (weighted by block size), the noise floor of that RMS from white noise alone, and the
block chi^2 ``mean(d^2 n / sigma^2)`` (1 = as expected from white noise).

Units: SI inside (m/s^2, rad/s, s, K); the JSON summary gives the gyroscope in deg/s.
Pure numerics, no I/O.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field

import numpy as np

from station.diagnose import pose_tilt
from station.diagnose.candidates import attitude_rows
from station.diagnose.effect_registry import EFFECTS, REGISTRY, simulator_input
from station.diagnose.residuals import SENSORS, Baseline, SensorData
from station.diagnose.results import BlockStatistics, FindingRerun, Improvement, KindStatistics, RerunSummary
from station.fit.blocks import block_exp_mean
from station.kernel.errors import FitError
from station.kernel.geometry import Kinematics
from station.physics.effects import EffectShapes, EffectTruth
from station.physics.imu import Environment, ImuModel
from station.physics.unit import TriadTruth, UnitTruth
from station.session.model import Kind

#: Samples the simulator renders at a time (a chunk ends at the first sample after this many outside every block).
CHUNK = 1 << 18

#: Effects with a mean signal and a simulator mapping: simulated with their fitted parameters.
SIMULATED = tuple(e.name for e in EFFECTS if e.simulate is not None)
#: Effects that change only the noise, not the expected output.
STOCHASTIC = tuple(e.name for e in EFFECTS if e.kind != "mean")

_UNITS = {"accel": ("m/s^2", 1.0), "gyro": ("deg/s", 180.0 / math.pi)}


@dataclass(frozen=True, eq=False)
class FittedEffect:
    """An accepted finding: effect name, sensor (accel|gyro) and its fitted SI parameters ``theta`` as
    :mod:`station.diagnose.candidates` defines them (e.g. lever arm (3,) in m, g-sensitivity (9,) row-major
    in rad/s per m/s^2, time offset (1,) in s, Earth rotation (1,) as a multiple of the Earth rate)."""

    effect: str
    sensor: str
    theta: np.ndarray


@dataclass(frozen=True, eq=False)
class Triad:
    """The base model of one triad as the simulator takes it (U = m/s^2 or rad/s).

    Attributes:
        misalignment: M (3, 3); bias_static, bias_drift (U) and correlation_time_s (s), (3,) each.
        drift_on: axes with a drift term (finite T_c), (3,).
    """

    misalignment: np.ndarray
    bias_static: np.ndarray
    bias_drift: np.ndarray
    correlation_time_s: np.ndarray
    drift_on: np.ndarray

    def truth(self) -> TriadTruth:
        """The simulator's triad: these parameters, no noise, no drift noise, no outliers, no ADC."""
        z3 = np.zeros(3)
        return TriadTruth(
            misalignment=self.misalignment, bias_static=self.bias_static,
            bias_drift=np.where(self.drift_on, self.bias_drift, 0.0),
            correlation_time_s=np.where(self.drift_on, self.correlation_time_s, 1.0),
            drift_noise=z3, noise_std=z3, lsb=0.0, full_scale=math.inf, outlier_probability=0.0, outlier_size=z3,
        )


@dataclass(frozen=True, eq=False)
class ModelRun:
    """One noise-free simulator run compared with the recording.

    Attributes:
        label: ``base``, ``extended`` or ``base + EFFECT (SENSOR)``.
        effects: the simulated findings.
        triads: the base-model parameters after the block re-fit, per sensor.
        effect_truth: the simulator's effect coefficients (SI).
        time_offset_s: per sensor, the time offset applied (s).
        output: per sensor, the block means of the simulated output (m, 3) (m/s^2 or rad/s); None when the
            final re-fit was applied to the block residual only (see :func:`run_model`).
        block_residual: per sensor, recording minus simulation per block (m, 3).

    Runs of a single finding (``Rerun.alone``) hold only that finding's sensor.
    """

    label: str
    effects: tuple[FittedEffect, ...]
    triads: dict[str, Triad]
    effect_truth: EffectTruth
    time_offset_s: dict[str, float]
    output: dict[str, np.ndarray] | None = field(repr=False)
    block_residual: dict[str, np.ndarray] = field(repr=False)


@dataclass(frozen=True, eq=False)
class Rerun:
    """Base and extended re-runs of one recording (see the module docstring).

    Attributes:
        baseline: the base fit and its blocks.
        base, extended: the two runs (``extended is base`` without simulated findings).
        alone: per simulated finding (same order as ``extended.effects``), the run with only that effect.
        skipped: findings not simulated, with the reason (JSON-ready).
    """

    baseline: Baseline
    base: ModelRun
    extended: ModelRun
    alone: tuple[ModelRun, ...]
    skipped: tuple[dict[str, str], ...]

    def statistics(self, run: ModelRun) -> dict[str, BlockStatistics]:
        """The statistic of ``run`` per sensor (see :func:`block_statistics`)."""
        return {s: block_statistics(self.baseline.sensor(s), run.block_residual[s]) for s in SENSORS}

    def summary(self) -> RerunSummary:
        """The ``rerun`` section of the diagnosis report (gyro in deg/s)."""
        base, ext = self.statistics(self.base), self.statistics(self.extended)
        improvement = {}
        for s in SENSORS:
            rb, re = np.array(base[s].overall.rms), np.array(ext[s].overall.rms)
            cb, ce = np.array(base[s].overall.chi2), np.array(ext[s].overall.chi2)
            improvement[s] = Improvement(
                tuple(np.round(np.divide(rb, re, out=np.ones(3), where=re > 0), 4).tolist()),
                tuple(np.round(np.divide(cb, ce, out=np.ones(3), where=ce > 0), 4).tolist()))
        return RerunSummary(
            method="noise-free simulator on the recording's reference motion and temperature; base = fitted "
                   "eq. 1 + eq. 3, extended = base + accepted effects; both with M rows, b_stat, b_drift and T_c "
                   "re-fitted on the block means; statistic: recording minus simulation per block",
            effects=tuple((e.effect, e.sensor) for e in self.extended.effects),
            not_simulated=self.skipped, base=base, extended=ext, improvement=improvement)

    def finding_part(self, effect: str, sensor: str) -> FindingRerun | None:
        """Per finding: RMS per axis of its sensor for base, base + this effect alone, and extended."""
        unit, factor = _UNITS[sensor]
        count = self.baseline.sensor(sensor).count

        def rms(r: ModelRun) -> list[float]:
            return _round(_rms(r.block_residual[sensor], count) * factor)

        for e, run in zip(self.extended.effects, self.alone, strict=True):
            if e.effect == effect and e.sensor == sensor:
                return FindingRerun(unit, tuple(rms(self.base)), tuple(rms(run)), tuple(rms(self.extended)))
        return None


# --- the statistic -------------------------------------------------------------------------
def _round(a: np.ndarray) -> list[float]:
    return [float(f"{v:.4g}") for v in np.asarray(a, dtype=float)]


def _rms(d: np.ndarray, count: np.ndarray) -> np.ndarray:
    return np.sqrt(np.average(d**2, axis=0, weights=count)) if len(d) else np.full(3, math.nan)


def block_statistics(sd: SensorData, d: np.ndarray) -> BlockStatistics:
    """Block residual ``d`` (m, 3) of one sensor: RMS (weighted by block size), its white-noise floor
    and the block chi^2 per axis, overall and per kind of segment (gyro in deg/s)."""
    unit, factor = _UNITS[sd.sensor]
    white = sd.sigma[None, :] ** 2 / sd.count[:, None]  # (m, 3), block-mean noise variance

    def stats(sel: np.ndarray) -> KindStatistics:
        w = sd.count[sel]
        return KindStatistics(int(sel.sum()), tuple(_round(_rms(d[sel], w) * factor)),
                              tuple(_round(np.sqrt(np.average(white[sel], axis=0, weights=w)) * factor)),
                              tuple(_round(np.mean(d[sel] ** 2 / white[sel], axis=0))))

    per_kind = {}
    for kind in Kind:
        sel = sd.kind == int(kind)
        if np.any(sel):
            per_kind[kind.label] = stats(sel)
    return BlockStatistics(unit, stats(np.ones(len(d), dtype=bool)), per_kind)


# --- the simulator, driven by the recording --------------------------------------------------
def _triads(baseline: Baseline) -> dict[str, Triad]:
    out = {}
    for s in SENSORS:
        p = baseline.sensor(s).params
        m = np.nan_to_num(np.asarray(p.misalignment, dtype=float))
        if s == "accel":  # the accelerometer's input is the specific force: a G term is part of M
            m = m + np.nan_to_num(np.asarray(p.g_sensitivity, dtype=float))
        tc = np.asarray(p.correlation_time_s, dtype=float)
        drift = np.nan_to_num(np.asarray(p.bias_drift, dtype=float))
        on = np.isfinite(tc) & (tc > 0)
        out[s] = Triad(m, np.nan_to_num(np.asarray(p.bias_static, dtype=float)), drift, np.where(on, tc, 1.0), on)
    return out


def _effect_truth(
    drive: Drive, effects: Iterable[FittedEffect]
) -> tuple[EffectTruth, dict[str, float], np.ndarray | None]:
    """The simulator's coefficients (SI) for the base gyro G plus ``effects`` (each by its registry entry's
    simulator mapping), the time offset per sensor, and the change of the true specific force (m/s^2, (n, 3))
    by fitted pose tilts (None without)."""
    effects = list(effects)
    acc = simulator_input(drive.baseline, lambda: drive.rotation() is not None,
                          [(e.effect, e.sensor, e.theta) for e in effects if e.effect != pose_tilt.NAME])
    for e in effects:  # the registry's pose-tilt mapping, its (n, 3) force made once per theta (Drive.tilt_force)
        if e.effect == pose_tilt.NAME:
            acc.tilt_force = drive.tilt_force(e.theta)
    return acc.truth(), acc.time_offset_s, acc.tilt_force


class Drive:
    """What the recording imposes on the simulator: rig motion, temperature course, time stamps.

    Built once per recording; the attitude (only the Earth rate needs it) is computed on first use and
    kept. The simulator renders the recording in time chunks of about :data:`CHUNK` samples, cut between
    blocks, and each chunk is reduced to its blocks' sums before the next one is rendered: the motion and the
    output exist for one chunk at a time, never for the whole recording. The chunked render is bit-identical to
    one render of the whole (``ImuModel.render`` continues the last call; the noise-free model is elementwise
    in time, eq. 3's warm-up taken from absolute time), and so are the block means (each block summed as one
    piece, in sample order).
    """

    def __init__(self, baseline: Baseline) -> None:
        session = baseline.session
        t = session.t_s
        if len(t) == 0 or t[0] < 0 or np.any(np.diff(t) <= 0):
            raise FitError("rerun: the recording's time stamps are not increasing from power-on (t >= 0)")
        self.baseline = baseline
        temp = np.asarray(session.temp_degc, dtype=float)
        finite = temp[np.isfinite(temp)]
        self.t0_degc = float(finite[0]) if len(finite) else 0.0
        self.environment = Environment(ambient_degc=self.t0_degc, ambient_rate_k_per_s=0.0)
        self._rotation: tuple[Callable[[int, int], np.ndarray] | None] | None = None
        self._tilt: dict[bytes, np.ndarray] = {}
        self._cuts: list[int] | None = None
        self._block_index: dict[str, tuple[np.ndarray, np.ndarray | None]] = {}
        self._recorded: dict[str, np.ndarray] = {}
        self._ref_cols: dict[str, np.ndarray] = {}
        self._ref_idx: dict[str, list[int]] = {}
        self._basis: dict[str, tuple[np.ndarray, np.ndarray]] = {}

    def temperature(self, t_s: np.ndarray) -> np.ndarray:
        """True temperature (degC) at sensor times (s): the smoothed recorded course."""
        return self.t0_degc + np.interp(t_s, self.baseline.session.t_s, self.baseline.d_temp)

    def rotation(self) -> Callable[[int, int], np.ndarray] | None:
        """Sensor-to-world attitude integrated from the rate reference, as rows lo:hi (the scanned quaternions
        kept, not (n, 3, 3) matrices), None when the start pose is unknown."""
        if self._rotation is None:
            self._rotation = (attitude_rows(self.baseline),)
        return self._rotation[0]

    def tilt_force(self, theta: np.ndarray) -> np.ndarray:
        """The change of the true specific force (m/s^2, (n, 3)) by the fitted pose tilts ``theta``
        (:func:`station.diagnose.pose_tilt.specific_force_change`), made once per ``theta`` and kept."""
        key = np.asarray(theta, dtype=float).tobytes()
        if key not in self._tilt:
            self._tilt[key] = pose_tilt.specific_force_change(self.baseline, self.baseline.accel, theta)
        return self._tilt[key]

    def _reference(self, values: np.ndarray, x: np.ndarray) -> np.ndarray:
        """``values`` (n, 3) with NaN -> 0, linearly interpolated at times ``x`` (increasing), as
        ``np.interp(x, t, nan_to_num(values[:, k]))`` of the whole record, from the rows around ``x`` only."""
        t = self.baseline.session.t_s
        lo = max(int(np.searchsorted(t, x[0], side="right")) - 3, 0)
        hi = min(int(np.searchsorted(t, x[-1], side="left")) + 3, len(t))
        v = np.nan_to_num(values[lo:hi])
        return np.column_stack([np.interp(x, t[lo:hi], v[:, k]) for k in range(3)])

    def motion(self, delta_s: float, need_rotation: bool, a: int, b: int) -> tuple[Kinematics, np.ndarray]:
        """Kinematics and specific force (m/s^2) of samples ``a:b`` from the recording's references, read at
        ``t - delta_s`` (the angular acceleration is the time derivative of the whole record's rate, taken
        with a neighbour sample on each side of the chunk)."""
        session = self.baseline.session
        t = session.t_s
        n = len(t)
        a0, b0 = max(a - 1, 0), min(b + 1, n)  # one neighbour each side: np.gradient's central differences
        tc = t[a0:b0]
        if delta_s != 0.0:
            f = self._reference(session.ref_accel_mps2, tc - delta_s)
            w = self._reference(session.ref_gyro_radps, tc - delta_s)
        else:
            f = np.nan_to_num(session.ref_accel_mps2[a0:b0])
            w = np.nan_to_num(session.ref_gyro_radps[a0:b0])
        alpha = np.gradient(w, tc, axis=0) if n > 1 else np.zeros_like(w)
        keep = slice(a - a0, a - a0 + (b - a))
        f, w, alpha = f[keep], w[keep], alpha[keep]
        rows = self.rotation() if need_rotation else None
        if rows is None:
            # only row 2 ('up' in the sensor frame) is ever read: by the vertical Earth rate
            norm = np.linalg.norm(f, axis=1)
            up = np.divide(f, norm[:, None], out=np.zeros_like(f), where=norm[:, None] > 0)
            rot = np.zeros((b - a, 3, 3))
            rot[:, 2, :] = up
        else:
            rot = rows(a, b)
        return Kinematics(t[a:b], rot, w, alpha), f

    def cuts(self) -> list[int]:
        """Sample positions ``0 = c_0 < c_1 < ... = n`` of the render chunks: about :data:`CHUNK` samples apart,
        none inside a block of either sensor; ``[0, n]`` when a sensor's blocks do not run in sample order."""
        if self._cuts is None:
            n = len(self.baseline.session)
            spans = []  # per sensor: first and last kept sample of each block
            for s in SENSORS:
                idx, starts = self._blocks(s)
                if starts is None:
                    self._cuts = [0, n]
                    return self._cuts
                ends = np.append(starts[1:], len(idx)) - 1
                spans.append((idx[starts], idx[ends]))
            cuts = [0]
            while n - cuts[-1] > CHUNK:
                p = cuts[-1] + CHUNK
                moved = True
                while moved:  # to the first position no block straddles (a block holds samples on both sides)
                    moved = False
                    for first, last in spans:
                        j = int(np.searchsorted(first, p, side="left")) - 1  # the last block starting before p
                        if j >= 0 and last[j] >= p:
                            p, moved = int(last[j]) + 1, True
                if p >= n:
                    break
                cuts.append(p)
            cuts.append(n)
            self._cuts = cuts
        return self._cuts

    def _blocks(self, sensor: str) -> tuple[np.ndarray, np.ndarray | None]:
        """Kept sample indices of ``sensor``'s blocks and, when the labels run in sample order (as
        :mod:`station.diagnose.residuals` makes them), each block's first position among them."""
        if sensor not in self._block_index:
            sd = self.baseline.sensor(sensor)
            idx = np.flatnonzero(sd.label >= 0)
            lab = sd.label[idx]
            starts = None
            if len(lab) and np.all(np.diff(lab) >= 0) and lab[0] == 0 and lab[-1] == len(sd.t_s) - 1:
                starts = np.flatnonzero(np.diff(lab, prepend=-1))
                if len(starts) != len(sd.t_s):
                    starts = None
            self._block_index[sensor] = (idx, starts)
        return self._block_index[sensor]

    def block_mean(self, sensor: str, values: np.ndarray) -> np.ndarray:
        """Mean of per-sample ``values`` (n, 3) over each block of ``sensor`` (m, 3)."""
        sd = self.baseline.sensor(sensor)
        if self._blocks(sensor)[1] is None:
            return sd.block_mean(values)
        cuts = self.cuts()
        sums = [self._block_sums(sensor, values[a:b], a, b) for a, b in itertools.pairwise(cuts)]
        return np.concatenate(sums) / sd.count[:, None]

    def _block_sums(self, sensor: str, values: np.ndarray, a: int, b: int) -> np.ndarray:
        """Sums over each block of ``sensor`` that starts in samples ``a:b`` of ``values`` (those samples, (b - a, 3));
        ``a`` and ``b`` are :meth:`cuts` (no block crosses them)."""
        idx, starts = self._blocks(sensor)
        assert starts is not None
        first = idx[starts]
        j0, j1 = np.searchsorted(first, [a, b], side="left")
        if j0 == j1:
            return np.zeros((0, values.shape[1]))
        k0 = starts[j0]
        k1 = starts[j1] if j1 < len(starts) else len(idx)
        return np.add.reduceat(values[idx[k0:k1] - a], starts[j0:j1] - k0, axis=0)

    def residual(self, sensor: str, simulated: np.ndarray) -> np.ndarray:
        """Recording minus the simulation per block of ``sensor`` (m, 3), the simulation given by its block means
        (m, 3) (:meth:`simulate`)."""
        if sensor not in self._recorded:
            s = self.baseline.session
            self._recorded[sensor] = self.block_mean(sensor, s.accel_mps2 if sensor == "accel" else s.gyro_radps)
        return self._recorded[sensor] - simulated

    def ref_columns(self, sensor: str) -> np.ndarray:
        """Block means of the rig reference columns that vary between blocks (M row terms), (m, j)."""
        if sensor not in self._ref_cols:
            ref_b = self.block_mean(sensor, self.baseline.sensor(sensor).ref)
            scale = max(1.0, float(np.abs(ref_b).max()))
            self._ref_idx[sensor] = [j for j in range(3) if np.ptp(ref_b[:, j]) > 1e-9 * scale]
            self._ref_cols[sensor] = ref_b[:, self._ref_idx[sensor]]
        return self._ref_cols[sensor]

    def ref_index(self, sensor: str) -> list[int]:
        """Which reference columns :meth:`ref_columns` holds."""
        self.ref_columns(sensor)
        return self._ref_idx[sensor]

    def fixed_basis(self, sensor: str) -> tuple[np.ndarray, np.ndarray]:
        """Orthonormal basis (m, p) of the block-size-weighted reference columns and ones, and sqrt(block sizes)."""
        if sensor not in self._basis:
            sw = np.sqrt(self.baseline.sensor(sensor).count)
            x = np.column_stack([self.ref_columns(sensor), np.ones(len(sw))]) * sw[:, None]
            u, sv, _ = np.linalg.svd(x, full_matrices=False)
            self._basis[sensor] = (u[:, sv > 1e-10 * sv[0]], sw)
        return self._basis[sensor]

    def simulate(
        self, triads: dict[str, Triad], effect_truth: EffectTruth, time_offset_s: dict[str, float],
        sensors: Sequence[str] = SENSORS, tilt_force: np.ndarray | None = None,
    ) -> dict[str, np.ndarray]:
        """Block means (m, 3) of the noise-free simulator output of ``sensors`` on the recording's motion,
        temperature and time stamps; one render per distinct time offset among them, in chunks (see the class).
        ``tilt_force``: added to the specific force (m/s^2, (n, 3)), the fitted pose tilts."""
        session = self.baseline.session
        z3 = np.zeros(3)
        shapes = EffectShapes(z3, z3, z3, z3, np.zeros((3, 3)), z3, z3, z3, z3, z3)
        unit = UnitTruth(serial=session.serial, accel=triads["accel"].truth(), gyro=triads["gyro"].truth(),
                         self_heating_k=0.0, self_heating_tau_s=1.0, temp_noise_std_k=0.0, temp_lsb_k=0.0,
                         shapes=shapes)
        need_rotation = bool(np.any(effect_truth.earth_rate_radps))
        out: dict[str, np.ndarray] = {}
        cuts = self.cuts()
        whole = len(cuts) == 2
        for delta in sorted({time_offset_s[s] for s in sensors}):
            model = ImuModel(unit, effect_truth=effect_truth, environment=self.environment,
                             temperature_degc=self.temperature)
            mine = [s for s in sensors if time_offset_s[s] == delta]
            sums: dict[str, list[np.ndarray]] = {s: [] for s in mine}
            for a, b in itertools.pairwise(cuts):
                kin, f = self.motion(delta, need_rotation, a, b)
                raw = model.render(kin, session.gravity_mps2,
                                   specific_force_mps2=f if tilt_force is None else f + tilt_force[a:b])
                del kin, f
                for s in mine:
                    y = raw.accel_mps2 if s == "accel" else raw.gyro_radps
                    if whole:  # one chunk: the blocks may not run in sample order
                        out[s] = self.block_mean(s, y)
                    else:
                        sums[s].append(self._block_sums(s, y, a, b))
                del raw
            if not whole:
                for s in mine:
                    out[s] = np.concatenate(sums[s]) / self.baseline.sensor(s).count[:, None]
        return out


#: Drift time constants tried by the re-fit, relative to the base fit's T_c (or the record's span).
TC_FACTORS = np.geomspace(0.2, 5.0, 17)


def _refit(drive: Drive, sensor: str, triad: Triad, d: np.ndarray) -> tuple[Triad, np.ndarray]:
    """Re-fit the base model's linear terms to the block residual ``d`` (m, 3): per axis the row of M,
    b_stat and the eq. (3) drift ``b_drift exp(-t/T_c)`` (T_c from a grid around the base fit's, or around
    the record's span where the base fit left it unresolved; inside the sensor class's range where the
    baseline has one), weighted least squares (weights: block sizes).

    Returns the corrected triad and the block residual it leaves (the linear terms taken off ``d``).
    """
    sd = drive.baseline.sensor(sensor)
    q, sw = drive.fixed_basis(sensor)
    span = float(sd.t_s.max() + 0.5 * sd.width_s.max())
    tc_old = np.where(triad.drift_on, triad.correlation_time_s, span)
    tc0 = sd.clip_tc(tc_old)

    def drift(tc: np.ndarray) -> np.ndarray:  # block means of exp(-t/T_c), (m, ...) for T_c of shape (...)
        shape = (-1, *([1] * tc.ndim))
        return block_exp_mean(sd.t_s.reshape(shape), sd.width_s.reshape(shape), tc)

    # the residual without the old drift, whitened by the block sizes; then all T_c of the grid at once
    # (Frisch-Waugh: the drift column after projecting out M row and b_stat)
    y = (d + drift(tc_old) * np.where(triad.drift_on, triad.bias_drift, 0.0)) * sw[:, None]  # (m, 3)
    grid = sd.clip_tc(tc0[None, :] * TC_FACTORS[:, None])  # (g, 3), inside the sensor class's T_c range
    e = drift(grid) * sw[:, None, None]  # (m, g, 3)
    ry = y - q @ (q.T @ y)
    re = e - np.einsum("mp,pgk->mgk", q, np.einsum("mp,mgk->pgk", q, e))
    num = np.einsum("mgk,mk->gk", re, ry)
    den = np.einsum("mgk,mgk->gk", re, re)
    gain = np.divide(num**2, den, out=np.zeros_like(num), where=den > 0)
    tc_new = grid[np.argmax(gain, axis=0), np.arange(3)]
    expo = drift(tc_new)  # (m, 3)
    refs = drive.ref_columns(sensor)
    nref = refs.shape[1]
    m, b, bd = triad.misalignment.copy(), triad.bias_static.copy(), np.zeros(3)
    left = np.empty_like(d)
    for k in range(3):
        x = np.column_stack([refs, np.ones(len(d)), expo[:, k]]) * sw[:, None]
        beta, *_ = np.linalg.lstsq(x, y[:, k], rcond=None)
        left[:, k] = (y[:, k] - x @ beta) / sw
        m[k, drive.ref_index(sensor)] += beta[:nref]
        b[k] += beta[nref]
        bd[k] = beta[nref + 1]
    return Triad(m, b, bd, tc_new, np.ones(3, dtype=bool)), left


def run_model(
    drive: Drive, label: str, effects: Sequence[FittedEffect], *, refit: bool = True, render_refit: bool = True,
    sensors: Sequence[str] = SENSORS,
) -> ModelRun:
    """Simulate base + ``effects`` on the recording's motion and compare per block (only ``sensors``).

    With ``refit``, the base model's linear terms are corrected on the block means first and, with
    ``render_refit``, the simulator is run again with the corrected parameters (otherwise the correction is
    applied to the block residual, exact up to its product with the multiplicative effects; ``output`` is
    then None). Without effects the first run is not needed: the simulated base model is the base fit's
    mean model, whose block residual the baseline holds.
    """
    baseline = drive.baseline
    triads = _triads(baseline)
    et, offsets, tilt_force = _effect_truth(drive, effects)
    out: dict[str, np.ndarray] | None = None
    if effects or not refit:
        out = drive.simulate(triads, et, offsets, sensors, tilt_force)
        res = {s: drive.residual(s, out[s]) for s in sensors}
    else:
        res = {s: baseline.sensor(s).y for s in sensors}
    if refit:
        fits = {s: _refit(drive, s, triads[s], res[s]) for s in sensors}
        triads = {**triads, **{s: fits[s][0] for s in sensors}}
        if render_refit:
            out = drive.simulate(triads, et, offsets, sensors, tilt_force)
            res = {s: drive.residual(s, out[s]) for s in sensors}
        else:
            out = None
            res = {s: fits[s][1] for s in sensors}
    return ModelRun(label=label, effects=tuple(effects), triads=triads, effect_truth=et, time_offset_s=offsets,
                    output=out, block_residual=res)


def rerun(baseline: Baseline, findings: Iterable[FittedEffect], *, refit: bool = True) -> Rerun:
    """Re-run the simulator with the base model and with base + the accepted ``findings`` on the recording
    of ``baseline`` and compare both with it (see the module docstring).

    Raises :class:`station.kernel.errors.FitError` when the recording's time stamps cannot drive the simulator.
    """
    simulated, skipped = [], []
    for e in findings:
        effect = REGISTRY.get(e.effect)
        if effect is not None and effect.simulate is not None:
            simulated.append(e)
        else:
            reason = effect.not_simulated if effect is not None else "no simulator counterpart"
            skipped.append({"effect": e.effect, "sensor": e.sensor, "reason": reason})
    drive = Drive(baseline)
    for e in simulated:  # the pose tilts' force, then the (n, 3, p) regressors it came from can go
        if e.effect == pose_tilt.NAME:
            drive.tilt_force(e.theta)
    pose_tilt.release(baseline)
    base = run_model(drive, "base", [], refit=refit)
    if not simulated:
        return Rerun(baseline, base, base, (), tuple(skipped))
    extended = run_model(drive, "extended", simulated, refit=refit)
    # an effect on the specific force (the lever arm) reaches the gyro through G f
    coupled = (any(REGISTRY[e.effect].reaches_gyro for e in simulated)
               and bool(np.any(extended.effect_truth.g_sensitivity)))
    alone = []
    for e in simulated:
        only = all(x is e for x in simulated if x.sensor == e.sensor)
        if only and (e.sensor == "accel" or not coupled):  # the only effect on its sensor, and none reaches it
            alone.append(extended)
        else:
            alone.append(run_model(drive, f"base + {e.effect} ({e.sensor})", [e], refit=refit, render_refit=False,
                                   sensors=(e.sensor,)))
    return Rerun(baseline, base, extended, tuple(alone), tuple(skipped))


__all__ = [
    "SIMULATED", "STOCHASTIC", "Drive", "FittedEffect", "ModelRun", "Rerun", "Triad", "block_statistics", "rerun",
    "run_model",
]
