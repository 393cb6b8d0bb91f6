"""The found terms in the line's joint fit: the gyro's IEEE 952 scale polynomial and the sensor's time offset.

The joint fit (:mod:`station.fit.joint`) fits eq. 1 with eq. 3's drift over a unit's rack rest and rig recording.
Here it gets the two terms the rig's fit (:func:`station.fit.calibrate.fit_session`) carries into the unit
(docs/found-terms.md), by the same rules and the same code:

* **The polynomial** ``y = u + k2 u^2 + k3 u^3`` per gyro axis (:mod:`station.fit.scale_polynomial`): the terms the
  rig's rate steps identify (k3 with two or more rate magnitudes, k2 with both signs as well; the rack's rest sees
  no rate, so only the rig part can), the regressors appended to the joint design (after the rack's offsets), two
  passes, a term kept where ``(k/sigma_k)^2`` reaches ``FitOptions.nonlinearity_wald``. An axis the line's rig plan
  cannot determine is named in ``quality.scale_nonlinearity.not_identifiable`` with the rig step that would.
* **The time offset** tau (:func:`station.fit.time_offset.estimate_time_offset`) on the rig recording's
  transitions (the rack has none: a rest in one orientation), the joint fit's gyro mean model evaluated at the
  rig samples' sensor time since power-on (the warm-up's shape comes from the rack as well); kept where
  ``(tau/sigma)^2`` reaches ``FitOptions.time_offset_wald`` and Algorithm 1 can apply it. A rig recording without
  references in its moves (the station's capture records them only in the settled windows) leaves it
  ``not_determined``, with the reason.

Both follow ``FitOptions.scale_nonlinearity`` and ``FitOptions.time_offset`` (``'off'``: not estimated, no note,
as before).
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import numpy as np

from station.fit.axis_ml import fit_axis
from station.fit.blocks import Blocks
from station.fit.calibrate import FitOptions, TriadLinear, mean_model, unpack_triad
from station.fit.scale_polynomial import Polynomial, identifiable_terms, select_polynomial, with_polynomial
from station.fit.time_offset import estimate_time_offset
from station.kernel.parameters import NonlinearityNote, ParameterSet
from station.session.model import Session


def joint_polynomial(
    blocks: Blocks, design: np.ndarray, sigma: np.ndarray, options: FitOptions, tri: TriadLinear,
    tc_range_s: tuple[float, float] | None,
) -> tuple[TriadLinear, dict[str, Any] | None]:
    """The gyro's joint fit ``tri`` (over ``blocks`` with linear ``design``: references, 1, the rack's offsets)
    refitted with the polynomial's columns where the blocks identify them and the Wald test keeps them; and the
    note (None when ``options.scale_nonlinearity`` is ``'off'``: ``tri`` unchanged)."""
    if options.scale_nonlinearity == "off":
        return tri, None
    m_hat = np.asarray(unpack_triad(tri)["misalignment"], dtype=float)
    use, base = identifiable_terms(blocks, m_hat, options.nonlinearity_wald)

    def refit(poly: Polynomial) -> tuple[dict[str, np.ndarray], TriadLinear]:
        fits, cols = [], []
        for k in range(3):
            d_k, col = with_polynomial(design, blocks, poly, k)
            fits.append(fit_axis(blocks, k, d_k, float(sigma[k]), lr_threshold=options.drift_lr_threshold,
                                 tc_range_s=tc_range_s))
            cols.append(col)
        out = TriadLinear(fits=fits, n_ref=tri.n_ref, extra=tri.extra, nonlin_col=tuple(cols))
        return unpack_triad(out), out

    fitted, note = select_polynomial(refit, m_hat, use, base, options.nonlinearity_wald)
    return (tri if fitted is None else fitted[1]), note


def with_found_terms(
    params: ParameterSet, rig: Session, gyro: dict[str, np.ndarray], sigma: np.ndarray, options: FitOptions,
    polynomial_note: dict[str, Any] | None,
) -> ParameterSet:
    """``params`` (the joint fit's set) with the polynomial's note and the time offset estimated on ``rig``'s
    transitions with the fitted gyro ``gyro`` (white noise ``sigma``): the note, and the value and uncertainty the
    set keeps (0 when not kept)."""
    quality = params.quality
    if polynomial_note is not None:
        quality = replace(quality, scale_nonlinearity=NonlinearityNote.from_dict(polynomial_note))
    if options.time_offset == "off":
        return replace(params, quality=quality)
    note, tau, tau_std = estimate_time_offset(rig, lambda t, r, f, d: mean_model(gyro, t, r, f, d), sigma, None,
                                              wald=options.time_offset_wald)
    return replace(params, quality=replace(quality, time_offset=note), time_offset_s=tau, time_offset_std_s=tau_std)


__all__ = ["joint_polynomial", "with_found_terms"]
