"""Which candidate effects the recording supports: nested model comparison on block means.

Data: per sensor, the block-mean residuals of :mod:`station.diagnose.residuals`, three axes
stacked. Noise model per axis (block covariance, eq. 3's drift included):

    C = diag(sigma_w^2 / n_b + v_b) + q GM(T_c) + K^2 min(t_i, t_j)

with ``GM(T_c)_ij = exp(-|t_i - t_j|/T_c) - exp(-(t_i + t_j)/T_c)`` (the Gauss-Markov drift
started at power-on, eq. 3; ``T_c`` from the base fit, or the record's span when the base
fit left it unresolved) and ``q`` re-estimated per axis by maximum likelihood; ``K`` is the
``bias_random_walk`` candidate (0 in the base model); ``v_b`` the block's known extra variance
(``SensorData.extra_var``, 0 but on rig-free recordings). Without K the covariance is
diagonalized once per ``T_c`` (``D^-1/2 GM D^-1/2 = V diag(lambda) V^T``), so profiling q
costs one small weighted least-squares fit per trial value.


``bias_random_walk`` (:meth:`SensorProblem.test_random_walk`) is tested once no mean candidate passes
(an unmodelled mean signal also looks like a wander): a constrained likelihood-ratio test of ``K^2`` against eq. 3's
drift noise bounded by ``DRIFT_NOISE_MAX`` of the warm-up (a Gauss-Markov process much
slower than the record has the covariance of a random walk; only its size against the
warm-up tells them apart), with the temperature course as a nuisance term.

With the sensor class's range of T_c (``SensorData.tc_range_s``, e.g. from the station's limits
file), the warm-up's T_c stays inside it throughout (base model, re-fits, and the warm-up shapes a
temperature course is compared with): a self-heating course that decays faster than the class's
drift (gyroscope T_c 1030-3760 s against a self-heating time constant of a few hundred seconds) is
then no longer the same signal as the warm-up. Without it the recording alone decides T_c.

The forward selection that uses this is :mod:`station.diagnose.selection`; its checks under
misspecification :mod:`station.diagnose.robust`; the findings' report entries :mod:`station.diagnose.reporting`.
"""

from __future__ import annotations

import contextlib
import hashlib
import math
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy import linalg, optimize, stats
from scipy.ndimage import uniform_filter1d

from station.diagnose.effect_registry import EFFECTS
from station.diagnose.residuals import Baseline, SensorData
from station.fit.blocks import block_exp_mean, power_on_gm_correlation
from station.session.model import Kind

#: Significance of a single candidate test (chi^2 tail), on top of the BIC.
ALPHA = 1e-5
FOLDS = 4
#: A candidate may raise the held-out error by at most this many standard errors of the (paired) change.
HELDOUT_SE = 2.0
#: Relative singular-value cutoff of the candidate and held-out least squares: a candidate's columns that
#: the base terms already span (e.g. half of a pose tilt is a cross-axis term of M) get no wild coefficients.
RCOND = 1e-10
#: Drift noise the base model allows, relative to the warm-up's change over the record (see
#: :meth:`SensorProblem.drift_noise_max`); the simulated sensor class has about 1 % of b_drift.
DRIFT_NOISE_MAX = 0.1
#: The warm-up b_drift that bounds the drift noise is taken this many standard errors above its estimate.
WARMUP_SIGMAS = 2.0
#: Most rounds of the drift's T_c re-fit (:meth:`SensorProblem.refit_drift`); each moves T_c by up to a factor 4.
REFIT_ROUNDS = 8
#: Drift-noise correlation matrices kept per T_c (each (m, m) for m blocks).
GM_CACHE = 48
#: Cholesky factors of the block covariance kept (each (m, m), the most recently used): the T_c re-fit of a nested
#: test factors the same covariances for the null and the alternative (the candidate changes the mean, not C), and
#: the random walk's K^2 profile (:meth:`SensorProblem._profile_k2`) visits the same (q = 0, K^2) grid for both. 64
#: of 390 blocks hold 78 MB per sensor; 24 missed about a third of the repeats on a 15-minute recording
#: (docs/measurements/diagnosis.md).
CHOL_CACHE = 64
#: Outcomes of the drift's T_c re-fit kept (:meth:`SensorProblem.refit_drift`).
REFIT_CACHE = 4
#: Whether the drift noise q of eq. 3 is bounded in every fit (off: the base model as before):
#: its wander over the record at most ``Q_BOUND`` times the random-walk test's bound
#: (:meth:`SensorProblem.drift_noise_max`), i.e. at most the warm-up's own change over the record. Unbounded,
#: a large q takes any unmodelled mean structure (e.g. pose tilts) for drift noise and hides it from every test
#: and from the dispersion.
Q_BOUNDED = False
Q_BOUND = 10.0
#: Whether the bias random walk's test bounds eq. 3's drift noise q in its null by the sensor class too (``q_class``,
#: as the walk's size is), not by the warm-up's share alone (:meth:`SensorProblem.drift_noise_max`). Over a record
#: shorter than T_c the drift noise is itself a random walk, so a q above the class takes up the wander: on the
#: gyroscope the class bound raises the test's gain 2.5-22 fold at 10 x the independent generator's walk
#: (benchmarks/bench_gyro_walk_power.py) with no false finding on the generators' nulls; but a unit whose drift noise
#: is above its class then gets a walk named (the real OpenAXES BMI160 recording judged against Table 1, where the
#: locator reports that drift noise as unexplained). Off: the test as it was (docs/measurements/diagnosis.md).
WALK_NULL_CLASS_BOUND = False
#: Whether the bias random walk's test is a full profile likelihood ratio: eq. 3's warm-up T_c and drift noise q per
#: axis re-fitted in both hypotheses (:meth:`SensorProblem._walk_profiled_gain`), where the default keeps the null's T_c
#: and q in the alternative (conservative). See docs/measurements/diagnosis.md for what it gains and costs.
WALK_PROFILE_TC = False
#: T_c factors of one round of the walk test's T_c re-fit (:meth:`SensorProblem._walk_refit_tc`) and its most rounds.
WALK_TC_FACTORS = (0.5, 0.7, 1.4, 2.0)
WALK_TC_ROUNDS = 4
#: A bias random walk's increments are the same everywhere in the record: its K^2 estimated from the
#: settled blocks' increments in the first and the second half of the record, and from pairs of blocks inside
#: one segment and across a segment boundary, must agree within this many standard errors
#: (:meth:`SensorProblem.walk_consistency`); structure a mis-modelled mean effect leaves (jumps between poses,
#: a part of the record) does not.
WALK_CONSISTENCY_Z = 4.0
#: Shortest warm-up T_c (s) the diagnosis considers: a faster "warm-up" is no drift of eq. 3 at the blocks'
#: resolution (and its block means overflow).
TC_FLOOR_S = 1.0
#: T_c values (log-spaced over the class's range) over which a warm-up-like effect's size is integrated
#: (:meth:`SensorProblem.tc_marginal`).
TC_MARGINAL_POINTS = 9
#: Candidates that look like the warm-up drift: tested with the drift's T_c re-fitted.
PROFILE_TC = tuple(e.name for e in EFFECTS if e.identifiability.profile_tc)
#: Candidates a bias random walk can imitate (a function of time alone): tested with the walk allowed too.
WANDER_LIKE = tuple(e.name for e in EFFECTS if e.identifiability.wander_like)

#: Per axis of a held-out fold: Cholesky of the training covariance, kriging weights, conditional Cholesky.
_FoldAxis = tuple[np.ndarray, np.ndarray, np.ndarray | None]
#: The drift state of a :class:`SensorProblem`: T_c per axis, base columns, GM correlations, q per axis.
_State = tuple[np.ndarray, list[np.ndarray], list[np.ndarray], np.ndarray]


@dataclass
class Test:
    """Outcome of testing one candidate on one sensor at one selection step."""

    effect: str
    sensor: str
    gain: float  # 2 x log-likelihood gain (chi^2 units)
    params: int  # identifiable parameters added
    bic_gain: float  # gain - params ln N
    critical: float
    heldout_before: float = math.nan
    heldout_after: float = math.nan
    heldout_change_se: float = math.nan  # standard error of heldout_after - heldout_before (paired over the blocks)
    theta: np.ndarray = field(default_factory=lambda: np.zeros(0))
    cov: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    signal: np.ndarray = field(default_factory=lambda: np.zeros(0))  # whitened fitted signal of the effect
    span: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))  # whitened effect columns
    #: a ``WANDER_LIKE`` candidate's gain with a bias random walk (K^2 profiled) in both hypotheses; nan: not tried
    gain_given_walk: float = math.nan

    @property
    def threshold(self) -> float:
        """The chi^2 gain the test must exceed: the larger of the critical value and the BIC penalty ``p ln N``."""
        return max(self.critical, self.gain - self.bic_gain)

    @property
    def passes(self) -> bool:
        return self.params > 0 and self.gain > self.threshold and not self.walk_explains

    @property
    def walk_explains(self) -> bool:
        """A wander-like candidate that is significant only as long as no random walk is allowed: a bias random
        walk explains its signal as well (``gain_given_walk`` below the threshold)."""
        return bool(self.gain_given_walk <= self.threshold)  # False for nan

    @property
    def validates(self) -> bool:
        """The held-out error does not rise significantly with the effect (by at most ``HELDOUT_SE`` paired
        standard errors): an effect that only fits the segments it was fitted on fails; a slow effect, which
        the drift's conditional mean predicts about as well on held-out segments, is not left to a coin flip."""
        return self.heldout_after - self.heldout_before <= HELDOUT_SE * self.heldout_change_se


