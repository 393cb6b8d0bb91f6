"""One registry of the diagnosis's candidate effects: each one's regressors, parameters, units and rules.

One :class:`Effect` per candidate owns everything the diagnosis knows about it:

* its **regressors** (mean candidates: ``build(baseline, sensor_data) -> Z`` of shape (n, 3, p), the
  functions of :mod:`station.diagnose.candidates` and :mod:`station.diagnose.pose_tilt`; None for the two
  candidates that are not mean terms: ``bias_random_walk`` changes the block covariance and ``outliers``
  is a count),
* its **parameters and their engineering units** (``units[sensor] = (factor, unit)``: SI parameter times
  factor is the reported value; ``shape`` where the parameters form a matrix; :func:`engineering`),
* its **simulator mapping** (``simulate``: how a fitted theta enters the simulator's
  :class:`~station.physics.effects.EffectTruth` for the re-run of :mod:`station.diagnose.rerun`; None with
  the reason in ``not_simulated``),
* its **compensation mapping** (``compensation``: the physics effect whose parameter-set fields
  (:data:`station.fit.compensation.COMPENSATION`) compensate it; ``not_compensated``: why the calibration
  leaves it in the output where it does),
* its **identifiability rules** (:class:`Identifiability`: what the recording must hold for it to be
  testable, whether it competes with eq. 3's warm-up, and the rig step that separates it from the base
  model or from a candidate it is confused with).

:data:`NAMES` (the canonical order), :data:`MEAN_CANDIDATES`, :data:`LIBRARY` (the mean candidates) and
:data:`RIG_STEPS` are derived from :data:`EFFECTS`; no other module lists the effects.

Units: SI inside (m/s^2, rad/s, s, K); engineering units in the report.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import MISSING, dataclass, field, fields
from typing import Any, Literal

import numpy as np

from station.diagnose import candidates as c
from station.diagnose import pose_tilt
from station.diagnose.residuals import SENSORS, Baseline, SensorData
from station.physics.effects import EARTH_RATE_RADPS, GYRO_NONLINEARITY_REF_RADPS, STANDARD_GRAVITY, EffectTruth

_DEG = math.pi / 180.0

#: The simulator's per-axis effect coefficients (the vector fields of EffectTruth except G and the pose tilts).
_TRUTH_VECTORS = tuple(f.name for f in fields(EffectTruth)
                       if f.default is MISSING and f.name not in ("g_sensitivity", "pose_tilt_rad"))


class SimulatorInput:
    """What the accepted effects change in the simulator, accumulated effect by effect (SI).

    Attributes:
        baseline: the base fit the effects were fitted on.
        rotation_known: whether the recording's attitude is known (the Earth rate then has all three
            components; otherwise only the vertical one, as :func:`station.diagnose.candidates.attitude`).
        coefficients: :class:`EffectTruth` vector coefficients by field name, (3,) each.
        g_sensitivity: the gyro's G (3, 3), rad/s per m/s^2, starting from the base fit's.
        time_offset_s: per sensor, the time offset (s).
        tilt_force: the change of the true specific force (m/s^2, (n, 3)) by fitted pose tilts, None without.
    """

    def __init__(self, baseline: Baseline, rotation_known: Callable[[], bool]) -> None:
        self.baseline = baseline
        self.rotation_known = rotation_known
        self.coefficients: dict[str, Any] = {name: np.zeros(3) for name in _TRUTH_VECTORS}
        self.g_sensitivity = np.nan_to_num(np.asarray(baseline.params.gyro.g_sensitivity, dtype=float)).copy()
        self.time_offset_s = dict.fromkeys(SENSORS, 0.0)
        self.tilt_force: np.ndarray | None = None

    def truth(self) -> EffectTruth:
        """The simulator's coefficients (SI) of everything accumulated (time offsets apart)."""
        return EffectTruth(g_sensitivity=self.g_sensitivity, **self.coefficients)


