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

FORMAT = "station-golden/2"
FORMAT_V1 = "station-golden/1"
MIN_REGISTRATION_RUNS = 10
RECOMMENDED_REGISTRATION_RUNS = 20
DEFAULT_FALSE_STOP_RATE = 0.0027


def student_t_two_sided_tail(t: float, dof: int) -> float:
    """``P(|T| > t)`` for Student's t with an integer number of degrees of freedom ``dof >= 1``, ``t >= 0``.

    Abramowitz & Stegun 26.7.3/26.7.4 (exact finite sums for integer ``dof``): with
    ``theta = atan(t / sqrt(dof))``, ``c = cos^2 theta``, the central probability
    ``A = sin(theta) * (1 + c/2 + 1*3/(2*4) c^2 + ...)`` (``dof`` even, ``dof/2`` terms) or
    ``A = (2/pi) * (theta + sin(theta) cos(theta) (1 + 2/3 c + 2*4/(3*5) c^2 + ...))`` (``dof`` odd,
    ``(dof-1)/2`` terms in the bracket). The tail is ``1 - A``, evaluated as such: the sums are in
    [0, 1], so the absolute error stays near 1e-16, i.e. a relative error below 1e-10 for tails >= 1e-6.
    """
    if dof < 1:
        raise ValueError("dof must be >= 1")
    if t <= 0:
        return 1.0
    theta = math.atan(t / math.sqrt(dof))
    c = math.cos(theta) ** 2
    sin_t = math.sin(theta)
    if dof % 2 == 0:
        term, total = 1.0, 1.0
        for j in range(1, dof // 2):
            term *= c * (2 * j - 1) / (2 * j)
            total += term
        central = sin_t * total
    else:
        term, total = 1.0, 0.0
        if dof > 1:
            total = 1.0
            for j in range(1, (dof - 1) // 2):
                term *= c * (2 * j) / (2 * j + 1)
                total += term
        central = (2 / math.pi) * (theta + sin_t * math.cos(theta) * total)
    return max(0.0, 1.0 - central)


def student_t_quantile(p: float, dof: int) -> float:
    """The ``p`` quantile of Student's t with integer ``dof`` (``0.5 <= p < 1``): bisection on
    :func:`student_t_two_sided_tail` (monotone in ``t``) to a relative width of 1e-14."""
    if not 0.5 <= p < 1:
        raise ValueError("p must be in [0.5, 1)")
    tail = 2 * (1 - p)
    lo, hi = 0.0, 1.0
    while student_t_two_sided_tail(hi, dof) > tail:
        lo, hi = hi, hi * 2
    while hi - lo > 1e-14 * hi:
        mid = 0.5 * (lo + hi)
        if student_t_two_sided_tail(mid, dof) > tail:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


def allowance_multiple(false_stop_rate: float, runs: int, parameters: int) -> float:
    """``k``: the allowed deviation in registered sigmas for a family-wise false-stop rate per check of
    ``false_stop_rate`` over ``parameters`` parameters, each registered from ``runs`` runs (see the module)."""
    if not 0 < false_stop_rate < 1:
        raise StationError(f"the false-stop rate must lie in (0, 1), got {false_stop_rate}")
    if runs < 2 or parameters < 1:
        raise StationError("a golden allowance needs at least 2 runs and 1 parameter")
    q = student_t_quantile(1 - false_stop_rate / (2 * parameters), runs - 1)
    return q * math.sqrt(1 + 1 / runs)


def normal_cdf(x: float) -> float:
    return 0.5 * math.erfc(-x / math.sqrt(2))


def detectable_shift(k: float, runs: int, probability: float = 0.5) -> float:
    """The shift of one parameter, in its true sigmas, that one check catches with ``probability``, taking
    the registered sigma equal to the true one: the ``d`` with ``P(|N(d, 1 + 1/n)| > k) = probability``."""
    scale = math.sqrt(1 + 1 / runs)
    lo, hi = 0.0, k + 10 * scale
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        p = normal_cdf((mid - k) / scale) + normal_cdf((-mid - k) / scale)
        lo, hi = (mid, hi) if p < probability else (lo, mid)
    return 0.5 * (lo + hi)


@dataclass(frozen=True)
class GoldenRule:
    """How the allowed deviations were set: family-wise false-stop rate per check, registration runs ``n``,
    referenced parameters ``m`` (Bonferroni), and the resulting multiple ``k`` of the registered sigma."""

    false_stop_rate: float
    runs: int
    parameters: int
    k: float
    fraction: float

    @property
    def dof(self) -> int:
        return self.runs - 1

    def describe(self) -> str:
        return (f"false-stop rate {100 * self.false_stop_rate:.3g} % per check over {self.parameters} parameters, "
                f"n = {self.runs} runs ({self.dof} dof): allowed max({self.k:.3g} s, "
                f"{100 * self.fraction:.3g} % of the limit width)")


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
    rule: GoldenRule | None = None  # None: a ``station-golden/1`` registration (its allowed values stand)

    def reference(self, parameter: str) -> GoldenReference | None:
        return next((r for r in self.references if r.parameter == parameter), None)

    def to_json(self) -> dict[str, Any]:
        rule = None if self.rule is None else {
            "false_stop_rate": self.rule.false_stop_rate, "runs": self.rule.runs,
            "parameters": self.rule.parameters, "k": self.rule.k, "fraction": self.rule.fraction}
        return {
            "format": FORMAT if self.rule is not None else FORMAT_V1,
            "serial": self.serial,
            "registered_at": self.registered_at,
            "rule": rule,
            "references": [
                {"parameter": r.parameter, "unit": r.unit, "value": r.value, "allowed": r.allowed,
                 "repeatability": r.repeatability, "runs": r.runs} for r in self.references
            ],
        }


def golden_from_json(data: Mapping[str, Any]) -> GoldenUnit:
    """Read a golden unit's registration (``station-golden/2``, or ``/1`` with its stored allowed values and
    no rule); refuses other formats."""
    fmt = data.get("format")
    if fmt not in (FORMAT, FORMAT_V1):
        raise UnsupportedVersionError(f"golden unit format {fmt!r} is not {FORMAT!r} or {FORMAT_V1!r}")
    refs = data.get("references")
    if not isinstance(refs, list):
        raise FormatError(f"{fmt}: references must be a list")
    try:
        out = tuple(GoldenReference(str(r["parameter"]), str(r["unit"]), float(r["value"]), float(r["allowed"]),
                                    float(r["repeatability"]), int(r["runs"])) for r in refs)
        rule = None
        if fmt == FORMAT:
            raw = data["rule"]
            rule = GoldenRule(float(raw["false_stop_rate"]), int(raw["runs"]), int(raw["parameters"]),
                              float(raw["k"]), float(raw["fraction"]))
    except (KeyError, TypeError, ValueError) as exc:
        raise FormatError(f"{fmt}: a reference or the rule is malformed ({exc})") from None
    return GoldenUnit(str(data.get("serial", "")), str(data.get("registered_at", "")), out, rule)


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
    false_stop_rate: float = DEFAULT_FALSE_STOP_RATE,
    fraction: float = 0.1,
    min_runs: int = MIN_REGISTRATION_RUNS,
) -> GoldenUnit:
    """The golden unit's references from its repeated runs.

    ``runs``: per run, parameter -> (value, unit, low limit, high limit). Every parameter measured (finite) in
    all runs is referenced: value the mean, allowed ``max(k * s, fraction * (high - low))`` (the fraction term
    only where both limits exist), ``k`` from :func:`allowance_multiple` for ``false_stop_rate`` over the ``m``
    referenced parameters and the ``n`` runs. At least ``min_runs`` runs (default
    :data:`MIN_REGISTRATION_RUNS`; lower only for tests): fewer make ``k`` so large that the check is blind.
    """
    if len(runs) < max(min_runs, 2):
        raise StationError(f"a golden unit needs at least {max(min_runs, 2)} runs to register, got {len(runs)}")
    names = set(runs[0])
    for r in runs[1:]:
        names &= set(r)
    candidates = []
    for name in sorted(names):
        values = [r[name][0] for r in runs]
        if not all(math.isfinite(v) for v in values):
            continue
        unit, low, high = runs[-1][name][1], runs[-1][name][2], runs[-1][name][3]
        s = statistics.stdev(values)
        width = (high - low) if low is not None and high is not None and high > low else 0.0
        if s <= 0 and width <= 0:
            continue
        candidates.append((name, unit, statistics.fmean(values), s, width))
    if not candidates:
        raise StationError(f"golden unit {serial}: no parameter was measured in every run")
    k = allowance_multiple(false_stop_rate, len(runs), len(candidates))
    rule = GoldenRule(false_stop_rate, len(runs), len(candidates), k, fraction)
    refs = tuple(GoldenReference(name, unit, mean, max(k * s, fraction * width), s, len(runs))
                 for name, unit, mean, s, width in candidates)
    return GoldenUnit(serial, registered_at, refs, rule)


@dataclass(frozen=True)
class GoldenTrend:
    """The individuals chart of one parameter over a golden unit's checks (oldest first).

    ``z``: each deviation over the registered repeatability (the chart's sigma, estimated from ``runs``
    registration runs, so with ``runs - 1`` degrees of freedom; centre line the reference); ``rules``: per
    point the Nelson rules (1-8) whose window ends there; ``first_signal``: the index of the
    first point completing any rule (None: in control).
    """

    parameter: str
    unit: str
    deviations: tuple[float | None, ...]
    z: tuple[float | None, ...]
    rules: tuple[tuple[int, ...], ...]
    runs: int = 0

    @property
    def dof(self) -> int:
        """The degrees of freedom of the chart's sigma (its registration runs - 1)."""
        return max(self.runs - 1, 0)

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
        out.append(GoldenTrend(r.parameter, r.unit, dev, z, tuple(tuple(sorted(f)) for f in flags), r.runs))
    return tuple(out)
