"""``servodesk move …`` in real subprocesses: each kind runs on a real controller and leaves
its run on disk (listed by ``servodesk runs list``); a bad field exits 2 naming it, with
nothing started or saved; Ctrl+C during the move, or the board's E-stop, exits 1 with the
run recorded so far saved; the serial backend against ``servodesk emulate`` on a pty.
The bad-input cases call the CLI's ``main`` in this process (the code ``python -m app``
exits with), two processes fewer each; one of them, and bad usage, run as processes too.
A move's run on disk is read back (``runs list``, ``runs show``) by ``main`` here too: the
move is this module's subject, and ``runs`` runs in processes in test_cli_runs.py.

The moves run with ``--lockstep`` (the simulator as fast as the controller computes) but
for the end-to-end ones that are about real time: a step on the simulator, Ctrl+C during a
move, and the serial backend's two."""

from __future__ import annotations

import contextlib
import io
import json
import os
import re
import select
import signal
import subprocess
import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np
import pytest

from app.cli import main
from control.motion.robot_model import unimate_model
from control.recorder import json_numbers
from hw.machine import load_machine
from tests.conftest import EmulatorProcess

ROOT = Path(__file__).resolve().parents[2]
ENV = {**os.environ, "PYTHONPATH": str(ROOT)}
MOVE_S = 120.0  # the longest of these takes ~10 s alone; a loaded two-core machine, more
UNIMATE = load_machine("unimate2000b")
MIDDLE = [(j.lower + j.upper) / 2 for j in UNIMATE.joints]  # the simulator starts there


def servodesk(*args: str, data_dir: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "app", *args, "--data-dir", str(data_dir)],
                          cwd=ROOT, env=ENV, capture_output=True, text=True, timeout=MOVE_S)


def move(*args: str, data_dir: Path, lockstep: bool = True) -> subprocess.CompletedProcess[str]:
    """``servodesk move ARGS``, in lockstep unless the test is about real time."""
    return servodesk("move", *args, *(["--lockstep"] if lockstep else []), data_dir=data_dir)


def in_process(capsys: pytest.CaptureFixture[str], *args: str) -> tuple[int, str, str]:
    """``servodesk ARGS`` run by the CLI's ``main`` here: its exit code, stdout and stderr."""
    capsys.readouterr()
    try:
        code = main(list(args))
    except SystemExit as exited:  # argparse's usage errors
        code = exited.code if isinstance(exited.code, int) else 1
    out, err = capsys.readouterr()
    return code, out, err


def runs(*args: str, data_dir: Path) -> str:
    """What ``servodesk runs ARGS`` prints, run by the CLI's ``main`` here: the move's run is
    read from disk as a later process would (``runs`` in its own processes:
    test_cli_runs.py)."""
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main(["runs", *args, "--data-dir", str(data_dir)])
    assert code == 0, err.getvalue()
    return out.getvalue()


def listed(data_dir: Path) -> list[dict]:
    return json.loads(runs("list", "--json", data_dir=data_dir))


def test_a_step_runs_saves_its_run_and_reports_it_as_json(tmp_path: Path) -> None:
    done = move("step", "--joint", "updown", "--target", "5", "--duration", "1.5", "--json",
                data_dir=tmp_path, lockstep=False)
    assert done.returncode == 0, done.stderr
    report = json.loads(done.stdout)  # one object, nothing else on stdout
    assert (report["status"], report["kind"], report["backend"]) == ("complete", "step", "sim")
    assert report["path_samples"] == 1501 < report["samples"]  # then the settle's rows
    assert report["settle"]["settle_s"][2] is not None and not report["unsettled"]
    files = report["run"]
    assert all(Path(files[k]).is_file() for k in ("json", "csv", "tsv"))
    [metric] = report["metrics"]
    assert metric["joint"] == "Up/Down" and metric["final"] == 5.0
    assert metric["step"] == pytest.approx(5.0 - MIDDLE[2], abs=0.3)
    assert metric["settling_time_s"] is not None and metric["settling_time_s"] < 1.5
    assert [run["stem"] for run in listed(tmp_path)] == [files["stem"]]
    shown = runs("show", files["stem"], "--json", data_dir=tmp_path)
    # the saved metrics, as the run's JSON writes numbers (10 significant digits)
    assert json.loads(shown)["metrics"] == json_numbers(report["metrics"])