Simulate = Callable[[SimulatorInput, np.ndarray, str], None]


def _add(field_suffix: str) -> Simulate:
    """Simulator mapping: theta (3,) added to ``{sensor}_{field_suffix}`` of the EffectTruth."""
    def simulate(acc: SimulatorInput, theta: np.ndarray, sensor: str) -> None:
        acc.coefficients[f"{sensor}_{field_suffix}"] += theta
    return simulate


def _sim_g_sensitivity(acc: SimulatorInput, theta: np.ndarray, sensor: str) -> None:
    acc.g_sensitivity += theta.reshape(3, 3)  # row k: gyro axis k per specific force


def _sim_lever_arm(acc: SimulatorInput, theta: np.ndarray, sensor: str) -> None:
    acc.coefficients["lever_arm_m"] += theta  # sensor frame (m)


def _sim_earth_rotation(acc: SimulatorInput, theta: np.ndarray, sensor: str) -> None:
    session = acc.baseline.session
    lat = session.meta_float("latitude_deg") or 0.0
    world = c.earth_rate_world(lat, session.meta_float("heading_deg") or 0.0)
    if not acc.rotation_known():  # as candidates.py: only the vertical part, along 'up'
        world = np.array([0.0, 0.0, world[2]])
    acc.coefficients["earth_rate_radps"] += float(theta[0]) * world


def _sim_time_offset(acc: SimulatorInput, theta: np.ndarray, sensor: str) -> None:
    acc.time_offset_s[sensor] += float(theta[0])


def _sim_pose_tilt(acc: SimulatorInput, theta: np.ndarray, sensor: str) -> None:
    # the poses' true gravity is f_ref x phi off the reference
    acc.tilt_force = pose_tilt.specific_force_change(acc.baseline, acc.baseline.accel, theta)


@dataclass(frozen=True)
class Identifiability:
    """What a candidate needs from the recording, and what separates it.

    Where the rules act: ``needs`` in the regressors (None or zeros: a rejection ``not testable``);
    ``profile_tc`` in :meth:`station.diagnose.likelihood.SensorProblem.test_mean`; ``base_twin`` and the
    pairs of candidates in :func:`station.diagnose.selection.select`; ``rig_free`` in
    :mod:`station.diagnose.rigfree_diagnosis` (the candidates a hand-held recording tests, and the reasons for the
    others, :func:`rig_free_testable`). Which candidates a recording cannot
    tell apart (e.g. ``scale_asymmetry`` and ``scale_nonlinearity_even`` with fewer than three input
    magnitudes) is decided from the data, not from the plan: two candidates whose fitted signals explain
    each other to ``COLLINEAR_R2`` are listed as inseparable, with both candidates' ``rig_step``.

    Attributes:
        needs: what the recording must hold for the candidate to be testable at all; the regressors
            return None (``not testable: no data for it``) or zeros (``never excites it``) otherwise.
        rig_step: the rig step that separates it from the base model or from a candidate it is confused
            with (quoted for rejections the base model absorbs and for inseparable pairs).
        profile_tc: it looks like eq. 3's warm-up drift: tested with the drift's T_c re-fitted
            (:data:`station.diagnose.likelihood.PROFILE_TC`).
        base_twin: the part of the base model it can be inseparable from (listed as the pair's second
            member by :mod:`station.diagnose.selection`), or None.
        rig_free: per sensor, why a rig-free recording (hand-held still poses, no rig reference:
            :mod:`station.fit.rigfree_fit`) cannot test it; a sensor not listed: testable there, as far as the
            recording holds what ``needs`` says.
        wander_like: a function of time alone, the same in every pose (a temperature bias follows the
            temperature's slow course): a bias random walk can imitate it, so
            :meth:`station.diagnose.likelihood.SensorProblem.test_mean` also tests it with a random walk
            allowed in both hypotheses (the walk's own test has the temperature course as a nuisance term:
            each is tested given the other).
        family: candidates of one family are forms of the same physics (the odd scale terms ``u|u|`` and
            ``u^3``: a scale nonlinearity odd in the input); where the recording cannot tell the forms apart,
            :mod:`station.diagnose.selection` names the better-fitting form as the finding and lists the others
            in its evidence (``form_inseparable_from``) instead of naming nothing. None: no family.
    """

    needs: str
    rig_step: str
    profile_tc: bool = False
    base_twin: str | None = None
    rig_free: Mapping[str, str] = field(default_factory=dict)
    wander_like: bool = False
    family: str | None = None


