"""The IEEE scale polynomial ``y = u + k2 u^2 + k3 u^3`` in a fit (IEEE Std 952 for the gyro, the same form as
IEEE Std 1293's accelerometer model): which terms the blocks identify, their regressors, and the two-pass
selection by the Wald test.

Shared by the rig's fit (:func:`station.fit.calibrate.fit_session`) and the line's joint fit
(:mod:`station.fit.joint_found`): both ask the same questions of their blocks and keep a term by the same rule;
only how a triad is refitted with the extra columns differs (a callable here).

The gyro (rate steps):

* k3 (odd) where the axis sees **two or more rate magnitudes** (with one, ``u^3 = |u|^2 u`` is a scale error M
  already holds);
* k2 (even) where it also sees **both signs** (with one sign, ``u^2`` is not separable from the bias and ``u^3``).

The accelerometer (poses), by the same rule: k3 where the poses hold two or more magnitudes of specific force
along the axis, k2 where they also hold both signs. On a 1 g rig of face-up poses (+g, -g and about 0 along each
axis) neither is fitted: k3 is a scale error there, and although ``k2 g^2`` could be told from the bias (the mean
of the +g and -g poses less the poses across the axis), with it the three levels would carry three parameters (b,
M, k2) and nothing would be left to test them: one pose off its reference would be taken for a k2 and applied.
Tilted poses (an axis at ``g cos theta``) determine both terms and leave that test (``not_identifiable`` says
so per axis).

In both, a term is kept where its Wald statistic ``(k / sigma_k)^2`` reaches the threshold, in two passes (the
regressors' ``u = M^_k . ref`` from the previous pass's M^).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, TypeVar

import numpy as np

from station.fit.blocks import Blocks

AXES = "xyz"
#: Rate magnitudes within this relative tolerance count as one level (identifiability of the nonlinearity).
LEVEL_RTOL = 0.05

#: A per-axis choice of the IEEE 952 polynomial's terms: M^ (3, 3) and which terms each axis gets, (3, 2) bool
#: (column 0: the even k2 u^2, column 1: the odd k3 u^3).
Polynomial = tuple[np.ndarray, np.ndarray]
#: What a refit returns besides the triad's parameters (the fits, the blocks: the caller's own types).
Fitted = TypeVar("Fitted")


def with_polynomial(
    design: np.ndarray, blocks: Blocks, nonlin: Polynomial | None, k: int
) -> tuple[np.ndarray, tuple[int, int]]:
    """Axis ``k``'s design with the IEEE 952 polynomial's regressors ``u^2`` and ``u^3`` (``u = M^_k . ref`` per
    block) appended where ``nonlin`` selects them; returns the design and the two columns (-1: not in it)."""
    if nonlin is None or not nonlin[1][k].any():
        return design, (-1, -1)
    u = blocks.ref @ nonlin[0][k]
    cols, at = [design], design.shape[1]
    out = [-1, -1]
    for j, power in enumerate((2, 3)):
        if nonlin[1][k, j]:
            cols.append((u**power)[:, None])
            out[j] = at
            at += 1
    return np.column_stack(cols), (out[0], out[1])


def nonlinearity_levels(blocks: Blocks, m_row: np.ndarray) -> int:
    """Distinct rate magnitudes axis ``m_row`` sees in the blocks (levels within :data:`LEVEL_RTOL` merge; rates
    under 5 % of the largest, e.g. rest and poses, do not count). Two or more identify ``u + k u|u|``."""
    u = np.abs(blocks.ref @ m_row)
    top = float(u.max()) if u.size else 0.0
    if top <= 0.0:
        return 0
    levels: list[float] = []
    for v in np.sort(u[u > 0.05 * top]):
        if not levels or v > levels[-1] * (1.0 + LEVEL_RTOL):
            levels.append(float(v))
    return len(levels)


def rate_signs(blocks: Blocks, m_row: np.ndarray) -> int:
    """How many signs (0, 1 or 2) the rate along axis ``m_row`` takes in the rate blocks (rates over 5 % of the
    largest)."""
    u = blocks.ref @ m_row
    top = float(np.abs(u).max()) if u.size else 0.0
    if top <= 0.0:
        return 0
    big = u[np.abs(u) > 0.05 * top]
    return int(np.any(big > 0)) + int(np.any(big < 0))


def polynomial_rule(wald: float, triad: str = "gyro") -> str:
    """The selection rule as the note states it."""
    steps = "poses hold >= 2 magnitudes of specific force along the axis" if triad == "accel" else \
        "rate steps hold >= 2 rate magnitudes"
    return (f"{'IEEE 952 ' if triad == 'gyro' else ''}u + k2 u^2 + k3 u^3 per axis: k3 where the {steps}, k2 where "
            f"they also hold both signs; a term kept where (k/sigma_k)^2 >= {wald:g}")


def no_rate_note(wald: float) -> dict[str, Any]:
    """The note of a gyro fitted without rate steps (M_w from known angles)."""
    return {"status": "not_identifiable", "rule": polynomial_rule(wald), "axes": [],
            "reason": "no rate steps (M_w from known angles): the nonlinearity needs rates"}


def identifiable_terms(
    blocks: Blocks, m_hat: np.ndarray, wald: float, triad: str = "gyro"
) -> tuple[np.ndarray, dict[str, Any]]:
    """Which terms the blocks identify per axis, (3, 2) bool (k2, k3), and the note's common part: the rule,
    levels and signs per axis, the axes per term, and
    for each axis lacking a term the rig step that would separate it (``not_identifiable``). ``triad``:
    ``'gyro'`` (rate steps) or ``'accel'`` (poses; see the module's rules)."""
    levels = [nonlinearity_levels(blocks, m_hat[k]) for k in range(3)]
    signs = [rate_signs(blocks, m_hat[k]) for k in range(3)]
    use = np.array([[lv >= 2 and sg == 2, lv >= 2] for lv, sg in zip(levels, signs, strict=True)])
    identifiable = {"k2": [AXES[k] for k in range(3) if use[k, 0]], "k3": [AXES[k] for k in range(3) if use[k, 1]]}
    missing = []
    for k in range(3):
        if not use[k, 1] and triad == "accel":
            missing.append(f"{AXES[k]}: one magnitude of specific force, neither term (add poses tilted so that "
                           "the axis sees a second magnitude, e.g. g cos 60 deg, in both directions)")
        elif not use[k, 1]:
            missing.append(f"{AXES[k]}: one rate magnitude, neither term (add a step at a second magnitude, "
                           "e.g. 50 and 200 deg/s)")
        elif not use[k, 0]:
            missing.append(f"{AXES[k]}: one sign, k2 u^2 not separable from the bias and k3 (add the same "
                           "magnitudes in the other direction)")
    base: dict[str, Any] = {"rule": polynomial_rule(wald, triad), "levels": levels, "signs": signs,
                            "identifiable": identifiable}
    if missing:
        base["not_identifiable"] = missing
    return use, base


def select_polynomial(
    refit: Callable[[Polynomial], tuple[dict[str, np.ndarray], Fitted]], m_hat: np.ndarray, use: np.ndarray,
    base: dict[str, Any], wald: float,
) -> tuple[tuple[dict[str, np.ndarray], Fitted] | None, dict[str, Any]]:
    """The two passes: ``refit(poly)`` refits the triad with the polynomial's columns (:func:`with_polynomial`)
    and returns its parameters (``misalignment``, ``scale_quadratic``, ``scale_cubic`` with ``*_std``) and
    whatever else the caller keeps. Returns the last refit (None when no term is identifiable or none passes the
    Wald test: the caller keeps its fit without the polynomial) and the note (``status`` fitted /
    not_identifiable / not_significant; per axis the terms identifiable, kept and their z)."""
    if not use.any():
        return None, {"status": "not_identifiable", "axes": [], **base,
                      "reason": "; ".join(base.get("not_identifiable", []))}
    z = np.zeros((3, 2))
    fitted: tuple[dict[str, np.ndarray], Fitted] | None = None
    for _ in range(2):
        fitted = refit((m_hat, use))
        p = fitted[0]
        for j, name in enumerate(("scale_quadratic", "scale_cubic")):
            std = p[f"{name}_std"]
            z[:, j] = np.divide(p[name], std, out=np.zeros(3), where=std > 0)
        keep = use & (z**2 >= wald)
        m_hat = np.asarray(p["misalignment"], dtype=float)
        if not keep.any():
            return None, {"status": "not_significant", "axes": [], **base,
                          "z": {"k2": [round(float(v), 2) for v in z[:, 0]],
                                "k3": [round(float(v), 2) for v in z[:, 1]]},
                          "reason": "no axis's term passes the Wald test"}
        use = keep  # the second pass: the kept terms, the regressors from this pass's M^
    axes = [AXES[k] for k in range(3) if use[k].any()]
    return fitted, {"status": "fitted", "axes": axes, **base,
                    "kept": {"k2": [AXES[k] for k in range(3) if use[k, 0]],
                             "k3": [AXES[k] for k in range(3) if use[k, 1]]},
                    "z": {"k2": [round(float(v), 2) for v in z[:, 0]],
                          "k3": [round(float(v), 2) for v in z[:, 1]]}, "reason": ""}


__all__ = ["LEVEL_RTOL", "Polynomial", "identifiable_terms", "no_rate_note", "nonlinearity_levels",
           "polynomial_rule", "rate_signs", "select_polynomial", "with_polynomial"]
