"""``station demo --line`` end to end: rack (relay board, ptys) -> powered transfer -> rig (the line's runner)
-> joint fit; a unit that lost power on the way is refused with the reason."""

from __future__ import annotations

import io

from rich.console import Console

from station.sequence.records import Outcome
from station.sim.demo import run_line_demo


def test_line_demo_runs_the_rack_and_the_rig_and_refuses_an_interrupted_unit() -> None:
    out = io.StringIO()
    result = run_line_demo(2, 300.0, seed=3, console=Console(file=out, width=140), interrupt=(1,))
    text = out.getvalue()
    first, second = result.units
    assert first.outcome == Outcome.PASS, first.message
    assert first.params is not None and first.params.source["fit"] == "joint (rack + rig)"
    assert first.params.quality.extra["line"]["rack_span_s"] > 290.0
    assert second.outcome == Outcome.REFUSED
    assert "full: power-on counter changed" in second.message
    assert "rig time per unit: " in text