@dataclass(frozen=True)
class Effect:
    """One candidate effect of the diagnosis (see the module docstring).

    Attributes:
        name: the effect's name in reports (and, where the simulator has it, in
            :class:`station.physics.effects.Effects`).
        kind: ``mean`` (regressors), ``noise`` (block covariance) or ``count`` (outlier count).
        sensors: the sensors it applies to.
        description: one line for people.
        build: the regressors of a mean candidate, None otherwise.
        units: per sensor, (factor from the SI parameters to the engineering unit, the unit).
        shape: the parameters' shape where they form a matrix (None: a vector).
        per_axis: a three-parameter vector whose parameter k acts on output axis k (False: e.g. the lever arm).
        engineering: a custom conversion of (theta, cov) to the report's parameters (replaces the generic one).
        extra: additional engineering values from theta (e.g. the lever arm's length).
        consistency: the splits of the recording its effect-specific consistency checks compare its
            parameters across (:data:`station.diagnose.finding_consistency.PARTS` names).
        not_checked: why it has no consistency check (empty where it has one).
        simulate: the simulator mapping of fitted parameters, None when not simulated.
        not_simulated: why it is not simulated (empty when it is).
        reaches_gyro: an accelerometer effect whose simulated change of the specific force reaches the gyro
            through G (the re-run then simulates each gyro finding alone instead of reusing the extended run).
        compensation: the physics effect whose parameter-set fields compensate it, None without parameters.
        not_compensated: why the calibration leaves it in the output (empty where it may compensate it).
        identifiability: :class:`Identifiability`.
    """

    name: str
    kind: Literal["mean", "noise", "count"]
    sensors: tuple[str, ...]
    description: str
    build: Callable[[Baseline, SensorData], np.ndarray | None] | None
    units: Mapping[str, tuple[float, str]]
    identifiability: Identifiability
    simulate: Simulate | None = None
    not_simulated: str = ""
    reaches_gyro: bool = False
    compensation: str | None = None
    not_compensated: str = ""
    shape: tuple[int, int] | None = None
    per_axis: bool = True
    engineering: Callable[[np.ndarray, np.ndarray], dict[str, object]] | None = None
    extra: Callable[[np.ndarray], dict[str, object]] | None = None
    consistency: tuple[str, ...] = ()
    not_checked: str = ""

    def regressors(self, baseline: Baseline, sd: SensorData) -> np.ndarray | None:
        """The per-sample regressors (n, 3, p) of a mean candidate on ``sd`` (None: not a mean term, or no data)."""
        return None if self.build is None else self.build(baseline, sd)

    def regressor_rows(self, baseline: Baseline, sd: SensorData) -> c.Rows | None:
        """:meth:`regressors` a piece of samples at a time (:class:`~station.diagnose.candidates.Rows`): the
        candidate's rows where its builder was made of them (:func:`~station.diagnose.candidates.whole`), else the
        rows of its whole array."""
        rows = c.rows_builder(self.build) if self.build is not None else None
        if rows is not None:
            return rows(baseline, sd)
        z = self.regressors(baseline, sd)
        return None if z is None else c.rows_of(z)


def _both(accel: tuple[float, str], gyro: tuple[float, str]) -> dict[str, tuple[float, str]]:
    return {"accel": accel, "gyro": gyro}


