"""The JSON answers of the measurement system analysis (``/api/msa``): SI values, percentages in %."""

from __future__ import annotations

from pydantic import BaseModel, Field


class MsaComponent(BaseModel):
    """One source of variation of one parameter."""

    name: str = Field(description="repeatability (EV), reproducibility (AV), interaction, grr, part (PV) or total")
    std: float = Field(description="standard deviation, in the parameter's SI unit")
    std_ci_low: float = Field(description="lower confidence limit of the standard deviation (SI unit)")
    std_ci_high: float | None = Field(description="upper confidence limit (SI unit); null: unbounded")
    pct_total_variation: float | None = Field(description="100 * std / total std (%); null: no variation")
    pct_contribution: float | None = Field(description="100 * variance / total variance (%)")
    pct_tolerance: float | None = Field(description="100 * 6 std / (high - low limit) (%); null: no two limits")


class MsaParameter(BaseModel):
    """The Gage R&R of one limited parameter, or why there is none."""

    parameter: str = Field(description="the product-limit name, e.g. gyro.M.xz")
    unit: str = Field(description="its SI unit")
    reason: str | None = Field(description="why it was not analysed (null: analysed)")
    dropped: int = Field(description="values left out to balance the design")
    repeats: int | None = Field(default=None, description="repeats per part and appraiser")
    pct_grr: float | None = Field(default=None, description="%GRR of the tolerance, else of the total variation")
    ndc: int | None = Field(default=None, description="number of distinct categories (AIAG asks >= 5)")
    verdict: str | None = Field(default=None, description="acceptable (<10 %), conditional (<=30 %), unacceptable, "
                                                          "or not determined")
    pooled_interaction: bool | None = Field(default=None, description="the interaction was pooled into the error")
    components: list[MsaComponent] = Field(default_factory=list, description="the sources of variation (empty: "
                                                                              "not analysed)")


class MsaStudy(BaseModel):
    """A crossed study (parts x appraisers x repeats) of every limited parameter (format station-msa/1)."""

    format: str = Field(description="station-msa/1")
    by: str = Field(description="what the appraisers are: nest, rig or operator")
    parts: list[str] = Field(description="the parts' serials")
    appraisers: list[str] = Field(description="the appraisers: nests ('nest 1', ...), rigs or operators")
    confidence_level: float = Field(description="two-sided level of the intervals")
    parameters: list[MsaParameter] = Field(description="one study per limited parameter")


__all__ = ["MsaComponent", "MsaParameter", "MsaStudy"]
