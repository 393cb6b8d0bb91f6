"""The golden (reference) unit: its registered reference values, and the check of a station against it.

A plant keeps a unit whose parameters are known and stable, runs it at every shift start before any
production unit, and compares what the station measures with the unit's reference values. A station that
has drifted (a worn nest, a rig that no longer reaches its rate, a temperature change) shows up as a
golden unit outside its limits before it has calibrated a shift's production wrongly.

A :class:`GoldenUnit` holds, per checked parameter (the product-limit names, e.g. ``gyro.M.xz``), the
reference value and the allowed deviation, in the parameter's SI unit. :func:`check_golden` judges one
measurement of the unit: PASS when every parameter is within ``reference +- allowed``. The registered values
come from the unit's own repeated runs (:func:`register_golden`): the mean, and an allowed deviation of
``max(k_sigma * s, fraction * limit width)`` where ``s`` is the standard deviation over those runs (the
station's repeatability on that unit) and the limit width that of the product limits.

Saved as JSON, format ``station-golden/1``.
"""

from __future__ import annotations

import math
import statistics
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from station.kernel.errors import FormatError, StationError, UnsupportedVersionError

FORMAT = "station-golden/1"
MIN_REGISTRATION_RUNS = 5


@dataclass(frozen=True)
class GoldenReference:
    """One parameter's reference value, allowed deviation and the spread it was registered with (SI unit)."""

    parameter: str
    unit: str
    value: float
    allowed: float
    repeatability: float
    runs: int


@dataclass(frozen=True)
class GoldenUnit:
    """A registered golden unit: serial, when, and its references by parameter name."""

    serial: str
    registered_at: str
    references: tuple[GoldenReference, ...]

    def reference(self, parameter: str) -> GoldenReference | None:
        return next((r for r in self.references if r.parameter == parameter), None)

    def to_json(self) -> dict[str, Any]:
        return {
            "format": FORMAT,
            "serial": self.serial,
            "registered_at": self.registered_at,
            "references": [
                {"parameter": r.parameter, "unit": r.unit, "value": r.value, "allowed": r.allowed,
                 "repeatability": r.repeatability, "runs": r.runs} for r in self.references
            ],
        }


def golden_from_json(data: Mapping[str, Any]) -> GoldenUnit:
    """Read a golden unit's registration; refuses other formats."""
    if data.get("format") != FORMAT:
        raise UnsupportedVersionError(f"golden unit format {data.get('format')!r} is not {FORMAT!r}")
    refs = data.get("references")
    if not isinstance(refs, list):
        raise FormatError(f"{FORMAT}: references must be a list")
    try:
        out = tuple(GoldenReference(str(r["parameter"]), str(r["unit"]), float(r["value"]), float(r["allowed"]),
                                    float(r["repeatability"]), int(r["runs"])) for r in refs)
    except (KeyError, TypeError, ValueError) as exc:
        raise FormatError(f"{FORMAT}: a reference is malformed ({exc})") from None
    return GoldenUnit(str(data.get("serial", "")), str(data.get("registered_at", "")), out)


@dataclass(frozen=True)
class GoldenDeviation:
    """One parameter of one golden check: measured - reference, against the allowed deviation (SI unit)."""

    parameter: str
    unit: str
    measured: float | None
    deviation: float | None
    allowed: float
    passed: bool

    @property
    def z(self) -> float | None:
        """The deviation in units of the allowed deviation (None: not measured)."""
        return None if self.deviation is None or self.allowed <= 0 else self.deviation / self.allowed


@dataclass(frozen=True)
class GoldenCheck:
    """The check of one golden-unit run: PASS when every referenced parameter was measured and is in bounds."""

    serial: str
    deviations: tuple[GoldenDeviation, ...]

    @property
    def passed(self) -> bool:
        return all(d.passed for d in self.deviations)

    @property
    def failed(self) -> tuple[GoldenDeviation, ...]:
        return tuple(d for d in self.deviations if not d.passed)

    def describe(self) -> str:
        if self.passed:
            return f"golden unit {self.serial}: all {len(self.deviations)} parameters within their limits"
        bad = "; ".join(
            f"{d.parameter} not measured" if d.deviation is None
            else f"{d.parameter} off by {d.deviation:+.3g} {d.unit} (allowed ± {d.allowed:.3g})"
            for d in self.failed[:5])
        more = f" and {len(self.failed) - 5} more" if len(self.failed) > 5 else ""
        return f"golden unit {self.serial} FAILED: {bad}{more}"


