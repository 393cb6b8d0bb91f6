"""The rig role of the line: which plan a unit gets, the rig run without a power cycle, the joint fit.

Before anything moves, :func:`choose_plan` looks up the unit's rack recording by serial (a
:class:`~station.line.recordings.RackArchive`) and compares it with what the unit reports now (its boot
count, its uptime on the station clock) by the rules of :func:`station.fit.joint.power_continuity`:

* ``line``: one power-on since the rack's first sample: the short rig plan, then the joint fit;
* otherwise the unit gets the ``full`` rig plan (warm-up on the rig, as without a rack) or goes ``back to
  the rack`` (``on_interruption``), and :class:`LineDecision` says why (no rack recording, a changed
  boot count, a sensor time that restarted or disagrees with the station clock, a transfer too long).

:class:`LineRigRunner` is the sequence runner for the line's units: the units keep the power they had in
the rack (:class:`KeepPowered`: the rest step's power cycle becomes a check that the unit did not reboot),
each recording carries the station clock's offset from the unit's sensor time (``clock_offset_s``), a unit
whose plan is not ``line`` is refused before anything moves with its decision's reason, and each unit is
fitted over its rack and rig recordings together (:func:`fit_line_unit`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from station.fit.calibrate import FitOptions
from station.fit.joint import BOOT_KEY, OFFSET_KEY, check_power, fit_joint, power_continuity
from station.kernel.clock import Clock
from station.kernel.errors import FitError, HardwareError
from station.kernel.line_plan import ANY_ORIENTATION, RACK_TILT_TOLERANCE_DEG
from station.kernel.parameters import ParameterSet
from station.line.recordings import RackArchive, StoredRackRecording
from station.sensor.protocol import Sensor
from station.sequence.capture import UnitChannel
from station.sequence.runner import SequenceRunner, UnitResult
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
    archive: RackArchive, serial: str, *, boot_count: int | None, uptime_s: float, clock_now_s: float,
    max_transfer_s: float = 1800.0, on_interruption: str = FULL, clock_slack_s: float = 2.0,
) -> LineDecision:
    """The plan for ``serial`` from its rack recording and what the unit reports now (boot count, uptime read
    at station clock ``clock_now_s``); ``clock_slack_s``: see :func:`~station.fit.joint.check_power`."""
    if on_interruption not in ON_INTERRUPTION:
        raise ValueError(f"on_interruption must be one of {ON_INTERRUPTION}, got {on_interruption!r}")
    stored = archive.latest(serial)
    if stored is None:
        return LineDecision(serial, FULL, "no rack recording of this unit", None)
    rack = stored.session
    power = power_continuity(
        rack_serial=rack.serial, rig_serial=serial, rack_boot=rack.metadata.get(BOOT_KEY),
        rig_boot=None if boot_count is None else str(boot_count), rack_end_s=float(rack.t_s[-1]),
        rack_end_clock_s=_wall(rack) + float(rack.t_s[-1] - rack.t_s[0]), rig_start_s=float(uptime_s),
        rig_start_clock_s=float(clock_now_s), max_transfer_s=max_transfer_s, clock_slack_s=clock_slack_s)
    if not power.continuous:
        return LineDecision(serial, on_interruption, power.reason, stored)
    return LineDecision(serial, LINE, "", stored)


def fit_line_unit(rack: Session, rig: Session, options: FitOptions | None = None, *,
                  max_transfer_s: float = 1800.0, clock_slack_s: float = 2.0, rack_orientation: str = ANY_ORIENTATION,
                  rack_tilt_tolerance_deg: float = RACK_TILT_TOLERANCE_DEG) -> ParameterSet:
    """The joint fit of one unit's rack and rig recordings (refused with the reason when they are not one
    power-on: :class:`~station.kernel.errors.FitError`; when the rack holds its units in ``rack_orientation``
    and this unit's rest was not: :class:`~station.kernel.errors.RackOrientationError`)."""
    power = check_power(rack, rig, max_transfer_s=max_transfer_s, clock_slack_s=clock_slack_s)
    params = fit_joint(rack, rig, options, max_transfer_s=max_transfer_s, clock_slack_s=clock_slack_s,
                       rack_orientation=rack_orientation, rack_tilt_tolerance_deg=rack_tilt_tolerance_deg)
    params.source["line"] = {"transfer_s": round(power.sensor_gap_s, 6)}
    return params