#: An accepted random walk's size (:meth:`SensorProblem._walk_profile`): the step in log K^2 of its bracket search
#: and the most steps either way; the tolerance of the search in the bracket (log K^2: 0.02 is 1 % in K).
WALK_SIZE_STEP = 0.5
WALK_SIZE_SPAN = 6
WALK_SIZE_XATOL = 0.02
#: Step in log K^2 either side of the walk's size at which its profile's fall gives K's std
#: (:meth:`SensorProblem._walk_size`); a relative std of K of 4-10 % is 0.08-0.2 in log K^2.
WALK_STD_STEP = 0.3


@dataclass(frozen=True)
class WalkConsistency:
    """:meth:`SensorProblem.walk_consistency`: whether the wander is the same throughout the record; ``z`` per
    comparison ("halves", "inside_vs_across_segments") the difference of the two K^2 estimates in standard
    errors; ``k2_pooled`` the pooled moment estimate; ``reason`` where no comparison could be made."""

    consistent: bool
    z: Mapping[str, float]
    k2_pooled: float | None = None
    reason: str | None = None


@dataclass(frozen=True, eq=False)
class ModelQuality:
    """The current model of one sensor (:meth:`SensorProblem.quality`): negative log-likelihood, BIC, block chi^2
    per axis (white-noise units), block residual RMS per axis and the raw block residual (m, 3), sensor units."""

    nll: float
    bic: float
    block_chi2: np.ndarray
    block_rms: np.ndarray
    block_residual: np.ndarray


def _digest(a: np.ndarray) -> bytes:
    """A digest of an array's bytes: the key of a cached factorization that depends on it."""
    return hashlib.blake2b(np.ascontiguousarray(a).tobytes(), digest_size=16).digest()


def base_drift(t_s: np.ndarray, sd: SensorData) -> np.ndarray:
    """The base fit's warm-up ``b_drift exp(-t/T_c)`` (eq. 3) at the sample times ``t_s`` (s), (n, 3), in the
    sensor's unit (m/s^2 or rad/s); zero on axes where the base fit left it unresolved.

    The block residual is taken against the base mean model *without* it: the base design's drift column
    then carries the whole ``b_drift`` at whatever T_c the diagnosis settles on. (A correction column
    ``exp(-t/T_c')`` on top of the base fit's ``b_drift exp(-t/T_c)`` leaves the base fit's drift in the data
    whenever T_c' moves away from T_c, e.g. when an unmodelled effect distorted the base fit's T_c.)
    """
    return sd.params.warmup_drift(t_s)


#: The temperature's direction (heating or cooling) is its slope over this window (s): the reading is quantized.
TEMP_SLOPE_WINDOW_S = 30.0
#: The walk's test holds the temperature's direction as a nuisance term when at least this share of the blocks
#: heats and as much cools.
TEMP_DIRECTION_SHARE = 0.1


def temperature_direction(baseline: Baseline, sd: SensorData) -> np.ndarray:
    """Per block, whether the temperature rises (+1) or falls (-1): the sign of its slope over
    :data:`TEMP_SLOPE_WINDOW_S`, block-averaged (m,); zeros without a temperature course."""
    temp = np.asarray(baseline.d_temp, dtype=float)
    if not np.ptp(temp) > 0:
        return np.zeros(len(sd.t_s))
    session = baseline.session
    w = max(3, int(TEMP_SLOPE_WINDOW_S * session.sample_rate_hz) | 1)
    slope = np.gradient(uniform_filter1d(temp, w, mode="nearest"), session.t_s)
    return np.asarray(sd.block_mean(np.sign(slope)), dtype=float)


@dataclass(frozen=True, eq=False)
class WhitenedFit:
    """The current model (the accepted effects) fitted by least squares in whitened units
    (:meth:`SensorProblem.whitened_fit`).

    Attributes:
        chols: per-axis Cholesky factors of the block covariance.
        yw: the whitened stacked data.
        x: the whitened stacked design (base columns per axis, then the accepted effects).
        nbase: the number of base columns.
        beta: the least-squares coefficients.
        res: the whitened residual ``yw - x beta``.
    """

    chols: list[np.ndarray]
    yw: np.ndarray
    x: np.ndarray
    nbase: int
    beta: np.ndarray
    res: np.ndarray


