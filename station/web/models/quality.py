"""Quality statistics in the JSON API (``/api/quality/...``): filters, yield tables, capability, control charts
and histograms. Definitions: see :mod:`station.store.quality_index` (tested, first pass, final) and
:mod:`station.store.spc` (sigma within/overall, Cp/Cpk, Pp/Ppk, control limits, run rules)."""

from __future__ import annotations

from datetime import date
from typing import Literal

from pydantic import BaseModel, Field, field_validator, model_validator

from station.store.quality import QualityFilter, QualityFilterError, ShiftCalendar


class QualityQuery(BaseModel):
    """Which results the statistics cover (all filters combine; none: everything)."""

    date_from: date | None = Field(None, description="first UTC day of the run start (inclusive), YYYY-MM-DD")
    date_to: date | None = Field(None, description="last UTC day of the run start (inclusive), YYYY-MM-DD")
    station: str | None = Field(None, max_length=100, description="station name")
    lot: str | None = Field(None, max_length=100, description="production lot")
    limits_version: str | None = Field(None, max_length=100, description="limits name and version, e.g. "
                                                                          "'table1-default 2.0.0'")
    shifts: str | None = Field(None, max_length=200, description="shift calendar, NAME=HH:MM (UTC start) in "
                                                                 "ascending order, e.g. 'A=06:00,B=14:00,C=22:00' "
                                                                 "(default: the station's)")

    @field_validator("station", "lot", "limits_version", "shifts", mode="before")
    @classmethod
    def _blank_is_none(cls, v: object) -> object:
        return None if isinstance(v, str) and not v.strip() else v

    @model_validator(mode="after")
    def _check(self) -> QualityQuery:
        if self.date_from and self.date_to and self.date_from > self.date_to:
            raise ValueError("date_from is after date_to")
        if self.shifts is not None:
            try:
                ShiftCalendar.parse(self.shifts)
            except QualityFilterError as exc:
                raise ValueError(str(exc)) from None
        return self

    def filter(self) -> QualityFilter:
        return QualityFilter(self.date_from, self.date_to, self.station, self.lot, self.limits_version)

    def calendar(self, default: ShiftCalendar) -> ShiftCalendar:
        return ShiftCalendar.parse(self.shifts) if self.shifts else default


GroupBy = Literal["station", "shift", "day", "lot", "total"]


class YieldEntry(BaseModel):
    """Yield of one group (see ``YieldTable.definitions``)."""

    group: str = Field(description="the station, shift, day (YYYY-MM-DD, UTC) or lot; '' for the total")
    results: int = Field(description="unit results of ended runs")
    not_tested: int = Field(description="results without a verdict: ERROR, ABORTED, REFUSED")
    tested: int = Field(description="tested results (PASS, FAIL, RETEST)")
    units_tested: int | None = Field(description="distinct units with a tested result (the total only; null for a "
                                                 "group, where one unit may count in several)")
    first_tested: int = Field(description="units whose first tested result is in the group")
    first_pass: int = Field(description="of those, units that passed their first test")
    final_pass: int = Field(description="of those, units whose newest tested result is PASS")
    retests: int = Field(description="tested results that were not a unit's first")
    first_pass_yield: float | None = Field(description="first_pass / first_tested (1); null: none tested")
    final_yield: float | None = Field(description="final_pass / first_tested (1); null: none tested")


DEFINITIONS = (
    "A result is one unit in one ended run. Tested: the run reached a verdict on the unit (PASS, FAIL or RETEST); "
    "ERROR, ABORTED and REFUSED results are not tested and never use up a unit's first pass. First pass: a "
    "unit's first tested result. First-pass yield: units that passed their first test / units first tested in "
    "the group. Final yield: of the same units, those whose newest tested result is PASS. Groups: station, "
    "shift (by the UTC start of the run and the shift calendar), UTC day of the run start, lot.")


class YieldTable(BaseModel):
    """Yield grouped by one key, with the definitions used."""

    by: GroupBy = Field(description="the grouping")
    shifts: str = Field(description="the shift calendar used (NAME=HH:MM UTC start, ...)")
    definitions: str = Field(description="what counts as tested, first pass and final")
    rows: list[YieldEntry] = Field(description="one entry per group, in order")