def _same(unit: tuple[float, str], sensors: tuple[str, ...] = SENSORS) -> dict[str, tuple[float, str]]:
    return dict.fromkeys(sensors, unit)


_NL_UNIT = ("relative scale error at 1 g", "relative scale error at 200 deg/s")
_TEMPERATURE = "a temperature rise during the recording (the temperature column changes)"
_INPUT = "a non-zero input on the axis (poses for the accelerometer, rate steps for the gyroscope)"
_STOCHASTIC = "stochastic: does not change the expected output"
# why a rig-free recording cannot test a candidate (Identifiability.rig_free)
_RF_NO_RATE = ("no known rate: a hand-held recording's only gyro reference is zero in the still poses (the moves' "
               "rates are unknown; only the rotation between two stills is known, and the base fit spends it on M)")
_RF_NORM_ONLY = ("no per-axis reference: each still pose's gravity direction is a free parameter of the rig-free fit "
                 "(2 of its 3 numbers), only the gravity norm is left, and the rig-free fit takes the linear part of "
                 "it; a scale polynomial shows only through its projection on the norm, which this per-axis test "
                 "does not model")
_RF_DELAY = ("the references are the still poses: a delay shifts no still's mean, and the rotation between two "
             "stills does not depend on when it was sampled (an accelerometer-gyroscope delay could show in the "
             "moves' gravity direction, not modelled)")
_NO_SIM = "no simulator counterpart"
_ODD_SCALE = "scale nonlinearity odd in the input"

