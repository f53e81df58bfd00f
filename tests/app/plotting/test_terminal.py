"""A run's response drawn in the terminal with plotext (``servodesk move --plot``, ``servodesk
runs show --plot``): as wide as the terminal and no wider, its height, one panel per joint
that moved (two columns when one would squash them), titled with the joint and its unit,
with its axes and the E-stop; coloured on a real pseudo-terminal only, and not under
NO_COLOR."""

from __future__ import annotations

import io
import os
import pty
import re
import threading

import numpy as np
import pytest

from app.plotting.terminal import moved, print_response, response_text
from control.recorder import Run
from hw.machine import load_machine

UNIMATE = load_machine("unimate2000b")
ANSI = re.compile(r"\x1b\[[0-9;]*m")
STILL = "not drawn, did not move: In/Out, Up/Down, Bend, Yaw, Swivel"


def step(joints: list[int], status: str = "complete") -> Run:
    """``joints`` step 0 → 10 at 0.1 s and lag 50 ms behind, 1.5 s; the others hold at 0."""
    t = np.arange(1500) * 1e-3
    desired = np.zeros((len(t), UNIMATE.n_joints))
    desired[np.ix_(t >= 0.1, joints)] = 10.0
    actual = desired.copy()
    actual[:, joints] = np.where(t >= 0.1, 10.0 * (1 - np.exp(-(t - 0.1) / 0.05)), 0.0)[:, None]
    return Run.from_machine(UNIMATE, "step", status, {}, t, desired, actual,
                            4.0 * (desired - actual))


def on_a_terminal(run: Run) -> str:
    """What ``print_response`` writes to a real pseudo-terminal, read from its other end
    while it writes (a terminal holds only so much unread)."""
    parent, child = pty.openpty()
    terminal = os.fdopen(child, "w", encoding="utf-8")
    assert terminal.isatty()

    def write() -> None:
        with terminal:
            print_response(run, terminal)

    writer = threading.Thread(target=write)
    writer.start()
    chunks = []
    while True:
        try:
            chunk = os.read(parent, 65536)
        except OSError:  # EIO: the writer closed its end and everything is read
            break
        chunks.append(chunk)
    writer.join()
    os.close(parent)
    return b"".join(chunks).decode().replace("\r\n", "\n")


def lines_of(text: str) -> list[str]:
    return [ANSI.sub("", line) for line in text.splitlines()]


@pytest.mark.parametrize(("columns", "rows"), [(72, 24), (80, 24), (150, 40)])
def test_one_joint_fills_the_terminal_titled_with_its_axes(columns: int, rows: int) -> None:
    text = response_text(step([1], "estop: operator E-stop"), columns, rows, color=False)
    lines = lines_of(text)
    assert columns - 2 <= max(map(len, lines)) <= columns
    assert rows - 2 <= len(lines) <= rows
    assert lines[0].strip() == "Rotate (deg)   · desired  ⣀ actual  • duty % (right)"
    assert "time (s)" in text and "duty (%)" in text and lines[-3].startswith("deg")
    assert "desired" in text and "actual" in text
    assert lines[-2:] == ["E-stop: operator E-stop at 1.499 s", STILL]
    ticks = [float(v) for v in lines[-4].split()]  # round, as the SVG's: 0, 0.5, 1.0 …
    assert ticks[0] == 0.0 and len(ticks) >= 3
    assert np.allclose(np.diff(ticks), ticks[1] - ticks[0])
    assert ticks[1] - ticks[0] in (0.1, 0.2, 0.25, 0.5, 1.0)
    assert not ANSI.search(text)


def test_six_joints_take_two_columns_where_they_fit_and_grow_where_not() -> None:
    six = step(list(range(6)))
    wide = lines_of(response_text(six, 160, 48, color=False))
    titles = [line for line in wide if "(deg)" in line or "(mm)" in line]
    assert len(titles) == 3 and "In/Out (mm)" in titles[0] and "Rotate (deg)" in titles[0]
    assert max(map(len, wide)) <= 160 and len(wide) <= 48
    narrow = lines_of(response_text(six, 80, 24, color=False))
    assert max(map(len, narrow)) <= 80
    assert len([line for line in narrow if "desired  ⣀ actual" in line]) == 6
    assert len(narrow) >= 6 * 12  # taller than the terminal: each panel keeps 12 lines
    assert "did not move" not in "\n".join(narrow)


def test_a_joint_pushed_off_its_place_is_drawn_one_count_of_jitter_is_not() -> None:
    run = step([1])
    count = UNIMATE.joints[3].encoder.gradient
    run.actual[700:, 3] += 12 * count  # Bend pushed, its desired unchanged
    run.actual[::2, 4] += count  # Yaw reads one count either way
    assert moved(run) == [1, 3]
    assert moved(step([])) == []
    assert response_text(step([]), 80, 24, color=False) == "no joint moved: nothing to plot\n"


def test_colour_on_a_terminal_only_and_never_under_no_color(
        monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("COLUMNS", "90")
    monkeypatch.setenv("LINES", "30")
    run = step([1])
    for no_color, coloured in (("", True), ("1", False)):
        monkeypatch.setenv("NO_COLOR", no_color)
        text = on_a_terminal(run)
        assert bool(ANSI.search(text)) is coloured
        assert 88 <= max(map(len, lines_of(text))) <= 90
    pipe = io.StringIO()
    monkeypatch.delenv("NO_COLOR")
    print_response(run, pipe)
    assert "Rotate (deg)" in pipe.getvalue() and not ANSI.search(pipe.getvalue())
