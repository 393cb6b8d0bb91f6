"""Section 6 of ``compare_openaxes.py --gyro-study``: extensions of the rig-free gyro model, held out.

On the OpenAXES BMI160 recording, each candidate is a nested extension of the station's gyro model
(``w = C (y - b(t))``, C the 9 elements, b(t) eq. 3's bias curve), fitted on all moves and in the station's
5 leave-poses-out folds (``station.fit.rigfree_fit.folds``: the same held-out poses, the accelerometer refitted
per fold, the same gravity directions as the station's cross-validation), on two inputs: the reads as they
come (the model before the read-timing correction) and the sensor's samples (``station.fit.readtiming``:
stale reads dropped, the sensor's period). Printed per candidate: fitted and held-out direction RMS (deg),
the held-out difference against the base model (C only) on the same input and against imu_tk's model
re-fitted in the same folds (its own bias and accelerometer, the reads, 0.01 s), each +- the paired bootstrap
standard error over the moves, and the nested F-test of the extension on the fitted moves (2 dof per move).

Candidates (``y`` the bias-free raw rate per sensor axis, the correction applied before C; f the calibrated
specific force during the move, g = 9.81744 m/s^2):

- IEEE Std 952 scale-factor nonlinearity per axis: ``y + k3 y^3``; ``y + k2 y|y|``; ``y + k2 y^2``;
  ``y + k2 y^2 + k3 y^3``; ``y + k2 y|y| + k3 y^3``; scale-factor asymmetry ``y + a |y|``;
- g-sensitivity: ``y - G f / g`` with G full (9) or diagonal (3), rad/s per g;
- a scale drift over the recording (temperature): ``y (1 + k t / 100 s)``.

The search over these 9 candidates was not part of the product; the read-timing model was adopted by its own
selection rule (exact repeats in the gyro record), not by these numbers.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy import stats

from station.fit.multipos import integrate_moves
from station.fit.rigfree_fit import RigFreeOptions, calibrated_accel, folds, prepare, still_directions
from station.session.model import Session

G = 9.81744
Rates = Callable[[np.ndarray, np.ndarray], np.ndarray]  # (params, padded (K, N, 7)) -> calibrated rates (K, N, 3)


@dataclass(frozen=True)
class Candidate:
    name: str
    n_extra: int
    correction: Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray]  # (k, y, padded) -> added to y


def _model(c: Candidate) -> Rates:
    def rates(x: np.ndarray, p: np.ndarray) -> np.ndarray:
        y = p[..., :3]
        live = np.any(y != 0, axis=-1, keepdims=True)  # padding after a move's end stays zero
        y2 = y + c.correction(x[9:], y, p) * live if c.n_extra else y
        return np.einsum("ij,knj->kni", x[:9].reshape(3, 3), y2)
    return rates


CANDIDATES = (
    Candidate("base: C (9) only", 0, lambda k, y, p: 0.0 * y),
    Candidate("a. k3 y^3", 3, lambda k, y, p: k * y**3),
    Candidate("a. k2 y|y|", 3, lambda k, y, p: k * y * np.abs(y)),
    Candidate("a. k2 y^2", 3, lambda k, y, p: k * y**2),
    Candidate("a. k2 y^2 + k3 y^3", 6, lambda k, y, p: k[:3] * y**2 + k[3:] * y**3),
    Candidate("a. k2 y|y| + k3 y^3", 6, lambda k, y, p: k[:3] * y * np.abs(y) + k[3:] * y**3),
    Candidate("a. asymmetry a|y|", 3, lambda k, y, p: k * np.abs(y)),
    Candidate("b. g-sensitivity, G full", 9,
              lambda k, y, p: -np.einsum("ij,knj->kni", k.reshape(3, 3), p[..., 3:6]) / G),
    Candidate("b. g-sensitivity, G diagonal", 3, lambda k, y, p: -k * p[..., 3:6] / G),
    Candidate("c. scale drift k t/100 s", 1, lambda k, y, p: k[0] * y * p[..., 6:7] / 100.0),
)


def _pad(moves: list[np.ndarray]) -> np.ndarray:
    out = np.zeros((max(len(m) for m in moves), len(moves), moves[0].shape[1]))
    for j, m in enumerate(moves):
        out[: len(m), j] = m
    return out


def _predict(rates: Rates, xs: np.ndarray, padded: np.ndarray, dt: float, ub: np.ndarray) -> np.ndarray:
    """Gravity direction after each move, (P, N, 3), for each parameter vector in ``xs`` (P, n): one integration."""
    w = np.concatenate([rates(x, padded) for x in xs], axis=1)
    rot = integrate_moves(w, dt).reshape(len(xs), padded.shape[1], 3, 3)
    return np.einsum("pnji,nj->pni", rot, ub)


def _errors(rates: Rates, x: np.ndarray, moves: list[np.ndarray], dt: float, ub: np.ndarray,
            ua: np.ndarray) -> np.ndarray:
    pred = _predict(rates, x[None], _pad(moves), dt, ub)[0]
    cos = np.clip(np.sum(pred * ua, axis=1) / np.linalg.norm(pred, axis=1), -1.0, 1.0)
    return np.degrees(np.arccos(cos))


def _fit(rates: Rates, x0: np.ndarray, moves: list[np.ndarray], dt: float, ub: np.ndarray, ua: np.ndarray,
         iterations: int = 40, eps: float = 1e-6) -> tuple[np.ndarray, float]:
    """Levenberg-Marquardt on ``u_after - R' u_before`` (as station.fit.multipos.fit_gyro_rotations), the
    Jacobian by forward differences in one batched integration. Returns (x, residual sum of squares)."""
    padded = _pad(moves)
    x = np.array(x0, dtype=float)
    n = len(x)

    def rj(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        xs = np.repeat(x[None], n + 1, axis=0)
        xs[np.arange(1, n + 1), np.arange(n)] += eps
        p = _predict(rates, xs, padded, dt, ub)
        return (ua - p[0]).ravel(), -(p[1:] - p[0][None]).reshape(n, -1).T / eps

    lam = 1e-3
    r, j = rj(x)
    cost = float(r @ r)
    for _ in range(iterations):
        jtj, jtr = j.T @ j, j.T @ r
        improved = done = False
        for _ in range(12):
            step = np.linalg.solve(jtj + lam * np.diag(np.diag(jtj) + 1e-12), -jtr)
            r_t, j_t = rj(x + step)
            cost_t = float(r_t @ r_t)
            if cost_t < cost:
                done = cost - cost_t < 1e-12 * cost or np.abs(step).max() < 1e-10
                x, r, j, cost, lam, improved = x + step, r_t, j_t, cost_t, max(lam / 10.0, 1e-9), True
                break
            lam *= 10.0
        if not improved or done:
            break
    return x, cost


def _rms(e: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.square(e))))


def _paired(a: np.ndarray, b: np.ndarray, draws: int = 4000, seed: int = 0) -> tuple[float, float]:
    idx = np.random.default_rng(seed).integers(0, len(a), size=(draws, len(a)))
    d = np.sqrt(np.mean(a[idx] ** 2, axis=1)) - np.sqrt(np.mean(b[idx] ** 2, axis=1))
    return _rms(a) - _rms(b), float(np.std(d))


def run(session: Session, imu_tk_held_out: np.ndarray) -> None:
    """Print section 6 for ``session`` (the BMI160 import at 9.81744); ``imu_tk_held_out``: the per-move held-out
    errors of imu_tk's model re-fitted in the same folds (``compare_openaxes.imu_tk_cross_validation``)."""
    opt = RigFreeOptions()
    prep, extra = prepare(session, opt)
    reads, _ = prepare(session, RigFreeOptions(read_timing=False))
    u = still_directions(session, prep, extra, opt)
    cv = folds(session, prep, extra, opt)
    pairs = np.array(prep.move_pairs)
    ub, ua = u[pairs[:, 0]], u[pairs[:, 1]]
    t_s = session.t_s
    force = calibrated_accel(session, prep, extra, opt)  # the specific force for the g-sensitivity (m/s^2)
    spans = [(prep.still[i].stop - 1, prep.still[i + 1].start + 1) for i in range(len(prep.still) - 1)]
    timing = extra["read_timing"]

    def augment(moves: list[np.ndarray], samples: bool) -> list[np.ndarray]:
        out = []
        for m, (a, b) in zip(moves, spans, strict=True):
            f = force[a:b]
            if samples:  # the force on the sensor's sample grid: the reads' time base shortened to the samples
                f = f[np.linspace(0, len(f) - 1, len(m)).round().astype(int)]
            out.append(np.column_stack([m, f, np.full(len(m), t_s[a:b].mean())]))
        return out

    inputs = {"reads as they come": augment(reads.moves, False),
              "sensor samples (read timing)": augment(prep.moves, True)}
    print(f"\n6. Gyro model extensions, fitted and held out in the station's {opt.cv_folds} leave-poses-out folds "
          f"(BMI160, {len(spans)} moves; read timing: {timing.reason})")
    print(f"{'input / candidate':<44}{'extra':>6}{'fitted':>8}{'held out':>10}{'vs base (same input)':>24}"
          f"{'vs imu_tk re-fit':>20}{'F-test p':>10}")
    for label, moves in inputs.items():
        print(label)
        base_x, base_cost, base_held = None, 0.0, None
        for cand in CANDIDATES:
            rates = _model(cand)
            x0 = np.concatenate([np.eye(3).ravel() if base_x is None else base_x[:9], np.zeros(cand.n_extra)])
            x, cost = _fit(rates, x0, moves, prep.ts, ub, ua)
            fitted = _errors(rates, x, moves, prep.ts, ub, ua)
            held = np.full(len(moves), np.nan)
            for fold in cv:
                tr, te = fold.train, fold.test
                xf, _ = _fit(rates, x, [moves[j] for j in tr], prep.ts, fold.u[pairs[tr, 0]], fold.u[pairs[tr, 1]])
                held[te] = _errors(rates, xf, [moves[j] for j in te], prep.ts, fold.u[pairs[te, 0]],
                                   fold.u[pairs[te, 1]])
            if base_x is None:
                base_x, base_cost, base_held = x, cost, held
                vs_base, p_text = "", ""
            else:
                dof = 2 * len(moves) - 9 - cand.n_extra
                f_stat = ((base_cost - cost) / cand.n_extra) / (cost / dof)
                p_text = f"{stats.f.sf(f_stat, cand.n_extra, dof):10.3f}"
                d, se = _paired(held, base_held)
                vs_base = f"{d:+.4f} +- {se:.4f}"
            d_tk, se_tk = _paired(held, imu_tk_held_out)
            print(f"  {cand.name:<42}{cand.n_extra:>6}{_rms(fitted):8.4f}{_rms(held):10.4f}{vs_base:>24}"
                  f"{f'{d_tk:+.4f} +- {se_tk:.4f}':>20}{p_text}")
