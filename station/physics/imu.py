"""The simulated IMU: renders raw accelerometer, gyroscope and temperature samples.

:class:`ImuModel` applies the paper's eq. (1) per triad,

    x~ = M x + b_stat + b_drift * g(t) + n,    g(0) = 1,   dg/dt = -g / T_c + w_g   (eq. 3)

plus the optional effects of :mod:`station.physics.effects`, outliers, and the ADC
(quantization to the LSB, clipping at full scale, applied last). It is stateful and
chunkable: consecutive :meth:`ImuModel.render` calls continue the time series, and
rendering in one call or in any split into consecutive chunks gives bit-identical
output, because every random stream has its own generator and consumes a fixed number
of draws per sample.

Per axis, in this order (``u`` the true input: specific force at the accelerometer incl.
lever arm, or body rate incl. Earth rate; ``dT`` true temperature minus its power-on value):

    u1 = (M u) * (1 + s_T dT)                     misalignment (eq. 1), temperature scale
    u2 = u1 + k u1|u1|,  u3 = u2 (1 +- a/2)        scale nonlinearity, asymmetry (sign of u2)
    y  = u3 + b_stat + b_drift exp(-t/T_c) + x_GM(t) + c_T dT + b_RW(t) + n + outliers
    gyro only: y += G f                            g-sensitivity
    output = clip(round(y / LSB)) * LSB

where ``b_drift (exp(-t/T_c) + x_GM/b_drift)`` is the exact solution of eq. (3) with g(0) = 1:
its mean ``exp(-t/T_c)`` plus a zero-start GM process of stationary std ``drift_noise``.

Units: t in s since power-on, specific force m/s^2, angular rate rad/s, temperature degC.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy.signal import lfilter

from station.kernel.geometry import Kinematics
from station.kernel.sensor_class import TABLE1, SensorClass
from station.physics.effects import Effects, EffectTruth
from station.physics.unit import TriadTruth, UnitTruth

#: Random streams, each its own generator spawned from the model's seed (order is part of the contract).
STREAMS = (
    "accel_noise",
    "gyro_noise",
    "accel_drift",
    "gyro_drift",
    "accel_outliers",
    "gyro_outliers",
    "temperature",
    "accel_walk",
    "gyro_walk",
    "environment",
)

#: Time resolution (s) to which sample intervals are rounded for the Gauss-Markov recursion.
DT_RESOLUTION_S = 1e-6


@dataclass(frozen=True)
class Environment:
    """The room the unit is powered on in.

    Attributes:
        ambient_degc: ambient temperature at power-on (degC); the unit starts at it, and it
            is the reference ``T_ref`` of the temperature effects.
        ambient_rate_k_per_s: slow linear drift of the ambient temperature (K/s).
        cycle_k, cycle_period_s: climate-chamber cycle ``cycle_k sin(2 pi t / cycle_period_s)`` (K, s).
    """

    ambient_degc: float = 23.0
    ambient_rate_k_per_s: float = 0.0
    cycle_k: float = 0.0
    cycle_period_s: float = 600.0

    @classmethod
    def draw(cls, sensor_class: SensorClass, rng: np.random.Generator) -> Environment:
        amb = float(rng.uniform(*sensor_class.ambient_degc))
        rate = float(rng.uniform(*sensor_class.ambient_rate_k_per_h)) / 3600.0
        return cls(amb, rate, sensor_class.ambient_cycle_k, sensor_class.ambient_cycle_period_s)

    def ambient(self, t_s: np.ndarray) -> np.ndarray:
        """Ambient temperature (degC) at ``t_s`` (s since power-on)."""
        out = self.ambient_degc + self.ambient_rate_k_per_s * t_s
        if self.cycle_k:
            out = out + self.cycle_k * np.sin(2.0 * np.pi * t_s / self.cycle_period_s)
        return out


@dataclass(frozen=True, eq=False)
class RawSamples:
    """What the sensor outputs for a block of samples.

    Attributes:
        t_s: sensor time since power-on (s), (n,).
        accel_mps2: specific force (m/s^2), (n, 3).
        gyro_radps: angular rate (rad/s), (n, 3).
        temp_degc: temperature (degC), (n,).
    """

    t_s: np.ndarray
    accel_mps2: np.ndarray
    gyro_radps: np.ndarray
    temp_degc: np.ndarray

    def __len__(self) -> int:
        return int(self.t_s.shape[0])


def _matvec(x: np.ndarray, m: np.ndarray) -> np.ndarray:
    """Rows ``m @ x[i]`` for x (n, 3), by elementwise operations.

    Not ``x @ m.T``: BLAS may change its summation order (or use FMA) with the block size,
    which would break bit-identical chunked rendering.
    """
    return x[:, 0:1] * m[:, 0] + x[:, 1:2] * m[:, 1] + x[:, 2:3] * m[:, 2]


class _GaussMarkov:
    """Per-axis first-order GM process ``y_k = phi_k y_{k-1} + std sqrt(1 - phi_k^2) e_k``, y(0) = 0.

    Exact discretization for the actual (rounded) sample interval; the recursion runs in
    :func:`scipy.signal.lfilter` over runs of equal interval, bit-identically across chunks.
    """

    def __init__(self, tau_s: np.ndarray, std: np.ndarray) -> None:
        self.tau = np.asarray(tau_s, dtype=float)
        self.std = np.asarray(std, dtype=float)
        self.y = np.zeros(3)

    def step(self, dt_s: np.ndarray, e: np.ndarray) -> np.ndarray:
        out = np.empty_like(e)
        change = np.flatnonzero(np.diff(dt_s) != 0) + 1
        starts = np.concatenate(([0], change))
        stops = np.concatenate((change, [len(dt_s)]))
        for a, b in zip(starts, stops, strict=True):
            for k in range(3):
                phi = math.exp(-dt_s[a] / self.tau[k])
                q = self.std[k] * math.sqrt(max(0.0, 1.0 - phi * phi))
                y, _ = lfilter([1.0], [1.0, -phi], q * e[a:b, k], zi=[phi * self.y[k]])
                out[a:b, k] = y
                self.y[k] = y[-1]
        return out


class _Triad:
    """One triad's configuration, random streams and process state (a helper of :class:`ImuModel`)."""

    def __init__(self, tr: TriadTruth, et: EffectTruth, name: str, rng: dict[str, np.random.Generator]) -> None:
        def on(v: np.ndarray) -> np.ndarray | None:
            return v if np.any(v) else None

        self.tr = tr
        self.temp_scale = on(getattr(et, f"{name}_temp_scale"))
        self.nonlinearity = on(getattr(et, f"{name}_nonlinearity"))
        self.quadratic = on(np.asarray(getattr(et, f"{name}_quadratic")))
        self.cubic = on(np.asarray(getattr(et, f"{name}_cubic")))
        self.asymmetry = on(getattr(et, f"{name}_asymmetry"))
        self.temp_bias = on(getattr(et, f"{name}_temp_bias"))
        self.walk_density = float(getattr(et, f"{name}_random_walk"))
        self.outlier_p = tr.outlier_probability + et.extra_outlier_probability
        self.outlier_size = tr.outlier_size if np.any(tr.outlier_size) else np.full(3, 8.0 * tr.lsb)
        self.gm = _GaussMarkov(tr.correlation_time_s, tr.drift_noise) if np.any(tr.drift_noise) else None
        self.walk = np.zeros(3)
        self.noise = np.any(tr.noise_std)
        self.rng_noise = rng[f"{name}_noise"]
        self.rng_drift = rng[f"{name}_drift"]
        self.rng_walk = rng[f"{name}_walk"]
        self.rng_outliers = rng[f"{name}_outliers"]
        self.top = round(tr.full_scale / tr.lsb) if tr.lsb > 0 else 0

    def output(self, x: np.ndarray, t: np.ndarray, dt: np.ndarray, dt_gm: np.ndarray, d_temp: np.ndarray) -> np.ndarray:
        """Unquantized output for the true input ``x`` (n, 3); advances the streams and state."""
        n, tr = t.shape[0], self.tr
        u = _matvec(x, tr.misalignment)  # M x, eq. (1)
        if self.temp_scale is not None:
            u = u * (1.0 + self.temp_scale * d_temp)
        if self.nonlinearity is not None:
            u = u + self.nonlinearity * u * np.abs(u)
        if self.quadratic is not None or self.cubic is not None:  # IEEE 952 polynomial
            q = np.zeros(3) if self.quadratic is None else self.quadratic
            c = np.zeros(3) if self.cubic is None else self.cubic
            u = u + q * u * u + c * u * u * u
        if self.asymmetry is not None:
            u = u * (1.0 + 0.5 * self.asymmetry * np.sign(u))
        # b_stat + b_drift g(t): the deterministic part of eq. (3) exactly, plus the stochastic GM part
        y = u + tr.bias_at(t)
        if self.gm is not None:
            y += self.gm.step(dt_gm, self.rng_drift.standard_normal((n, 3)))
        if self.temp_bias is not None:
            y += self.temp_bias * d_temp
        if self.walk_density > 0:
            steps = self.walk_density * np.sqrt(dt)[:, None] * self.rng_walk.standard_normal((n, 3))
            steps[0] += self.walk
            path = np.cumsum(steps, axis=0)
            self.walk = path[-1].copy()
            y += path
        if self.noise:
            y += tr.noise_std * self.rng_noise.standard_normal((n, 3))
        if self.outlier_p > 0:
            w = self.rng_outliers.random((n, 3, 2))  # one block per sample: chunking keeps the stream order
            v = 2.0 * w[..., 1] - 1.0
            y += np.where(w[..., 0] < self.outlier_p, np.sign(v) * (0.5 + np.abs(v)) * self.outlier_size, 0.0)
        return y

    def adc(self, y: np.ndarray) -> np.ndarray:
        """Quantize to the LSB and clip to ``[-full_scale, full_scale - lsb]`` (the last step)."""
        if self.top == 0:
            return y
        return np.clip(np.rint(y / self.tr.lsb), -self.top, self.top - 1) * self.tr.lsb


