"""Typing fidelity in a real terminal: wrong values / tries at 5, 10 and 20 ms between keys.

``python -m app`` runs in a tmux session (160 × 48, tests/app/terminal.py); on the Moves tab
every numeric field of the Unimate 2000B's forms is clicked in turn and typed into as an
operator would type fast (tests/app/typist.py): 10 backspaces, then a number, each key a
``tmux send-keys`` ``gap`` after the one before. A try is right when the field then shows
the number typed; it is wrong when the field settles on anything else (nothing changes on
the screen for ``SETTLE_S`` after the last key).

Run: ``python benchmarks/typing.py [--tries 60] [--gaps 5 10 20]``. For the code before a
change, run this script with the old tree first on the path:
``git worktree add /tmp/typing_old <commit>`` then
``PYTHONPATH=/tmp/typing_old python benchmarks/typing.py`` (the app started in tmux is the
one found on PYTHONPATH's first entry, see ``--repo``).
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from tests.app import terminal
from tests.app.terminal import START_S, kill_server, launch
from tests.app.typist import FORMS, Typist, number, shown_text

RETYPE_S = 0.1  # between keys when a wrong value is typed again: none was lost at 40 ms
SETTLE_S = 3.0  # a field unchanged this long after the last key has taken every key


def settled_text(typist: Typist, field: object, expected: str) -> str:
    """The field's text once it shows ``expected``, or once it stopped changing."""
    last, since = None, time.monotonic()
    deadline = since + 30.0
    while time.monotonic() < deadline:
        text = shown_text(typist.term.screen(), field)
        if text == expected:
            return text
        if text != last:
            last, since = text, time.monotonic()
        elif time.monotonic() - since > SETTLE_S:
            break
        time.sleep(0.02)
    return last or ""


def run(gap_ms: float, tries: int, session: str) -> tuple[int, list[str]]:
    """``tries`` numbers typed at ``gap_ms`` into the fields in turn: (wrong, examples)."""
    with tempfile.TemporaryDirectory() as tmp:
        socket = f"servodesk-typing-{os.getpid()}-{session}"
        term = launch(socket, session, Path(tmp))
        try:
            term.wait(lambda s: " RUN" in s and "mode HOLD" in s, "a live screen", START_S)
            typist = Typist(term, gap_ms / 1000)
            typist.open_moves()
            fields = [(form, help_starts, field) for form, help_starts, spec in FORMS
                      for field in spec]
            wrong, examples = 0, []
            shown_form = ""
            for k in range(tries):
                form, help_starts, (label, unit, (low, high)) = fields[k % len(fields)]
                if form != shown_form:
                    typist.open_form(form, help_starts)
                    shown_form = form
                field = typist.focus(label, unit)
                value = number(k, low, high)
                typist.type(value)
                text = settled_text(typist, field, value)
                if text != value:
                    wrong += 1
                    examples.append(f"{form} {label}: {value!r} -> {text!r}")
                    # slowly, so that it comes right: a wrong value's error line would move
                    # the form's last fields out of view
                    typist.type(value, gap_s=RETYPE_S)
                    term.wait(lambda s, f=field, v=value: shown_text(s, f) == v,
                              f"{value} retyped in {label}")
                    if os.environ.get("TYPING_SCREENS"):
                        print(term.screen())
            return wrong, examples
        finally:
            kill_server(socket)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--tries", type=int, default=60, help="numbers typed per gap")
    parser.add_argument("--gaps", type=float, nargs="+", default=[5.0, 10.0, 20.0],
                        metavar="MS", help="time between keys")
    parser.add_argument("--repo", type=Path, default=None,
                        help="the tree whose app to run (default: PYTHONPATH's first entry, "
                             "else this one)")
    args = parser.parse_args()
    paths = os.environ.get("PYTHONPATH", "").split(os.pathsep)
    repo = args.repo or (Path(paths[0]) if paths[0] else terminal.REPO)
    terminal.REPO = repo.resolve()
    print(f"app from {terminal.REPO}; {args.tries} tries per gap over "
          f"{sum(len(spec) for _, _, spec in FORMS)} fields of {len(FORMS)} Moves forms")
    for gap in args.gaps:
        wrong, examples = run(gap, args.tries, f"gap{gap:g}")
        shown = "; ".join(examples[:4])
        print(f"{gap:5g} ms between keys: {wrong:3d} / {args.tries} wrong"
              + (f"  e.g. {shown}" if shown else ""), flush=True)


if __name__ == "__main__":
    main()
