"""Multi-position calibration without a rig (Tedaldi et al. 2014, the model imu_tk implements).

Pure numerics: arrays in, frozen results out. Units: m/s^2, rad/s, s.

**Accelerometer, gravity norm.** At rest the specific force has the norm of local gravity g
whatever the orientation. With eq. (1) ``y = M f + b`` (y the measurement, f the specific force),
the calibration ``f = A (y - b)`` with ``A = M^-1`` must give ``|A (y_i - b)| = g`` for the mean
``y_i`` of every still pose i. The norm cannot see a rotation of the whole triad (3 degrees of
freedom): the convention here is imu_tk's, ``A = T K`` **upper-triangular**, which takes the
accelerometer's own axes as the frame. Equivalently ``M = A^-1`` is upper-triangular: the
accelerometer's z sensing axis is the frame's z axis and its y sensing axis lies in the frame's
y-z plane. Parameters ``p = (A00, A01, A02, A11, A12, A22, b0, b1, b2)``; residual per pose
``r_i = |A (y_i - b)| - g`` (m/s^2); Levenberg-Marquardt from an axis-aligned algebraic ellipsoid
fit (which finds offsets of any size); covariance ``s^2 (J'J)^-1`` with the residual scale
``s^2 = sum r^2 / (m - 9)`` (model errors of a real sensor count, not only its noise).

**Gyroscope, rotations between poses.** Over the move from still pose i to pose i+1 the
calibrated rate ``w = C (y_w - b_w(t))`` (``C = M_w^-1``, all 9 elements: the gyro is referred to
the accelerometer's frame, so there is no gauge freedom left) is integrated as a unit quaternion
with the classical Runge-Kutta method (RK4, the rate linearly interpolated between samples),
giving the rotation R of the body from the start to the end of the move. Gravity is fixed in the
world, so the calibrated accelerometer's gravity direction before the move, ``u_i``, must turn
into the one after it: residual ``u_{i+1} - R' u_i`` (3 components, 2 degrees of freedom: a
rotation about gravity is invisible). Gauss-Newton with Levenberg-Marquardt damping; the Jacobian
by forward differences (one batched integration); covariance ``s^2 (J'J)^-1``, ``s^2 = sum r^2 /
(2 m - 9)``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from station.kernel.errors import FitError

__all__ = [
    "AccelJointFit",
    "AccelNormFit",
    "GyroRotationFit",
    "accel_from_params",
    "direction_errors_deg",
    "fit_accel_joint",
    "fit_accel_norm",
    "fit_gyro_rotations",
    "integrate_moves",
    "norm_residuals",
    "rough_directions",
]

UPPER_TRIANGLE = ((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2))


def accel_from_params(p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(A upper-triangular (3, 3), b (3,)) from the 9 accelerometer parameters."""
    a = np.zeros((3, 3))
    for k, (i, j) in enumerate(UPPER_TRIANGLE):
        a[i, j] = p[k]
    return a, np.asarray(p[6:9], dtype=float)


def norm_residuals(a: np.ndarray, b: np.ndarray, means: np.ndarray, gravity_mps2: float) -> np.ndarray:
    """``|A (y_i - b)| - g`` per pose (m/s^2)."""
    return np.linalg.norm((np.asarray(means) - b) @ np.asarray(a).T, axis=1) - gravity_mps2


@dataclass(frozen=True, eq=False)
class AccelNormFit:
    """Result of :func:`fit_accel_norm`.

    Attributes:
        a_matrix: A = T K, upper-triangular (3, 3): calibrated = A (y - bias).
        bias: b (m/s^2, the measurement's frame), (3,); imu_tk's bias after the matrix is ``A b``.
        params, cov: the 9 parameters (A00, A01, A02, A11, A12, A22, b0, b1, b2) and their covariance.
        residual_mps2: ``|A (y_i - b)| - g`` per pose, (m,).
        scale_mps2: the residual scale s the covariance is scaled with (m/s^2).
        gravity_mps2: g fitted to.
    """

    a_matrix: np.ndarray
    bias: np.ndarray
    params: np.ndarray
    cov: np.ndarray
    residual_mps2: np.ndarray
    scale_mps2: float
    gravity_mps2: float

    @property
    def rms_mps2(self) -> float:
        return float(np.sqrt(np.mean(self.residual_mps2**2)))

    def calibrate(self, y: np.ndarray) -> np.ndarray:
        return (np.asarray(y) - self.bias) @ self.a_matrix.T


