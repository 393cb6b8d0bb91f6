"""The rig role of the line: which plan a unit gets, and the fit over its rack and rig recordings.

Before anything moves, :func:`choose_plan` looks up the unit's rack recording by serial
(:func:`station.line.recordings.latest_rack_recording`) and compares it with what the unit reports now
(its boot count, its uptime on the station clock) by the rules of :func:`station.fit.joint.power_continuity`:

* ``line``: one power-on since the rack's first sample: the short rig plan, then :func:`fit_line_unit`;
* otherwise the unit gets the ``full`` rig plan (warm-up on the rig, as without a rack) or goes ``back to
  the rack`` (``on_interruption``), and :class:`LineDecision` says why (no rack recording, a changed
  boot count, a sensor time that restarted or disagrees with the station clock, a transfer too long).

After the rig recording, :func:`fit_line_unit` checks the same again on the recordings themselves
(:func:`station.fit.joint.check_power`) and fits both together (:func:`station.fit.joint.fit_joint`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from sqlalchemy.orm import Session as DbSession

from station.fit.calibrate import FitOptions
from station.fit.joint import BOOT_KEY, check_power, fit_joint, power_continuity
from station.fit.params import ParameterSet
from station.line.recordings import StoredRackRecording, latest_rack_recording
from station.session.model import Session

#: what a unit gets
LINE, FULL, BACK_TO_RACK = "line", "full", "back to rack"
ON_INTERRUPTION = (FULL, BACK_TO_RACK)


@dataclass(frozen=True, eq=False)
class LineDecision:
    """Which plan a unit gets on the rig, and why.

    Attributes:
        serial: the unit.
        plan: ``'line'`` (short rig plan + joint fit), ``'full'`` (the full rig plan) or ``'back to rack'``.
        reason: why not ``'line'`` ('' when it is).
        rack: the rack recording used (None when there is none).
    """

    serial: str
    plan: str
    reason: str
    rack: StoredRackRecording | None


def _wall(session: Session) -> float:
    try:
        return float(session.metadata.get("wall_clock_at_start_s", "nan"))
    except ValueError:
        return math.nan


def choose_plan(
    db: DbSession, serial: str, *, boot_count: int | None, uptime_s: float, clock_now_s: float,
    max_transfer_s: float = 1800.0, on_interruption: str = FULL,
) -> LineDecision:
    """The plan for ``serial`` from its rack recording and what the unit reports now (boot count, uptime read
    at station clock ``clock_now_s``)."""
    if on_interruption not in ON_INTERRUPTION:
        raise ValueError(f"on_interruption must be one of {ON_INTERRUPTION}, got {on_interruption!r}")
    stored = latest_rack_recording(db, serial)
    if stored is None:
        return LineDecision(serial, FULL, "no rack recording of this unit", None)
    rack = stored.session
    power = power_continuity(
        rack_serial=rack.serial, rig_serial=serial, rack_boot=rack.metadata.get(BOOT_KEY),
        rig_boot=None if boot_count is None else str(boot_count), rack_end_s=float(rack.t_s[-1]),
        rack_end_clock_s=_wall(rack) + float(rack.t_s[-1] - rack.t_s[0]), rig_start_s=float(uptime_s),
        rig_start_clock_s=float(clock_now_s), max_transfer_s=max_transfer_s)
    if not power.continuous:
        return LineDecision(serial, on_interruption, power.reason, stored)
    return LineDecision(serial, LINE, "", stored)


def fit_line_unit(rack: Session, rig: Session, options: FitOptions | None = None, *,
                  max_transfer_s: float = 1800.0) -> ParameterSet:
    """The joint fit of one unit's rack and rig recordings (refused with the reason when they are not one
    power-on: :class:`~station.kernel.errors.FitError`)."""
    power = check_power(rack, rig, max_transfer_s=max_transfer_s)
    params = fit_joint(rack, rig, options, max_transfer_s=max_transfer_s)
    params.source["line"] = {"transfer_s": round(power.sensor_gap_s, 6)}
    return params


__all__ = ["BACK_TO_RACK", "FULL", "LINE", "LineDecision", "choose_plan", "fit_line_unit"]