#: Every candidate effect, in the canonical order of :data:`NAMES` (report, benchmarks' seeds and tables).
EFFECTS: tuple[Effect, ...] = (
    Effect(
        "temperature_bias", "mean", ("accel", "gyro"), "bias proportional to the temperature rise",
        c.temperature_bias, _both((1e3 / STANDARD_GRAVITY, "mg/K"), (1.0 / _DEG, "deg/s/K")),
        Identifiability(
            _TEMPERATURE,
            "a temperature course no warm-up exponential can follow: a climate-chamber cycle (e.g. "
            "+-2 K with a 5 min period) during the session; a ramp is not enough (a slow warm-up "
            "is a ramp too)",
            profile_tc=True, base_twin="bias_drift (eq. 3 warm-up)", wander_like=True),
        simulate=_add("temp_bias"),  # + c dT
        compensation="temperature_bias", consistency=("early_vs_late", "heating_vs_cooling"),
    ),
    Effect(
        "temperature_scale", "mean", ("accel", "gyro"), "scale factor proportional to the temperature rise",
        c.temperature_scale, _same((1e6, "ppm/K")),
        Identifiability(_TEMPERATURE + " and a non-zero input while it does",
                        "repeat poses or rate steps late in the session, when the unit is warm", profile_tc=True,
                        rig_free={"gyro": _RF_NO_RATE + "; a scale change needs a non-zero input"}),
        simulate=_add("temp_scale"),  # (M x)(1 + s dT)
        compensation="temperature_scale", consistency=("early_vs_late",),
    ),
    Effect(
        "g_sensitivity", "mean", ("gyro",), "gyro output proportional to specific force",
        c.g_sensitivity, _same((STANDARD_GRAVITY / _DEG, "deg/s per g"), ("gyro",)),
        Identifiability("a specific-force reference (gravity poses or rate steps)",
                        "rate steps with the spin axis horizontal, or poses at two headings"),
        simulate=_sim_g_sensitivity, compensation="g_sensitivity", shape=(3, 3), consistency=("poses_vs_rates",),
    ),
    Effect(
        "scale_nonlinearity", "mean", ("accel", "gyro"), "quadratic scale term u|u|",
        c.nonlinearity,
        _both((STANDARD_GRAVITY, _NL_UNIT[0]), (GYRO_NONLINEARITY_REF_RADPS, _NL_UNIT[1])),
        Identifiability(_INPUT + "; told from the scale factor at two or more input magnitudes",
                        "steps at a second input magnitude (more rates, or tilted poses for the accelerometer)",
                        rig_free={"accel": _RF_NORM_ONLY, "gyro": _RF_NO_RATE}, family=_ODD_SCALE),
        simulate=_add("nonlinearity"),  # u + k u|u|
        compensation="scale_nonlinearity", consistency=("negative_vs_positive_input", "low_vs_high_input"),
    ),
    Effect(
        "scale_asymmetry", "mean", ("accel", "gyro"), "different scale for positive and negative input",
        c.asymmetry, _same((1.0, "relative (positive - negative scale)")),
        Identifiability(_INPUT + "; told from the even scale term at three or more input magnitudes",
                        "both signs of every rate step and both poses of every axis, at three or more rates",
                        rig_free={"accel": _RF_NORM_ONLY, "gyro": _RF_NO_RATE}),
        simulate=_add("asymmetry"),  # u (1 + a/2 sign u) = u + (a/2)|u|
        compensation="scale_asymmetry",
        not_compensated="no parameter for a sign-dependent scale in the parameter set",
        consistency=("negative_vs_positive_input", "low_vs_high_input"),
    ),
    Effect(
        "lever_arm", "mean", ("accel",), "accelerometer off the rotation centre: w x (w x r) + a x r",
        c.lever_arm, _same((1e3, "mm"), ("accel",)),
        Identifiability("a non-zero rate reference (rate steps or ramps)",
                        "rate steps at two or more rates about each axis",
                        rig_free={"accel": "needs known rates and angular accelerations (rate-table steps); "
                                           "the hand's are unknown"}),
        simulate=_sim_lever_arm, reaches_gyro=True, compensation="lever_arm",
        not_compensated="a property of the rig mounting, not of the unit",
        per_axis=False, extra=lambda theta: {"length_mm": round(float(np.linalg.norm(theta) * 1e3), 3)},
        consistency=("low_vs_high_input",),
    ),
    Effect(
        "earth_rotation", "mean", ("gyro",), "Earth rate at the site's latitude and heading",
        c.earth_rotation, _same((1.0, "multiple of the Earth rate"), ("gyro",)),
        Identifiability("the site's latitude_deg in the recording's metadata (heading_deg, and a start pose "
                        "among the rig's six for the horizontal part)",
                        "each pose held at two headings (table turned 180 deg about the vertical)",
                        rig_free={"gyro": "needs the heading of every pose, which a hand does not keep; the vertical "
                                          "part Omega sin(lat) lies along gravity in every pose, a g-sensitivity "
                                          "c I: removed with latitude_deg in the metadata, otherwise a "
                                          "g-sensitivity it explains is not named"}),
        simulate=_sim_earth_rotation, compensation="earth_rotation",
        not_compensated="a property of the place, not of the unit",
        extra=lambda theta: {"deg_per_h": round(float(theta[0] * EARTH_RATE_RADPS / _DEG * 3600.0), 4)},
        consistency=("early_vs_late",),
    ),
    Effect(
        "time_offset", "mean", ("accel", "gyro"),
        "sensor samples late against the rig reference (exact delay, fitted by a 1-D search)",
        c.time_offset, _same((1e3, "ms")),
        Identifiability("a reference that changes in time (rate ramps or pose changes)",
                        "rate-table ramps with higher angular acceleration",
                        rig_free={"accel": _RF_DELAY, "gyro": _RF_DELAY}),
        simulate=_sim_time_offset, compensation="time_offset",
        not_compensated="carried as time_offset_s in the set but not estimated by the fit nor applied to values",
        consistency=("tumbles_vs_ramps",),
    ),
    Effect(
        "bias_random_walk", "noise", ("accel", "gyro"),
        "bias wandering as K sqrt(t) (block covariance K^2 min(t_i, t_j))",
        None, _both((1.0, "m/s^2/sqrt(s)"), (180.0 / math.pi, "deg/s/sqrt(s)")),
        Identifiability("a record long against eq. 3's warm-up (tested once no mean candidate passes)",
                        "a still rest several correlation times long", profile_tc=True),
        not_simulated=_STOCHASTIC, compensation="bias_random_walk",
        not_compensated="a random process: no calibration removes it",
        not_checked="a covariance, not a mean term: no parameters to compare between parts of the recording",
    ),
    Effect(
        "outliers", "count", ("accel", "gyro"), "more single bad samples than the sensor class allows",
        None, _same((1.0, "1")),
        Identifiability("settled samples (the base fit's outlier count)", "a longer still rest"),
        not_simulated=_STOCHASTIC, compensation="outliers",
        not_compensated="single bad samples: Algorithm 1's moving average only dilutes them",
        not_checked="a count of single samples, tested against the sensor class's allowance",
    ),
    Effect(
        pose_tilt.NAME, "mean", pose_tilt.SENSORS, pose_tilt.DESCRIPTION,  # ours: the rig's poses are off
        pose_tilt.build, _same((1.0 / _DEG, "deg"), pose_tilt.SENSORS),
        Identifiability("still gravity poses (pose segments); the half-sums also segments outside the poses "
                        "that see gravity along the pose's axis", pose_tilt.RIG_STEP,
                        rig_free=dict.fromkeys(pose_tilt.SENSORS, "no independent pose reference: every pose's "
                                               "gravity direction is a free parameter of the rig-free fit")),
        # its tilt force reaches the gyro through G as well, but the re-run has not marked it (kept as it was)
        simulate=_sim_pose_tilt, compensation="pose_tilt",
        not_compensated="a property of the rig's poses, not of the unit",
        per_axis=False, engineering=pose_tilt.engineering,
        not_checked="parameters per pose, most poses visited once: no second part to compare with",
    ),
    # the IEEE Std 952 / 1431 scale-factor polynomial, its even (k2 u^2) and odd (k3 u^3) terms apart
    Effect(
        "scale_nonlinearity_even", "mean", ("accel", "gyro"),
        "IEEE scale polynomial, even term k2 u^2 (same error for both signs)",
        c.poly_even, _both((STANDARD_GRAVITY, _NL_UNIT[0]), (GYRO_NONLINEARITY_REF_RADPS, _NL_UNIT[1])),
        Identifiability(_INPUT + "; told from the scale asymmetry at three or more input magnitudes",
                        "rate steps at three or more magnitudes, both signs (|w| and w^2 then differ)",
                        rig_free={"accel": _RF_NORM_ONLY, "gyro": _RF_NO_RATE}),
        not_simulated=_NO_SIM,
        not_compensated="no parameter: the even scale term (k2 w^2) is not in the parameter set",
        consistency=("negative_vs_positive_input", "low_vs_high_input"),
    ),
    Effect(
        "scale_nonlinearity_odd", "mean", ("accel", "gyro"), "IEEE scale polynomial, odd term k3 u^3",
        c.poly_odd,
        _both((STANDARD_GRAVITY**2, _NL_UNIT[0]), (GYRO_NONLINEARITY_REF_RADPS**2, _NL_UNIT[1])),
        Identifiability(_INPUT + "; told from u|u| at three or more input magnitudes",
                        "rate steps at three or more magnitudes (w|w| and w^3 then differ)",
                        rig_free={"accel": _RF_NORM_ONLY, "gyro": _RF_NO_RATE}, family=_ODD_SCALE),
        not_simulated=_NO_SIM,
        # the fit's u + k u|u| is odd in the rate: it stands for the odd (cubic-like) term, not the even one
        compensation="scale_nonlinearity", consistency=("negative_vs_positive_input", "low_vs_high_input"),
    ),
)

