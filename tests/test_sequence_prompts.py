"""The operator's prompts as steps of the sequence (in-process fakes, the virtual clock).

A scripted operator answers each prompt; the records show the prompts in order with their nests, a
prompt not confirmed before the rig moves ends the run ABORTED without motion, a timeout says so, an
operator who cannot be reached is a station fault (ERROR), and a scanned serial that is not the unit
in the nest refuses that unit before anything moves.
"""

from __future__ import annotations

import threading
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import replace

import pytest

from station.compose import Station, StationConfig
from station.kernel.limits import table1_limits
from station.kernel.limits_file import load_limits
from station.kernel.plan import RigPlan
from station.kernel.virtual_clock import VirtualClock, acting
from station.sequence import Outcome, PromptAnswered, PromptShown, RigReading, StepStarted
from station.sequence.prompts import (
    Answer,
    AutoConfirm,
    NoOperator,
    Prompt,
    PromptPlan,
    fixture_prompts,
    load_prompt,
    nest_list,
)
from station.sim.fakes import FakeStation

PLAN = RigPlan(sample_rate_hz=50.0, rest_s=30.0, pose_hold_s=3.0,
               rate_steps=(("x", 100.0), ("y", 100.0), ("z", 100.0)), rate_hold_s=3.0)


class Scripted:
    """Answers prompts from a list; records what it was asked."""

    def __init__(self, answers: list[Answer | Exception]) -> None:
        self.answers = answers
        self.asked: list[tuple[str, Prompt]] = []

    def ask(self, prompt_id: str, prompt: Prompt, cancel: threading.Event) -> tuple[Answer, str]:
        self.asked.append((prompt_id, prompt))
        a = self.answers.pop(0)
        if isinstance(a, Exception):
            raise a
        return a, "pytest"


@contextmanager
def virtual_station(units: int, seed: int) -> Iterator[FakeStation]:
    """The fakes on a virtual clock; the test's thread owns time until the run does."""
    clock = VirtualClock()
    with acting(clock, name="test"), FakeStation(units, clock.scale, seed, plan=PLAN, clock=clock) as sim:
        yield sim


def _station(sim: FakeStation, prompter: object) -> Station:
    config = StationConfig(sim.rig_url, tuple(sim.sensor_urls), station_id="pytest", record=False, out_dir=None,
                           plan=PLAN, rig_options=sim.rig_client_options(), provision=False)
    limits = replace(load_limits(), product=table1_limits())
    return Station(config, clock=sim.clock, limits=limits, prompter=prompter)  # type: ignore[arg-type]


def test_nest_list() -> None:
    assert nest_list((1, 2, 3, 5)) == "1-3, 5"
    assert nest_list((4,)) == "4"
    assert load_prompt((1, 2, 3, 4)).text.startswith("Load the units into nests 1-4")
    with pytest.raises(ValueError):
        Prompt(fixture_prompts(1).before[0].kind, "x", (0,))


def test_prompts_in_order_with_their_nests_and_the_unload_names_each_verdict() -> None:
    op = Scripted(["confirmed", "confirmed", "confirmed"])
    with virtual_station(2, 3) as sim:
        result = _station(sim, op).run()
    assert result.outcome == Outcome.PASS, [u.message for u in result.units]
    shown = [r for r in result.records if isinstance(r, PromptShown)]
    answered = [r for r in result.records if isinstance(r, PromptAnswered)]
    assert [p.kind for p in shown] == ["load", "close-lid", "unload"]
    assert shown[0].nests == (1, 2) and "nests 1-2" in shown[0].text
    assert shown[2].text == "Open the lid and unload nest 1: PASS; nest 2: PASS."
    assert [a.answer for a in answered] == ["confirmed"] * 3 and {a.by for a in answered} == {"pytest"}
    assert [a.prompt_id for a in answered] == [p.prompt_id for p in shown]
    kinds = [type(r).__name__ for r in result.records if not isinstance(r, RigReading)]
    # the load and lid prompts come before the first step, the unload after the verdicts and before the end
    assert kinds.index("PromptAnswered") < kinds.index("StepStarted")
    assert kinds[-3:] == ["PromptShown", "PromptAnswered", "RunFinished"]
    assert result.message == ""


@pytest.mark.parametrize(("answer", "why"), [("cancelled", "aborted by the operator at the prompt 'close-lid'"),
                                             ("timeout", "aborted: no answer to the prompt 'close-lid' within 600 s")])
def test_a_prompt_not_confirmed_aborts_before_anything_moves(answer: Answer, why: str) -> None:
    op = Scripted(["confirmed", answer])
    with virtual_station(1, 4) as sim:
        result = _station(sim, op).run()
    assert result.outcome == Outcome.ABORTED and result.outcome.exit_code == 130
    assert result.units[0].outcome == Outcome.ABORTED and result.units[0].message == why
    assert not [r for r in result.records if isinstance(r, StepStarted)]
    assert all(r.rate_dps == 0.0 and "MOVING" not in r.status for r in result.records if isinstance(r, RigReading))
    assert result.rig_at_rest
    assert len(op.asked) == 2  # no unload prompt: the units may never have been loaded


def test_an_operator_out_of_reach_is_a_station_fault() -> None:
    op = Scripted([NoOperator("the terminal was closed (end of input)")])
    with virtual_station(1, 4) as sim:
        result = _station(sim, op).run()
    assert result.outcome == Outcome.ERROR
    assert "the terminal was closed" in result.units[0].message
    assert not [r for r in result.records if isinstance(r, StepStarted)]
    answered = [r for r in result.records if isinstance(r, PromptAnswered)]
    assert [a.answer for a in answered] == ["cancelled"]  # the displays close the prompt


def test_unload_not_confirmed_leaves_the_verdicts() -> None:
    op = Scripted(["confirmed", "confirmed", "timeout"])
    with virtual_station(1, 3) as sim:
        result = _station(sim, op).run()
    assert result.units[0].outcome == Outcome.PASS and result.outcome == Outcome.PASS
    assert result.message == "unload not confirmed (timeout)"


def test_a_scanned_serial_that_is_not_the_unit_in_the_nest_is_refused() -> None:
    with virtual_station(2, 6) as sim:
        serials = [u.truth.serial for u in sim.units]
        station = _station(sim, AutoConfirm())
        station.prompter = None
        result = station.run(serials={0: serials[0], 1: serials[0]})
    assert result.units[0].outcome == Outcome.PASS
    refused = result.units[1]
    assert refused.outcome == Outcome.REFUSED
    assert refused.message == (f"nest 2: the scanned serial is {serials[0]} but the unit in the nest reports "
                               f"{serials[1]} (wrong unit, or the right unit in the wrong nest)")


def test_auto_confirm() -> None:
    ev = threading.Event()
    assert AutoConfirm("ci").ask("r/p1", load_prompt((1,)), ev) == ("confirmed", "ci")
    ev.set()
    assert AutoConfirm().ask("r/p1", load_prompt((1,)), ev)[0] == "cancelled"


def test_a_plan_without_prompts_asks_nothing() -> None:
    op = Scripted([])
    with virtual_station(1, 3) as sim:
        station = _station(sim, op)
        config = station.config
        result = station.run(on_runner=lambda r: setattr(r, "prompts", PromptPlan(before=(), unload=False)))
    assert config.record is False and result.outcome == Outcome.PASS
    assert op.asked == [] and not [r for r in result.records if isinstance(r, PromptShown)]
