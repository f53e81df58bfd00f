"""``servodesk run PROGRAM`` in real subprocesses: the two example programs run to the end
(lockstep) with their runs grouped by the program run; a program that fails its check exits
2 with every problem and moves nothing; ``--check`` and ``--from``; an operator's wait
without a terminal is refused; Ctrl+C mid-program is an E-stop with the run saved (exit 1,
in real time: the signal must land while a move runs)."""

from __future__ import annotations

import json
import os
import resource
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from app.cli import main
from control.motion.positions import PositionBook, positions_file, save_positions
from hw.machine import load_machine

ROOT = Path(__file__).resolve().parents[2]
ENV = {**os.environ, "PYTHONPATH": str(ROOT)}
UNIMATE = load_machine("unimate2000b")
RUN_S = 180.0  # the pick and place takes ~8 s alone in lockstep; a loaded machine, more


def servodesk_run(*args: str, data_dir: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "app", "run", *args, "--data-dir",
                           str(data_dir)], cwd=ROOT, env=ENV, capture_output=True, text=True,
                          timeout=RUN_S, stdin=subprocess.DEVNULL)


def grouped(run_id: str, data_dir: Path, capsys: pytest.CaptureFixture[str]) -> list[dict]:
    """``servodesk runs list --program RUN_ID --json``, in this process."""
    capsys.readouterr()
    assert main(["runs", "list", "--program", run_id, "--json", "--data-dir",
                 str(data_dir)]) == 0
    return json.loads(capsys.readouterr().out)


def test_the_rig_sequence_runs_to_the_end(tmp_path: Path,
                                          capsys: pytest.CaptureFixture[str]) -> None:
    done = servodesk_run("programs/rig_sequence.toml", "--lockstep", "--json",
                         data_dir=tmp_path)
    assert done.returncode == 0, done.stderr
    report = json.loads(done.stdout)
    assert (report["program"], report["machine"], report["state"]) == (
        "rig test sequence", "rig", "done")
    steps = report["steps"]
    assert [s["step"] for s in steps] == [1, 2, 3, 4, 5, 6, 7]
    assert all(s["ok"] for s in steps) and steps[0]["status"].startswith("complete: initialised")
    assert [s.get("kind") for s in steps] == [None, "step", "step", "ramp", "sine",
                                              "multi_step", "go_to"]
    step_up = steps[1]["metrics"][0]  # Figure 3.7's step, 200 → 600 mm
    assert step_up["final"] == pytest.approx(600.0, abs=0.5)
    assert step_up["step"] == pytest.approx(400.0, abs=1.0)
    runs = grouped(report["run_id"], tmp_path, capsys)
    assert [r["stem"] for r in runs] == [s["run"] for s in steps[1:]]