#: Effect by name.
REGISTRY: dict[str, Effect] = {e.name: e for e in EFFECTS}
#: Every candidate's name, in the canonical order.
NAMES: tuple[str, ...] = tuple(REGISTRY)
#: Candidates that are mean terms (regressors); the others are tested by the selection directly.
MEAN_CANDIDATES: tuple[str, ...] = tuple(e.name for e in EFFECTS if e.kind == "mean")
#: The mean candidates by name (each with ``build``, ``sensors``, ``description``).
LIBRARY: dict[str, Effect] = {e.name: e for e in EFFECTS if e.kind == "mean"}
#: Per candidate, the rig step that separates it from the base model or from another candidate.
RIG_STEPS: dict[str, str] = {e.name: e.identifiability.rig_step for e in EFFECTS}
#: Candidates whose parameters form a matrix rather than a per-axis vector.
SHAPES: dict[str, tuple[int, int]] = {e.name: e.shape for e in EFFECTS if e.shape is not None}


def rig_free_testable() -> tuple[dict[str, tuple[str, ...]], list[tuple[str, str, str]]]:
    """What a rig-free recording can test (``Identifiability.rig_free``): per sensor the mean candidates, and
    (effect, sensor, reason) for each candidate it cannot test. ``bias_random_walk`` and ``outliers`` are
    tested on any recording (not mean candidates: the selection tests them itself)."""
    testable: dict[str, tuple[str, ...]] = {}
    not_testable: list[tuple[str, str, str]] = []
    for sensor in SENSORS:
        here = [e for e in EFFECTS if sensor in e.sensors]
        testable[sensor] = tuple(e.name for e in here if e.kind == "mean" and sensor not in e.identifiability.rig_free)
        not_testable += [(e.name, sensor, e.identifiability.rig_free[sensor]) for e in here
                         if sensor in e.identifiability.rig_free]
    return testable, not_testable


