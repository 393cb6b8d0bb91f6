"""Which fitted parameters the recording cannot determine: the rule, applied to a fitted set.

A number with a standard uncertainty is a result only when the recording pins it down. These cases are
flagged instead of printed (:class:`~station.kernel.parameters.Undetermined`):

* eq. 3's correlation time T_c is not determined when its standard uncertainty exceeds T_c itself, or when
  T_c exceeds the time from power-on to the recording's last sample (the recording does not follow the
  decay to its end, so a longer T_c fits about as well) and the fit had no prior range for it (with the
  sensor class's range as a prior, as the station's run fits, T_c beyond the recording is the class's
  statement, which the set's ``source.tc_prior_s`` records; only its uncertainty decides);
* b_drift, the amplitude of that decay, is not determined where T_c is not (it trades against T_c);
* b_stat, the bias the decay settles to, is not determined where T_c lies beyond the recording (the
  asymptote is an extrapolation: only the sum ``b_stat + b_drift exp(-t/T_c)`` at the recording's end is
  pinned down by the data), and, with product limits given, where its standard uncertainty exceeds the
  width of its limit range (no verdict on it can mean anything).

The rule uses only the fit's own numbers, the record length and the limits when given; it is not tuned on
any recording. An export then uses :meth:`ParameterSet.constant_bias_values`'s stated fallback; an EEPROM image
keeps the fitted warm-up curve and says so (:func:`station.eeprom.image.image_notes`).
"""

from __future__ import annotations

import math
from dataclasses import replace

from station.kernel.limits import ProductLimits
from station.kernel.parameters import AXES, ParameterSet, TriadParams, Undetermined

RULE = ("T_c not determined when its standard uncertainty exceeds it or, without a prior range for it, it exceeds "
        "the time from power-on to the recording's last sample; b_drift not determined where T_c is not; b_stat "
        "not determined where T_c exceeds the recording (an extrapolated asymptote) or where its standard "
        "uncertainty exceeds its limit range's width (when limits are given)")


def undetermined(
    name: str, tri: TriadParams, record_end_s: float, bias_limit_width: float | None = None, *, prior: bool = False
) -> list[Undetermined]:
    """The parameters of one triad (``'accel'`` or ``'gyro'``) that the rule flags, in axis order (``prior``: the
    fit had a prior range for this triad's T_c)."""
    out: list[Undetermined] = []
    for k in range(3):
        tc, tc_std = float(tri.correlation_time_s[k]), float(tri.correlation_time_s_std[k])
        tc_reason = beyond = None
        if math.isfinite(tc):
            if math.isfinite(record_end_s) and tc > record_end_s and not prior:
                tc_reason = beyond = f"T_c {tc:.4g} s beyond the recording's {record_end_s:.4g} s since power-on"
            elif not math.isfinite(tc_std) or tc_std > tc:
                tc_reason = f"T_c {tc:.4g} s with standard uncertainty {tc_std:.4g} s, larger than itself"
        if tc_reason is not None:
            out.append(Undetermined(name, "correlation_time_s", k, tc_reason))
            out.append(Undetermined(name, "bias_drift", k, f"the decay's amplitude, with {tc_reason}"))
        b_std = float(tri.bias_static_std[k])
        if beyond is not None:
            out.append(Undetermined(name, "bias_static", k, f"the asymptote of a decay with {beyond}"))
        elif bias_limit_width is not None and math.isfinite(bias_limit_width) and (
                not math.isfinite(b_std) or b_std > bias_limit_width):
            out.append(Undetermined(name, "bias_static", k, f"standard uncertainty {b_std:.4g} exceeds the limit "
                                                           f"range's width {bias_limit_width:.4g}"))
    return out


def assess(params: ParameterSet, record_end_s: float, limits: ProductLimits | None = None) -> ParameterSet:
    """``params`` with :attr:`FitQuality.undetermined` set by :data:`RULE` (the numbers themselves unchanged)."""
    flags: list[Undetermined] = []
    priors = params.source.get("tc_prior_s")
    priors = priors if isinstance(priors, dict) else {}
    for name, tri in (("accel", params.accel), ("gyro", params.gyro)):
        width = None
        if limits is not None:
            low, high = (limits.accel if name == "accel" else limits.gyro).bias_static
            width = float(high) - float(low)
        flags += undetermined(name, tri, record_end_s, width, prior=name in priors)
    quality = replace(params.quality, determinability_rule=RULE, undetermined=tuple(flags),
                      record_end_s=float(record_end_s))
    return replace(params, quality=quality)


def describe(u: Undetermined) -> str:
    """One line: ``'accel z T_c: not determined (reason)'``."""
    return f"{u.triad} {AXES[u.axis]} {u.parameter}: not determined ({u.reason})"
