"""Quality statistics of the whole line, aggregated in SQL over the quality tables (see
:mod:`station.store.quality_index` for what counts as a result, tested, first pass and final).

- :func:`yields`: first-pass and final yield grouped by station, shift, day or lot;
- :func:`capabilities`: per parameter n, mean, sigma within/overall, Cp/Cpk, Pp/Ppk against its limits;
- :func:`control_charts`: X-bar/S per day with control limits and run rules (:mod:`station.store.spc`);
- :func:`histogram`: one parameter's values in bins (counted by the database).

Every function takes a :class:`QualityFilter` (UTC date range of the run start, station, lot, limits version)
and opens its own read transaction. SQLite and PostgreSQL run the same statements.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from datetime import date
from typing import Any, TypeVar

from sqlalchemy import Select, case, func, literal, select

from station.store.db import Database
from station.store.models import QualityDaily, QualityParameter, QualityResult, QualityValue, QualityYield
from station.store.models import Station as StationRow
from station.store.spc import Capability, ControlChart, capability, control_chart

GROUPS = ("station", "shift", "day", "lot")


class QualityFilterError(ValueError):
    """A filter or shift calendar the statistics cannot use."""


@dataclass(frozen=True)
class ShiftCalendar:
    """Named shifts by their UTC start (minutes after midnight, ascending); each runs until the next starts.

    Starts are quarter hours (the yield counts are kept per quarter hour of the day).
    Results between 00:00 and the first start belong to the last shift (the night shift running past midnight);
    the day table groups by the UTC calendar day of the run start.
    Text form: ``"A=06:00,B=14:00,C=22:00"`` (:meth:`parse`).
    """

    shifts: tuple[tuple[str, int], ...] = (("A", 360), ("B", 840), ("C", 1320))

    @classmethod
    def parse(cls, text: str) -> ShiftCalendar:
        out: list[tuple[str, int]] = []
        for part in (p.strip() for p in text.split(",") if p.strip()):
            name, sep, hhmm = part.partition("=")
            if not sep:
                raise QualityFilterError(f"shift {part!r}: write NAME=HH:MM")
            try:
                hh, mm = (int(x) for x in hhmm.strip().split(":"))
            except ValueError:
                raise QualityFilterError(f"shift {part!r}: the start must be HH:MM (UTC)") from None
            if not (0 <= hh < 24 and 0 <= mm < 60) or not name.strip() or len(name.strip()) > 20:
                raise QualityFilterError(f"shift {part!r}: a name of 1-20 characters and a start 00:00-23:59")
            if mm % 15:
                raise QualityFilterError(f"shift {part!r}: shifts start on a quarter hour (:00, :15, :30, :45)")
            out.append((name.strip(), hh * 60 + mm))
        starts = [m for _, m in out]
        if not out or starts != sorted(set(starts)) or len({n for n, _ in out}) != len(out):
            raise QualityFilterError("shifts: at least one, distinct names, starts in ascending order")
        return cls(tuple(out))

    def text(self) -> str:
        return ",".join(f"{n}={m // 60:02d}:{m % 60:02d}" for n, m in self.shifts)

    def of(self, minute: int) -> str:
        name = self.shifts[-1][0]
        for n, start in self.shifts:
            if minute >= start:
                name = n
        return name


@dataclass(frozen=True)
class QualityFilter:
    """Which results the statistics cover: run start between ``date_from`` and ``date_to`` (UTC days,
    inclusive), on ``station``, of ``lot``, under ``limits_version`` (None: all)."""

    date_from: date | None = None
    date_to: date | None = None
    station: str | None = None
    lot: str | None = None
    limits_version: str | None = None

    def __post_init__(self) -> None:
        if self.date_from and self.date_to and self.date_from > self.date_to:
            raise QualityFilterError("date_from is after date_to")


def _station_id(s: Any, name: str | None) -> int | None:
    if name is None:
        return None
    return s.scalar(select(StationRow.id).where(StationRow.name == name)) or -1


#: A select of any row shape (``_where`` keeps it).
_Q = TypeVar("_Q", bound="Select[*tuple[Any, ...]]")


def _where(q: _Q, table: Any, f: QualityFilter, station_id: int | None) -> _Q:
    if f.date_from is not None:
        q = q.where(table.day >= f.date_from.isoformat())
    if f.date_to is not None:
        q = q.where(table.day <= f.date_to.isoformat())
    if station_id is not None:
        q = q.where(table.station_id == station_id)
    if f.lot is not None:
        q = q.where(table.lot == f.lot)
    if f.limits_version is not None:
        q = q.where(table.limits_version == f.limits_version)
    return q


@dataclass(frozen=True)
class YieldRow:
    """Yield of one group (a station, shift, day or lot; '' for the total).

    ``results``: unit results of ended runs; ``not_tested``: those without a verdict (ERROR, ABORTED, REFUSED);
    ``tested``: tested results (PASS, FAIL, RETEST); ``units_tested``: distinct units with a tested result (the
    total only; None for a group, where a unit may be counted in several); ``first_tested``: units whose first
    tested result falls in the group; ``first_pass``: of those, how many passed it; ``final_pass``: how many of
    them pass on their newest tested result; ``retests``: tested results that were not a unit's first.
    """

    group: str
    results: int
    not_tested: int
    tested: int
    first_tested: int
    first_pass: int
    final_pass: int
    retests: int
    units_tested: int | None = None

    @property
    def first_pass_yield(self) -> float | None:
        return self.first_pass / self.first_tested if self.first_tested else None

    @property
    def final_yield(self) -> float | None:
        return self.final_pass / self.first_tested if self.first_tested else None


def _shift_case(shifts: ShiftCalendar, minute: Any) -> Any:
    whens = [(minute < shifts.shifts[0][1], literal(shifts.shifts[-1][0]))]
    whens += [(minute < nxt, literal(name))
              for (name, _), (_, nxt) in zip(shifts.shifts, shifts.shifts[1:], strict=False)]
    return case(*whens, else_=literal(shifts.shifts[-1][0]))


def yield_tables(db: Database, f: QualityFilter = QualityFilter(),
                 shifts: ShiftCalendar = ShiftCalendar()) -> dict[str, list[YieldRow]]:
    """Yield rows grouped by 'station', 'shift', 'day', 'lot' and 'total' (one row, group '').

    One aggregate over the quarter-hour yield counts (:class:`~station.store.models.QualityYield`), grouped by
    day, shift, station and lot, is rolled up into the five tables (every count is additive); one more query
    counts the distinct units tested (the total's ``units_tested``).
    """
    y, q = QualityYield, QualityResult
    shift = _shift_case(shifts, y.quarter * 15)
    with db.transaction() as s:
        sid = _station_id(s, f.station)
        names: dict[int, str] = {int(i): str(n) for i, n in s.execute(select(StationRow.id, StationRow.name))}
        cols = [func.sum(getattr(y, k)) for k in ("results", "not_tested", "tested", "first_tested", "first_pass",
                                                   "final_pass", "retests")]
        stmt = _where(select(y.day, shift, y.station_id, y.lot, *cols), y, f, sid)
        rows = s.execute(stmt.group_by(y.day, shift, y.station_id, y.lot)).all()
        distinct_units = s.scalar(_where(select(func.count(func.distinct(q.unit_id))).where(q.tested), q, f, sid))
    acc: dict[str, dict[str, list[int]]] = {by: {} for by in (*GROUPS, "total")}
    for day, sh, st, lot, *counts in rows:
        for by, key in (("station", names.get(st, str(st))), ("shift", sh), ("day", day), ("lot", lot),
                        ("total", "")):
            tot = acc[by].setdefault(str(key), [0] * 7)
            for i, c in enumerate(counts):
                tot[i] += int(c or 0)
    out: dict[str, list[YieldRow]] = {}
    order = {n: i for i, (n, _) in enumerate(shifts.shifts)}
    for by, groups in acc.items():
        keys = sorted(groups, key=lambda k: (order.get(k, len(order)), k) if by == "shift" else (0, k))
        out[by] = [YieldRow(k, *groups[k]) for k in keys]
    total = out["total"][0] if out["total"] else YieldRow("", 0, 0, 0, 0, 0, 0, 0)
    out["total"] = [YieldRow(**{**total.__dict__, "units_tested": int(distinct_units or 0)})]
    return out


def yields(db: Database, by: str, f: QualityFilter = QualityFilter(),
           shifts: ShiftCalendar = ShiftCalendar()) -> list[YieldRow]:
    """Yield rows grouped ``by`` 'station', 'shift', 'day', 'lot' or 'total' (see :func:`yield_tables`)."""
    if by not in (*GROUPS, "total"):
        raise QualityFilterError(f"group by one of {', '.join(GROUPS)} or total, not {by!r}")
    return yield_tables(db, f, shifts)[by]


@dataclass(frozen=True)
class ParameterCapability:
    """One parameter's capability (see :class:`~station.store.spc.Capability`) with its name, unit, the
    limits version(s) it was checked under, out-of-limit counts and extremes (unit)."""

    name: str
    unit: str
    limits_versions: str
    cap: Capability
    n_below: int
    n_above: int
    vmin: float
    vmax: float
    one_sided: bool = False

    @property
    def rank_key(self) -> float:
        c = self.cap.cpk if self.cap.cpk is not None else self.cap.ppk
        return c if c is not None else math.inf


def _natural_zero(name: str) -> bool:
    """Fit-quality figures (``fit.*``: residuals and uncertainties) are >= 0 by nature: only their upper limit
    is a specification, so their Cpk is the upper side's."""
    return name.startswith("fit.")


def capabilities(db: Database, f: QualityFilter = QualityFilter()) -> list[ParameterCapability]:
    """Every parameter's capability over the filtered results, worst Cpk first (one row per parameter and
    limits; a parameter checked under limits that differ between versions has a row per set of limits)."""
    d = QualityDaily
    with db.transaction() as s:
        sid = _station_id(s, f.station)
        stmt = select(d.param_id, d.low, d.high, func.sum(d.n), func.sum(d.s1), func.sum(d.s2),
                      func.sum(d.s1 * d.s1 / d.n), func.sum(d.n - 1), func.min(d.vmin), func.max(d.vmax),
                      func.sum(d.n_below), func.sum(d.n_above), func.min(d.limits_version),
                      func.max(d.limits_version))
        rows = s.execute(_where(stmt, d, f, sid).group_by(d.param_id, d.low, d.high)).all()
        params = {p.id: p for p in s.scalars(select(QualityParameter))}
    out = []
    for pid, low, high, n, s1, s2, sq, df, vmin, vmax, nb, na, v1, v2 in rows:
        p = params[pid]
        one = _natural_zero(p.name)
        cap = capability(int(n), float(s1), float(s2), float(s2) - float(sq), int(df), p.ref,
                         None if one else low, high)
        out.append(ParameterCapability(p.name, p.unit, v1 if v1 == v2 else f"{v1} .. {v2}", cap, int(nb), int(na),
                                       float(vmin), float(vmax), one))
    out.sort(key=lambda c: (c.rank_key, c.name))
    return out


@dataclass(frozen=True)
class ParameterChart:
    """One parameter's X-bar/S chart per day (unit) and the limits (null: none)."""

    name: str
    unit: str
    low: float | None
    high: float | None
    chart: ControlChart = field(repr=False)


def control_charts(db: Database, f: QualityFilter = QualityFilter(),
                   names: Sequence[str] | None = None) -> list[ParameterChart]:
    """X-bar/S charts (one subgroup per day) of every parameter (or ``names``), by name."""
    d = QualityDaily
    with db.transaction() as s:
        sid = _station_id(s, f.station)
        params = {p.id: p for p in s.scalars(select(QualityParameter))}
        stmt = select(d.param_id, d.day, func.sum(d.n), func.sum(d.s1), func.sum(d.s2), func.min(d.low),
                      func.max(d.high))
        if names is not None:
            stmt = stmt.where(d.param_id.in_([p.id for p in params.values() if p.name in set(names)]))
        rows = s.execute(_where(stmt, d, f, sid).group_by(d.param_id, d.day).order_by(d.param_id, d.day)).all()
    series: dict[int, list[Any]] = {}
    for pid, day, n, s1, s2, low, high in rows:
        series.setdefault(pid, []).append((day, int(n), float(s1), float(s2), low, high))
    out = []
    for pid, pts in series.items():
        p = params[pid]
        chart = control_chart([x[0] for x in pts], [x[1] for x in pts], [x[2] for x in pts], [x[3] for x in pts],
                              p.ref)
        lows = [x[4] for x in pts if x[4] is not None]
        highs = [x[5] for x in pts if x[5] is not None]
        out.append(ParameterChart(p.name, p.unit, None if _natural_zero(p.name) or not lows else min(lows),
                                  max(highs) if highs else None, chart))
    out.sort(key=lambda c: c.name)
    return out


@dataclass(frozen=True)
class Histogram:
    """Counts of one parameter's values in ``len(counts)`` equal bins from ``lo`` to ``hi`` (unit); values
    outside fall in the first or last bin. ``n``, ``mean``, ``sigma`` (overall): the fitted normal."""

    name: str
    unit: str
    lo: float
    hi: float
    counts: tuple[int, ...]
    n: int
    mean: float
    sigma: float | None
    low: float | None
    high: float | None


def histogram(db: Database, name: str, f: QualityFilter = QualityFilter(), bins: int = 40) -> Histogram | None:
    """The histogram of parameter ``name`` over the filtered results, its range covering values and limits."""
    caps = [c for c in capabilities(db, f) if c.name == name]
    if not caps:
        return None
    n = sum(c.cap.n for c in caps)
    mean = sum(c.cap.mean * c.cap.n for c in caps) / n
    low = min((c.cap.low for c in caps if c.cap.low is not None), default=None)
    high = max((c.cap.high for c in caps if c.cap.high is not None), default=None)
    sig = caps[0].cap.sigma_overall if len(caps) == 1 else None
    lo = min([c.vmin for c in caps] + ([low] if low is not None else []))
    hi = max([c.vmax for c in caps] + ([high] if high is not None else []))
    if not hi > lo:
        hi = lo + (abs(lo) * 1e-6 or 1e-12)
    pad = (hi - lo) * 0.02
    lo, hi = lo - pad, hi + pad
    width = (hi - lo) / bins
    v, r = QualityValue, QualityResult
    with db.transaction() as s:
        sid = _station_id(s, f.station)
        pid = s.scalar(select(QualityParameter.id).where(QualityParameter.name == name))
        raw = (v.value - lo) / width
        b = func.min(func.max(func.cast(raw, _int()), 0), bins - 1) if s.get_bind().dialect.name == "sqlite" else \
            func.least(func.greatest(func.floor(raw), 0), bins - 1)
        stmt = select(b, func.count()).where(v.param_id == pid)
        if f.date_from is not None:
            stmt = stmt.where(v.day >= f.date_from.isoformat())
        if f.date_to is not None:
            stmt = stmt.where(v.day <= f.date_to.isoformat())
        if sid is not None or f.lot is not None or f.limits_version is not None:
            stmt = stmt.join(r, r.id == v.result_id)
            if sid is not None:
                stmt = stmt.where(r.station_id == sid)
            if f.lot is not None:
                stmt = stmt.where(r.lot == f.lot)
            if f.limits_version is not None:
                stmt = stmt.where(r.limits_version == f.limits_version)
        counts = [0] * bins
        for k, c in s.execute(stmt.group_by(b)).all():
            counts[min(max(int(k), 0), bins - 1)] += int(c)
    if sig is None and n > 1:
        sig = caps[0].cap.sigma_overall
    return Histogram(name, caps[0].unit, lo, hi, tuple(counts), n, mean, sig, low, high)


def _int() -> Any:
    from sqlalchemy import Integer

    return Integer


__all__ = ["GROUPS", "Histogram", "ParameterCapability", "ParameterChart", "QualityFilter", "QualityFilterError",
           "ShiftCalendar", "YieldRow", "capabilities", "control_charts", "histogram", "yield_tables", "yields"]
