"""Programs written back (control/program/dump.py) read back to the same steps: the
examples, every kind, and programs of any shape (hypothesis)."""

from __future__ import annotations

from pathlib import Path

from hypothesis import given, settings
from hypothesis import strategies as st

from control.program import Program, parse_program, read_program
from control.program.dump import dump_program
from tests.control.program.test_parse import EVERY_KIND

ROOT = Path(__file__).resolve().parents[3]


def shape(program: Program) -> list[tuple]:
    """What a program says, without where its file said it."""
    out = []
    for step, depth in program.listing():
        fields = {k: v for k, v in vars(step).items() if k not in ("line", "keys", "steps")}
        out.append((type(step).__name__, depth, sorted(fields.items(), key=str)))
    return out


def again(program: Program) -> Program:
    return parse_program(dump_program(program), "again.toml")


def test_the_examples_and_every_kind_read_back_the_same() -> None:
    programs = [read_program(p) for p in sorted((ROOT / "programs").glob("*.toml"))]
    programs.append(parse_program(EVERY_KIND, "p.toml"))
    for program in programs:
        back = again(program)
        assert shape(back) == shape(program)
        assert (back.name, back.machine, dict(back.positions)) == (
            program.name, program.machine, dict(program.positions))


text = st.text(st.characters(blacklist_categories=("Cs",)), min_size=1, max_size=12).filter(
    str.strip)
numbers = st.floats(-1e6, 1e6, allow_nan=False).map(lambda v: round(v, 3))


def repr_toml(text: str) -> str:
    """A TOML basic string, every character that is not plain printed as an escape."""
    return '"' + "".join(c if c.isprintable() and c not in '"\\' else f"\\U{ord(c):08x}"
                         for c in text) + '"'


leaf = st.one_of(
    st.builds(lambda n, s: f"go = {n}\nspeed = {s}", text.map(repr_toml),
              st.sampled_from([0.05, 0.5, 1.0])),
    st.builds(lambda v: f"wait = {v}", st.sampled_from([0.1, 2.0, '"operator"'])),
    st.builds(lambda v: f"feed = {v}", st.sampled_from([1, 50.5, 100])),
    st.builds(lambda t: f"comment = {repr_toml(t)}", text),
    st.builds(lambda j, t: f'move = "step"\njoint = {repr_toml(j)}\ntarget = {t}', text,
              numbers),
    st.builds(lambda p: "line = [" + ", ".join(map(str, p)) + "]",
              st.lists(numbers, min_size=6, max_size=6)),
)
trees = st.recursive(leaf, lambda inner: st.tuples(st.integers(1, 5),
                                                   st.lists(inner, min_size=1, max_size=3)),
                     max_leaves=6)


def _toml(tree: object, table: str = "step") -> str:
    if isinstance(tree, str):
        return f"[[{table}]]\n{tree}\n"
    count, children = tree
    return f"[[{table}]]\nrepeat = {count}\n" + "".join(_toml(c, table + ".steps")
                                                       for c in children)


@settings(deadline=None)  # a loaded two-core machine stalls any example now and then
@given(st.lists(trees, min_size=1, max_size=3), text)
def test_programs_of_any_shape_read_back_the_same(steps: list, label: str) -> None:
    source = 'machine = "rig"\n' + "".join(_toml(t) for t in steps)
    source = source.replace("[[step]]\n", f"[[step]]\nlabel = {repr_toml(label[:80])}\n", 1)
    program = parse_program(source, "any.toml")
    assert shape(again(program)) == shape(program)
