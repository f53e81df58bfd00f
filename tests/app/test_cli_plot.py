"""``servodesk move … --plot`` and ``servodesk runs show RUN --plot`` in real subprocesses
(issue 26, item 9): the response of each joint that moved, drawn with plotext to the
terminal's size (COLUMNS × LINES), titled with the joint and its unit, with its axes; the
joints that did not move named in one line; no colour into a pipe; with --json, stdout stays
one object. Sizes, layouts and colour on a terminal: tests/app/plotting/test_terminal.py."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from control.recorder import Run, save_run
from hw.machine import load_machine

ROOT = Path(__file__).resolve().parents[2]
UNIMATE = load_machine("unimate2000b")
ANSI = re.compile(r"\x1b\[[0-9;]*m")
STILL = "not drawn, did not move: In/Out, Up/Down, Bend, Yaw, Swivel"


def servodesk(*args: str, columns: int, lines: int, **env: str
              ) -> subprocess.CompletedProcess[str]:
    environ = {k: v for k, v in os.environ.items() if k != "NO_COLOR"}
    environ |= {"PYTHONPATH": str(ROOT), "COLUMNS": str(columns), "LINES": str(lines), **env}
    return subprocess.run([sys.executable, "-m", "app", *args], cwd=ROOT, env=environ,
                          capture_output=True, text=True, timeout=120)


def drawn_width(text: str) -> int:
    return max(len(ANSI.sub("", line)) for line in text.splitlines())


@pytest.fixture
def data_dir(tmp_path: Path) -> Path:
    """One saved run: Rotate steps 0 → 10° and lags 50 ms behind, E-stopped at 1.5 s; the
    other joints hold."""
    t = np.arange(1500) * 1e-3
    desired = np.zeros((len(t), UNIMATE.n_joints))
    desired[t >= 0.1, 1] = 10.0
    actual = desired.copy()
    actual[:, 1] = np.where(t >= 0.1, 10.0 * (1 - np.exp(-(t - 0.1) / 0.05)), 0.0)
    duty = 4.0 * (desired - actual)
    save_run(Run.from_machine(UNIMATE, "step", "estop: operator E-stop", {}, t, desired, actual,
                              duty, start_time="2026-11-26T10:00:00+00:00",
                              meta={"moving": [1], "backend": "sim"}), tmp_path)
    return tmp_path


def test_runs_show_plot_draws_the_joint_that_moved_to_the_terminals_width(
        data_dir: Path) -> None:
    columns, lines = 72, 24
    done = servodesk("runs", "show", "latest", "--plot", "--data-dir", str(data_dir),
                     columns=columns, lines=lines)
    assert done.returncode == 0, done.stderr
    out = done.stdout
    assert out.startswith("20261126-100000-unimate2000b-step\n")  # the summary first
    assert "Rotate (deg)" in out and "time (s)" in out and "duty (%)" in out
    assert "desired" in out and "actual" in out
    assert columns - 2 <= drawn_width(out) <= columns  # as wide as the terminal, no wider
    assert "E-stop: operator E-stop at 1.499 s" in out
    assert STILL in out and "Up/Down (deg)" not in out
    assert not ANSI.search(out)  # a pipe, not a terminal: no colour
    plot = out[out.index("Rotate (deg)"):out.index(STILL)].splitlines()
    assert lines - 4 <= len(plot) <= lines  # the terminal's height, less the notes


def test_runs_show_json_keeps_stdout_one_object_and_plots_on_stderr(data_dir: Path) -> None:
    done = servodesk("runs", "show", "latest", "--json", "--plot", "--data-dir", str(data_dir),
                     columns=80, lines=24)
    assert done.returncode == 0, done.stderr
    assert done.stdout.count("\n") == 1 and done.stdout.startswith("{")
    assert "Rotate (deg)" in done.stderr and drawn_width(done.stderr) <= 80


def test_move_plot_draws_the_step_response_after_the_move(tmp_path: Path) -> None:
    done = servodesk("move", "step", "--lockstep", "--joint", "rotate", "--target", "10",
                     "--duration", "1", "--plot", "--data-dir", str(tmp_path),
                     columns=90, lines=30)
    assert done.returncode == 0, done.stderr
    out = done.stdout
    summary, plot = out[:out.index("Rotate (deg)")], out[out.index("Rotate (deg)"):]
    assert "saved as" in summary and "Rotate" in summary  # the report and its table first
    assert "time (s)" in plot and "deg" in plot and "duty (%)" in plot
    assert plot.rstrip().endswith(STILL)
    assert 88 <= drawn_width(plot) <= 90
    assert re.search(r"^ *10┤", plot, re.MULTILINE)  # the target, a round tick on its axis
