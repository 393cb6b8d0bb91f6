"""A physics gate every unit of a step fails is the station's fault (ERROR), not the units' (FAIL)."""

from __future__ import annotations

from station.kernel.measurement import Measurement
from station.sequence.runner import common_cause
from station.sequence.steps import StepReport


def _gates(steady: float, ratio: float = 1.0, samples: float = 1.0) -> list[Measurement]:
    return [
        Measurement.in_range("sample_fraction", samples, 0.98, float("inf"), "1", link=True),
        Measurement.in_range("rate_steadiness", steady, 0.0, 0.005, "rad/s"),
        Measurement.in_range("gravity_ratio", ratio, 0.98, 1.02, "1"),
    ]


def test_every_unit_failing_the_same_gate_is_a_common_cause() -> None:
    report = StepReport()
    report.gates = {0: _gates(0.02), 1: _gates(0.03), 2: _gates(0.021, ratio=0.9)}
    assert common_cause(report) == {"rate_steadiness"}


def test_one_unit_failing_is_the_unit() -> None:
    report = StepReport()
    report.gates = {0: _gates(0.02), 1: _gates(0.001), 2: _gates(0.001)}
    assert common_cause(report) == set()


def test_a_single_unit_cannot_tell_and_link_gates_are_not_counted() -> None:
    one = StepReport()
    one.gates = {0: _gates(0.02)}
    assert common_cause(one) == set()
    links = StepReport()
    links.gates = {0: _gates(0.001, samples=0.5), 1: _gates(0.001, samples=0.4)}
    assert common_cause(links) == set()  # a link gate is already a station fault on its own