class SensorProblem:
    """The stacked block problem of one sensor; see the module docstring."""

    def __init__(self, baseline: Baseline, sd: SensorData) -> None:
        self.sd = sd
        self.m = len(sd.t_s)
        self.y = sd.y + sd.block_mean(base_drift(baseline.session.t_s, sd))  # (m, 3), see base_drift
        t = sd.t_s
        self.white = (sd.sigma[None, :] ** 2) / sd.count[:, None]  # (m, 3)
        if sd.extra_var is not None:  # known physics of unknown phase (SensorData.extra_var)
            self.white = self.white + sd.extra_var
        span = float(t.max() + 0.5 * sd.width_s.max())
        self.dist = np.abs(t[:, None] - t[None, :])
        # a random walk W (Var W(t) = K^2 t) averaged over blocks: Cov(mean_i, mean_j) = K^2 min(t_i, t_j) at the block
        # centres for two blocks, Var(mean_i) = K^2 (t_i - w_i / 6) for one of width w_i (the mean of W over
        # [a, a + w] has variance K^2 (a + w / 3)); without it, the walk's increments between adjacent blocks are
        # modelled K^2 w_i / 3 too large and K comes out low
        self.tmin = np.minimum(t[:, None], t[None, :])
        self.tmin[np.diag_indices(self.m)] -= sd.width_s / 6.0
        self._tmin_nonneg = bool(np.all(self.tmin >= 0.0))  # see _covariance
        self.d_temp = sd.block_mean(baseline.d_temp)  # temperature rise per block (K)
        self.temp_direction = temperature_direction(baseline, sd)  # heating +1 / cooling -1 per block
        # eq. 3's T_c inside the sensor class's range, where one is given (SensorData.tc_range_s)
        self.tc = np.maximum(sd.clip_tc(np.array([tc if np.isfinite(tc) and tc > 0 else span
                                                  for tc in sd.params.correlation_time_s])), TC_FLOOR_S)
        self._gm_cache: dict[float, np.ndarray] = {}
        self.gm = [self._gm(float(tc)) for tc in self.tc]
        ref_b = sd.block_mean(sd.ref)
        self.base: list[np.ndarray] = []
        self._ref_cols = [ref_b[:, j] for j in range(3) if np.ptp(ref_b[:, j]) > 1e-9 * max(1.0, np.abs(ref_b).max())]
        for k in range(3):
            self.base.append(self._base_design(float(self.tc[k])))
        self.n_rows = 3 * self.m
        self.q = np.zeros(3)
        self.k2 = 0.0
        self._eig_cache: dict[tuple[int, float], tuple[np.ndarray, np.ndarray, np.ndarray]] = {}
        #: Cholesky factors by (axis, T_c, q, K^2, white variance's digest), see :meth:`chol`
        self._chol_cache: dict[tuple[int, float, float, float, bytes], np.ndarray] = {}
        self._white_key = _digest(self.white)
        #: the held-out folds of the last covariance state (:meth:`_heldout_folds`)
        self._folds: tuple[tuple[bytes, bytes, float, bytes], list[tuple[np.ndarray, np.ndarray,
                                                                         list[_FoldAxis]]]] | None = None
        #: outcomes of :meth:`refit_drift` by the state it started from
        self._refit_cache: dict[tuple[bytes, bytes, float, bytes, tuple[bytes, ...]], _State] = {}
        self._accepted: list[np.ndarray] = []  # block regressors (m, 3, p) of accepted mean effects, see accepted
        #: the sensor class's largest drift-noise variance per axis (U^2), where the caller knows the class
        #: (selection.py, from locator.class_drift_noise): bounds q when an accepted walk's size is fitted
        self.q_class: np.ndarray | None = None
        #: the walk's test bounds q in its null by :attr:`q_class` too (:data:`WALK_NULL_CLASS_BOUND`)
        self.walk_null_class_bound = WALK_NULL_CLASS_BOUND
        #: the walk's test re-fits T_c and q in both hypotheses (:data:`WALK_PROFILE_TC`)
        self.walk_profile_tc = WALK_PROFILE_TC
        self._fit_q()
        self.refit_drift()

    # --- the accepted model: changed through these methods only -----------------------------------------------
    @property
    def accepted(self) -> tuple[np.ndarray, ...]:
        """Block regressors (m, 3, p) of the accepted mean effects, in the order accepted."""
        return tuple(self._accepted)

    def accept(self, zb: np.ndarray, *, refit: bool = True) -> None:
        """Take the mean effect with block regressors ``zb`` into the model (the drift's T_c re-fitted unless
        ``refit`` is False, e.g. before taking in more)."""
        self._accepted.append(zb)
        if refit:
            self.refit_drift()

    def retain(self, indices: Sequence[int], *, random_walk: bool) -> None:
        """Keep only the accepted effects at ``indices`` (in that order) and the bias random walk only when
        ``random_walk``; then re-fit the drift (:meth:`refit_drift`)."""
        self._accepted = [self._accepted[i] for i in indices]
        if not random_walk:
            self.k2 = 0.0
        self.refit_drift()

    @contextlib.contextmanager
    def given(self, zb: np.ndarray) -> Iterator[None]:
        """Inside: ``zb`` taken into the model as well (nothing re-fitted); afterwards as before."""
        self._accepted.append(zb)
        try:
            yield
        finally:
            self._accepted.pop()

    @contextlib.contextmanager
    def without(self, index: int) -> Iterator[np.ndarray]:
        """Inside: the model without accepted effect ``index`` (yields its block regressors); afterwards as before."""
        accepted = self._accepted
        self._accepted = accepted[:index] + accepted[index + 1:]
        try:
            yield accepted[index]
        finally:
            self._accepted = accepted

    def set_random_walk(self, k2: float) -> None:
        """The bias random walk's K^2 in the block covariance (0: none), eq. 3's drift noise q re-fitted with it."""
        self.k2 = float(k2)
        self._fit_q()

    @contextlib.contextmanager
    def random_walk_off(self) -> Iterator[None]:
        """Inside: no bias random walk (q re-fitted); afterwards the walk and q as before."""
        k2 = self.k2
        self.set_random_walk(0.0)
        try:
            yield
        finally:
            self.set_random_walk(k2)

    @contextlib.contextmanager
    def inflated_noise(self, phi: np.ndarray) -> Iterator[None]:
        """Inside: the white block noise variance multiplied by ``phi`` (m, 3), e.g. the final model's dispersion
        (:func:`station.diagnose.robust.dispersion`); afterwards as before."""
        white, key, cache = self.white, self._white_key, dict(self._eig_cache)
        self.white = self.white * phi
        self._white_key = _digest(self.white)
        self._eig_cache.clear()
        try:
            yield
        finally:
            self.white, self._white_key = white, key
            self._eig_cache.clear()
            self._eig_cache.update(cache)

    @contextlib.contextmanager
    def drift_noise_at_most(self, q_max: np.ndarray) -> Iterator[None]:
        """Inside: eq. 3's drift noise q per axis bounded by ``q_max`` (3,), e.g. the sensor class's
        (:func:`station.diagnose.locator.class_drift_noise`); afterwards as before."""
        q, cache = self.q.copy(), dict(self._eig_cache)
        self.q = np.minimum(self.q, q_max)
        try:
            yield
        finally:
            self.q = q
            self._eig_cache.clear()
            self._eig_cache.update(cache)

    def heldout_errors(self) -> np.ndarray:
        """Per held-out block, the prediction error of the current model (see :meth:`heldout`)."""
        return self._heldout_errors(self._accepted, self._heldout_folds())

    def _base_design(self, tc: float) -> np.ndarray:
        """Base linear terms of one axis: corrections to the row of M and b_stat, and b_drift exp(-t/T_c) (eq. 3)."""
        return np.column_stack([*self._ref_cols, np.ones(self.m), block_exp_mean(self.sd.t_s, self.sd.width_s, tc)])

    def _gm(self, tc: float) -> np.ndarray:
        """Correlation of eq. 3's drift noise started at power-on between the blocks, for T_c (s), (m, m):
        ``exp(-|t_i - t_j|/T_c) - exp(-t_i/T_c) exp(-t_j/T_c)``; the last ``GM_CACHE`` T_c are kept (the
        T_c re-fit of a nested test visits the same values for the null and the alternative)."""
        hit = self._gm_cache.pop(tc, None)
        if hit is None:
            hit = power_on_gm_correlation(self.sd.t_s, self.dist, tc)
            hit.flags.writeable = False
            if len(self._gm_cache) >= GM_CACHE:
                self._gm_cache.pop(next(iter(self._gm_cache)))
        self._gm_cache[tc] = hit
        return hit

    def _set_tc(self, k: int, tc: float) -> None:
        """Set axis k's warm-up time constant T_c (s), clipped into the sensor class's range: its drift column
        and its GM covariance (eq. 3)."""
        tc = max(float(self.sd.clip_tc(tc)), TC_FLOOR_S)
        self.tc[k] = tc
        self.base[k] = self._base_design(tc)
        self.gm[k] = self._gm(tc)

    def refit_drift(self) -> None:
        """Re-fit each axis's T_c (and q) with the accepted effects: the base fit's T_c may have absorbed them.

        Rounds of a grid search around the current T_c (q held), then q, until no T_c moves (at most
        ``REFIT_ROUNDS``): a nested test re-fits the null and the alternative this way, and both must reach
        their optimum, or the alternative's extra round counts as the candidate's gain.

        The re-fit is a function of the state it starts from (T_c, q, K^2, the white variance, the accepted
        effects): the last :data:`REFIT_CACHE` outcomes are kept by that state (every candidate whose test
        re-fits the drift starts its null from the same state), and a repeat takes the kept outcome.
        """
        key = (self.tc.tobytes(), self.q.tobytes(), self.k2, self._white_key,
               tuple(_digest(a) for a in self._accepted))
        hit = self._refit_cache.pop(key, None)
        if hit is None:
            self._refit_drift()
            hit = self._snapshot()
            if len(self._refit_cache) >= REFIT_CACHE:
                self._refit_cache.pop(next(iter(self._refit_cache)))
        else:
            self._restore(hit)
        self._refit_cache[key] = hit

    def _refit_drift(self) -> None:
        """:meth:`refit_drift` without its cache."""
        for _ in range(REFIT_ROUNDS):
            moved = False
            for k in range(3):
                extra = self._accepted_axis(k)
                tc0 = float(self.tc[k])
                best = (self._axis_nll(k, float(self.q[k]), self.k2, extra), tc0)
                for f in (0.25, 0.5, 0.7, 1.4, 2.0, 4.0):
                    tc = float(self.sd.clip_tc(tc0 * f))
                    if tc == tc0:
                        continue
                    self._set_tc(k, tc)
                    val = self._axis_nll(k, float(self.q[k]), self.k2, extra)
                    if val < best[0]:
                        best = (val, tc)
                self._set_tc(k, best[1])
                moved = moved or best[1] != tc0
            self._fit_q()
            if not moved:
                break

    # --- covariance ----------------------------------------------------------
    def chol(self, k: int, q: float, k2: float, rows: np.ndarray | None = None,
             white: np.ndarray | None = None) -> np.ndarray:
        """Cholesky factor of axis ``k``'s block covariance; ``rows``: only those blocks (default all),
        ``white``: the white block variance (m, 3) to use instead of :attr:`white`."""
        if rows is None and white is None:
            # the factor depends on T_c (through the GM correlation), q, K^2 and the white variance only: kept for
            # the most recent CHOL_CACHE of them (the same bytes as a new factorization)
            key = (k, float(self.tc[k]), float(q), float(k2), self._white_key)
            hit = self._chol_cache.pop(key, None)
            if hit is None:
                hit = linalg.cholesky(self._covariance(k, q, k2), lower=True, check_finite=False)
                hit.flags.writeable = False
                if len(self._chol_cache) >= CHOL_CACHE:
                    self._chol_cache.pop(next(iter(self._chol_cache)))
            self._chol_cache[key] = hit
            return hit
        white = self.white if white is None else white
        if rows is None:
            c = self._covariance(k, q, k2, white)
        else:
            c = q * self.gm[k][np.ix_(rows, rows)] + k2 * self.tmin[np.ix_(rows, rows)]
            c[np.diag_indices_from(c)] += white[rows, k]
        return linalg.cholesky(c, lower=True, check_finite=False)

    def _covariance(self, k: int, q: float, k2: float, white: np.ndarray | None = None) -> np.ndarray:
        """Axis ``k``'s block covariance ``q GM + K^2 min(t_i, t_j) + diag(white)`` (a new array).

        Built in place, and without the walk's term where K^2 = 0: the same bytes as the plain expression
        (``0 * tmin`` is +0 where ``tmin >= 0``, and adding the scalar +0 turns a -0 into +0 as that sum does)."""
        c = q * self.gm[k]
        if k2 != 0.0 or not self._tmin_nonneg:
            c += k2 * self.tmin
        else:
            c += 0.0
        c[np.diag_indices_from(c)] += (self.white if white is None else white)[:, k]
        return c

    def _axis_nll(self, k: int, q: float, k2: float, extra: np.ndarray | None, *, reml: bool = False) -> float:
        """Negative log-likelihood of axis k with the mean columns profiled out; ``reml``: the restricted
        likelihood (+ 1/2 log det X^T C^-1 X over the design's identifiable directions), whose variance
        components are not biased low by the mean terms' share of the data (Patterson & Thompson 1971)."""
        try:
            ch = self.chol(k, q, k2)
        except linalg.LinAlgError:
            return np.inf
        x = self.base[k] if extra is None else np.column_stack([self.base[k], extra])
        xw = linalg.solve_triangular(ch, x, lower=True, check_finite=False)
        yw = linalg.solve_triangular(ch, self.y[:, k], lower=True, check_finite=False)
        beta, *_ = linalg.lstsq(xw, yw, check_finite=False)
        r = yw - xw @ beta
        nll = 0.5 * float(r @ r) + float(np.log(np.diag(ch)).sum())
        if reml:
            sv = np.linalg.svd(xw, compute_uv=False)
            nll += float(np.log(sv[sv > RCOND ** 0.5 * sv[0]]).sum())
        return nll

    def _eigen(self, k: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(1/sqrt(d), lambda, V) with ``D^-1/2 GM D^-1/2 = V diag(lambda) V^T`` for axis k at its current T_c,
        so that ``C(q) = D^1/2 V (1 + q lambda) V^T D^1/2`` for every q (cached per T_c)."""
        key = (k, float(self.tc[k]))
        hit = self._eig_cache.get(key)
        if hit is None:
            s = 1.0 / np.sqrt(self.white[:, k])
            lam, vec = linalg.eigh(s[:, None] * self.gm[k] * s[None, :], check_finite=False)
            hit = (s, np.clip(lam, 0.0, None), vec)
            self._eig_cache[key] = hit
        return hit

    def _profile_q(self, k: int, k2: float, extra: np.ndarray | None, q_max: float = math.inf, *,
                   reml: bool = False) -> tuple[float, float]:
        """(q, nll) maximizing the likelihood of axis k over 0 <= q <= ``q_max`` at fixed K^2.

        Without a random walk (K^2 = 0) the covariance is diagonalized once per T_c (:meth:`_eigen`) and
        every q costs one weighted least-squares fit in the rotated basis.
        """
        q0 = float(np.median(self.white[:, k]))
        hi = 10.0 if not math.isfinite(q_max) else min(10.0, math.log(max(q_max, 1e-300) / q0))
        if k2 == 0.0 and not reml:
            s, lam, vec = self._eigen(k)
            x = self.base[k] if extra is None else np.column_stack([self.base[k], extra])
            xt = vec.T @ (s[:, None] * x)
            yt = vec.T @ (s * self.y[:, k])
            const = -float(np.log(s).sum())

            def nll(q: float) -> float:
                w = 1.0 / (1.0 + q * lam)
                sw = np.sqrt(w)
                beta, *_ = np.linalg.lstsq(xt * sw[:, None], yt * sw, rcond=None)
                r = yt - xt @ beta
                return 0.5 * float(np.sum(w * r * r)) + 0.5 * float(np.log1p(q * lam).sum()) + const
        else:
            def nll(q: float) -> float:
                return self._axis_nll(k, q, k2, extra, reml=reml)
        nll0 = nll(0.0)
        if q_max <= 0.0 or hi <= -12.0:
            return 0.0, nll0
        res = optimize.minimize_scalar(lambda u: nll(q0 * math.exp(u)), bounds=(-12.0, hi), method="bounded",
                                       options={"xatol": 0.1 if k2 == 0.0 else 0.25})
        q = q0 * math.exp(float(res.x))
        if math.isfinite(q_max):
            at_max = nll(q_max)
            if at_max < res.fun:
                return q_max, at_max
        return (0.0, nll0) if nll0 <= res.fun else (q, float(res.fun))

    def _accepted_axis(self, k: int) -> np.ndarray | None:
        if not self._accepted:
            return None
        z = np.concatenate([a[:, k, :] for a in self._accepted], axis=1)
        keep = np.any(z != 0, axis=0)
        return z[:, keep] if keep.any() else None

    def _fit_q(self) -> None:
        """q per axis by maximum likelihood, at most :meth:`drift_noise_max` (eq. 3's drift noise is a small
        part of the warm-up: a larger q would take any unmodelled mean structure for drift noise)."""
        for k in range(3):
            q_max = Q_BOUND**2 * self.drift_noise_max(k) if Q_BOUNDED else math.inf
            self.q[k] = self._profile_q(k, self.k2, self._accepted_axis(k), q_max=q_max)[0]

    # --- mean fit ----------------------------------------------------------------
    def whitened(self, rows: np.ndarray | None = None,
                 white: np.ndarray | None = None) -> tuple[list[np.ndarray], np.ndarray]:
        """Per-axis Cholesky factors and the whitened stacked data; ``rows``, ``white`` as in :meth:`chol`."""
        chols = [self.chol(k, float(self.q[k]), self.k2, rows, white) for k in range(3)]
        y = self.y if rows is None else self.y[rows]
        yw = np.concatenate([linalg.solve_triangular(chols[k], y[:, k], lower=True, check_finite=False)
                             for k in range(3)])
        return chols, yw

    def whitened_fit(self) -> WhitenedFit:
        """The current model fitted by least squares in whitened units (:class:`WhitenedFit`)."""
        chols, yw = self.whitened()
        x, nbase = self.design(chols, self._accepted)
        beta, *_ = linalg.lstsq(x, yw, check_finite=False)
        return WhitenedFit(chols, yw, x, nbase, beta, yw - x @ beta)

    def design(self, chols: list[np.ndarray], blocks: Sequence[np.ndarray],
               rows: np.ndarray | None = None) -> tuple[np.ndarray, int]:
        """Whitened stacked design: per-axis base columns (block diagonal), then ``blocks`` (m, 3, p) shared;
        ``rows``: only those blocks (the ``chols`` of :meth:`whitened` with the same rows)."""
        nb = [b.shape[1] for b in self.base]
        total_base = sum(nb)
        p = sum(b.shape[2] for b in blocks)
        m = self.m if rows is None else len(rows)
        pick = slice(None) if rows is None else rows
        x = np.zeros((3 * m, total_base + p))
        col = 0
        for k in range(3):
            span = slice(k * m, (k + 1) * m)
            x[span, col:col + nb[k]] = linalg.solve_triangular(chols[k], self.base[k][pick], lower=True,
                                                               check_finite=False)
            col += nb[k]
            if p:
                zk = np.concatenate([b[pick, k, :] for b in blocks], axis=1)
                x[span, total_base:] = linalg.solve_triangular(chols[k], zk, lower=True, check_finite=False)
        return x, total_base

    @staticmethod
    def _rank(x: np.ndarray) -> int:
        if x.shape[1] == 0:
            return 0
        norms = np.linalg.norm(x, axis=0)
        xs = x[:, norms > 0] / norms[norms > 0]
        s = np.linalg.svd(xs, compute_uv=False)
        return int(np.sum(s > 1e-7 * s[0])) if len(s) else 0

    def total_nll(self) -> float:
        return sum(self._axis_nll(k, float(self.q[k]), self.k2, self._accepted_axis(k)) for k in range(3))

    def test_mean(self, name: str, zb: np.ndarray, *, profile: bool = False) -> Test:
        """Nested test of a mean candidate with block regressors ``zb`` (m, 3, p) against the current model.

        Candidates that compete with the drift (``PROFILE_TC``), and every candidate with ``profile``, get the
        drift's T_c and q re-fitted for the null and the alternative (a likelihood ratio with both profiled).
        """
        chols, yw = self.whitened()
        x0, _ = self.design(chols, self._accepted)
        b0, *_ = linalg.lstsq(x0, yw, cond=RCOND, check_finite=False)
        chi0 = float(np.sum((yw - x0 @ b0) ** 2))
        r0 = self._rank(x0)
        saved = None
        if profile or name in PROFILE_TC:
            saved = self._snapshot()
            # the null gets the same T_c refinement as the alternative: only the candidate may make the gain
            self.refit_drift()
            nll0 = self.total_nll()
            chols, yw = self.whitened()
            x0, _ = self.design(chols, self._accepted)
            r0 = self._rank(x0)
            self._accepted.append(zb)
            self.refit_drift()
            self._accepted.pop()
            chols, yw = self.whitened()
        x1, _ = self.design(chols, [*self._accepted, zb])
        gain_rank = self._rank(x1) - r0
        if profile:
            # the null's and the alternative's drift (T_c, q) differ: count the rank gain on one well-conditioned
            # weighting (the white block noise), not on two different whitenings
            wch = [np.diag(np.sqrt(self.white[:, k])) for k in range(3)]
            gain_rank = (self._rank(self.design(wch, [*self._accepted, zb])[0])
                         - self._rank(self.design(wch, self._accepted)[0]))
        b1, *_ = linalg.lstsq(x1, yw, cond=RCOND, check_finite=False)
        chi1 = float(np.sum((yw - x1 @ b1) ** 2))
        gain = chi0 - chi1
        if saved is not None:
            self._accepted.append(zb)
            gain = 2.0 * (nll0 - self.total_nll())
            self._accepted.pop()
            self._restore(saved)
        p = zb.shape[2]
        nfix = x1.shape[1] - p
        zcols = x1[:, nfix:]
        theta = b1[nfix:]
        cov = linalg.pinv(x1.T @ x1)[nfix:, nfix:]
        test = Test(
            effect=name, sensor=self.sd.sensor, gain=gain, params=gain_rank,
            bic_gain=gain - gain_rank * math.log(self.n_rows),
            critical=float(stats.chi2.isf(ALPHA, max(gain_rank, 1))),
            theta=theta, cov=cov, signal=zcols @ theta, span=np.column_stack([x1[:, :nfix], zcols]),
        )
        if name in WANDER_LIKE and self.k2 == 0.0 and test.passes:
            # significant without a random walk; is it with one? (only then: the walk's profile is costly)
            test.gain_given_walk = self.gain_given_walk(zb, refit=saved is not None)
        if test.passes:
            test.heldout_before, test.heldout_after, test.heldout_change_se = self.heldout(zb)
        return test

    def tc_marginal(self, index: int, q_max: np.ndarray | None = None
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
        """The size of accepted effect ``index`` with eq. 3's warm-up T_c integrated out, per axis: (mean, std) of
        its parameters (p,) with the drift noise q free, and the mean with q at most ``q_max`` per axis (the same
        as the first where the free q stays below it at every T_c); None where a parameter is not one axis's alone
        (the axes' fits are separate here).

        A size conditional on one T_c (:meth:`test_mean`'s ``pinv(X^T X)``) leaves out the trade-off between the
        effect and the warm-up ``b_drift exp(-t/T_c)``: a temperature course ``1 - exp(-t/tau_h)`` and the warm-up
        have nearly the same shape, and the T_c the re-fit settles on (:meth:`refit_drift`, a search at fixed q) is
        often a bound of the class's range. Here every T_c of :data:`TC_MARGINAL_POINTS` log-spaced over the class's
        range (or 1 % to 10 x the record without one) is weighted by its likelihood: q profiled at each T_c, the
        linear terms integrated out with a flat prior (the restricted likelihood's
        ``1/2 log det X^T C^-1 X``, Patterson & Thompson 1971), a flat prior in log T_c. The mean and the
        variance are those of the mixture: ``sum w_i theta_i`` and ``sum w_i (var_i + (theta_i - mean)^2)``.
        """
        zb = self._accepted[index]
        p = zb.shape[2]
        owner = np.any(zb != 0, axis=0)  # (3, p): the axes whose rows carry each parameter
        if not np.all(owner.sum(axis=0) == 1):
            return None
        span = float(self.sd.t_s.max())
        lo, hi = self.sd.tc_range_s if self.sd.tc_range_s else (0.01 * span, 10.0 * span)
        grid = np.geomspace(max(lo, TC_FLOOR_S), max(hi, TC_FLOOR_S), TC_MARGINAL_POINTS)
        mean, std, mean_c = np.zeros(p), np.zeros(p), np.zeros(p)
        saved = self._snapshot()
        try:
            for k in range(3):
                mine = np.flatnonzero(owner[k])
                if not len(mine):
                    continue
                cols = np.concatenate([a[:, k, :] for a in self._accepted], axis=1)
                start = sum(a.shape[2] for a in self._accepted[:index])
                keep = np.any(cols != 0, axis=0)
                pos = np.cumsum(keep) - 1  # column of each kept parameter in the reduced design
                extra = cols[:, keep]
                j = self.base[k].shape[1] + pos[start + mine]
                qk = math.inf if q_max is None else float(q_max[k])
                # (nll, value, variance) per T_c: q free, q bounded
                fits: list[list[tuple[float, np.ndarray, np.ndarray]]] = [[], []]
                for tc in grid:
                    self._set_tc(k, float(tc))
                    q, _ = self._profile_q(k, self.k2, extra)
                    fits[0].append(self._restricted_fit(k, q, extra, j))
                    fits[1].append(fits[0][-1] if q <= qk else
                                   self._restricted_fit(k, self._profile_q(k, self.k2, extra, q_max=qk)[0], extra, j))
                for out_mean, out_std, fit in ((mean, std, fits[0]), (mean_c, None, fits[1])):
                    nll = np.array([f[0] for f in fit])
                    w = np.exp(-(nll - nll.min()))
                    w /= w.sum()
                    v, s2 = np.array([f[1] for f in fit]), np.array([f[2] for f in fit])
                    m = w @ v
                    out_mean[mine] = m
                    if out_std is not None:
                        out_std[mine] = np.sqrt(w @ (s2 + (v - m) ** 2))
                self._restore(saved)
        finally:
            self._restore(saved)
        return mean, std, mean_c

    def _restricted_fit(self, k: int, q: float, extra: np.ndarray, j: np.ndarray
                        ) -> tuple[float, np.ndarray, np.ndarray]:
        """Axis k's restricted negative log-likelihood at drift noise q (the linear terms integrated out with a flat
        prior, see :meth:`_axis_nll`), and the GLS values and variances of its design's columns ``j`` (base columns,
        then ``extra``)."""
        ch = self.chol(k, q, self.k2)
        x = np.column_stack([self.base[k], extra])
        xw = linalg.solve_triangular(ch, x, lower=True, check_finite=False)
        yw = linalg.solve_triangular(ch, self.y[:, k], lower=True, check_finite=False)
        beta, *_ = linalg.lstsq(xw, yw, check_finite=False)
        r = yw - xw @ beta
        sv = np.linalg.svd(xw, compute_uv=False)
        nll = (0.5 * float(r @ r) + float(np.log(np.diag(ch)).sum())
               + float(np.log(sv[sv > RCOND ** 0.5 * sv[0]]).sum()))
        return nll, beta[j], np.diag(linalg.pinv(xw.T @ xw))[j]

    def _snapshot(self) -> _State:
        """The drift's current T_c, base columns, GM correlations and q (see :meth:`_restore`)."""
        return self.tc.copy(), list(self.base), list(self.gm), self.q.copy()

    def _restore(self, state: _State) -> None:
        tc, base, gm, q = state
        self.tc, self.base, self.gm, self.q = tc.copy(), list(base), list(gm), q.copy()

    def heldout(self, zb: np.ndarray) -> tuple[float, float, float]:
        """Predictive error on held-out segments without/with ``zb``: mean squared Mahalanobis residual
        per held-out block (1 = as expected), under the block covariance at the current drift (T_c, q), the
        linear parameters fitted by GLS on the other segments (4 folds by segment; the power-on rest always
        stays in training); and the standard error of their difference, paired over the held-out blocks.
        """
        folds = self._heldout_folds()
        before = self._heldout_errors(self._accepted, folds)
        after = self._heldout_errors([*self._accepted, zb], folds)
        d = after - before
        se = float(np.std(d, ddof=1) / math.sqrt(len(d))) if len(d) > 1 else math.inf
        return float(before.mean()), float(after.mean()), se

    def _heldout_folds(self) -> list[tuple[np.ndarray, np.ndarray, list[_FoldAxis]]]:
        """Per fold (held-out mask, training mask, per axis): the block covariance's factorizations, which
        do not depend on the mean model: Cholesky of the training part, kriging weights of the held-out
        blocks on the training blocks, Cholesky of the conditional covariance (None when not positive). Kept for the
        last covariance state (T_c, q, K^2, white variance): every candidate of a selection step that passes asks for
        the same folds."""
        key = (self.tc.tobytes(), self.q.tobytes(), self.k2, self._white_key)
        if self._folds is not None and self._folds[0] == key:
            return self._folds[1]
        out = self._new_heldout_folds()
        self._folds = (key, out)
        return out

    def _new_heldout_folds(self) -> list[tuple[np.ndarray, np.ndarray, list[_FoldAxis]]]:
        """:meth:`_heldout_folds` without the kept folds."""
        seg = self.sd.segment % FOLDS
        seg[self.sd.segment == self.sd.segment.min()] = -1
        covs = [self._covariance(k, float(self.q[k]), self.k2) for k in range(3)]
        out = []
        for f in range(FOLDS):
            te = seg == f
            tr = ~te
            if not te.any() or te.sum() < 2:
                continue
            axes = []
            for c in covs:
                ch = linalg.cholesky(c[np.ix_(tr, tr)], lower=True, check_finite=False)
                a = linalg.cho_solve((ch, True), c[np.ix_(tr, te)], check_finite=False)
                try:
                    cc = linalg.cholesky(c[np.ix_(te, te)] - c[np.ix_(te, tr)] @ a, lower=True, check_finite=False)
                except linalg.LinAlgError:
                    cc = None
                axes.append((ch, a, cc))
            out.append((te, tr, axes))
        return out

    def _heldout_errors(
        self, blocks: Sequence[np.ndarray], folds: list[tuple[np.ndarray, np.ndarray, list[_FoldAxis]]]
    ) -> np.ndarray:
        """The squared whitened prediction errors of :meth:`heldout` per held-out block (folds and axes in
        turn) for the mean model with ``blocks``."""
        nb = [b.shape[1] for b in self.base]
        p = sum(b.shape[2] for b in blocks)
        xs = []
        for k in range(3):
            xk = np.zeros((self.m, sum(nb) + p))
            xk[:, sum(nb[:k]):sum(nb[:k + 1])] = self.base[k]
            if p:
                xk[:, sum(nb):] = np.concatenate([b[:, k, :] for b in blocks], axis=1)
            xs.append(xk)
        out = []
        for te, tr, axes in folds:
            x = np.concatenate([linalg.solve_triangular(ch, xs[k][tr], lower=True, check_finite=False)
                                for k, (ch, _, _) in enumerate(axes)])
            y = np.concatenate([linalg.solve_triangular(ch, self.y[tr, k], lower=True, check_finite=False)
                                for k, (ch, _, _) in enumerate(axes)])
            beta, *_ = linalg.lstsq(x, y, cond=RCOND, check_finite=False)
            for k, (_, a, cc) in enumerate(axes):
                r = self.y[:, k] - xs[k] @ beta
                e = r[te] - a.T @ r[tr]
                if cc is not None:
                    ew = linalg.solve_triangular(cc, e, lower=True, check_finite=False)
                else:
                    ew = e / np.sqrt(self.white[te, k])
                out.append(ew**2)
        return np.concatenate(out) if out else np.zeros(0)

    # --- random walk -------------------------------------------------------------
    def drift_noise_max(self, k: int) -> float:
        """Largest drift-noise variance ``q`` (U^2) the base model grants axis k (eq. 3).

        In eq. 3 the noise ``w`` perturbs the warm-up ``b_drift g(t)``; the paper neglects it. The
        base model here allows the drift noise to wander, over the record ``S``, by up to
        ``DRIFT_NOISE_MAX`` of the warm-up's own change over the record:
        ``sqrt(q (1 - exp(-2 S/T_c))) <= DRIFT_NOISE_MAX |b_drift| (1 - exp(-S/T_c))``.
        A wander larger than that is not eq. 3's drift noise: a random walk (or a GM far slower
        than the record and larger than the warm-up, which is the same thing within the record).
        """
        span = float(self.sd.t_s.max())
        tc = float(self.tc[k])
        # the warm-up's change over the record: b_drift exp(-t/T_c) re-fitted here with the accepted effects
        # (the drift column carries the whole b_drift, see base_drift; an effect the base fit missed distorts
        # the base fit's own drift)
        change = 0.0
        extra = self._accepted_axis(k)
        x = self.base[k] if extra is None else np.column_stack([self.base[k], extra])
        try:
            ch = self.chol(k, float(self.q[k]), self.k2)
            xw = linalg.solve_triangular(ch, x, lower=True, check_finite=False)
            yw = linalg.solve_triangular(ch, self.y[:, k], lower=True, check_finite=False)
            beta, *_ = linalg.lstsq(xw, yw, check_finite=False)
            j = self.base[k].shape[1] - 1
            std = math.sqrt(max(float(linalg.pinv(xw.T @ xw)[j, j]), 0.0))
            change = (abs(float(beta[j])) + WARMUP_SIGMAS * std) * -math.expm1(-span / tc)
        except linalg.LinAlgError:
            pass
        return (DRIFT_NOISE_MAX * change) ** 2 / -math.expm1(-2.0 * span / tc)

    def test_random_walk(self, *, size: bool = True) -> Test:
        """Constrained likelihood-ratio test of a bias random walk ``K^2 min(t_i, t_j)`` shared by the
        three axes, against eq. 3's drift noise bounded by :meth:`drift_noise_max`.

        Null: per axis, q over ``[0, q_max]`` (at most the sensor class's, :attr:`q_class`, too where it is known and
        :attr:`walk_null_class_bound`), and a bias proportional to the temperature rise as a
        nuisance term (so a temperature course the warm-up does not absorb is not taken for a wander).
        Alternative: K^2 >= 0 added, q kept at the null's value (which makes the test conservative).
        Both at the warm-up T_c re-fitted with the temperature term (then restored). ``size``: a walk that passes
        is sized on its profile likelihood (:meth:`_walk_size`); without, its ``theta`` and ``cov`` are the test's
        (K at the null's q, for a caller that uses the decision and the gain only).
        """
        saved = self._snapshot()
        try:
            if np.any(self.d_temp):
                # a temperature bias that the warm-up absorbed (T_c pulled to the self-heating's time constant)
                # leaves eq. 3's slower drift unexplained: with the temperature term, T_c goes back to it
                self._accepted.append(self.d_temp[:, None, None] * np.eye(3)[None, :, :])
                try:
                    self.refit_drift()
                finally:
                    self._accepted.pop()
            return self._random_walk_at_current_tc(size=size)
        finally:
            self._restore(saved)

    def _random_walk_at_current_tc(self, *, size: bool) -> Test:
        """:meth:`test_random_walk` at the current T_c."""
        q_max = [self.drift_noise_max(k) for k in range(3)]
        if self.walk_null_class_bound and self.q_class is not None:
            # eq. 3's drift noise at most the sensor class's in the null too, as in the walk's size (_walk_size): over
            # a record shorter than T_c its noise is itself a random walk (GM(T_c) ~ 2 min(t_i, t_j) / T_c), so a q
            # the class does not grant takes up the wander and leaves the test nothing (see WALK_NULL_CLASS_BOUND)
            q_max = [min(a, float(b)) for a, b in zip(q_max, self.q_class, strict=True)]
        extra = []
        # the temperature course is a nuisance term of both hypotheses; where the temperature both rises and falls,
        # so is an offset that depends on its direction (a bias with a play or lag in temperature, hysteresis: a
        # wander that turns with the temperature is not a random walk)
        nuisance = [self.d_temp] if np.any(self.d_temp) else []
        both_ways = float(np.mean(self.temp_direction > 0.5)), float(np.mean(self.temp_direction < -0.5))
        if min(both_ways) >= TEMP_DIRECTION_SHARE:
            nuisance.append(self.temp_direction)
        for k in range(3):
            acc = self._accepted_axis(k)
            if nuisance:
                acc = np.column_stack(nuisance) if acc is None else np.column_stack([acc, *nuisance])
            extra.append(acc)

        def constrained_q() -> tuple[list[float], float]:
            out = [self._profile_q(k, 0.0, extra[k], q_max=q_max[k]) for k in range(3)]
            return [q for q, _ in out], sum(v for _, v in out)

        qs, nll0 = constrained_q()
        alt = self._profile_k2(qs, extra)
        best_nll, k2, k_std = alt
        gain = max(0.0, 2.0 * (nll0 - best_nll))
        if self.walk_profile_tc:
            gain = self._walk_profiled_gain(extra, q_max, k2, nll0, best_nll)
        # K^2 >= 0 sits on the boundary: the null distribution is half chi^2_1
        crit = float(stats.chi2.isf(2.0 * ALPHA, 1))
        k_walk = math.sqrt(k2)
        if size and gain > crit and gain > math.log(self.n_rows):
            k_walk, k_std = self._walk_size(extra, q_max, k2)
        return Test(effect="bias_random_walk", sensor=self.sd.sensor, gain=gain, params=1,
                    bic_gain=gain - math.log(self.n_rows), critical=crit, theta=np.array([k_walk]),
                    cov=np.array([[k_std**2]]))

    def _walk_profiled_gain(self, extra: list[np.ndarray | None], q_max: list[float], k2: float, nll0: float,
                            nll1: float) -> float:
        """The walk's gain with eq. 3's nuisance re-fitted in both hypotheses: per axis the warm-up's T_c (in the
        class's range) and q (0 <= q <= ``q_max``, the same bound in both), at K^2 = 0 for the null and at the
        profiled K^2 for the alternative (T_c and K^2 in turn, twice). The default test's null T_c was fitted with q
        unbounded (:meth:`refit_drift`), and its alternative keeps it. ``nll0``, ``nll1``: the default test's null
        and alternative (points of the same spaces: each hypothesis takes the better). Leaves T_c changed (the
        caller restores it)."""
        start = self.tc.copy()
        null = min(nll0, self._walk_refit_tc(extra, q_max, 0.0))
        for k in range(3):
            self._set_tc(k, float(start[k]))
        u = math.log(k2)
        alt = nll1
        for _ in range(2):
            alt = min(alt, self._walk_refit_tc(extra, q_max, math.exp(u)))
            res = optimize.minimize_scalar(
                lambda v: sum(self._profile_q(k, math.exp(v), extra[k], q_max=q_max[k])[1] for k in range(3)),
                bounds=(u - 2.0, u + 2.0), method="bounded", options={"xatol": 0.1, "maxiter": 12})
            if float(res.fun) < alt:
                alt, u = float(res.fun), float(res.x)
        return max(0.0, 2.0 * (null - alt))

    def _walk_refit_tc(self, extra: list[np.ndarray | None], q_max: list[float], k2: float) -> float:
        """Per axis, T_c by a grid search around the current one (:data:`WALK_TC_FACTORS`, the class's range; rounds
        until none moves, at most :data:`WALK_TC_ROUNDS`) with q profiled (0 <= q <= ``q_max``) at K^2 = ``k2``: the
        summed negative log-likelihood at the best T_c (set)."""
        total = 0.0
        for k in range(3):
            best = (self._profile_q(k, k2, extra[k], q_max=q_max[k])[1], float(self.tc[k]))
            for _ in range(WALK_TC_ROUNDS):
                tc0 = best[1]
                for f in WALK_TC_FACTORS:
                    tc = max(float(self.sd.clip_tc(tc0 * f)), TC_FLOOR_S)
                    if tc == tc0:
                        continue
                    self._set_tc(k, tc)
                    val = self._profile_q(k, k2, extra[k], q_max=q_max[k])[1]
                    if val < best[0]:
                        best = (val, tc)
                if best[1] == tc0:
                    break
            self._set_tc(k, best[1])
            total += best[0]
        return total

    def _walk_size(self, extra: list[np.ndarray | None], q_max: list[float], k2: float) -> tuple[float, float]:
        """(K, std of K) of an accepted random walk with eq. 3's drift noise profiled beside it (0 <= q <= q_max per
        axis). The test keeps q at the null's value (conservative for the decision), where q has taken up part of
        the wander: K from there is low and its curvature ignores the trade between the two. Here K^2 is fitted on
        its profile likelihood (:meth:`_walk_profile`: q per axis re-fitted at every K^2), q bounded by the sensor
        class where it is known (:attr:`q_class`): the drift noise of eq. 3 must not take up the wander. On the
        restricted likelihood (REML, :meth:`_axis_nll`): the mean terms (b_stat, the warm-up, the row of M,
        accepted effects) take up the walk's slowest part, and maximum likelihood then states K low.

        K and q trade along a ridge (more walk, less drift noise), so fitting them in turn stops short of the
        joint optimum: alternating two rounds from the test's point left K up to 15 % low with q at its bound,
        where the profile still fell steeply towards larger K. The std is from the profile on the side where it
        is flatter: ``0.5 K h / sqrt(2 (nll(log K^2 +- h) - nll))`` in log K^2 for the step ``h`` either way, the
        larger of the two (the profile has a kink where q reaches its bound or 0; a symmetric curvature there
        states K as surer than either side of the profile allows)."""
        if self.q_class is not None:
            q_max = [min(a, float(b)) for a, b in zip(q_max, self.q_class, strict=True)]
        u_hat, nll_hat = self._walk_profile(extra, q_max, math.log(k2))
        h = WALK_STD_STEP
        sides = [self._walk_nll(extra, q_max, u_hat + s) - nll_hat for s in (h, -h)]
        k = math.exp(0.5 * u_hat)
        if min(sides) <= 0.0:
            return k, math.nan
        return k, k * 0.5 * h / math.sqrt(2.0 * min(sides))

    def _walk_nll(self, extra: list[np.ndarray | None], q_max: list[float], u: float) -> float:
        """Profile of the walk's restricted likelihood at ``K^2 = exp(u)``: q per axis (0 <= q <= q_max) re-fitted."""
        return sum(self._profile_q(k, math.exp(u), extra[k], q_max=q_max[k], reml=True)[1] for k in range(3))

    def _walk_profile(self, extra: list[np.ndarray | None], q_max: list[float], u0: float) -> tuple[float, float]:
        """(log K^2, nll) at the minimum of :meth:`_walk_nll`, searched from the test's ``u0 = log K^2``: steps of
        :data:`WALK_SIZE_STEP` in log K^2 downhill until the profile rises, then a bounded search in that bracket."""
        step = WALK_SIZE_STEP
        vals = {u0: self._walk_nll(extra, q_max, u0)}
        for _ in range(WALK_SIZE_SPAN):
            u = min(vals, key=vals.__getitem__)
            for v in (u - step, u + step):
                if v not in vals:
                    vals[v] = self._walk_nll(extra, q_max, v)
            if min(vals, key=vals.__getitem__) == u:
                break
        u = min(vals, key=vals.__getitem__)
        res = optimize.minimize_scalar(lambda v: self._walk_nll(extra, q_max, v), bounds=(u - step, u + step),
                                       method="bounded", options={"xatol": WALK_SIZE_XATOL})
        if float(res.fun) < vals[u]:
            return float(res.x), float(res.fun)
        return u, vals[u]

    def _profile_k2(self, qs: list[float], extra: list[np.ndarray | None], *,
                    reml: bool = False, with_std: bool = True) -> tuple[float, float, float]:
        """(nll, K^2, std of K) with a random walk ``K^2 min(t_i, t_j)`` shared by the three axes profiled at the
        current T_c and the drift noise ``qs``; ``extra``: per axis the mean columns besides the base terms;
        ``with_std`` False: the std is not computed (nan; two profile points fewer, the same nll and K^2)."""
        k2_0 = float(np.median(self.white)) / max(float(self.sd.t_s.max()), 1.0)
        grid = [k2_0 * 10.0 ** e for e in np.arange(-2.0, 3.01, 1.0)]

        def total(k2: float) -> float:
            return sum(self._axis_nll(k, qs[k], k2, extra[k], reml=reml) for k in range(3))

        vals = [total(g) for g in grid]
        i = int(np.argmin(vals))
        lo, hi = math.log(grid[max(i - 1, 0)]), math.log(grid[min(i + 1, len(grid) - 1)])
        res = optimize.minimize_scalar(lambda u: total(math.exp(u)), bounds=(lo, hi), method="bounded",
                                       options={"xatol": 0.2, "maxiter": 10})
        nll, k2 = (float(res.fun), math.exp(float(res.x))) if res.fun < vals[i] else (vals[i], grid[i])
        if not with_std:
            return nll, k2, math.nan
        # uncertainty of K from the curvature of the profile in log K^2
        h = 0.3
        curv = (total(k2 * math.exp(h)) - 2.0 * nll + total(k2 * math.exp(-h))) / h**2
        return nll, k2, math.sqrt(k2) * 0.5 / math.sqrt(curv) if curv > 0 else math.nan

    def walk_profiled_nll(self) -> float:
        """Negative log-likelihood of the current mean model (accepted effects, T_c) with a bias random walk
        allowed beside eq. 3's drift noise: from each of two starts, the current q and q = 0 (an unbounded q of a
        fast warm-up and a walk over the whole record trade against each other), K^2 profiled at that q, then q
        per axis profiled at that K^2; the best of these and of the model as it is (K^2 = 0). The nuisance
        hypothesis under which a ``WANDER_LIKE`` candidate is tested as well (:meth:`gain_given_walk`)."""
        extra = [self._accepted_axis(k) for k in range(3)]
        best = self.total_nll()
        for start in ([float(q) for q in self.q], [0.0, 0.0, 0.0]):
            _, k2, _ = self._profile_k2(start, extra, with_std=False)
            fits = [self._profile_q(k, k2, extra[k]) for k in range(3)]
            best = min(best, sum(v for _, v in fits))
        return best

    def gain_given_walk(self, zb: np.ndarray, *, refit: bool) -> float:
        """2 x log-likelihood gain of the mean candidate ``zb`` with a bias random walk allowed in the null and
        the alternative (:meth:`walk_profiled_nll`); ``refit``: each hypothesis's T_c re-fitted first, as in
        :meth:`test_mean`. The symmetric counterpart of the walk's own test, whose null holds the temperature
        course: a slow wander is not evidence of a temperature bias, nor a temperature course of a wander."""
        saved = self._snapshot()
        try:
            if refit:
                self.refit_drift()
            nll0 = self.walk_profiled_nll()
            self._accepted.append(zb)
            try:
                if refit:
                    self.refit_drift()
                nll1 = self.walk_profiled_nll()
            finally:
                self._accepted.pop()
        finally:
            self._restore(saved)
        return max(0.0, 2.0 * (nll0 - nll1))

    def walk_consistency(self) -> WalkConsistency:
        """Whether the wander in the current model's block residual is a random walk: the increments of the
        residual between consecutive settled blocks (rest, pose, rate; moves left out), ``d = r_j - r_i``, have
        ``E d^2 = w_i + w_j + K^2 dt`` (white block noise ``w``, :attr:`white`) for a random walk wherever they are
        taken. Moment estimates of K^2 (three axes pooled, ``sum(d^2 - w_i - w_j) / sum(dt)``) from four sets of
        pairs: the first / second half of the record, pairs inside one segment / across a segment boundary, and where
        the temperature both rises and falls, pairs while it rises / falls; the
        standard error of each from ``var d^2 = 2 (E d^2)^2`` at the pooled K^2. And between the axes (``axes``,
        :meth:`_walk_axes_z`: the walk is one K^2 for the triad). Consistent when every difference is within
        :data:`WALK_CONSISTENCY_Z` standard errors."""
        raw = self.quality().block_residual
        sd = self.sd
        settled = np.flatnonzero(sd.kind != int(Kind.MOVE))
        if len(settled) < 6:
            return WalkConsistency(True, {}, reason="too few settled blocks")
        i, j = settled[:-1], settled[1:]
        dt = sd.t_s[j] - sd.t_s[i]
        d2 = (raw[j] - raw[i]) ** 2  # (pairs, 3)
        same = sd.segment[i] == sd.segment[j]
        w = self.white[i] + self.white[j]
        if sd.extra_var is not None:
            # SensorData.extra_var is one offset per segment (e.g. the horizontal Earth rate in a pose of unknown
            # heading): it cancels in an increment inside a segment and enters one across a boundary only
            w = w - np.where(same[:, None], sd.extra_var[i] + sd.extra_var[j], 0.0)
        excess = (d2 - w).sum(axis=1)
        k2_all = max(float(excess.sum()) / max(3.0 * float(dt.sum()), 1e-300), 0.0)
        var = (2.0 * (w + k2_all * dt[:, None]) ** 2).sum(axis=1)
        mid = 0.5 * float(sd.t_s.max())
        z_of: dict[str, float] = {}
        splits = [("halves", sd.t_s[j] <= mid), ("inside_vs_across_segments", same)]
        td = self.temp_direction
        if min(float(np.mean(td > 0.5)), float(np.mean(td < -0.5))) >= TEMP_DIRECTION_SHARE:
            # a random walk wanders alike while the temperature rises and while it falls; a bias with a play or lag
            # in temperature (hysteresis) moves where the temperature turns
            splits.append(("heating_vs_cooling", td[i] + td[j] >= 0.0))
        # the library's walk is one K^2 shared by the three axes: it wanders alike on each; structure on one axis
        # that the walk takes up there (a bias with a play in temperature on that axis) is not it
        consistent = True
        if sd.extra_var is None:  # a rig-free gyro's per-pose Earth rate (extra_var) differs by axis: not compared
            z_axes = self._walk_axes_z()
            z_of["axes"] = round(z_axes, 2)
            consistent = abs(z_axes) <= WALK_CONSISTENCY_Z
        for name, a in splits:
            est: list[tuple[float, float]] = []
            for sel in (a, ~a):
                if not sel.any():
                    est = []
                    break
                den = 3.0 * float(dt[sel].sum())
                est.append((float(excess[sel].sum()) / den, math.sqrt(float(var[sel].sum())) / den))
            if len(est) < 2:
                continue
            z = (est[0][0] - est[1][0]) / max(math.hypot(est[0][1], est[1][1]), 1e-300)
            z_of[name] = round(z, 2)
            consistent = consistent and abs(z) <= WALK_CONSISTENCY_Z
        return WalkConsistency(consistent, z_of, k2_all)

    def _walk_axes_z(self) -> float:
        """Whether one K^2 serves the three axes: the likelihood ratio of a walk ``K_k^2`` per axis against the shared
        one (the current model's mean terms; drift noise q per axis, at most the sensor class's where it is known,
        :attr:`q_class`), 2 degrees of freedom, as the z-score of
        the same tail probability (two-sided: comparable with the other splits' z)."""
        extra = [self._accepted_axis(k) for k in range(3)]
        qs = [float(q) for q in self.q]
        if self.q_class is not None:  # eq. 3's drift noise at most the class's: it must not take up one axis's part
            qs = [min(a, float(b)) for a, b in zip(qs, self.q_class, strict=True)]
        shared, _, _ = self._profile_k2(qs, extra, with_std=False)
        k2_0 = float(np.median(self.white)) / max(float(self.sd.t_s.max()), 1.0)
        separate = 0.0
        for k in range(3):
            def nll(u: float, k: int = k) -> float:
                return self._axis_nll(k, qs[k], math.exp(u), extra[k])

            grid = [math.log(k2_0) + e * math.log(10.0) for e in np.arange(-2.0, 4.01, 1.0)]
            vals = [nll(g) for g in grid]
            i = int(np.argmin(vals))
            res = optimize.minimize_scalar(nll, bounds=(grid[max(i - 1, 0)], grid[min(i + 1, len(grid) - 1)]),
                                           method="bounded", options={"xatol": 0.2, "maxiter": 12})
            separate += min(float(res.fun), vals[i], self._axis_nll(k, qs[k], 0.0, extra[k]))
        lr = max(0.0, 2.0 * (shared - separate))
        return min(float(stats.norm.isf(0.5 * float(stats.chi2.sf(lr, 2)))), 99.0)

    def _temperature_vs_warmup(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(T grid s, R^2 (T, axis), energy (axis,)) of the block temperature course against eq. 3's warm-up.

        Per axis, the temperature course and the base model's columns are weighted by the block
        noise; the part of the temperature course that the other base columns (row of M, b_stat)
        leave (its energy, in block-noise units per K^2) is regressed on ``exp(-t/T)``.
        """
        sd = self.sd
        span = float(sd.t_s.max())
        grid = np.geomspace(*sd.tc_range_s, 12) if sd.tc_range_s else np.geomspace(10.0, 20.0 * span, 40)
        r2 = np.zeros((len(grid), 3))
        energy = np.zeros(3)
        cols = [block_exp_mean(sd.t_s, sd.width_s, float(tc)) for tc in grid]
        for k in range(3):
            w = 1.0 / np.sqrt(self.white[:, k])
            qo, _ = np.linalg.qr(self.base[k][:, :-1] * w[:, None])
            z = self.d_temp * w
            z = z - qo @ (qo.T @ z)
            energy[k] = zz = float(z @ z)
            for i, col in enumerate(cols):
                e = col * w
                e = e - qo @ (qo.T @ e)
                ee = float(e @ e)
                r2[i, k] = float((z @ e) ** 2 / (zz * ee)) if zz > 0 and ee > 0 else 0.0
        return grid, r2, energy

    def temperature_collinearity(self) -> tuple[float, float]:
        """(R^2, T) of the best explanation of the temperature course by eq. 3's warm-up exp(-t/T), T from
        10 s to 20 records (or over the sensor class's T_c range): the smallest R^2 over the axes at the T
        that fits best. R^2 near 1: a temperature bias and a warm-up drift are the same signal in this
        recording."""
        grid, r2, _ = self._temperature_vs_warmup()
        worst = r2.min(axis=1)
        i = int(np.argmax(worst))
        return float(worst[i]), float(grid[i])

    def temperature_unique(self, theta: np.ndarray) -> float:
        """chi^2 of the part of a temperature bias ``theta`` (U/K per axis) that no warm-up exp(-t/T) of
        eq. 3 (any T from 10 s to 20 records, or in the sensor class's T_c range, per axis) can take over: what
        tells the two apart."""
        _, r2, energy = self._temperature_vs_warmup()
        return float(np.sum(np.asarray(theta) ** 2 * energy * (1.0 - r2.max(axis=0))))

    # --- fit quality ---------------------------------------------------------------
    def quality(self) -> ModelQuality:
        """Negative log-likelihood, BIC, block chi^2 per axis (white-noise units) of the current model."""
        fit = self.whitened_fit()
        chols, x, beta, rw = fit.chols, fit.x, fit.beta, fit.res
        logdet = sum(float(np.log(np.diag(c)).sum()) for c in chols)
        nll = 0.5 * float(rw @ rw) + logdet
        npar = self._rank(x) + int(np.count_nonzero(self.q)) + (1 if self.k2 > 0 else 0)
        # raw block residual (not whitened) per axis, for the engineer
        raw = np.zeros((self.m, 3))
        nb = [b.shape[1] for b in self.base]
        col = 0
        total_base = sum(nb)
        for k in range(3):
            fit = self.base[k] @ beta[col:col + nb[k]]
            if self._accepted:
                fit = fit + np.concatenate([a[:, k, :] for a in self._accepted], axis=1) @ beta[total_base:]
            col += nb[k]
            raw[:, k] = self.y[:, k] - fit
        chi = np.mean(raw**2 / self.white, axis=0)
        return ModelQuality(nll, 2.0 * nll + npar * math.log(self.n_rows), chi,
                            np.sqrt(np.average(raw**2, axis=0, weights=self.sd.count)), raw)


__all__ = [
    "ALPHA", "DRIFT_NOISE_MAX", "FOLDS", "HELDOUT_SE", "PROFILE_TC", "RCOND", "TC_FLOOR_S", "WALK_CONSISTENCY_Z",
    "WANDER_LIKE",
    "ModelQuality", "SensorProblem", "Test", "WhitenedFit", "base_drift",
]
