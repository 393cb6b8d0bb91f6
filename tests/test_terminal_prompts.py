"""The station's prompts at the terminal (``station run``): Enter confirms, ``n`` cancels, end of input is no
operator, no answer times out; the progress display prints each prompt and its answer."""

from __future__ import annotations

import contextlib
import io
import os
import threading
from collections.abc import Iterator

import pytest
from rich.console import Console

from station.sequence.prompts import NoOperator, close_lid_prompt, load_prompt
from station.sequence.records import PromptAnswered, PromptShown
from station.terminal import ProgressDisplay, TerminalOperator


@pytest.fixture
def pipe() -> Iterator[tuple[io.TextIOWrapper, int]]:
    r, w = os.pipe()
    reader = os.fdopen(r, "r")
    try:
        yield reader, w
    finally:
        reader.close()
        with contextlib.suppress(OSError):  # closed by the test already
            os.close(w)


def _operator(reader: io.TextIOWrapper) -> tuple[TerminalOperator, io.StringIO]:
    out = io.StringIO()
    return TerminalOperator(Console(file=out, width=120), "bob", reader), out


def test_enter_confirms_and_n_cancels(pipe: tuple[io.TextIOWrapper, int]) -> None:
    reader, w = pipe
    op, out = _operator(reader)
    os.write(w, b"\n")
    assert op.ask("r/p1", load_prompt((1, 2)), threading.Event()) == ("confirmed", "bob")
    assert "press Enter to confirm" in out.getvalue()
    os.write(w, b"n\n")
    assert op.ask("r/p2", close_lid_prompt(), threading.Event()) == ("cancelled", "bob")


def test_no_answer_times_out_and_an_abort_stops_the_wait(pipe: tuple[io.TextIOWrapper, int]) -> None:
    reader, _ = pipe
    op, _ = _operator(reader)
    assert op.ask("r/p1", close_lid_prompt(timeout_s=0.3), threading.Event()) == ("timeout", "")
    cancel = threading.Event()
    threading.Timer(0.2, cancel.set).start()
    assert op.ask("r/p2", close_lid_prompt(), cancel) == ("cancelled", "")


def test_end_of_input_is_no_operator(pipe: tuple[io.TextIOWrapper, int]) -> None:
    reader, w = pipe
    os.close(w)
    op, _ = _operator(reader)
    with pytest.raises(NoOperator, match=r"end of input.*--yes"):
        op.ask("r/p1", close_lid_prompt(), threading.Event())


def test_the_display_prints_the_prompt_and_its_answer() -> None:
    out = io.StringIO()
    display = ProgressDisplay(Console(file=out, width=200), ["a", "b"], 1.0)
    p = load_prompt((1, 2))
    display(PromptShown("r", "r/p1", p.kind.value, p.text, p.nests, p.timeout_s))
    display(PromptAnswered("r", "r/p1", "confirmed", "bob", 2.25))
    text = out.getvalue()
    assert " LOAD  Load the units into nests 1-2 and plug in their cables." in text
    assert "confirmed by bob after 2.2 s" in text
