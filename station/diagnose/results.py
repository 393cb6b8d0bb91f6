"""Typed results of a diagnosis: :class:`Finding`, :class:`Rejection`, :class:`Inseparable` and
:class:`station.diagnose.robust.Unexplained`; ``to_dict`` gives the JSON entries of the report
(``station-diagnosis/1``, see :mod:`station.diagnose.report`)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from station.diagnose.bootstrap import Bootstrap
from station.diagnose.consistency import Check
from station.diagnose.robust import Unexplained


@dataclass(frozen=True, eq=False)
class Finding:
    """An effect the recording supports, with its parameters in engineering units.

    ``theta``: the fitted SI parameters (for the simulator re-run); ``block_residual``: the block residual
    before and after the effect (m, 3), sensor units; neither is part of the JSON entry.
    """

    effect: str
    sensor: str
    axes: tuple[str, ...]
    parameters: Mapping[str, Any]
    evidence: Mapping[str, Any]
    fit: Mapping[str, Any]
    confidence: Mapping[str, Any] | None = None
    #: the effect-specific consistency checks (:mod:`station.diagnose.consistency`; a ``not checked`` entry with
    #: the reason where none could run)
    consistency: tuple[Check, ...] = ()
    #: the bootstrap over segments (:mod:`station.diagnose.bootstrap`), None where not run
    bootstrap: Bootstrap | None = None
    theta: np.ndarray | None = None
    block_residual: tuple[np.ndarray, np.ndarray] | None = None

    @classmethod
    def from_entry(cls, d: Mapping[str, Any]) -> Finding:
        return cls(effect=d["effect"], sensor=d["sensor"], axes=tuple(d["axes"]), parameters=d["parameters"],
                   evidence=d["evidence"], fit=d.get("fit", {}), confidence=d.get("confidence"),
                   consistency=tuple(d.get("consistency", ())), bootstrap=d.get("bootstrap"), theta=d.get("_theta"),
                   block_residual=d.get("_block_residual"))

    def to_dict(self) -> dict[str, Any]:
        out = {"effect": self.effect, "sensor": self.sensor, "axes": list(self.axes),
               "parameters": dict(self.parameters), "evidence": dict(self.evidence), "fit": dict(self.fit)}
        if self.confidence is not None:
            out["confidence"] = dict(self.confidence)
        if self.consistency:
            out["consistency"] = [c.to_dict() for c in self.consistency]
        if self.bootstrap is not None:
            out["bootstrap"] = self.bootstrap.to_dict()
        return out


@dataclass(frozen=True)
class Rejection:
    """A candidate tested and not named, and why (``details``: its test numbers, detectable sizes, rig step)."""

    effect: str
    sensor: str
    reason: str
    details: Mapping[str, Any] = field(default_factory=dict)

    @classmethod
    def from_entry(cls, d: Mapping[str, Any]) -> Rejection:
        return cls(effect=d["effect"], sensor=d["sensor"], reason=d["reason"],
                   details={k: v for k, v in d.items() if k not in ("effect", "sensor", "reason")})

    def to_dict(self) -> dict[str, Any]:
        return {"effect": self.effect, "sensor": self.sensor, **self.details, "reason": self.reason}


@dataclass(frozen=True)
class Inseparable:
    """Effects this recording cannot tell apart, and the rig step that would."""

    effects: tuple[str, ...]
    sensor: str
    evidence: Mapping[str, Any]
    rig_step: str

    @classmethod
    def from_entry(cls, d: Mapping[str, Any]) -> Inseparable:
        return cls(effects=tuple(d["effects"]), sensor=d["sensor"], evidence=d.get("evidence", {}),
                   rig_step=d["rig_step"])

    def to_dict(self) -> dict[str, Any]:
        return {"effects": list(self.effects), "sensor": self.sensor, "evidence": dict(self.evidence),
                "rig_step": self.rig_step}


__all__ = ["Finding", "Inseparable", "Rejection", "Unexplained"]