def test_a_move_not_in_position_within_goal_time_exits_1_and_says_so(tmp_path: Path) -> None:
    """Issue 24: Bend asked 100° in a step of 0.1 s on a machine whose goal_time is 0.5 s: at
    90°/s it cannot be there, so the move ends unsettled, naming Bend; the table says so, the
    exit is 1, and the run is saved. In real time: the settle lasts the 0.5 s the progress
    line on stderr needs to be seen."""
    machine = tmp_path / "quick.toml"
    machine.write_text((ROOT / "hw/machines/unimate2000b.toml").read_text().replace(
        "goal_time = 2.0", "goal_time = 0.5"))
    done = move("step", "--machine", str(machine), "--joint", "bend", "--target", "100",
                "--duration", "0.1", data_dir=tmp_path / "runs", lockstep=False)
    assert done.returncode == 1, (done.stdout, done.stderr)
    lines = done.stdout.splitlines()
    assert re.fullmatch(r"step Bend to 100°: unsettled: Bend \d+\.\d\d° from its goal(; Yaw "
                        r"[^;]*)? after 0\.5 s", lines[0]), lines[0]  # Yaw reads Bend in too
    assert lines[1].startswith("saved as ")
    table = lines[lines.index(next(line for line in lines if line.startswith("UNSETTLED"))):]
    assert table[0].startswith("UNSETTLED: not in position 0.5 s after the path")
    assert table[1].split() == ["joint", "in", "position", "error", "at", "end"]
    (bend,) = [line for line in table if line.startswith("Bend ")]
    assert "not in position" in bend
    assert "settling: holding the end" in done.stderr


def _path_file(tmp_path: Path) -> str:
    t = np.linspace(0.0, 2.0, 21)
    rows = "\n".join(f"{a:.2f},{MIDDLE[2] + 3 * (1 - np.cos(np.pi * a / 2)):.4f}" for a in t)
    (tmp_path / "nod.csv").write_text(f"t,Up/Down\n{rows}\n")
    return str(tmp_path / "nod.csv")


def _endpoint(tmp_path: Path) -> list[str]:
    z = unimate_model(UNIMATE).pose(np.array(MIDDLE))[2]
    return ["--z", f"{z + 20:.3f}", "--ramp-time", "1.5"]


GOOD: dict[str, tuple[str, Callable[[Path], list[str]], str]] = {
    # kind: (the summary's first line starts, the options, the run's kind)
    "ramp": ("ramp Rotate to 10°: complete",
             lambda d: ["--joint", "2", "--end", "10", "--ramp-time", "1", "--total", "1.5"],
             "ramp"),
    "sine": ("sine Up/Down", lambda d: ["--joint", "Up/Down", "--end", "4", "--period", "1",
                                        "--duration", "1"], "sine"),
    "multistep": ("multi-step: complete",
                  lambda d: ["--targets", ",".join(f"{q + (2 if j == 3 else 0):g}"
                                                   for j, q in enumerate(MIDDLE)),
                             "--duration", "1"], "multi_step"),
    "endpoint": ("end point, solution 1: complete", _endpoint, "end_point"),
    "path": ("path nod.csv: complete", lambda d: [_path_file(d)], "path"),
    "via": ("path through 1 via points: complete",
            lambda d: ["--point", " ".join(f"{q + (3 if j == 4 else 0):g}"
                                            for j, q in enumerate(MIDDLE)), "--speed", "0.8"],
            "via_points"),
    "goto": ("go to: complete",
             lambda d: ["--targets", ",".join(f"{q - (3 if j == 5 else 0):g}"
                                              for j, q in enumerate(MIDDLE))], "go_to"),
}


@pytest.mark.parametrize("kind", sorted(GOOD))
def test_every_kind_runs_and_leaves_its_run_on_disk(kind: str, tmp_path: Path) -> None:
    first_line, options, run_kind = GOOD[kind]
    done = move(kind, *options(tmp_path), data_dir=tmp_path)
    assert done.returncode == 0, done.stderr
    lines = done.stdout.splitlines()
    assert lines[0].startswith(first_line), done.stdout
    assert lines[1].startswith(f"saved as {tmp_path}"), done.stdout
    assert "running " in done.stderr and "Ctrl+C is the E-stop" in done.stderr
    [run] = listed(tmp_path)
    assert run["kind"] == run_kind
    # a loaded machine may stall the controller past stall_ms: the run says so, complete
    assert re.fullmatch(r"complete(, with a [\d.]+ s controller stall)?", run["status"]), run
    # the result table as the Moves tab's for the kind: a step's response, a sine's
    # fundamentals, else a smooth path's tracking error
    second = {"multistep": "step", "sine": "amplitude"}.get(kind, "travel")
    assert any(line.split()[:2] == ["joint", second] for line in lines), done.stdout
    shown = runs("show", run["stem"], data_dir=tmp_path)
    assert any(line.split()[:2] == ["joint", second] for line in shown.splitlines())