def check_golden(golden: GoldenUnit, measured: Mapping[str, float]) -> GoldenCheck:
    """Judge one measurement (parameter name -> value, SI) of the golden unit against its references."""
    out = []
    for r in golden.references:
        v = measured.get(r.parameter)
        if v is None or not math.isfinite(v):
            out.append(GoldenDeviation(r.parameter, r.unit, None, None, r.allowed, False))
            continue
        d = v - r.value
        out.append(GoldenDeviation(r.parameter, r.unit, v, d, r.allowed, abs(d) <= r.allowed))
    return GoldenCheck(golden.serial, tuple(out))


def register_golden(
    serial: str,
    registered_at: str,
    runs: Sequence[Mapping[str, tuple[float, str, float | None, float | None]]],
    *,
    k_sigma: float = 4.0,
    fraction: float = 0.1,
) -> GoldenUnit:
    """The golden unit's references from its repeated runs.

    ``runs``: per run, parameter -> (value, unit, low limit, high limit). Every parameter measured in all runs
    is referenced: value the mean, allowed ``max(k_sigma * s, fraction * (high - low))`` (the fraction term
    only where both limits exist). At least :data:`MIN_REGISTRATION_RUNS` runs: fewer cannot say how much
    the station itself scatters on this unit.
    """
    if len(runs) < MIN_REGISTRATION_RUNS:
        raise StationError(f"a golden unit needs at least {MIN_REGISTRATION_RUNS} runs to register, got {len(runs)}")
    names = set(runs[0])
    for r in runs[1:]:
        names &= set(r)
    refs = []
    for name in sorted(names):
        values = [r[name][0] for r in runs]
        if not all(math.isfinite(v) for v in values):
            continue
        unit, low, high = runs[-1][name][1], runs[-1][name][2], runs[-1][name][3]
        s = statistics.stdev(values)
        width = (high - low) if low is not None and high is not None and high > low else 0.0
        allowed = max(k_sigma * s, fraction * width)
        if allowed <= 0:
            continue
        refs.append(GoldenReference(name, unit, statistics.fmean(values), allowed, s, len(values)))
    if not refs:
        raise StationError(f"golden unit {serial}: no parameter was measured in every run")
    return GoldenUnit(serial, registered_at, tuple(refs))


@dataclass(frozen=True)
class GoldenTrend:
    """The individuals chart of one parameter over a golden unit's checks (oldest first).

    ``z``: each deviation over the registered repeatability (the chart's sigma; centre line the reference);
    ``rules``: per point the Nelson rules (1-8) whose window ends there; ``first_signal``: the index of the
    first point completing any rule (None: in control).
    """

    parameter: str
    unit: str
    deviations: tuple[float | None, ...]
    z: tuple[float | None, ...]
    rules: tuple[tuple[int, ...], ...]

    @property
    def first_signal(self) -> int | None:
        return next((i for i, r in enumerate(self.rules) if r), None)


def golden_trends(golden: GoldenUnit, deviations: Sequence[Mapping[str, float | None]],
                  rules: Callable[[Sequence[float | None]], list[set[int]]]) -> tuple[GoldenTrend, ...]:
    """Per referenced parameter, its individuals chart over ``deviations`` (one mapping per check, in time
    order). ``rules`` is the run-rule evaluator (:func:`station.store.spc.run_rules`)."""
    out = []
    for r in golden.references:
        dev = tuple(d.get(r.parameter) for d in deviations)
        z = tuple(None if v is None or r.repeatability <= 0 else v / r.repeatability for v in dev)
        flags = rules(z)
        out.append(GoldenTrend(r.parameter, r.unit, dev, z, tuple(tuple(sorted(f)) for f in flags)))
    return tuple(out)
