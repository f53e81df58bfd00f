"""Typing fast in a real terminal never leaves a wrong value (issue 26 item 1).

``python -m app`` in tmux (terminal.py); on the Moves tab every numeric field of the Unimate
2000B's forms is typed into in turn, 200 times in all, as an operator types fast
(typist.py): 10 backspaces then a number, a key every 5 ms, each a ``tmux send-keys`` through
the terminal and Textual's input parser. The field must then show that number. Each try
waits for it; a wrong value never comes right, and the wait fails showing the screen.

Before app/widgets/typed.py the backspaces went in after the digits typed behind them:
61 of 104 such tries were wrong (``python benchmarks/typing.py``), and this test failed at
its first or second field.
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from tests.app.terminal import HEIGHT, START_S, TMUX, WIDTH, kill_server, launch
from tests.app.typist import FORMS, Typist, number, shown_text

SOCKET = f"servodesk-typing-{os.getpid()}"
TRIES = 200
GAP_S = 0.005

pytestmark = pytest.mark.skipif(
    TMUX is None, reason="tmux is not installed: the real-terminal typing test needs it "
                         "(apt-get install tmux; .ci/run installs it)")


def test_fast_typing_leaves_the_value_typed_in_every_field(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    # Under pytest the process environment (not os.environ) carries COLUMNS=80 LINES=24, the
    # tmux server hands them to the app, and Textual takes them over the pane's size
    monkeypatch.setenv("COLUMNS", str(WIDTH))
    monkeypatch.setenv("LINES", str(HEIGHT))
    term = launch(SOCKET, "typing", tmp_path)
    try:
        term.wait(lambda s: " RUN" in s and "mode HOLD" in s, "a live screen", START_S)
        typist = Typist(term, GAP_S)
        typist.open_moves()
        fields = [(form, help_starts, field) for form, help_starts, spec in FORMS
                  for field in spec]
        for k in range(TRIES):
            form, help_starts, (label, unit, (low, high)) = fields[k % len(fields)]
            typist.open_form(form, help_starts)
            field = typist.focus(label, unit)
            value = number(k, low, high)
            typist.type(value)
            term.wait(lambda s, f=field, v=value: shown_text(s, f) == v,
                      f"{value} typed in the {form} form's {label} field (try {k + 1})")
        term.keys("Escape")
        term.wait(lambda s: "E-STOP LATCHED" in s, "the E-stop from Escape")
        term.quit_latched()
    finally:
        kill_server(SOCKET)
