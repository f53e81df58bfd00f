"""Typing fast in a real terminal never leaves a wrong value (issue 26 item 1).

``python -m app`` in tmux (terminal.py): every numeric field of each machine's Moves forms
(the Unimate 2000B's and the rig's, each in its own app) and of the Unimate's Identify and
Positions tabs is typed into in turn, 200 times in all, as an operator types fast
(typist.py): 10 backspaces then a number, a key every 5 ms, each a ``tmux send-keys`` through
the terminal and Textual's input parser. The field must then show that number. Each try
waits for it; a wrong value never comes right, and the wait fails showing the screen. A
field is clicked once and takes its tries one after another, as an operator retyping.
Each machine's app is started once for the module (the Unimate's serves the Tab test too),
and driven through one tmux control-mode client (typist.ControlTerminal).

Before app/widgets/typed.py the backspaces went in after the digits typed behind them:
61 of 104 such tries were wrong (``python benchmarks/typing.py``), and this test failed at
try 17.
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from contextlib import contextmanager
from functools import partial
from pathlib import Path

import pytest

from tests.app.terminal import START_S, TMUX, kill_server, launch
from tests.app.typist import (
    CLEAR,
    FORMS,
    IN_OUT,
    RIG_FORMS,
    TAB_FIELDS,
    ControlTerminal,
    Field,
    Typist,
    find_field,
    number,
    shown_text,
)

SOCKET = f"servodesk-typing-{os.getpid()}"
TRIES = 200
TAB_TRIES = 20
GAP_S = 0.005

pytestmark = pytest.mark.skipif(
    TMUX is None, reason="tmux is not installed: the real-terminal typing test needs it "
                         "(apt-get install tmux; .ci/run installs it)")


# the 200 tries shared by the two machines' apps in proportion to their fields
TRIES_OF = {"unimate2000b": 130, "rig": TRIES - 130}


@contextmanager
def app_in_tmux(tmp_path: Path, machine: str) -> Iterator[ControlTerminal]:
    """The machine's app in tmux, live; E-stopped and quit after."""
    try:
        with ControlTerminal(launch(SOCKET, "typing", tmp_path, "--machine", machine)) as term:
            term.wait(lambda s: " RUN" in s and "mode HOLD" in s, "a live screen", START_S)
            yield term
            term.keys("Escape")
            term.wait(lambda s: "E-STOP LATCHED" in s, "the E-stop from Escape")
            term.quit_latched()
    finally:
        kill_server(SOCKET)


@pytest.fixture(scope="module")
def machine(request: pytest.FixtureRequest) -> str:
    """The machine a test's app runs (parametrized indirectly)."""
    return str(request.param)


@pytest.fixture(scope="module")
def term(machine: str, tmp_path_factory: pytest.TempPathFactory) -> Iterator[ControlTerminal]:
    """The machine's app, one for the module's tests of that machine (pytest runs them one
    after another, then quits it before it starts the next machine's)."""
    with app_in_tmux(tmp_path_factory.mktemp(machine), machine) as term:
        yield term


@pytest.mark.parametrize("machine", list(TRIES_OF), indirect=True)
def test_fast_typing_leaves_the_value_typed_in_every_field(
        term: ControlTerminal, machine: str) -> None:
    """Every numeric field of the machine's Moves forms, then of its other tabs."""
    unimate = machine == "unimate2000b"
    fields = [(form, help_starts, field) for form, help_starts, spec
              in (FORMS if unimate else RIG_FORMS) for field in spec]
    fields += [(key, None, field) for key, spec in (TAB_FIELDS if unimate else ())
               for field in spec]
    typist = Typist(term, GAP_S)
    typist.open_moves()
    for i, (where, help_starts, (label, unit, (low, high))) in enumerate(fields):
        if help_starts is None:
            typist.open_tab(where, label, unit)
        else:
            typist.open_form(where, help_starts)
        field = typist.focus(label, unit)
        for k in range(i, TRIES_OF[machine], len(fields)):  # one field's tries in a row
            value = number(k, low, high)
            typist.type(value)
            term.wait(lambda s, f=field, v=value: shown_text(s, f) == v,
                      f"{value} typed in {where}'s {label} field (try {k + 1})")


@pytest.mark.parametrize("machine", ["unimate2000b"], indirect=True)
def test_keys_typed_after_tab_go_to_the_next_field(term: ControlTerminal) -> None:
    """A start, Tab, a target, keys 5 ms apart: the target goes in the target field.
    Before the app took Tab itself (app/tui.py), 12 of 12 such tries were wrong: the keys
    behind Tab reached the start field before the focus moved."""
    typist = Typist(term, GAP_S)
    typist.open_moves()
    step, help_starts, _ = FORMS[0]
    typist.open_form(step, help_starts)
    target = None
    for k in range(TAB_TRIES):
        start = typist.focus("start", "mm")
        target = target or find_field(term.screen(), "target", "mm")
        assert target is not None
        first, second = number(k, *IN_OUT), number(k + 1, *IN_OUT)
        typist.press(typist.clearing() + list(first) + ["Tab"] + ["BSpace"] * CLEAR
                     + list(second))
        shown = partial(shows_both, start, first, target, second)
        term.wait(shown, f"{first} in start and {second} in target (try {k + 1})")


def shows_both(one: Field, one_text: str, two: Field, two_text: str, screen: str) -> bool:
    return shown_text(screen, one) == one_text and shown_text(screen, two) == two_text