class ImuModel:
    """A stateful renderer of one unit's raw output.

    Args:
        truth: the unit (:func:`station.physics.unit.draw_unit`).
        sensor_class: used only to draw the :class:`Environment` when none is given.
        effects: optional physics (:class:`station.physics.effects.Effects`).
        seed: seeds every random stream (see :data:`STREAMS`).
        latitude_deg, heading_deg: the site, for ``earth_rotation``.
        environment: the room; drawn from the ``environment`` stream when None.
        effect_truth: explicit SI effect coefficients, used instead of realizing ``effects``
            with the unit's random shapes (e.g. coefficients fitted to a recording); the
            site arguments are then unused.
        temperature_degc: true sensor temperature (degC) as a function of sensor time (s),
            replacing the ambient drift and self-heating model (e.g. a recording's own
            temperature course); temperature effects act on it minus ``environment.ambient_degc``.

    Both keyword arguments default to None, which keeps the output bit-identical to a model
    built without them.

    The model does not shift time itself: with a ``time_offset`` effect, pass kinematics
    evaluated at rig time ``t_s - time_offset_s`` but stamped with the sensor times ``t_s``
    (``RigTrajectory.kinematics(t, time_offset_s=model.time_offset_s)`` does this).
    """

    def __init__(
        self,
        truth: UnitTruth,
        sensor_class: SensorClass = TABLE1,
        effects: Effects | None = None,
        seed: int | np.random.SeedSequence = 0,
        *,
        latitude_deg: float = 0.0,
        heading_deg: float = 0.0,
        environment: Environment | None = None,
        effect_truth: EffectTruth | None = None,
        temperature_degc: Callable[[np.ndarray], np.ndarray] | None = None,
    ) -> None:
        self.truth = truth
        self.effects = effects if effects is not None else Effects()
        self.effect_truth: EffectTruth = effect_truth if effect_truth is not None else self.effects.realize(
            truth.shapes, latitude_deg=latitude_deg, heading_deg=heading_deg
        )
        self._temperature = temperature_degc
        ss = seed if isinstance(seed, np.random.SeedSequence) else np.random.SeedSequence(seed)
        # explicit child keys (not ss.spawn) so a SeedSequence passed twice gives the same streams
        rng = {
            name: np.random.default_rng(np.random.SeedSequence(ss.entropy, spawn_key=(*ss.spawn_key, i)))
            for i, name in enumerate(STREAMS)
        }
        self._rng_temp = rng["temperature"]
        self.environment = environment if environment is not None else Environment.draw(
            sensor_class, rng["environment"]
        )
        et = self.effect_truth
        self._accel = _Triad(truth.accel, et, "accel", rng)
        self._gyro = _Triad(truth.gyro, et, "gyro", rng)
        self._lever_arm = et.lever_arm_m if np.any(et.lever_arm_m) else None
        self._earth = et.earth_rate_radps if np.any(et.earth_rate_radps) else None
        self._g_sens = et.g_sensitivity if np.any(et.g_sensitivity) else None
        self._t_last: float | None = None
        self.samples_rendered = 0

    @property
    def time_offset_s(self) -> float:
        """Sensor time minus rig time (s), from the ``time_offset`` effect."""
        return self.effect_truth.time_offset_s

    @property
    def t_last_s(self) -> float | None:
        """Time of the last rendered sample (s), None before the first."""
        return self._t_last

    def true_temperature(self, t_s: np.ndarray) -> np.ndarray:
        """True sensor temperature (degC): ambient drift plus self-heating since power-on, or the given course."""
        t = np.asarray(t_s, dtype=float)
        if self._temperature is not None:
            return np.asarray(self._temperature(t), dtype=float)
        env, u = self.environment, self.truth
        return env.ambient(t) + u.self_heating_k * -np.expm1(-t / u.self_heating_tau_s)

    def render(
        self, kin: Kinematics, gravity_mps2: float, *, specific_force_mps2: np.ndarray | None = None
    ) -> RawSamples:
        """Raw samples at ``kin.t_s`` (sensor time since power-on, s), continuing the last call.

        ``kin`` is what the sensor frame does (rotation, body rate, angular acceleration);
        ``gravity_mps2`` the local gravity. Times must be strictly increasing, >= 0, and
        later than the previous call's. ``specific_force_mps2`` (n, 3), when given, is the
        specific force at the rotation centre (m/s^2, sensor frame) instead of gravity along
        ``kin``'s up axis, e.g. a recording's reference; the lever arm is still added to it.
        """
        t = np.array(kin.t_s, dtype=float)
        n = t.shape[0]
        if n == 0:
            return RawSamples(t, np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0))
        prev = 0.0 if self._t_last is None else self._t_last
        if (self._t_last is None and t[0] < 0) or (self._t_last is not None and t[0] <= prev):
            raise ValueError(f"render: sample time {t[0]!r} does not follow the previous one ({prev!r})")
        dt = np.diff(t, prepend=prev)
        if n > 1 and not np.all(dt[1:] > 0):
            raise ValueError("render: sample times must be strictly increasing")
        dt_gm = np.round(dt / DT_RESOLUTION_S) * DT_RESOLUTION_S

        # --- what the sensor is exposed to ------------------------------------------------
        if specific_force_mps2 is None:
            f = kin.specific_force(gravity_mps2)
        else:
            f = np.array(specific_force_mps2, dtype=float)
            if f.shape != (n, 3):
                raise ValueError(f"render: specific_force_mps2 has shape {f.shape}, expected {(n, 3)}")
        omega = np.asarray(kin.omega_radps, dtype=float)
        if self._lever_arm is not None:
            r = self._lever_arm
            f = f + np.cross(omega, np.cross(omega, r)) + np.cross(kin.alpha_radps2, r)
        if self._earth is not None:
            rot, e = kin.rotation, self._earth  # R^T e: the world Earth rate in the sensor frame
            omega = omega + (rot[:, 0, :] * e[0] + rot[:, 1, :] * e[1] + rot[:, 2, :] * e[2])
        temp_true = self.true_temperature(t)
        d_temp = (temp_true - self.environment.ambient_degc)[:, None]

        # --- eq. (1) per triad, plus g-sensitivity of the gyro; the ADC last -------------------
        accel = self._accel.output(f, t, dt, dt_gm, d_temp)
        gyro = self._gyro.output(omega, t, dt, dt_gm, d_temp)
        if self._g_sens is not None:
            gyro += _matvec(f, self._g_sens)
        accel = self._accel.adc(accel)
        gyro = self._gyro.adc(gyro)

        # --- temperature channel ---------------------------------------------------------------
        temp = temp_true
        if self.truth.temp_noise_std_k > 0:
            temp = temp + self.truth.temp_noise_std_k * self._rng_temp.standard_normal(n)
        lsb = self.truth.temp_lsb_k
        temp = np.rint(temp / lsb) * lsb if lsb > 0 else temp

        self._t_last = float(t[-1])
        self.samples_rendered += n
        return RawSamples(t, accel, gyro, temp)
