"""Program files read (control/program/parse.py): every step kind, the listing's numbers and
lines, repeats unrolled into visits; every problem of form names its line and step, and
all of them are reported; any text at all ends in a ProgramError or a program."""

from __future__ import annotations

import re
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from control.program import ProgramError, parse_program, visits
from control.program.model import Comment, Feed, GoTo, Line, Move, Repeat, Wait

ROOT = Path(__file__).resolve().parents[3]

EVERY_KIND = """\
name = "every kind"
machine = "unimate2000b"

[positions]
pick = [1300.0, 10.0, 0.0, 0.0, 90.0, 0.0]

[[step]]
go = "home"
speed = 0.8

[[step]]
line = "pick"
speed = 20.0

[[step]]
line = [1500.0, 0.0, 700.0, -180.0, 0.0, -90.0]

[[step]]
move = "step"
joint = "Up/Down"
target = 10.0

[[step]]
wait = 1.5

[[step]]
wait = "operator"
label = "Load the part"

[[step]]
feed = 50

[[step]]
repeat = 2

[[step.steps]]
go = "pick"

[[step.steps]]
comment = "inside"

[[step]]
comment = "the end"
"""


def problems_of(text: str) -> list[str]:
    with pytest.raises(ProgramError) as caught:
        parse_program(text, "p.toml")
    return [str(p) for p in caught.value.problems]


def test_every_step_kind_is_read_with_its_number_line_and_fields() -> None:
    program = parse_program(EVERY_KIND, "p.toml")
    listing = [(step.number, type(step), step.line, depth) for step, depth in program.listing()]
    assert listing == [(1, GoTo, 7, 0), (2, Line, 11, 0), (3, Line, 15, 0), (4, Move, 18, 0),
                       (5, Wait, 23, 0), (6, Wait, 26, 0), (7, Feed, 30, 0),
                       (8, Repeat, 33, 0), (9, GoTo, 36, 1), (10, Comment, 39, 1),
                       (11, Comment, 42, 0)]
    go, line, pose, move, wait, operator, feed, repeat, inner, _, comment = (
        s for s, _ in program.listing())
    assert (go.position, go.speed) == ("home", 0.8)
    assert (line.position, line.speed) == ("pick", 20.0)
    assert pose.pose == (1500.0, 0.0, 700.0, -180.0, 0.0, -90.0) and pose.speed is None
    assert (move.kind, dict(move.fields)) == ("step", {"joint": "Up/Down", "target": 10.0})
    assert move.key_line("target") == 21
    assert (wait.seconds, wait.operator) == (1.5, False)
    assert operator.operator and operator.title == "Load the part"
    assert feed.percent == 50.0
    assert repeat.count == 2 and repeat.steps == (inner, program.step(10))
    assert comment.text == "the end"
    assert program.positions == {"pick": (1300.0, 10.0, 0.0, 0.0, 90.0, 0.0)}
    assert (program.name, program.machine) == ("every kind", "unimate2000b")


def test_repeats_unroll_into_visits_and_a_start_inside_one_runs_its_later_passes_whole(
        ) -> None:
    program = parse_program(EVERY_KIND, "p.toml")
    assert [v.where for v in visits(program)] == [
        "step 1", "step 2", "step 3", "step 4", "step 5", "step 6", "step 7",
        "step 9, pass 1", "step 9, pass 2"]
    assert [v.where for v in visits(program, 9)] == ["step 9, pass 1", "step 9, pass 2"]
    assert [v.where for v in visits(program, 7)] == ["step 7", "step 9, pass 1", "step 9, pass 2"]
    with pytest.raises(ValueError, match="no step 12: the program has steps 1…11"):
        visits(program, 12)


def test_nested_repeats_start_from_an_inner_step() -> None:
    text = """machine = "rig"
[[step]]
repeat = 2
[[step.steps]]
wait = 1
[[step.steps]]
repeat = 3
[[step.steps.steps]]
wait = 2
[[step]]
wait = 3
"""
    program = parse_program(text, "n.toml")
    assert [s.line for s, _ in program.listing()] == [2, 4, 6, 8, 10]
    assert len(visits(program)) == 2 * (1 + 3) + 1
    assert [v.where for v in visits(program, 4)] == [
        "step 4, pass 1/1", "step 4, pass 1/2", "step 4, pass 1/3",
        "step 2, pass 2", "step 4, pass 2/1", "step 4, pass 2/2", "step 4, pass 2/3", "step 5"]


def test_malformed_toml_names_its_line() -> None:
    [problem] = problems_of('machine = "rig"\n\n[[step]]\nwait 1\n')
    assert problem.startswith("p.toml line 4: not valid TOML: ")
    assert "(column" in problem