class KeepPowered:
    """A sensor client whose ``power_cycle`` keeps the unit's power: the line's units arrive powered from the rack,
    and a power cycle would restart the warm-up the rack observed. It checks instead that the unit did not reboot
    since it was wrapped (its boot count); everything else is the wrapped client's."""

    def __init__(self, sensor: Sensor) -> None:
        self._sensor = sensor
        self._boot_count = sensor.status().boot_count
        self.released = False

    def release(self) -> None:
        """From now on a power cycle is a real one (after the fit: the written image is loaded at power-on)."""
        self.released = True

    def power_cycle(self, boot_timeout_s: float | None = None) -> None:
        if self.released:
            self._sensor.power_cycle(boot_timeout_s)
            return
        now = self._sensor.status().boot_count
        if now != self._boot_count:
            raise HardwareError(f"the unit rebooted on the rig (boot count {self._boot_count} -> {now}): its rack "
                                "recording no longer shares its time base")

    def __getattr__(self, name: str) -> Any:
        return getattr(self._sensor, name)


class LineRigRunner(SequenceRunner):
    """The sequence runner for units that soaked in the rack (see the module docstring).

    Args are :class:`~station.sequence.runner.SequenceRunner`'s (``sensors`` are wrapped in :class:`KeepPowered`),
    plus ``archive`` (where the rack recordings are), ``max_transfer_s``, ``on_interruption``, ``clock_slack_s``
    (the allowed disagreement of sensor time and station clock, s; a simulated clock's command round trips take
    its scale times longer in its seconds) and the line plan's ``rack_orientation`` and
    ``rack_tilt_tolerance_deg`` (:class:`~station.kernel.line_plan.LinePlan`).
    """

    def __init__(self, rig: Any, sensors: Sequence[Sensor], clock: Clock, *, archive: RackArchive,
                 max_transfer_s: float = 1800.0, on_interruption: str = FULL, clock_slack_s: float = 2.0,
                 rack_orientation: str = ANY_ORIENTATION, rack_tilt_tolerance_deg: float = RACK_TILT_TOLERANCE_DEG,
                 **kwargs: Any) -> None:
        self.archive = archive
        self.rack_orientation = rack_orientation
        self.rack_tilt_tolerance_deg = float(rack_tilt_tolerance_deg)
        self.max_transfer_s = float(max_transfer_s)
        self.clock_slack_s = float(clock_slack_s)
        self.decisions: dict[str, LineDecision] = {}
        wrapped: list[Sensor] = []
        for s in sensors:
            serial = s.identify().serial
            t_a = clock.now()
            status = s.status()
            t_b = clock.now()
            self.decisions[serial] = choose_plan(archive, serial, boot_count=status.boot_count,
                                                 uptime_s=status.uptime_s, clock_now_s=0.5 * (t_a + t_b),
                                                 max_transfer_s=max_transfer_s, on_interruption=on_interruption,
                                                 clock_slack_s=clock_slack_s)
            wrapped.append(KeepPowered(s))
        super().__init__(rig, wrapped, clock, **kwargs)

    routes_units = True

    def refusal(self, serial: str) -> str | None:
        """A unit whose plan is not ``line`` is refused by the line's decision (not by the retest policy, which
        is asked only for the line's units)."""
        d = self.decisions.get(serial)
        if d is None:
            return "refused by the line: not identified before the run"
        if d.plan != LINE:
            return f"refused by the line's rack-to-rig decision, {d.plan}: {d.reason}"
        return super().refusal(serial)

    def metadata(self, unit: UnitChannel) -> dict[str, str]:
        meta = super().metadata(unit)
        offset = getattr(unit, "offset_s", None)
        if offset is not None and math.isfinite(offset):
            meta[OFFSET_KEY] = repr(float(offset))
        return meta

    def _provision(self, results: list[UnitResult]) -> list[UnitResult]:
        # the fit is done: the written image is loaded by a real power cycle before it is verified on the rig
        for s in self.sensors:
            if isinstance(s, KeepPowered):
                s.release()
        return super()._provision(results)

    def _fit_one(self, session: Session) -> ParameterSet:
        stored = self.archive.latest(session.serial)
        if stored is None:
            raise FitError("no rack recording of this unit")
        return fit_line_unit(stored.session, session, self.fit_options, max_transfer_s=self.max_transfer_s,
                             clock_slack_s=self.clock_slack_s, rack_orientation=self.rack_orientation,
                             rack_tilt_tolerance_deg=self.rack_tilt_tolerance_deg)


__all__ = ["BACK_TO_RACK", "FULL", "LINE", "KeepPowered", "LineDecision", "LineRigRunner", "choose_plan",
           "fit_line_unit"]