def unit_factor(name: str, sensor: str) -> tuple[float, str]:
    """The factor from candidate ``name``'s SI parameters to its engineering unit, and that unit."""
    return REGISTRY[name].units[sensor]


def engineering(name: str, sensor: str, theta: np.ndarray, cov: np.ndarray) -> dict[str, object]:
    """Fitted SI parameters (and covariance) of candidate ``name`` in engineering units (``units``), reshaped to
    the effect's ``shape``, with its ``extra`` values (lever_arm: the arm's length in mm, earth_rotation: the
    rate in deg/h); pose_tilt per pose pair (:func:`station.diagnose.pose_tilt.engineering`)."""
    effect = REGISTRY[name]
    if effect.engineering is not None:
        return effect.engineering(theta, cov)
    factor, unit = effect.units[sensor]
    v, s = theta * factor, np.sqrt(np.clip(np.diag(cov), 0.0, None)) * factor
    if effect.shape is not None:
        v, s = v.reshape(effect.shape), s.reshape(effect.shape)
    out: dict[str, object] = {"value": np.round(v, 9).tolist(), "std": np.round(s, 9).tolist(), "unit": unit}
    if effect.extra is not None:
        out.update(effect.extra(theta))
    return out


def simulator_input(baseline: Baseline, rotation_known: Callable[[], bool],
                    effects: list[tuple[str, str, np.ndarray]]) -> SimulatorInput:
    """The simulator's input for ``(name, sensor, theta)`` fitted effects (KeyError: an effect the simulator
    does not have)."""
    acc = SimulatorInput(baseline, rotation_known)
    for name, sensor, theta in effects:
        simulate = REGISTRY[name].simulate
        if simulate is None:
            raise KeyError(name)
        simulate(acc, np.asarray(theta, dtype=float), sensor)
    return acc


__all__ = [
    "EFFECTS", "LIBRARY", "MEAN_CANDIDATES", "NAMES", "REGISTRY", "RIG_STEPS", "SHAPES", "Effect", "Identifiability",
    "SimulatorInput", "engineering", "rig_free_testable", "simulator_input", "unit_factor",
]
