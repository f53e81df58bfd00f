"""The check of a whole program on a machine (control/program/check.py): each step planned
from the end of the one before, with the forms' rules and the acceptance rules; every
problem reported with its line and step (once, however many passes repeat it)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from control.motion.positions import PositionBook
from control.program import ProgramError, check, parse_program
from hw.machine import load_machine

UNIMATE = load_machine("unimate2000b")
RIG = load_machine("rig")
HOME = np.array(UNIMATE.home)
BOOK = PositionBook(UNIMATE)


def checked(text: str, machine=UNIMATE, book: PositionBook | None = None, here=None,
            start: int = 1, source: str = "p.toml"):
    program = parse_program(text, source)
    return check(program, machine, book or PositionBook(machine),
                 np.array(machine.home) if here is None else here, start=start)


def problems(text: str, machine=UNIMATE, source: str = "p.toml", **kw) -> list[str]:
    with pytest.raises(ProgramError) as caught:
        checked(text, machine, source=source, **kw)
    return [str(p) for p in caught.value.problems]


def test_each_step_is_planned_from_where_the_one_before_ends() -> None:
    """In/Out ramps to 1300 mm in 0.2 s: nothing to do after going home (In/Out at 1300),
    1,500 mm/s after going to park (1000 mm): refused there, naming the step."""
    ramp = '[[step]]\nmove = "ramp"\njoint = "inout"\nend = 1300\nramp_time = 0.2\n'
    after_home = checked('machine = "unimate2000b"\n[[step]]\ngo = "home"\n' + ramp)
    assert after_home.ends[-1][0] == pytest.approx(1300.0)
    [problem] = problems('machine = "unimate2000b"\n[[step]]\ngo = "park"\n' + ramp,
                         here=HOME)
    assert problem.startswith("p.toml line 4, step 2 (move ramp): ")
    assert "In/Out" in problem


def test_a_missing_position_lists_those_there_are_and_the_program_file_fills_the_book(
        ) -> None:
    text = """machine = "unimate2000b"
[positions]
pick = [1300.0, 10.0, 0.0, 0.0, 90.0, 0.0]

[[step]]
go = "pick"

[[step]]
label = "to the place"
go = "place"
"""
    assert problems(text) == [
        "p.toml line 10, step 2 (to the place): no taught position 'place' — taught: home, "
        "park, pick"]
    ok = checked(text.replace('"place"', '"pick"'))
    assert ok.ends[0] == pytest.approx([1300.0, 10.0, 0.0, 0.0, 90.0, 0.0])
    taught = BOOK.teach("pick", (1250.0, 5.0, 0.0, 0.0, 90.0, 0.0))  # the book's comes first
    assert checked(text.replace('"place"', '"pick"'), book=taught).ends[0][0] == 1250.0


def test_every_problem_on_the_machine_is_reported_once_with_its_line_and_step(
        tmp_path: Path) -> None:
    (tmp_path / "bad.csv").write_text("t,In/Out\n0,1300\n1,banana\n", encoding="utf-8")
    text = f"""machine = "unimate2000b"
[positions]
far = [5000.0, 0.0, 0.0, 0.0, 90.0, 0.0]

[[step]]
repeat = 3
[[step.steps]]
move = "step"
joint = "Up/Down"
target = 40

[[step]]
move = "path"
file = "{tmp_path / 'missing.csv'}"

[[step]]
move = "path"
file = "bad.csv"

[[step]]
line = [9000.0, 0.0, 0.0, 0.0, 0.0, 0.0]

[[step]]
line = "home"
speed = 500

[[step]]
move = "initialise"

[[step]]
move = "multistep"
targets = [1, 2]
"""
    found = problems(text, source=str(tmp_path / "p.toml"))
    assert [p.split(": ", 1)[0] for p in found] == [
        f"{tmp_path}/p.toml line 3",
        f"{tmp_path}/p.toml line 10, step 2 (move step)",
        f"{tmp_path}/p.toml line 14, step 3 (move path)",
        f"{tmp_path}/p.toml line 18, step 4 (move path)",
        f"{tmp_path}/p.toml line 21, step 5 (line to (9000, 0, 0, 0, 0, 0))",
        f"{tmp_path}/p.toml line 25, step 6 (line to 'home')",
        f"{tmp_path}/p.toml line 28, step 7 (move initialise)",
        f"{tmp_path}/p.toml line 32, step 8 (move multistep)"]
    far, target, missing, bad, reach, speed, initialise, targets = found
    assert "position 'far': In/Out target 5000" in far
    assert "Up/Down target 40° is outside -27…30°" in target  # once, not once a pass
    assert "missing.csv" in missing and "banana" in bad and "line 3" in bad
    assert "joint limit: In/Out would be 2041.0 mm, past its limits" in reach
    assert "line speed 500 mm/s" in speed and "at most 25 mm/s" in speed
    assert "encoders are absolute" in initialise
    assert "give 6 numbers in joint order" in targets


def test_a_line_to_a_position_on_another_branch_is_refused() -> None:
    """Rotate turned by 180° with the arm reaching back reaches a pose the straight line can
    reach only on the branch it starts on: the taught joints are not where it would end."""
    text = """machine = "unimate2000b"
[positions]
flipped = [1300.0, 0.0, 0.0, 0.0, -90.0, 180.0]
[[step]]
line = "flipped"
"""
    [problem] = problems(text)
    assert problem.startswith("p.toml line 5, step 1 (line to 'flipped'): ")


def test_a_line_on_the_rig_and_a_program_for_another_machine_are_refused() -> None:
    [line] = problems('machine = "rig"\n[[step]]\nline = "home"\n', RIG)
    assert line.startswith("p.toml line 3, step 1 (line to 'home'): machine rig has no "
                           "unimate2000b kinematics")
    [other] = problems('machine = "rig"\n[[step]]\nwait = 1\n', UNIMATE)
    assert other == ("p.toml line 1: the program is for machine 'rig', not 'unimate2000b': "
                     "run it with --machine rig")


def test_the_rig_initialise_ends_on_the_bottom_stop_and_a_pulse_leaves_the_position() -> None:
    text = """machine = "rig"
[[step]]
move = "initialise"
[[step]]
move = "pulse"
duty = 10
[[step]]
move = "step"
target = 300
"""
    ok = checked(text, RIG)
    assert ok.ends[:, 0].tolist() == [0.0, 0.0, 300.0]


def test_a_check_from_a_later_step_plans_only_from_there() -> None:
    text = """machine = "unimate2000b"
[[step]]
go = "nowhere"
[[step]]
go = "park"
"""
    assert len(problems(text)) == 1
    later = checked(text, start=2)
    assert [v.where for v in later.visits] == ["step 2"] and later.start == 2
    with pytest.raises(ProgramError, match="no step 3: the program has steps 1…2"):
        checked(text, start=3)


def test_the_examples_pass_their_check() -> None:
    root = Path(__file__).resolve().parents[3] / "programs"
    from control.program import read_program

    for name, machine in (("rig_sequence.toml", RIG),
                          ("unimate_pick_and_place.toml", UNIMATE)):
        program = read_program(root / name)
        ok = check(program, machine, PositionBook(machine), np.array(machine.home))
        assert len(ok.visits) > 5
