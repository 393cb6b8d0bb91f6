"""A unit's verdict in plain words for the operator: what it means and what to do with the unit.

The runner's messages are exact but technical (``out of limits (table1-default): gyro.bias_static.x =
0.0091 rad/s outside [-0.0087, 0.0087]``); the operator console shows them under a sentence an operator
acts on, built from the outcome and the limit checks the unit missed (:class:`Missed`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from station.kernel.measurement import Measurement, Verdict
from station.web.labels import parameter_label, unit_label

#: How many missed checks the sentence names (the rest are counted).
SHOWN = 2


@dataclass(frozen=True)
class Missed:
    """A limit check the unit did not pass: its readable name, value and limits (display unit)."""

    label: str
    value: float
    low: float
    high: float
    unit: str
    inconclusive: bool

    @classmethod
    def of(cls, m: Measurement) -> Missed:
        scale, unit = (180.0 / math.pi, "°/s") if m.unit == "rad/s" else (1.0, unit_label(m.unit))
        return cls(parameter_label(m.name), m.value * scale, m.low * scale, m.high * scale,
                   "" if unit == "–" else unit, m.verdict == Verdict.INCONCLUSIVE)

    def words(self) -> str:
        def num(x: float) -> str:
            return f"{x:.4g}".replace("-", "−")

        unit = f" {self.unit}" if self.unit else ""
        if math.isinf(self.low):
            allowed = f"at most {num(self.high)}{unit}"
        elif math.isinf(self.high):
            allowed = f"at least {num(self.low)}{unit}"
        else:
            allowed = f"{num(self.low)} to {num(self.high)}{unit}"
        if self.inconclusive:  # inside, but its uncertainty reaches over the limit
            return f"{self.label} is {num(self.value)}{unit}, too close to its limits ({allowed}) to be sure"
        return f"{self.label} is {num(self.value)}{unit}, allowed {allowed}"


def plain_reason(outcome: str, message: str, missed: tuple[Missed, ...] = ()) -> str:
    """One or two sentences: what ``outcome`` means for this unit and where it goes."""
    named = "; ".join(m.words() for m in missed[:SHOWN])
    more = f" and {len(missed) - SHOWN} more" if len(missed) > SHOWN else ""
    if outcome == "PASS":
        return "Good unit: every value within its limits. Put it with the good parts."
    if outcome == "FAIL":
        if named:
            return f"Bad unit: {named}{more}. Put it in the reject bin."
        return f"Bad unit: {message or 'it failed a check'}. Put it in the reject bin."
    if outcome == "RETEST":
        why = named + more if named else message
        return f"Not decided: the measurement was not clear enough ({why}). Test it again."
    if outcome == "REFUSED":
        return f"Not tested: {message}. Hand the unit to the engineer."
    if outcome == "ERROR":
        return f"Not the unit's fault: the station had a problem ({message}). Test the unit again once it is fixed."
    if outcome == "ABORTED":
        return f"Not tested: the run was stopped ({message or 'aborted'}). Test the unit again."
    return message


__all__ = ["SHOWN", "Missed", "plain_reason"]