class CapabilityEntry(BaseModel):
    """One parameter's capability over the filtered tested results (values in ``unit``)."""

    name: str = Field(description="the parameter, e.g. 'accel.bias_static.x'")
    label: str = Field(description="readable name, e.g. 'accelerometer static bias, x'")
    unit: str = Field(description="SI unit of mean, sigmas, limits and extremes ('1': dimensionless)")
    limits_versions: str = Field(description="the limits version(s) the values were checked under")
    n: int = Field(description="values")
    mean: float = Field(description="mean (unit)")
    sigma_within: float | None = Field(description="pooled within-subgroup standard deviation (unit); subgroup: "
                                                   "one day, station, lot and limits version")
    sigma_overall: float | None = Field(description="sample standard deviation of all values (unit)")
    low: float | None = Field(description="lower limit (unit); null: none (or a fit-quality figure, >= 0 by nature)")
    high: float | None = Field(description="upper limit (unit); null: none")
    cp: float | None = Field(description="(high - low) / (6 sigma_within) (1); null with one limit")
    cpk: float | None = Field(description="min(high - mean, mean - low) / (3 sigma_within) (1)")
    pp: float | None = Field(description="(high - low) / (6 sigma_overall) (1); null with one limit")
    ppk: float | None = Field(description="min(high - mean, mean - low) / (3 sigma_overall) (1)")
    n_below: int = Field(description="values below the lower limit")
    n_above: int = Field(description="values above the upper limit")
    min: float = Field(description="smallest value (unit)")
    max: float = Field(description="largest value (unit)")
    rules: list[int] = Field(default_factory=list, description="run rules (Nelson 1-8) violated on the daily "
                                                               "X-bar chart")
    enough: bool = Field(default=True, description="n reaches the minimum sample of the capability indices (25 "
                                                   "values); below it the page says 'too few units' instead of "
                                                   "Cp/Cpk/Pp/Ppk and does not flag the parameter for its Cpk")
    cpk_low: float | None = Field(default=None, description="lower end of the 95 % confidence interval of Cpk (1; "
                                                            "Bissell's approximation); null without a Cpk")
    cpk_high: float | None = Field(default=None, description="upper end of the 95 % confidence interval of Cpk (1)")


class ChartPointEntry(BaseModel):
    """One day on the X-bar/S chart (values in the parameter's unit)."""

    day: str = Field(description="UTC day, YYYY-MM-DD")
    n: int = Field(description="values that day")
    mean: float = Field(description="the day's mean (unit)")
    s: float | None = Field(description="the day's standard deviation (unit); null for one value")
    lcl: float | None = Field(description="lower control limit of the mean (unit)")
    ucl: float | None = Field(description="upper control limit of the mean (unit)")
    s_lcl: float | None = Field(description="lower control limit of s (unit)")
    s_ucl: float | None = Field(description="upper control limit of s (unit)")
    z: float | None = Field(description="(mean - centre) / (sigma_within / sqrt(n)) (1)")
    rules: list[int] = Field(description="the run rules whose window ends on this day")


class ControlChartEntry(BaseModel):
    """One parameter's daily X-bar/S chart."""

    name: str = Field(description="the parameter")
    unit: str = Field(description="SI unit of the values")
    center: float = Field(description="centre line: the grand mean (unit)")
    sigma_within: float | None = Field(description="pooled within-day standard deviation (unit)")
    low: float | None = Field(description="lower specification limit (unit)")
    high: float | None = Field(description="upper specification limit (unit)")
    violations: list[int] = Field(description="run rules violated anywhere on the chart")
    points: list[ChartPointEntry] = Field(description="one per day, in time order")


class RuleEntry(BaseModel):
    number: int = Field(description="Nelson's rule number")
    text: str = Field(description="what it detects")


class ControlCharts(BaseModel):
    """Daily X-bar/S charts and the run rules they are checked against."""

    rules: list[RuleEntry] = Field(description="the run rules")
    charts: list[ControlChartEntry] = Field(description="one per parameter, by name")


class HistogramEntry(BaseModel):
    """A parameter's values in equal bins with the fitted normal (unit)."""

    name: str = Field(description="the parameter")
    unit: str = Field(description="SI unit")
    lo: float = Field(description="left edge of the first bin (unit)")
    hi: float = Field(description="right edge of the last bin (unit)")
    counts: list[int] = Field(description="values per bin")
    n: int = Field(description="values")
    mean: float = Field(description="mean of the fitted normal (unit)")
    sigma: float | None = Field(description="standard deviation of the fitted normal (unit)")
    low: float | None = Field(description="lower limit (unit)")
    high: float | None = Field(description="upper limit (unit)")


__all__ = ["DEFINITIONS", "CapabilityEntry", "ChartPointEntry", "ControlChartEntry", "ControlCharts", "GroupBy",
           "HistogramEntry", "QualityQuery", "RuleEntry", "YieldEntry", "YieldTable"]