@pytest.mark.parametrize("kind, options, what", [
    ("multistep", ["--step", "60:0.8", "--step", "30:0.8"], "sequence of 2 steps: complete"),
    ("step", ["--target", "40", "--duration", "1"], "step Ram to 40mm: complete"),
])
def test_the_rig_moves_once_initialised(kind: str, options: list[str], what: str,
                                        tmp_path: Path) -> None:
    done = move(kind, "--machine", "rig", "--initialise", *options, data_dir=tmp_path)
    assert done.returncode == 0, done.stderr
    assert done.stdout.startswith(what), done.stdout
    assert "initialising" in done.stderr
    assert len(listed(tmp_path)) == 1


def test_the_rig_pulse_is_open_loop_and_needs_no_initialise(tmp_path: Path) -> None:
    done = move("pulse", "--machine", "rig", "--duty", "15", "--duration", "0.5", "--json",
                data_dir=tmp_path)
    assert done.returncode == 0, done.stderr
    report = json.loads(done.stdout)
    assert (report["kind"], report["samples"], report["metrics"]) == ("set_pulse", 501, [])


BAD = [
    # (arguments, what stderr must say)
    (["step", "--joint", "updown", "--target", "50"],
     "--target: Up/Down target 50° is outside -27…30° (machine unimate2000b)"),
    (["step", "--joint", "elbow", "--target", "5"], "--joint: no joint 'elbow'"),
    (["step", "--target", "1500", "--duration", "-1"],
     "--duration: duration -1 s is out of range: it must be more than 0 s and at most 600 s"),
    (["ramp", "--joint", "rotate", "--end", "10", "--ramp-time", "soon"],
     "--ramp-time: ramp time: 'soon' is not a number"),
    (["ramp", "--joint", "rotate", "--end", "100", "--ramp-time", "0.5"],
     "Rotate cannot ramp"),
    (["sine", "--joint", "bend", "--end", "nan"], "--end: Bend end: nan is not a usable number"),
    (["multistep", "--targets", "1,2"], "--targets: 2 values; give 6"),
    (["endpoint", "--z", "99999"], "unreachable"),
    (["path", "missing.csv"], "FILE: missing.csv: cannot read"),
    (["via", "--point", "1 2 3"], "--point: point line 1: 3 numbers; type 6 joint positions"),
    (["goto", "--targets", ",".join(map(str, MIDDLE)), "--speed", "2"],
     "--speed: speed fraction 2 is out of range: it must be more than 0 and at most 1"),
    (["pulse"], "pulse: the set pulse is the rig's open-loop test"),
    (["step", "--machine", "rig", "--target", "20"],
     "--initialise: the Single-axis hydraulic test rig's encoder is not zeroed"),
    (["multistep", "--machine", "rig", "--step", "20:later"],
     "--step: step 1 dwell: 'later' is not a number"),
    (["step", "--target", "5", "--backend", "serial"], "--port: --backend serial needs"),
    (["step", "--target", "5", "--machine", "nope.toml"], "nope.toml: no such machine file"),
    (["step", "--target", "5", "--backend", "serial", "--port", "/dev/null"],
     "--lockstep: an I/O board runs in real time"),
]


@pytest.mark.parametrize("args, message", BAD, ids=[" ".join(a)[:40] for a, _ in BAD])
def test_bad_input_exits_2_naming_the_field_and_moves_nothing(
        args: list[str], message: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    code, out, err = in_process(capsys, "move", *args, "--lockstep", "--data-dir", str(tmp_path))
    assert (code, out) == (2, ""), err
    assert err.startswith("servodesk: ") and message in err, err
    assert "Traceback" not in err
    code, out, err = in_process(capsys, "runs", "list", "--json", "--data-dir", str(tmp_path))
    assert (code, json.loads(out)) == (0, []), err


def test_bad_input_in_a_process_exits_2_and_lists_no_run(tmp_path: Path) -> None:
    args, message = BAD[0]
    done = move(*args, data_dir=tmp_path)
    assert (done.returncode, done.stdout) == (2, ""), done.stderr
    assert done.stderr.startswith("servodesk: ") and message in done.stderr, done.stderr
    assert listed(tmp_path) == []


@pytest.mark.timeout(90)
def test_a_fifo_as_the_path_file_exits_2_at_once_naming_it(tmp_path: Path) -> None:
    """``servodesk move path FIFO``: a named pipe no one writes to is refused as soon as it is
    opened, in one line that says what it is; reading it would wait for ever (the subprocess
    is given 60 s, the time a loaded machine may take to start the controller)."""
    fifo = tmp_path / "path.csv"
    os.mkfifo(fifo)
    done = subprocess.run([sys.executable, "-m", "app", "move", "path", str(fifo),
                           "--data-dir", str(tmp_path)], cwd=ROOT, env=ENV,
                          capture_output=True, text=True, timeout=60)
    assert (done.returncode, done.stdout) == (2, ""), done.stderr
    assert done.stderr == (f"servodesk: FILE: {fifo}: not a regular file but a named pipe "
                           "(FIFO): give a path file\n")
    assert listed(tmp_path) == []


def test_bad_usage_is_argparses_exit_2(tmp_path: Path) -> None:
    done = move("step", data_dir=tmp_path)  # --target is required
    assert done.returncode == 2 and "--target" in done.stderr


class Moving:
    """``servodesk move ARGS`` in the background, its stderr read line by line."""

    def __init__(self, args: Sequence[str], data_dir: Path) -> None:
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "app", "move", *args, "--data-dir", str(data_dir)],
            cwd=ROOT, env=ENV, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        self.err: list[str] = []

    def wait_for_line(self, start: str, timeout: float = 60.0) -> None:
        assert self.proc.stderr is not None
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if select.select([self.proc.stderr], [], [], 0.1)[0]:
                line = self.proc.stderr.readline()
                if not line:
                    break
                self.err.append(line)
                if line.startswith(start):
                    return
        self.proc.kill()
        pytest.fail(f"no line {start!r} on stderr: {''.join(self.err)}")

    def finish(self) -> tuple[int, str, str]:
        out, err = self.proc.communicate(timeout=MOVE_S)
        return self.proc.returncode, out, "".join(self.err) + err