def _ellipsoid_guess(means: np.ndarray, g: float) -> np.ndarray:
    """Axis-aligned algebraic ellipsoid ``sum c_k y_k^2 + d_k y_k = 1``: centre and semi-axes."""
    shift = means.mean(axis=0)  # the centroid is inside the ellipsoid: the "= 1" normalization is safe there
    y = means - shift
    x = np.column_stack([y**2, y])
    coef, *_ = np.linalg.lstsq(x, np.ones(len(y)), rcond=None)
    c, d = coef[:3], coef[3:]
    if np.all(c > 0):
        centre = shift - d / (2.0 * c)
        r = 1.0 + float(np.sum(d * d / (4.0 * c)))
        if r > 0:
            scale = g * np.sqrt(c / r)
            return np.array([scale[0], 0, 0, scale[1], 0, scale[2], *centre])
    s = g / float(np.median(np.linalg.norm(y, axis=1)))
    return np.array([s, 0, 0, s, 0, s, *shift])


def rough_directions(means: np.ndarray, gravity_mps2: float) -> np.ndarray:
    """Gravity directions of still means (m, 3) after the ellipsoid guess (any offset), for the pose checks."""
    y = np.asarray(means, dtype=np.float64)
    if len(y) < 6:
        return y / np.linalg.norm(y, axis=1, keepdims=True)
    p = _ellipsoid_guess(y, gravity_mps2)
    a, b = accel_from_params(p)
    c = (y - b) @ a.T
    return c / np.linalg.norm(c, axis=1, keepdims=True)


def _accel_jac(p: np.ndarray, means: np.ndarray) -> np.ndarray:
    a, b = accel_from_params(p)
    v = means - b
    c = v @ a.T
    n = np.linalg.norm(c, axis=1, keepdims=True)
    jac = np.empty((len(means), 9))
    for k, (i, j) in enumerate(UPPER_TRIANGLE):
        jac[:, k] = c[:, i] * v[:, j] / n[:, 0]
    jac[:, 6:9] = -(c @ a) / n
    return jac


def fit_accel_norm(means: np.ndarray, gravity_mps2: float) -> AccelNormFit:
    """Fit A (upper-triangular) and b to still-pose means (m, 3) so that ``|A (y - b)| = g``."""
    y = np.asarray(means, dtype=np.float64)
    m = len(y)
    if m < 10:
        raise FitError(f"{m} still poses: the gravity-norm fit of the accelerometer (9 parameters) needs at least 10")
    g = float(gravity_mps2)
    p0 = _ellipsoid_guess(y, g)
    sol = least_squares(lambda p: norm_residuals(*accel_from_params(p), y, g), p0,
                        jac=lambda p: _accel_jac(p, y), method="lm", xtol=1e-14, ftol=1e-14, gtol=1e-14,
                        max_nfev=2000)
    p = sol.x
    a, b = accel_from_params(p)
    if np.any(np.diag(a) < 0):  # the mirror solution: flip the signs of the rows with a negative diagonal
        sign = np.sign(np.diag(a))
        a = a * sign[:, None]
        p = np.array([a[i, j] for i, j in UPPER_TRIANGLE] + list(b))
    r = norm_residuals(a, b, y, g)
    jac = _accel_jac(p, y)
    s2 = float(np.sum(r**2) / (m - 9))
    cov = s2 * _inverse(jac, "accelerometer gravity-norm fit")
    return AccelNormFit(a_matrix=a, bias=b, params=p, cov=cov, residual_mps2=r, scale_mps2=float(np.sqrt(s2)),
                        gravity_mps2=g)


def _inverse(jac: np.ndarray, what: str) -> np.ndarray:
    """``(J'J)^-1``, refusing a design whose columns are (nearly) dependent."""
    col = np.linalg.norm(jac, axis=0)
    if np.any(col == 0):
        raise FitError(f"{what}: a parameter has no effect on the residuals (the poses or moves do not determine it)")
    js = jac / col
    sv = np.linalg.svd(js, compute_uv=False)
    if sv[-1] < 1e-6 * sv[0]:
        raise FitError(f"{what}: the poses or moves do not determine every parameter (condition number "
                       f"{sv[0] / sv[-1]:.3g}); vary the orientations more")
    inv = np.linalg.inv(js.T @ js)
    return inv / np.outer(col, col)


# --------------------------------------------------------------------------- gyroscope