def test_the_pick_and_place_runs_to_the_end_on_the_programs_positions(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    done = servodesk_run("programs/unimate_pick_and_place.toml", "--lockstep", "--json",
                         data_dir=tmp_path)
    assert done.returncode == 0, done.stderr
    report = json.loads(done.stdout)
    assert report["state"] == "done" and report["steps_run"] == report["steps_planned"] == 18
    steps = report["steps"]
    lines = [s for s in steps if s.get("kind") == "cartesian"]
    assert len(lines) == 8 and all(s["status"] == "complete" for s in lines)
    assert [s["passes"] for s in steps if s["step"] == 4] == [[1], [2]]
    pick = steps[2]  # down to the part: ends on the program's "pick" joints
    assert pick["title"] == "Down to the part"
    saved = json.loads((tmp_path / f"{pick['run']}.json").read_text())
    assert saved["meta"]["end_joints"] == [1297.56, 20.0, -1.323, 1.323, 90.0, 0.0]
    assert saved["meta"]["program"]["run_id"] == report["run_id"]
    assert len(grouped("pick and place", tmp_path, capsys)) == 14  # its moves: not the waits


def test_a_program_that_fails_its_check_exits_2_with_every_problem(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """In this process: the check comes before any controller starts."""
    program = tmp_path / "bad.toml"
    program.write_text('machine = "unimate2000b"\n\n[[step]]\ngo = "nowhere"\n\n[[step]]\n'
                       'move = "step"\njoint = "Up/Down"\ntarget = 40\n', encoding="utf-8")
    runs = tmp_path / "runs"
    assert main(["run", str(program), "--lockstep", "--data-dir", str(runs)]) == 2
    out, err = capsys.readouterr()
    assert err.splitlines() == [
        f"{program} line 4, step 1 (go to 'nowhere'): no taught position 'nowhere' — taught: "
        "home, park",
        f"{program} line 9, step 2 (move step): target: Up/Down target 40° is outside "
        "-27…30° (machine unimate2000b); enter a value in that range",
        f"servodesk: {program}: 2 problem(s); nothing moved"]
    assert out == "" and not runs.exists()
    # a position taught in the data directory's positions file (the Positions tab's) counts
    book = PositionBook(UNIMATE).teach("nowhere", UNIMATE.home)
    save_positions(book, positions_file(runs, UNIMATE))
    assert main(["run", str(program), "--check", "--data-dir", str(runs)]) == 2
    assert [line.split(": ", 1)[0] for line in capsys.readouterr().err.splitlines()] == [
        f"{program} line 9, step 2 (move step)", "servodesk"]
    program.write_text('machine = "rig"\n[[step]\n', encoding="utf-8")
    assert main(["run", str(program), "--data-dir", str(runs)]) == 2
    assert capsys.readouterr().err.startswith(f"{program} line 2: not valid TOML: ")


def test_check_only_and_from_a_step(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                    monkeypatch: pytest.MonkeyPatch) -> None:
    program = "programs/unimate_pick_and_place.toml"
    monkeypatch.chdir(ROOT)
    assert main(["run", program, "--check", "--from", "4", "--data-dir", str(tmp_path)]) == 0
    # pass 1 from step 4 (7 steps), pass 2 whole (8), then home
    assert capsys.readouterr().out.strip() == (
        f"{program}: checked, 12 steps, 16 to run from step 4 on unimate2000b")
    assert main(["run", program, "--check", "--from", "13", "--data-dir", str(tmp_path)]) == 2
    assert "no step 13: the program has steps 1…12" in capsys.readouterr().err


def test_the_rig_not_zeroed_is_refused_unless_the_program_or_the_option_zeroes_it(
        tmp_path: Path) -> None:
    done = servodesk_run("programs/rig_sequence.toml", "--from", "2", "--lockstep",
                         data_dir=tmp_path)
    assert done.returncode == 2
    assert "--initialise: the Single-axis hydraulic test rig's encoder is not zeroed" in (
        done.stderr)
    assert not list(tmp_path.glob("*.json"))


def test_an_operators_wait_without_a_terminal_is_refused(tmp_path: Path) -> None:
    program = tmp_path / "ask.toml"
    program.write_text('machine = "unimate2000b"\n[[step]]\nwait = "operator"\n',
                       encoding="utf-8")
    done = servodesk_run(str(program), "--check", data_dir=tmp_path)
    assert done.returncode == 2
    assert done.stderr.splitlines()[0] == (
        f"{program} line 2, step 1 (wait for the operator): waits for the operator, and stdin "
        "is not a terminal: run it from a terminal, or wait = SECONDS")


def test_ctrl_c_mid_program_is_an_estop_with_the_run_saved(tmp_path: Path) -> None:
    program = tmp_path / "long.toml"
    program.write_text('machine = "unimate2000b"\n[[step]]\nmove = "step"\njoint = "updown"\n'
                       'target = 5\nduration = 30\nlabel = "long"\n[[step]]\ngo = "home"\n',
                       encoding="utf-8")
    proc = subprocess.Popen([sys.executable, "-m", "app", "run", str(program), "--json",
                             "--data-dir", str(tmp_path)], cwd=ROOT, env=ENV, text=True,
                            stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE)
    try:
        seen = []
        deadline = time.monotonic() + RUN_S
        while not any(line.startswith("  moving: ") for line in seen):
            assert time.monotonic() < deadline and proc.poll() is None, "".join(seen)
            seen.append(proc.stderr.readline())
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=RUN_S)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 1, "".join(seen) + err
    assert "E-stop: every valve closed and latched" in err
    report = json.loads(out)
    assert report["state"] == "failed" and not report["complete"]
    [step] = report["steps"]  # home never ran
    assert step["status"].startswith("estop") and step["run"] is not None
    assert (tmp_path / f"{step['run']}.json").is_file()


def test_a_move_not_in_position_ends_the_program_with_exit_1(tmp_path: Path) -> None:
    """The rig with a goal_time of 0.5 s: a 1,100 mm step whose path lasts 0.3 s cannot be in
    position 0.5 s after it (the ram does 800 mm/s at most), so that step ends unsettled, the
    program ends there (park never runs) and exits 1 with the run saved."""
    machine = tmp_path / "rig.toml"
    machine.write_text((ROOT / "hw" / "machines" / "rig.toml").read_text(encoding="utf-8")
                       .replace("goal_time = 2.0", "goal_time = 0.5"), encoding="utf-8")
    program = tmp_path / "quick.toml"
    program.write_text('machine = "rig"\n[[step]]\nmove = "initialise"\n[[step]]\nmove = "step"\n'
                       'target = 1100\nduration = 0.3\n[[step]]\ngo = "park"\n', encoding="utf-8")
    done = servodesk_run(str(program), "--machine", str(machine), "--lockstep", "--json",
                         data_dir=tmp_path)
    assert done.returncode == 1, done.stderr
    report = json.loads(done.stdout)
    assert report["state"] == "failed" and [s["step"] for s in report["steps"]] == [1, 2]
    step = report["steps"][1]
    assert step["status"].startswith("unsettled") and not step["ok"]
    assert report["reason"].startswith("step 2 (move step): unsettled")
    assert (tmp_path / f"{step['run']}.json").is_file()


def test_an_operators_wait_goes_on_at_enter_on_a_terminal(tmp_path: Path) -> None:
    import pty

    program = tmp_path / "ask.toml"
    program.write_text('machine = "unimate2000b"\n[[step]]\nwait = "operator"\n'
                       'label = "Load the part"\n[[step]]\nwait = 0.1\n', encoding="utf-8")
    terminal, stdin = pty.openpty()
    proc = subprocess.Popen([sys.executable, "-m", "app", "run", str(program), "--lockstep",
                             "--data-dir", str(tmp_path)], cwd=ROOT, text=True, stdin=stdin,
                            env={**ENV, "PYTHONFAULTHANDLER": "1"},  # SIGABRT: its threads
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    os.close(stdin)
    resource.prlimit(proc.pid, resource.RLIMIT_CORE, (0, 0))  # its SIGABRT below: no core file
    try:
        seen = []
        deadline = time.monotonic() + RUN_S
        while "step 1: Load the part: press Enter to go on\n" not in seen:
            assert time.monotonic() < deadline and proc.poll() is None, "".join(seen)
            seen.append(proc.stderr.readline())
        os.write(terminal, b"\n")
        try:
            out, err = proc.communicate(timeout=RUN_S)
        except subprocess.TimeoutExpired:
            proc.send_signal(signal.SIGABRT)  # where every thread of it waits, on its stderr
            out, err = proc.communicate(timeout=30)
            pytest.fail(f"no end within {RUN_S:g} s of the Enter; it said:\n{''.join(seen)}"
                        f"{err}\nand on stdout:\n{out}")
    finally:
        os.close(terminal)
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 0, "".join(seen) + err
    assert "program ask, run " in out and ": done (every step completed)" in out


def test_reduced_speed_runs_the_program_in_t1_and_refuses_a_pulse(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    pulse = tmp_path / "pulse.toml"
    pulse.write_text('machine = "rig"\n[[step]]\nmove = "initialise"\n[[step]]\nmove = "pulse"\n',
                     encoding="utf-8")
    assert main(["run", str(pulse), "--reduced", "--check", "--data-dir", str(tmp_path)]) == 2
    assert capsys.readouterr().err.splitlines()[0] == (
        f"{pulse} line 4, step 2 (move pulse): a pulse is open-loop duty, which reduced speed "
        "cannot hold to 250 mm/s: leave --reduced out to run it")
    program = tmp_path / "go.toml"
    program.write_text('machine = "unimate2000b"\n[[step]]\ngo = "home"\nspeed = 1\n',
                       encoding="utf-8")
    done = servodesk_run(str(program), "--reduced", "--lockstep", "--json", data_dir=tmp_path)
    assert done.returncode == 0, done.stderr
    report = json.loads(done.stdout)
    [step] = report["steps"]
    assert report["speed_mode"] == "reduced" and step["status"] == "complete"
    saved = json.loads((tmp_path / f"{step['run']}.json").read_text())
    assert saved["meta"]["speed_mode"] == "reduced"
