"""A program as read from its file: steps in order, each a frozen record that knows its file
line and its number in the listing (``docs/programs.md``).

Numbers count every step of the file in the order written, a repeat's own steps after it
(the listing a Program tab shows, indented): ``number`` is what a problem, a result and
``--from`` name. ``Visit`` is one execution of a step: a repeat's steps are visited once a
pass, so one step may have several visits, told apart by ``passes``.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType

OPERATOR = "operator"  # wait = "operator": until the operator says go on



def _empty() -> Mapping:
    return MappingProxyType({})


@dataclass(frozen=True)
class Step:
    """What every step has: its number in the listing (from 1), the file line of its table,
    the line of each of its keys, and the operator's label for it ('' for none)."""

    number: int
    line: int
    label: str = ""
    keys: Mapping[str, int] = field(default_factory=_empty, compare=False)

    def key_line(self, key: str) -> int:
        """The line of ``key`` in this step's table, else the table's own."""
        return self.keys.get(key, self.line)

    @property
    def title(self) -> str:
        return self.label or self.describe()

    def describe(self) -> str:
        return "step"


@dataclass(frozen=True)
class GoTo(Step):
    """Joint space to a named position (taught, the program's, or home/park) at ``speed``
    of every joint's max speed and acceleration, as the Positions tab's go."""

    position: str = ""
    speed: float = 0.5

    def describe(self) -> str:
        return f"go to {self.position!r}"


@dataclass(frozen=True)
class Line(Step):
    """The tool on a straight line to a named position's pose, or to ``pose`` (x y z mm,
    γ β α deg), at ``speed`` mm/s, on the branch the arm is on (Unimate)."""

    position: str = ""
    pose: tuple[float, ...] = ()
    speed: float | None = None

    def describe(self) -> str:
        to = repr(self.position) if self.position else "(" + ", ".join(
            f"{v:g}" for v in self.pose) + ")"
        return f"line to {to}"


@dataclass(frozen=True)
class Move(Step):
    """One Moves kind (``kind``) with its form's fields as the file gives them, checked by
    the forms' rules when it is planned (``control.program.move_steps``)."""

    kind: str = ""
    fields: Mapping[str, object] = field(default_factory=_empty)

    def describe(self) -> str:
        return f"move {self.kind}"


@dataclass(frozen=True)
class Wait(Step):
    """Wait ``seconds``, or until the operator goes on (``operator``)."""

    seconds: float | None = None

    @property
    def operator(self) -> bool:
        return self.seconds is None

    def describe(self) -> str:
        return "wait for the operator" if self.operator else f"wait {self.seconds:g} s"


@dataclass(frozen=True)
class Feed(Step):
    """Set the feed override to ``percent`` of each path's speed, for the moves after."""

    percent: float = 100.0

    def describe(self) -> str:
        return f"feed {self.percent:g} %"


@dataclass(frozen=True)
class Comment(Step):
    """Words for the operator in the listing; running it does nothing."""

    text: str = ""

    def describe(self) -> str:
        return f"# {self.text}"


@dataclass(frozen=True)
class Repeat(Step):
    """``steps`` ``count`` times over."""

    count: int = 1
    steps: tuple[Step, ...] = ()

    def describe(self) -> str:
        return f"repeat {self.count} times"


@dataclass(frozen=True)
class Program:
    """A program: its name, machine, file, steps, the positions its file carries
    (``name → joints``; used where the data directory's book lacks the name), and the lines
    of its top keys."""

    name: str
    machine: str
    source: Path
    steps: tuple[Step, ...]
    positions: Mapping[str, tuple[float, ...]] = field(default_factory=_empty)
    lines: Mapping[str, int] = field(default_factory=_empty, compare=False)  # key → line; positions
    # under "positions.NAME"

    def listing(self) -> list[tuple[Step, int]]:
        """Every step with its depth (0 at the top), in number order."""
        return list(_listing(self.steps, 0))

    def step(self, number: int) -> Step:
        for step, _ in self.listing():
            if step.number == number:
                return step
        raise ValueError(f"no step {number}: the program has steps 1…{self.count}")

    @property
    def count(self) -> int:
        return len(self.listing())


def _listing(steps: tuple[Step, ...], depth: int) -> Iterator[tuple[Step, int]]:
    for step in steps:
        yield step, depth
        if isinstance(step, Repeat):
            yield from _listing(step.steps, depth + 1)


@dataclass(frozen=True)
class Visit:
    """One execution of ``step``: ``passes`` holds the pass (from 1) of each repeat around it,
    outermost first; ``index`` its place in the run's order (from 0)."""

    index: int
    step: Step
    passes: tuple[int, ...] = ()

    @property
    def where(self) -> str:
        """``step 4`` or ``step 4, pass 2``."""
        passes = "/".join(str(p) for p in self.passes)
        return f"step {self.step.number}" + (f", pass {passes}" if passes else "")


def visits(program: Program, start: int = 1) -> list[Visit]:
    """The run's order of step executions, repeats unrolled, from step ``start``: a step
    inside a repeat starts that repeat's first pass there, and its later passes run whole.
    Repeats and comments are not visited themselves (nothing to run)."""
    program.step(start)  # ValueError naming the steps there are
    out: list[Visit] = []
    _unroll(program.steps, (), start, out)
    return out


def _unroll(steps: tuple[Step, ...], passes: tuple[int, ...], start: int,
            out: list[Visit]) -> None:
    for step in steps:
        last = _last_number(step)
        if last < start:
            continue  # wholly before the start
        if isinstance(step, Repeat):
            for n in range(1, step.count + 1):
                _unroll(step.steps, (*passes, n), start if n == 1 else 0, out)
        elif not isinstance(step, Comment) and step.number >= start:
            out.append(Visit(len(out), step, passes))


def _last_number(step: Step) -> int:
    if isinstance(step, Repeat) and step.steps:
        return _last_number(step.steps[-1])
    return step.number