def _qmul(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Hamilton product of quaternions (w, x, y, z) along the last axis."""
    pw, px, py, pz = p[..., 0], p[..., 1], p[..., 2], p[..., 3]
    qw, qx, qy, qz = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    return np.stack([
        pw * qw - px * qx - py * qy - pz * qz,
        pw * qx + px * qw + py * qz - pz * qy,
        pw * qy - px * qz + py * qw + pz * qx,
        pw * qz + px * qy - py * qx + pz * qw,
    ], axis=-1)


def _qdot(q: np.ndarray, w: np.ndarray) -> np.ndarray:
    """dq/dt = q (0, w) / 2 for the body rate w (body frame)."""
    return 0.5 * _qmul(q, np.concatenate([np.zeros((*w.shape[:-1], 1)), w], axis=-1))


def integrate_moves(rates: np.ndarray, dt_s: float) -> np.ndarray:
    """Rotation matrices (N, 3, 3) from RK4 integration of body rates ``rates`` (K, N, 3), step ``dt_s``.

    Each column n is one move's calibrated rate at consecutive samples (pad with zeros: a zero rate
    leaves the attitude unchanged). The result maps a vector's body coordinates at the end of the move
    to its body coordinates at the start (``u_start = R u_end``).
    """
    k, n, _ = rates.shape
    q = np.zeros((n, 4))
    q[:, 0] = 1.0
    h = float(dt_s)
    for i in range(k - 1):
        w0, w1 = rates[i], rates[i + 1]
        wm = 0.5 * (w0 + w1)
        k1 = _qdot(q, w0)
        k2 = _qdot(q + 0.5 * h * k1, wm)
        k3 = _qdot(q + 0.5 * h * k2, wm)
        k4 = _qdot(q + h * k3, w1)
        q = q + (h / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
        q /= np.linalg.norm(q, axis=1, keepdims=True)
    w, x, y, z = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], axis=-1),
        np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], axis=-1),
        np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], axis=-1),
    ], axis=-2)


def _pad(moves: Sequence[np.ndarray]) -> np.ndarray:
    k = max(len(m) for m in moves)
    out = np.zeros((k, len(moves), 3))
    for j, m in enumerate(moves):
        out[: len(m), j] = m
    return out


def _predicted(c_matrices: np.ndarray, padded: np.ndarray, dt_s: float, u_before: np.ndarray) -> np.ndarray:
    """Gravity direction after each move predicted with calibration matrices ``c_matrices`` (P, 3, 3)."""
    p = c_matrices.shape[0]
    k, n, _ = padded.shape
    w = np.einsum("pij,knj->kpni", c_matrices, padded).reshape(k, p * n, 3)
    rot = integrate_moves(w, dt_s).reshape(p, n, 3, 3)
    # u_end = R' u_start (R maps end-body to start-body coordinates)
    return np.einsum("pnji,nj->pni", rot, u_before)


def direction_errors_deg(c_matrix: np.ndarray, moves: Sequence[np.ndarray], dt_s: float, u_before: np.ndarray,
                         u_after: np.ndarray) -> np.ndarray:
    """Angle (deg) between the measured and the predicted gravity direction after each move."""
    pred = _predicted(np.asarray(c_matrix)[None], _pad(moves), dt_s, np.asarray(u_before))[0]
    cos = np.clip(np.sum(pred * u_after, axis=1) / np.linalg.norm(pred, axis=1), -1.0, 1.0)
    return np.degrees(np.arccos(cos))


@dataclass(frozen=True, eq=False)
class GyroRotationFit:
    """Result of :func:`fit_gyro_rotations`.

    Attributes:
        c_matrix: C = M_w^-1, (3, 3): calibrated rate = C (y_w - b_w(t)), in the accelerometer's frame.
        cov: covariance of C's 9 elements (row-major).
        error_deg: direction error after each move (deg), (m,).
        scale: residual scale s (unit-vector difference, ~rad).
        jac: Jacobian of the residuals (u_after - R' u_before, (m, 3) row-major) by C's elements, (3 m, 9).
        rotations: R of each move at the fitted C (end-body to start-body coordinates), (m, 3, 3).
    """

    c_matrix: np.ndarray
    cov: np.ndarray
    error_deg: np.ndarray
    scale: float
    jac: np.ndarray
    rotations: np.ndarray

    @property
    def rms_deg(self) -> float:
        return float(np.sqrt(np.mean(self.error_deg**2)))


def fit_gyro_rotations(
    moves: Sequence[np.ndarray],
    dt_s: float,
    u_before: np.ndarray,
    u_after: np.ndarray,
    *,
    initial: np.ndarray | None = None,
    max_iterations: int = 30,
) -> GyroRotationFit:
    """Fit C (3, 3) to bias-free gyro samples over each move (list of (k_i, 3), each from the last
    sample of a still pose to the first sample of the next) so that the gravity direction before
    each move, turned by the integrated rotation, is the one after it."""
    m = len(moves)
    if m < 5:
        raise FitError(f"{m} moves between still poses: the gyroscope fit (9 parameters) needs at least 5")
    padded = _pad(moves)
    ub, ua = np.asarray(u_before, float), np.asarray(u_after, float)
    c = np.eye(3) if initial is None else np.array(initial, dtype=float)
    eps = 1e-6

    def residual_and_jac(c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        stack = np.repeat(c[None], 10, axis=0)
        for k in range(9):
            stack[k + 1].flat[k] += eps
        pred = _predicted(stack, padded, dt_s, ub)  # (10, m, 3)
        r = (ua - pred[0]).ravel()
        jac = -(pred[1:] - pred[0][None]).reshape(9, -1).T / eps
        return r, jac

    lam = 1e-3
    r, jac = residual_and_jac(c)
    cost = float(r @ r)
    for _ in range(max_iterations):
        jtj, jtr = jac.T @ jac, jac.T @ r
        improved = False
        for _ in range(12):
            step = np.linalg.solve(jtj + lam * np.diag(np.diag(jtj) + 1e-12), -jtr)
            trial = c + step.reshape(3, 3)
            r_t, jac_t = residual_and_jac(trial)
            cost_t = float(r_t @ r_t)
            if cost_t < cost:
                c, r, jac, lam, improved = trial, r_t, jac_t, max(lam / 10.0, 1e-9), True
                done = cost - cost_t < 1e-12 * max(cost, 1e-30) or np.abs(step).max() < 1e-10
                cost = cost_t
                break
            lam *= 10.0
        if not improved or done:
            break
    dof = max(2 * m - 9, 1)
    s2 = cost / dof
    cov = s2 * _inverse(jac, "gyroscope rotation fit")
    err = direction_errors_deg(c, moves, dt_s, ub, ua)
    rot = integrate_moves(np.einsum("ij,knj->kni", c, padded), dt_s)
    return GyroRotationFit(c_matrix=c, cov=cov, error_deg=err, scale=float(np.sqrt(s2)), jac=jac, rotations=rot)


# --------------------------------------------------------------------------- accelerometer, joint with eq. (3)


@dataclass(frozen=True, eq=False)
class AccelJointFit:
    """Result of :func:`fit_accel_joint`.

    Attributes:
        misalignment: M, upper-triangular (3, 3) (the convention of :class:`AccelNormFit`, ``A = M^-1``).
        bias: b_stat (m/s^2), (3,).
        drift: b_drift (m/s^2), (3,); tc_s: T_c (s), (3,); tc_free: whether T_c was fitted (else held fixed).
        cov: covariance of (M00, M01, M02, M11, M12, M22, b0, b1, b2, d0, d1, d2, log T_c of the free axes).
        directions: fitted gravity direction per pose (unit vectors, (P, 3)).
        scale: residual scale s (chi^2 / dof)^(1/2) of the block residuals in their noise units.
    """

    misalignment: np.ndarray
    bias: np.ndarray
    drift: np.ndarray
    tc_s: np.ndarray
    tc_free: np.ndarray
    cov: np.ndarray
    directions: np.ndarray
    scale: float

    def std(self) -> dict[str, np.ndarray]:
        sd = np.sqrt(np.clip(np.diag(self.cov), 0.0, None))
        m = np.zeros((3, 3))
        for k, (i, j) in enumerate(UPPER_TRIANGLE):
            m[i, j] = sd[k]
        tc = np.full(3, np.nan)
        tc[self.tc_free] = sd[12:12 + int(self.tc_free.sum())] * self.tc_s[self.tc_free]
        return {"misalignment": m, "bias": sd[6:9], "drift": sd[9:12], "tc_s": tc}

    def drift_at(self, t_s: np.ndarray) -> np.ndarray:
        """``b_drift exp(-t/T_c)`` (m/s^2) at times ``t_s``, (n, 3)."""
        return self.drift * np.exp(-np.asarray(t_s, dtype=float)[:, None] / self.tc_s)


def _tangent_basis(u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    helper = np.where(np.abs(u[:, :1]) < 0.9, np.array([[1.0, 0, 0]]), np.array([[0, 1.0, 0]]))
    e1 = np.cross(u, helper)
    e1 /= np.linalg.norm(e1, axis=1, keepdims=True)
    return e1, np.cross(u, e1)


def fit_accel_joint(
    t_s: np.ndarray,
    width_s: np.ndarray,
    y: np.ndarray,
    count: np.ndarray,
    pose: np.ndarray,
    sigma: np.ndarray,
    gravity_mps2: float,
    *,
    initial: AccelNormFit,
    tc_s: np.ndarray,
    tc_free: np.ndarray,
    drift0: np.ndarray,
    tc_bounds_s: tuple[float, float],
) -> AccelJointFit:
    """Joint ML fit of eq. (1) with the drift of eq. (3) over still blocks, gravity the only reference.

    Block j (centre ``t_s``, width ``width_s``, ``count`` samples, mean ``y``) of still pose ``pose[j]``:
    ``y_j = M g u_p + b_stat + b_drift * E_j(T_c)`` (E the block mean of exp(-t/T_c)), with ``u_p`` a unit
    vector per pose (2 parameters each, in the tangent plane of its start value), M upper-triangular.
    Residuals in units of the block's white noise ``sigma / sqrt(count)``. ``tc_free``: axes whose T_c is
    fitted (in ``tc_bounds_s``); the others hold ``tc_s`` fixed and fit only b_drift.
    """
    from station.fit.blocks import block_exp_mean

    g = float(gravity_mps2)
    poses = np.unique(pose)
    p_index = np.searchsorted(poses, pose)
    u0 = _unit3(initial.calibrate(np.array([y[pose == p].mean(axis=0) for p in poses])))
    e1, e2 = _tangent_basis(u0)
    weight = np.sqrt(count)[:, None] / np.asarray(sigma)[None, :]
    free = np.flatnonzero(tc_free)
    n_tc = len(free)
    m0 = np.linalg.inv(initial.a_matrix)
    x0 = np.concatenate([[m0[i, j] for i, j in UPPER_TRIANGLE], initial.bias, drift0, np.log(np.asarray(tc_s)[free]),
                         np.zeros(2 * len(poses))])

    def unpack(x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        m = np.zeros((3, 3))
        for k, (i, j) in enumerate(UPPER_TRIANGLE):
            m[i, j] = x[k]
        tc = np.array(tc_s, dtype=float)
        tc[free] = np.exp(x[12:12 + n_tc])
        ab = x[12 + n_tc:].reshape(-1, 2)
        u = _unit3(u0 + ab[:, :1] * e1 + ab[:, 1:] * e2)
        return m, x[6:9], x[9:12], tc, u

    def residual(x: np.ndarray) -> np.ndarray:
        m, b, d, tc, u = unpack(x)
        model = (g * u[p_index]) @ m.T + b + d * block_exp_mean(t_s[:, None], width_s[:, None], tc[None, :])
        return ((y - model) * weight).ravel()

    lo = np.full(len(x0), -np.inf)
    hi = np.full(len(x0), np.inf)
    lo[12:12 + n_tc], hi[12:12 + n_tc] = np.log(tc_bounds_s[0]), np.log(tc_bounds_s[1])
    x0[12:12 + n_tc] = np.clip(x0[12:12 + n_tc], lo[12:12 + n_tc] + 1e-9, hi[12:12 + n_tc] - 1e-9)
    # multi-start in T_c (the likelihood in T_c can have a second minimum at a bound): the given values, and
    # every free T_c at the geometric middle and at the upper quarter of its range (log scale)
    starts = [x0]
    for frac in (0.5, 0.75):
        if n_tc:
            x = x0.copy()
            x[12:12 + n_tc] = lo[12:12 + n_tc] + frac * (hi[12:12 + n_tc] - lo[12:12 + n_tc])
            starts.append(x)
    sol = None
    for x in starts:
        trial = least_squares(residual, x, bounds=(lo, hi), method="trf", x_scale="jac", xtol=1e-12, ftol=1e-12,
                              gtol=1e-12, max_nfev=200 * len(x0))
        if sol is None or trial.cost < sol.cost - 1e-9 * max(sol.cost, 1.0):
            sol = trial
    assert sol is not None
    r = sol.fun
    dof = max(len(r) - len(x0), 1)
    s2 = float(r @ r) / dof
    cov = s2 * _inverse(sol.jac, "accelerometer fit (gravity norm with eq. 3 drift)")
    m, b, d, tc, u = unpack(sol.x)
    return AccelJointFit(misalignment=m, bias=b, drift=d, tc_s=tc, tc_free=np.asarray(tc_free, dtype=bool),
                         cov=cov[:12 + n_tc, :12 + n_tc], directions=u, scale=float(np.sqrt(s2)))


def _unit3(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)
