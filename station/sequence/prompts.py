"""The station's prompts to its operator: a step type of the sequence that waits for a person.

A :class:`Prompt` asks the operator to do something with the fixture (load units into nests, close the
lid, unload, confirm) and waits for the answer. The runner emits a
:class:`~station.sequence.records.PromptShown` record (every display shows it: the terminal, the web
console), asks its :class:`Operator` (the prompt answerer: the terminal's Enter key, the web console's
button, or :class:`AutoConfirm` for CI and the demo) and emits a
:class:`~station.sequence.records.PromptAnswered` record with the answer.

Nests are the fixture's positions as the operator sees them, numbered from 1 (nest ``k + 1`` holds the
unit of fixture slot ``k``).

What an answer does (:class:`~station.sequence.runner.SequenceRunner`):

* ``confirmed``: the sequence goes on.
* ``cancelled``: the operator declined; before the measurement the run ends ABORTED (nothing moved),
  after the verdicts they stand and the run's message says the unload was not confirmed.
* ``timeout``: nobody answered within the prompt's ``timeout_s`` (wall-clock seconds: a person's time,
  not the station clock's). Before the measurement the run ends ABORTED ("no answer"): the units were
  not tested, nothing is wrong with the station. After the verdicts they stand (as for ``cancelled``).
* the answerer itself fails (:class:`NoOperator`, e.g. a terminal that was closed): a station fault,
  the run ends ERROR before anything moves.
"""

from __future__ import annotations

import threading
from collections.abc import Sequence
from dataclasses import dataclass
from enum import Enum
from typing import Literal, Protocol

from station.kernel.errors import HardwareError

#: How a prompt was answered.
Answer = Literal["confirmed", "cancelled", "timeout"]

#: Default time a prompt waits for its answer (wall-clock s).
PROMPT_TIMEOUT_S = 600.0


class NoOperator(HardwareError):
    """The prompt could not reach an operator (the terminal was closed): a station fault (ERROR)."""


class PromptKind(Enum):
    """What the operator is asked to do."""

    LOAD = "load"
    CLOSE_LID = "close-lid"
    UNLOAD = "unload"
    CONFIRM = "confirm"


def nest_list(nests: Sequence[int]) -> str:
    """``(1, 2, 3, 5)`` -> ``'1-3, 5'``: runs of consecutive nests joined."""
    out: list[str] = []
    ns = sorted(set(nests))
    k = 0
    while k < len(ns):
        j = k
        while j + 1 < len(ns) and ns[j + 1] == ns[j] + 1:
            j += 1
        out.append(str(ns[k]) if j == k else f"{ns[k]}-{ns[j]}")
        k = j + 1
    return ", ".join(out)


@dataclass(frozen=True)
class Prompt:
    """One prompt step.

    Attributes:
        kind: load, close the lid, unload or confirm.
        text: what the operator reads, in plain words (the nest numbers included).
        nests: the nests it concerns (1-based; empty: the whole fixture).
        timeout_s: how long to wait for the answer (wall-clock s).
    """

    kind: PromptKind
    text: str
    nests: tuple[int, ...] = ()
    timeout_s: float = PROMPT_TIMEOUT_S

    def __post_init__(self) -> None:
        if not self.timeout_s > 0:
            raise ValueError(f"a prompt's timeout must be positive, not {self.timeout_s}")
        if any(n < 1 for n in self.nests):
            raise ValueError(f"nests are numbered from 1: {self.nests}")


def load_prompt(nests: Sequence[int], timeout_s: float = PROMPT_TIMEOUT_S) -> Prompt:
    """'Load units into nests 1-4.'"""
    word = "nest" if len(nests) == 1 else "nests"
    return Prompt(PromptKind.LOAD, f"Load the units into {word} {nest_list(nests)} and plug in their cables.",
                  tuple(nests), timeout_s)


def close_lid_prompt(timeout_s: float = PROMPT_TIMEOUT_S) -> Prompt:
    """'Close the lid' (the rig moves after this answer)."""
    return Prompt(PromptKind.CLOSE_LID, "Close the lid and keep clear: the rig moves when you confirm.", (),
                  timeout_s)


def unload_prompt(verdicts: Sequence[tuple[int, str]], timeout_s: float = PROMPT_TIMEOUT_S) -> Prompt:
    """'Open the lid and unload': each nest with its verdict, so the unit goes to the right bin."""
    parts = [f"nest {n}: {v}" for n, v in verdicts]
    return Prompt(PromptKind.UNLOAD, "Open the lid and unload " + "; ".join(parts) + ".",
                  tuple(n for n, _ in verdicts), timeout_s)


def confirm_prompt(text: str, nests: Sequence[int] = (), timeout_s: float = PROMPT_TIMEOUT_S) -> Prompt:
    """Any confirmation the line needs (e.g. 'the reference unit is in nest 4')."""
    return Prompt(PromptKind.CONFIRM, text, tuple(nests), timeout_s)


@dataclass(frozen=True)
class PromptPlan:
    """The prompts of a run: ``before`` the rig moves (after the run started), and whether to ask for the
    unload after the verdicts (its text names each nest's verdict)."""

    before: tuple[Prompt, ...]
    unload: bool = True
    timeout_s: float = PROMPT_TIMEOUT_S


def fixture_prompts(units: int, timeout_s: float = PROMPT_TIMEOUT_S) -> PromptPlan:
    """The usual prompts of a fixture of ``units`` nests: load them, close the lid; unload at the end."""
    nests = tuple(range(1, units + 1))
    return PromptPlan((load_prompt(nests, timeout_s), close_lid_prompt(timeout_s)), True, timeout_s)


class Operator(Protocol):
    """Answers the station's prompts (the terminal, the web console, :class:`AutoConfirm`).

    :meth:`ask` blocks until the prompt is answered, ``timeout_s`` (wall-clock s) passed (``'timeout'``) or
    ``cancel`` is set (the run is being aborted: return ``'cancelled'``). It may raise
    :class:`KeyboardInterrupt` (Ctrl-C, a signal) and raises :class:`NoOperator` when it cannot reach a person.
    """

    def ask(self, prompt_id: str, prompt: Prompt, cancel: threading.Event) -> tuple[Answer, str]:
        """The answer and who gave it (a name, '' if unknown)."""
        ...


class AutoConfirm:
    """Confirms every prompt at once (CI, the demo, ``station run --yes``); the answer is by ``name``."""

    def __init__(self, name: str = "auto-confirm") -> None:
        self.name = name

    def ask(self, prompt_id: str, prompt: Prompt, cancel: threading.Event) -> tuple[Answer, str]:
        return ("cancelled", "") if cancel.is_set() else ("confirmed", self.name)


__all__ = [
    "PROMPT_TIMEOUT_S",
    "Answer",
    "AutoConfirm",
    "NoOperator",
    "Operator",
    "Prompt",
    "PromptKind",
    "PromptPlan",
    "close_lid_prompt",
    "confirm_prompt",
    "fixture_prompts",
    "load_prompt",
    "nest_list",
    "unload_prompt",
]
