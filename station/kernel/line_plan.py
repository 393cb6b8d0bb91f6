"""The calibration line's plan: how long a unit soaks in the rack, and what the rig does after.

In a line the warm-up of eq. 3 is observed in a powered soak rack (a rest in a fixed, unknown
orientation, logged from power-on) and only the poses and rate steps run on the rig. A
:class:`LinePlan` holds both parts: ``rack_s`` of rest from power-on, at most ``max_transfer_s``
to move the still-powered unit from its rack slot to the rig, then ``rig`` (a
:class:`~station.kernel.plan.RigPlan` whose ``rest_s`` is the short rest the rig itself holds).
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import asdict, dataclass, field, fields, replace
from pathlib import Path
from typing import Any

from station.kernel.geometry import POSE_ANGLES_DEG
from station.kernel.plan import PlanError, RigPlan

#: Format of a line plan written to a file (``station-line-plan/1``).
LINE_PLAN_FORMAT = "station-line-plan/1"
#: ``rack_orientation`` of a rack that holds its units in any orientation (nobody says which).
ANY_ORIENTATION = "any"
#: The largest tilt of a rack slot against the plan's rack orientation (deg) the joint fit accepts, by default.
RACK_TILT_TOLERANCE_DEG = 5.0


def line_rig_plan() -> RigPlan:
    """The rig part of the default line: no rest, six 25 s poses in an order whose every tumble is 90 deg
    (+z +x +y -x -y -z), +-100 deg/s about each axis held 3 s, the z axis first and upside down (the poses end
    with -z up: no tumble before it), then x and y (one 90 deg tumble each).

    Chosen on development units (``benchmarks/bench_line.py``): the accelerometer's M and b_stat come from the
    poses alone (the rack's orientation is unknown), and 20 s poses left the corrected pose error 1.13-1.24x the
    full plan's, 25 s about 1.0x; the rate holds are far above what the gyro's white noise needs (3 s at 100 Hz:
    7e-6 of 100 deg/s), so they paid for the longer poses. The rate axes' order saves one tumble against x, y, z
    (the trajectory 232.5 s instead of 236.5 s with the runner's 2 s rest).
    """
    return RigPlan(
        rest_s=0.0,
        poses=("+z", "+x", "+y", "-x", "-y", "-z"),
        pose_hold_s=25.0,
        rate_steps=tuple((axis, sign * 100.0) for axis in "zxy" for sign in (1.0, -1.0)),
        rate_flip=("z",),
        rate_hold_s=3.0,
    )


@dataclass(frozen=True)
class LinePlan:
    """A soak in the rack, then the rig.

    Attributes:
        rack_s: rest logged in the rack from power-on (s); long enough for the gyro's T_c
            (Table 1: 1030-3760 s) to show.
        max_transfer_s: longest time (sensor seconds) between the rack's last sample and the rig's
            first that still counts as one power-on (the unit must stay powered while it moves).
        rig: what the rig does.
        rack_orientation: how the rack holds its units: ``"any"`` (any fixed orientation, unknown: the joint
            fit gives the rack's rest one free offset per axis) or a pose name such as ``"+z"`` (every slot holds
            its unit with that axis up, e.g. lying on its base, within ``rack_tilt_tolerance_deg``: the joint fit
            then ties the rest's level along gravity to the norm of gravity, see :mod:`station.fit.joint`, and
            refuses a unit whose rest was farther from that orientation).
        rack_tilt_tolerance_deg: the largest tilt of a slot against ``rack_orientation`` (deg) the fit accepts.
    """

    rack_s: float = 3600.0
    max_transfer_s: float = 1800.0
    rig: RigPlan = field(default_factory=line_rig_plan)
    rack_orientation: str = ANY_ORIENTATION
    rack_tilt_tolerance_deg: float = RACK_TILT_TOLERANCE_DEG

    def __post_init__(self) -> None:
        if not self.rack_s > 0:
            raise PlanError(f"line plan: rack_s must be > 0, got {self.rack_s!r}")
        if not self.max_transfer_s > 0:
            raise PlanError(f"line plan: max_transfer_s must be > 0, got {self.max_transfer_s!r}")
        if not self.rig.poses or not self.rig.rate_steps:
            raise PlanError("line plan: the rig part needs poses and rate steps (M and b_stat come from the rig)")
        if self.rack_orientation != ANY_ORIENTATION and self.rack_orientation not in POSE_ANGLES_DEG:
            raise PlanError(f"line plan: rack_orientation must be {ANY_ORIENTATION!r} or one of "
                            f"{', '.join(POSE_ANGLES_DEG)}, got {self.rack_orientation!r}")
        if not 0.0 < self.rack_tilt_tolerance_deg <= 30.0:
            raise PlanError("line plan: rack_tilt_tolerance_deg must be in (0, 30] deg, got "
                            f"{self.rack_tilt_tolerance_deg!r}")


def line_plan_to_json(plan: LinePlan) -> str:
    """The plan as a versioned JSON document (``format``: :data:`LINE_PLAN_FORMAT`)."""
    rig = asdict(plan.rig)
    rig["rate_steps"] = [list(step) for step in plan.rig.rate_steps]
    doc: dict[str, Any] = {"format": LINE_PLAN_FORMAT, "rack_s": plan.rack_s, "max_transfer_s": plan.max_transfer_s,
                           "rig": rig}
    if plan.rack_orientation != ANY_ORIENTATION:  # the rack's keys only when set: a plan of any orientation keeps
        doc["rack_orientation"] = plan.rack_orientation  # the bytes (and SHA-256) it had before they existed
        doc["rack_tilt_tolerance_deg"] = plan.rack_tilt_tolerance_deg
    return json.dumps(doc, indent=2, sort_keys=True)


def line_plan_from_json(text: str) -> LinePlan:
    """Read a plan written by :func:`line_plan_to_json`; refuses (:class:`PlanError`) another format or version,
    unknown keys and values the plan does not accept."""
    try:
        doc: Any = json.loads(text)
    except json.JSONDecodeError as exc:
        raise PlanError(f"line plan: not JSON ({exc})") from None
    if not isinstance(doc, dict) or doc.get("format") != LINE_PLAN_FORMAT:
        found = doc.get("format") if isinstance(doc, dict) else None
        raise PlanError(f"line plan: format {found!r} is not {LINE_PLAN_FORMAT!r}")
    rig = doc.get("rig")
    if not isinstance(rig, dict):
        raise PlanError("line plan: 'rig' must be a table of the rig plan's fields")
    known = {f.name for f in fields(RigPlan)}
    top = {"format", "rack_s", "max_transfer_s", "rig", "rack_orientation", "rack_tilt_tolerance_deg"}
    unknown = sorted(set(rig) - known) + sorted(set(doc) - top)
    if unknown:
        raise PlanError(f"line plan: unknown key(s) {', '.join(unknown)}")
    try:
        rig_kwargs = dict(rig)
        if "rate_steps" in rig_kwargs:
            rig_kwargs["rate_steps"] = tuple((str(a), float(r)) for a, r in rig_kwargs["rate_steps"])
        for key in ("poses", "rate_flip"):
            if key in rig_kwargs:
                rig_kwargs[key] = tuple(rig_kwargs[key])
        return LinePlan(rack_s=float(doc.get("rack_s", 3600.0)),
                        max_transfer_s=float(doc.get("max_transfer_s", 1800.0)), rig=RigPlan(**rig_kwargs),
                        rack_orientation=str(doc.get("rack_orientation", ANY_ORIENTATION)),
                        rack_tilt_tolerance_deg=float(doc.get("rack_tilt_tolerance_deg", 5.0)))
    except (TypeError, ValueError) as exc:
        raise PlanError(f"line plan: {exc}") from None


@dataclass(frozen=True)
class LinePlanFile:
    """A line plan as read from its file, with what names it in the records.

    Attributes:
        plan: the plan.
        name: the file's name (``line-plan.json``; '' for the built-in plan).
        sha256: hex SHA-256 of the file's bytes (of :func:`line_plan_to_json` for the built-in plan).
    """

    plan: LinePlan
    name: str
    sha256: str

    @property
    def version(self) -> str:
        """The plan's identity in a run's record: format and file name."""
        return f"{LINE_PLAN_FORMAT} {self.name or '(built in)'}"

    def rig_plan(self) -> RigPlan:
        """The rig part as the sequence runs it: a rest of at least 2 s (the runner's first step holds the unit
        still while it synchronises the clocks; the units keep their power)."""
        return replace(self.plan.rig, rest_s=max(self.plan.rig.rest_s, 2.0))


def load_line_plan_file(path: Path | None) -> LinePlanFile:
    """The plan file written by ``station plan`` (None: the built-in :func:`default_line_plan`); refuses an
    unreadable file, another format or version (:class:`PlanError`)."""
    if path is None:
        plan = default_line_plan()
        return LinePlanFile(plan, "", hashlib.sha256(line_plan_to_json(plan).encode("utf-8")).hexdigest())
    try:
        data = Path(path).read_bytes()
    except OSError as exc:
        raise PlanError(f"line plan {path}: cannot read it ({exc.strerror or exc})") from None
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError:
        raise PlanError(f"line plan {path}: not UTF-8 text") from None
    return LinePlanFile(line_plan_from_json(text), Path(path).name, hashlib.sha256(data).hexdigest())


def default_line_plan() -> LinePlan:
    """One hour in the rack, then :func:`line_rig_plan`."""
    return LinePlan()


__all__ = ["ANY_ORIENTATION", "LINE_PLAN_FORMAT", "RACK_TILT_TOLERANCE_DEG", "LinePlan", "LinePlanFile",
           "default_line_plan",
           "line_plan_from_json", "line_plan_to_json", "line_rig_plan", "load_line_plan_file"]