def test_every_problem_of_form_is_reported_with_its_line_and_step() -> None:
    text = """machine = "unimate2000b"
colour = "red"

[positions]
bad = ["a"]

[[step]]
go = ""

[[step]]
go = "home"
wait = 2

[[step]]
label = "nothing"

[[step]]
move = "twirl"

[[step]]
move = "step"
target = 5
speeed = 3

[[step]]
wait = -1

[[step]]
wait = "later"

[[step]]
feed = 0

[[step]]
repeat = 1.5
[[step.steps]]
comment = 3

[[step]]
line = [1, 2]

[[step]]
go = "home"
speed = 2
"""
    assert problems_of(text) == [
        "p.toml line 2: unknown key 'colour': a program has name, machine, [positions] and "
        "[[step]] tables",
        "p.toml line 5: position 'bad': give a list of numbers, one per joint (mm, deg)",
        'p.toml line 8, step 1 (step): go = "NAME": the position to go to',
        "p.toml line 10: step 2: a step has one of go, line, move, wait, feed, repeat, "
        "comment; this one has go and wait",
        "p.toml line 14: step 3: a step has one of go, line, move, wait, feed, repeat, "
        "comment; this one has none",
        "p.toml line 18, step 4 (step): move = 'twirl': the kinds are step, ramp, sine, "
        "multistep, endpoint, path, via, goto, pulse, initialise",
        "p.toml line 23, step 5 (move step): unknown key 'speeed' for a move step; it takes "
        "duration, joint, label, move, start, target",
        "p.toml line 26, step 6 (step): wait -1 s is out of range: it must be more than 0 s "
        "and at most 600 s",
        "p.toml line 29, step 7 (step): wait: 'later' is not a number; write digits such as "
        "12.5",
        "p.toml line 32, step 8 (step): feed override 0 % is out of range: it must be more "
        "than 0 % and at most 100 %",
        "p.toml line 35, step 9 (step): repeat count: enter a whole number, not 1.5",
        'p.toml line 37, step 10 (step): comment = "TEXT"',
        'p.toml line 40, step 11 (step): line = "NAME" (a position) or line = [x, y, z, γ, '
        "β, α] (mm, deg)",
        "p.toml line 44, step 12 (go to 'home'): speed fraction 2 is outside 0.05…1; enter a "
        "value in that range",
    ]


def test_a_program_without_machine_or_steps_says_what_it_needs() -> None:
    assert problems_of("") == [
        'p.toml line 1: machine = "unimate2000b" (or "rig"): say which machine the program '
        "is for",
        "p.toml: no steps: add [[step]] tables (docs/programs.md)"]


def test_a_file_that_cannot_be_read_is_one_problem(tmp_path: Path) -> None:
    from control.program import read_program

    with pytest.raises(ProgramError, match=r"missing\.toml: cannot read it: No such file"):
        read_program(tmp_path / "missing.toml")
    (tmp_path / "latin.toml").write_bytes(b'machine = "rig"  # caf\xe9\n')
    with pytest.raises(ProgramError, match=r"latin\.toml: not UTF-8 text .* at byte 22"):
        read_program(tmp_path / "latin.toml")


def test_the_documented_steps_are_read() -> None:
    """Every TOML example of docs/programs.md is a program (with a machine where a snippet
    has none), so the documentation cannot drift from the parser."""
    doc = (ROOT / "docs" / "programs.md").read_text(encoding="utf-8")
    blocks = [b for b in re.findall(r"```toml\n(.*?)```", doc, re.S) if "[[step]]" in b]
    assert len(blocks) >= 8
    for block in blocks:
        text = block if "machine =" in block else 'machine = "unimate2000b"\n' + block
        assert parse_program(text, "doc.toml").steps


@settings(deadline=None)  # a loaded two-core machine stalls any example now and then
@given(st.text(max_size=300))
def test_any_text_is_a_program_or_a_program_error(text: str) -> None:
    try:
        program = parse_program(text, "any.toml")
    except ProgramError as exc:
        assert exc.problems and all(str(p).startswith("any.toml") for p in exc.problems)
    else:
        assert program.steps


step_tables = st.recursive(
    st.sampled_from(['wait = 1', 'feed = 50', 'go = "home"', 'comment = "c"',
                     'move = "initialise"']).map(lambda body: ("leaf", body)),
    lambda inner: st.tuples(st.integers(1, 3), st.lists(inner, min_size=1, max_size=3)),
    max_leaves=8)


def _toml(tree: object, path: str = "step") -> str:
    if tree[0] == "leaf":
        return f"[[{path}]]\n{tree[1]}\n"
    count, children = tree
    return (f"[[{path}]]\nrepeat = {count}\n"
            + "".join(_toml(child, path + ".steps") for child in children))


def _visits(tree: object) -> int:
    if tree[0] == "leaf":
        return 0 if "comment" in tree[1] else 1
    count, children = tree
    return count * sum(_visits(c) for c in children)


@settings(deadline=None)  # a loaded two-core machine stalls any example now and then
@given(st.lists(step_tables, min_size=1, max_size=3))
def test_repeats_of_any_shape_unroll_to_count_times_their_steps(trees: list) -> None:
    text = 'machine = "rig"\n' + "".join(_toml(t) for t in trees)
    program = parse_program(text, "r.toml")
    assert len(visits(program)) == sum(_visits(t) for t in trees)
    headers = [n for n, line in enumerate(text.splitlines(), 1) if line.startswith("[[")]
    assert [s.line for s, _ in program.listing()] == headers