def test_ctrl_c_during_the_move_is_an_estop_the_run_is_saved_and_the_exit_is_1(
        tmp_path: Path) -> None:
    moving = Moving(["sine", "--joint", "updown", "--end", "10", "--period", "4",
                     "--duration", "60", "--json"], tmp_path)
    try:
        moving.wait_for_line("running sine Up/Down")
        moving.proc.send_signal(signal.SIGINT)
        code, out, err = moving.finish()
    finally:
        if moving.proc.poll() is None:
            moving.proc.kill()
    assert code == 1, err
    assert "E-stop: every valve closed and latched" in err and "Traceback" not in err
    report = json.loads(out)
    assert report["status"].startswith("estop") and not report["complete"]
    assert 0 < report["samples"] < 60_001
    assert Path(report["run"]["json"]).is_file()
    [run] = listed(tmp_path)
    assert (run["stem"], run["samples"]) == (report["run"]["stem"], report["samples"])


@pytest.mark.skipif(os.geteuid() != 0, reason="raising a priority needs root or CAP_SYS_NICE")
def test_a_real_time_move_runs_at_the_uis_priority(tmp_path: Path) -> None:
    """It carries the heartbeat and Ctrl+C's E-stop as the TUI does: every thread of it is
    at the TUI's nice value while the arm moves."""
    from app.priority import UI_NICE

    moving = Moving(["sine", "--joint", "updown", "--end", "10", "--period", "4",
                     "--duration", "60"], tmp_path)
    try:
        moving.wait_for_line("running sine Up/Down")
        tasks = Path(f"/proc/{moving.proc.pid}/task")
        nice = {int(t.name): os.getpriority(os.PRIO_PROCESS, int(t.name))
                for t in tasks.iterdir()}
        moving.proc.send_signal(signal.SIGINT)
        moving.finish()
    finally:
        if moving.proc.poll() is None:
            moving.proc.kill()
    assert len(nice) > 1 and set(nice.values()) == {UI_NICE}, nice


def test_a_step_on_the_serial_backend_through_the_emulator(
        emulator: Callable[..., EmulatorProcess], tmp_path: Path) -> None:
    board = emulator("--glitch-scale", "0")
    done = move("step", "--backend", "serial", "--port", board.url, "--joint", "bend",
                "--target", "5", "--duration", "1.5", "--json", data_dir=tmp_path,
                lockstep=False)
    assert done.returncode == 0, done.stderr + done.stdout
    report = json.loads(done.stdout)
    assert (report["status"], report["backend"]) == ("complete", "serial")
    shown = json.loads(runs("show", "latest", "--json", data_dir=tmp_path))
    assert shown["meta"]["backend"] == "serial"
    assert board.stop()["frames_rx"] > 1000


def test_the_boards_estop_ends_a_serial_move_with_exit_1_and_its_run_saved(
        emulator: Callable[..., EmulatorProcess], tmp_path: Path) -> None:
    board = emulator("--glitch-scale", "0")
    moving = Moving(["ramp", "--backend", "serial", "--port", board.url, "--joint", "rotate",
                     "--end", "20", "--ramp-time", "30", "--json"], tmp_path)
    try:
        moving.wait_for_line("running ramp Rotate")
        board.send(signal.SIGUSR1)  # the E-stop button on the board
        code, out, err = moving.finish()
    finally:
        if moving.proc.poll() is None:
            moving.proc.kill()
    assert code == 1, err
    report = json.loads(out)
    assert report["status"].startswith("estop"), report["status"]
    assert Path(report["run"]["json"]).is_file() and report["samples"] > 0
