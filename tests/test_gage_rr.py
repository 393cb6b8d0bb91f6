"""Gage R&R by ANOVA against the AIAG MSA 4th edition worked example and against known truth."""

from __future__ import annotations

import numpy as np
import pytest

from station.msa.gage_rr import StudyDesignError, gage_rr

# AIAG MSA 4th ed., the gage study of chapter III section B: appraisers A, B, C; rows trials 1-3; columns parts 1-10.
AIAG = {
    "A": [[0.29, -0.56, 1.34, 0.47, -0.80, 0.02, 0.59, -0.31, 2.26, -1.36],
          [0.41, -0.68, 1.17, 0.50, -0.92, -0.11, 0.75, -0.20, 1.99, -1.25],
          [0.64, -0.58, 1.27, 0.64, -0.84, -0.21, 0.66, -0.17, 2.01, -1.31]],
    "B": [[0.08, -0.47, 1.19, 0.01, -0.56, -0.20, 0.47, -0.63, 1.80, -1.68],
          [0.25, -1.22, 0.94, 1.03, -1.20, 0.22, 0.55, 0.08, 2.12, -1.62],
          [0.07, -0.68, 1.34, 0.20, -1.28, 0.06, 0.83, -0.34, 2.19, -1.50]],
    "C": [[0.04, -1.38, 0.88, 0.14, -1.46, -0.29, 0.02, -0.46, 1.77, -1.49],
          [-0.11, -1.13, 1.09, 0.20, -1.07, -0.67, 0.01, -0.56, 1.45, -1.77],
          [-0.15, -0.96, 0.67, 0.11, -1.45, -0.49, 0.21, -0.49, 1.87, -2.16]],
}


def _aiag() -> tuple[list[int], list[str], list[float]]:
    parts: list[int] = []
    apps: list[str] = []
    values: list[float] = []
    for app, trials in AIAG.items():
        for trial in trials:
            for i, v in enumerate(trial):
                parts.append(i + 1)
                apps.append(app)
                values.append(v)
    return parts, apps, values


def test_aiag_anova_table_to_its_printed_digits() -> None:
    g = gage_rr(*_aiag())
    rows = {r.source: r for r in g.anova}
    # the manual's ANOVA table: DF, SS (4 decimals), MS (5 significant digits), F (2 decimals)
    printed = {
        "appraiser": (2, 3.1673, 1.58363, 79.41),
        "part": (9, 88.3619, 9.81799, 492.29),
        "interaction": (18, 0.3590, 0.01994, 0.434),
        "repeatability": (60, 2.7589, 0.04598, None),
        "total": (89, 94.6471, None, None),
    }
    for source, (df, ss, ms, f) in printed.items():
        row = rows[source]
        assert row.df == df
        assert round(row.ss, 4) == ss
        if ms is not None:
            assert float(f"{row.ms:.4g}") == float(f"{ms:.4g}")
        if f is not None:
            assert row.f is not None
            assert round(row.f, 2 if f > 1 else 3) == f
    assert g.pooled  # p(interaction) = 0.974 > 0.25


def test_aiag_components_percent_of_total_and_ndc() -> None:
    g = gage_rr(*_aiag())
    # the manual's ANOVA-method results: std devs and % of total variation, ndc = 4
    assert round(g.repeatability.std, 5) == 0.19993
    assert round(g.reproducibility.std, 5) == 0.22684
    assert g.interaction.std == 0.0
    assert round(g.grr.std, 5) == 0.30237
    assert round(g.part.std, 4) == 1.0423
    assert round(g.total.std, 4) == 1.0853
    assert [round(c.pct_total, 1) for c in (g.repeatability, g.reproducibility, g.grr, g.part)] == [
        18.4, 20.9, 27.9, 96.0]
    assert g.ndc == 4
    assert not g.ndc_adequate
    assert g.verdict == "conditional"  # 27.9 % of the total variation


def test_repeatability_interval_is_the_chi_square_one() -> None:
    # EV with 78 degrees of freedom after pooling: 90 % interval 0.177 .. 0.231
    g = gage_rr(*_aiag())
    assert round(g.repeatability.ci_low, 3) == 0.177
    assert round(g.repeatability.ci_high, 3) == 0.231
    for c in g.components:
        assert c.ci_low <= c.std <= c.ci_high or c.std == 0.0


def test_tolerance_percent_uses_six_sigma() -> None:
    g = gage_rr(*_aiag(), tolerance=6.0)
    assert g.grr.pct_tolerance == pytest.approx(100 * 6 * g.grr.std / 6.0)
    assert g.pct_grr == g.grr.pct_tolerance
    assert g.verdict == "unacceptable"  # 30.2 % of the tolerance


def test_recovers_known_components_from_simulated_studies() -> None:
    # 30 parts x 4 nests x 5 repeats, known sigmas: part 1.0, nest 0.3, interaction 0.2, repeat 0.1
    rng = np.random.default_rng(20261128)
    est = []
    for _ in range(20):
        part = rng.normal(0, 1.0, 30)
        nest = rng.normal(0, 0.3, 4)
        inter = rng.normal(0, 0.2, (30, 4))
        p, a, v = [], [], []
        for i in range(30):
            for j in range(4):
                for _r in range(5):
                    p.append(i)
                    a.append(f"nest{j}")
                    v.append(part[i] + nest[j] + inter[i, j] + rng.normal(0, 0.1))
        g = gage_rr(p, a, v, pool_p=1.0)
        est.append((g.repeatability.variance, g.interaction.variance, g.part.variance))
    mean = np.mean(est, axis=0)
    # unbiased ANOVA estimators: the means over 20 studies near the truth
    assert mean[0] == pytest.approx(0.01, rel=0.05)
    assert mean[1] == pytest.approx(0.04, rel=0.15)
    assert mean[2] == pytest.approx(1.0, rel=0.15)


def test_refuses_a_design_it_cannot_analyse() -> None:
    parts, apps, values = _aiag()
    with pytest.raises(StudyDesignError, match="not balanced"):
        gage_rr(parts[:-1], apps[:-1], values[:-1])
    keep = [i for i in range(len(parts)) if not (parts[i] == 3 and apps[i] == "B")]
    with pytest.raises(StudyDesignError, match="not crossed"):
        gage_rr([parts[i] for i in keep], [apps[i] for i in keep], [values[i] for i in keep])
    with pytest.raises(StudyDesignError, match="2 appraisers"):
        gage_rr([1, 1, 2, 2], ["A"] * 4, [1.0, 1.1, 2.0, 2.1])
    with pytest.raises(StudyDesignError, match="not finite"):
        gage_rr(parts, apps, [*values[:-1], float("nan")])


def test_parts_without_variation_are_not_determined() -> None:
    # every part reads the same: the same three repeats in every cell, a nest offset only
    p, a, v = [], [], []
    for i in range(5):
        for j, offset in enumerate((0.0, 0.05)):
            for d in (-0.1, 0.0, 0.1):
                p.append(i)
                a.append(j)
                v.append(offset + d)
    g = gage_rr(p, a, v)
    assert g.part.variance == 0.0
    assert not g.determined
    assert g.verdict == "not determined"
    assert g.ndc == 0
    assert g.part.ci_low == 0.0
