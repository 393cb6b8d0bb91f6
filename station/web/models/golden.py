"""The JSON answer of the golden unit's charts (``/api/quality/golden``): SI values, as recorded."""

from __future__ import annotations

from datetime import datetime

from pydantic import BaseModel, Field

from station.web.models.quality import RuleEntry


class GoldenCheckEntry(BaseModel):
    """One recorded check of a golden unit."""

    checked_at: datetime = Field(description="when the check was recorded (UTC)")
    station: str = Field(description="the station that ran the golden unit")
    version: int = Field(description="the registration version the check was judged against")
    passed: bool = Field(description="every referenced parameter measured and within its allowed deviation")


class GoldenParameterChart(BaseModel):
    """The individuals chart of one parameter over the unit's checks (oldest first): centre line the reference,
    sigma the registered repeatability."""

    parameter: str = Field(description="the product-limit name, e.g. accel.bias_static.x")
    unit: str = Field(description="its SI unit")
    reference: float = Field(description="the registered reference value (SI unit)")
    allowed: float = Field(description="the allowed deviation from the reference (SI unit)")
    repeatability: float = Field(description="the chart's sigma: the registered repeatability (SI unit)")
    deviation: list[float | None] = Field(description="per check, measured - reference (SI unit); null: not "
                                                      "measured")
    z: list[float | None] = Field(description="per check, the deviation over the repeatability (1)")
    rules: list[list[int]] = Field(description="per check, the Nelson rules (1-8) whose window ends there")
    first_signal: int | None = Field(description="0-based index of the first check completing a rule; null: in "
                                                 "control")


class GoldenChart(BaseModel):
    """A registered golden unit: its checks and every referenced parameter's individuals chart."""

    serial: str = Field(description="the golden unit's serial")
    version: int = Field(description="its newest registration version")
    registered_at: str = Field(description="when it was registered (ISO 8601)")
    checks: list[GoldenCheckEntry] = Field(description="its checks, oldest first (of the selected station)")
    parameters: list[GoldenParameterChart] = Field(description="one chart per referenced parameter")


class GoldenCharts(BaseModel):
    """Every registered golden unit's charts, with the run rules they are checked against."""

    rules: list[RuleEntry] = Field(description="the Nelson run rules by number")
    units: list[GoldenChart] = Field(description="one entry per registered golden unit")
