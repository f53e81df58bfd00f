"""A program file (TOML, ``docs/programs.md``) read into a ``Program``, every problem of its
form collected (``ProgramError``), each naming its line and step.

What the file's values mean on a machine (a position taught, a target in limits, a field
by the forms' rules) is the checker's (``control.program.check``); here: TOML, the keys,
one kind a step, the types of the keys a step of that kind takes.
"""

from __future__ import annotations

import re
import tomllib
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from types import MappingProxyType
from typing import Any

from control.motion.fields import FieldError, NumberRule, count_rule, seconds_rule
from control.program.model import (
    OPERATOR,
    Comment,
    Feed,
    GoTo,
    Line,
    Move,
    Program,
    Repeat,
    Step,
    Wait,
)

MAX_BYTES = 1 << 20  # a program is text a person writes: a megabyte is plenty
MAX_REPEAT = 1000
MAX_LABEL = 80  # characters: a label fits the Program tab's step column
GO_SPEEDS = (0.05, 1.0)  # the speed fraction a go may ask for (the Positions tab's)
KINDS = ("go", "line", "move", "wait", "feed", "repeat", "comment")
# The Moves forms' fields a ``move`` step of each kind takes (servodesk move's options)
MOVE_FIELDS: Mapping[str, frozenset[str]] = MappingProxyType({
    "step": frozenset({"joint", "start", "target", "duration"}),
    "ramp": frozenset({"joint", "start", "end", "ramp_time", "total"}),
    "sine": frozenset({"joint", "start", "end", "period", "duration"}),
    "multistep": frozenset({"targets", "sequence", "duration"}),
    "endpoint": frozenset({"x", "y", "z", "gamma", "beta", "alpha", "solution", "ramp_time"}),
    "path": frozenset({"file"}),
    "via": frozenset({"points", "cartesian", "speed"}),
    "goto": frozenset({"targets", "speed"}),
    "pulse": frozenset({"duty", "duration"}),
    "initialise": frozenset(),
})
_STEP_KEYS = {"go": {"speed"}, "line": {"speed"}, "wait": set(), "feed": set(),
              "repeat": {"steps"}, "comment": set()}
_STEP_HEADER = re.compile(r"^\s*\[\[\s*step(\s*\.\s*steps)*\s*\]\]\s*(#.*)?$")
_TABLE = re.compile(r"^\s*\[\[?\s*([^\]]+?)\s*\]\]?\s*(#.*)?$")
_KEY = re.compile(r"^\s*([\w-]+|\"[^\"]*\")\s*=")
_TOML_AT = re.compile(r"\s*\(at line (\d+), column (\d+)\)")
FEED_RULE = NumberRule("feed override", " %", 0.0, 100.0, strict_low=True)


@dataclass(frozen=True)
class Problem:
    """One thing wrong with a program: its file line (0: not known), its step (None: the
    program as a whole) and what is wrong and how to fix it."""

    source: str
    line: int
    text: str
    step: Step | None = None

    def __str__(self) -> str:
        at = f" line {self.line}" if self.line else ""
        step = f", step {self.step.number} ({self.step.title})" if self.step is not None else ""
        return f"{self.source}{at}{step}: {self.text}"


class ProgramError(ValueError):
    """A program cannot run; ``problems`` lists every reason, each naming its line and step."""

    def __init__(self, problems: list[Problem]) -> None:
        super().__init__("\n".join(str(p) for p in problems))
        self.problems = tuple(problems)


def read_program(path: str | Path) -> Program:
    """The program in the file ``path``; ProgramError for anything wrong with its form."""
    path = Path(path)
    try:
        if path.stat().st_size > MAX_BYTES:
            raise ProgramError([Problem(str(path), 0, f"larger than {MAX_BYTES >> 10} KiB: not "
                                                      "a program file")])
        text = path.read_text(encoding="utf-8")
    except UnicodeDecodeError as exc:
        raise ProgramError([Problem(str(path), 0, f"not UTF-8 text ({exc.reason} at byte "
                                                  f"{exc.start}): save it as UTF-8")]) from None
    except OSError as exc:
        raise ProgramError([Problem(str(path), 0, f"cannot read it: "
                                                  f"{exc.strerror or exc}")]) from None
    return parse_program(text, str(path))


def parse_program(text: str, source: str = "<program>") -> Program:
    """The program in ``text`` (``source`` names it in problems)."""
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        at = _TOML_AT.search(str(exc))
        line = int(at.group(1)) if at else 0
        what = _TOML_AT.sub("", str(exc))
        column = f" (column {at.group(2)})" if at else ""
        raise ProgramError([Problem(source, line, f"not valid TOML: {what}{column}")]) from None
    reader = _Reader(source, _Lines(text))
    program = reader.program(doc, Path(source))
    if reader.problems:
        raise ProgramError(reader.problems)
    return program


class _Lines:
    """Where the step tables and the keys are: the n-th ``[[step…]]`` header is the n-th
    step in the listing (TOML puts a repeat's steps after it), with the keys under it."""

    def __init__(self, text: str) -> None:
        self.top: dict[str, int] = {}
        self.steps: list[dict[str, int]] = []
        self.positions: dict[str, int] = {}
        section: dict[str, int] | None = self.top
        for n, line in enumerate(text.splitlines(), 1):
            if _STEP_HEADER.match(line):
                self.steps.append({"": n})
                section = self.steps[-1]
            elif table := _TABLE.match(line):
                name = table.group(1).strip("\"' ")
                self.top.setdefault(name.split(".")[0].strip(), n)
                section = self.positions if name == "positions" else None
            elif section is not None and (key := _KEY.match(line)):
                section.setdefault(key.group(1).strip('"'), n)


@dataclass
class _Reader:
    source: str
    lines: _Lines
    problems: list[Problem] = field(default_factory=list)
    count: int = 0

    def fail(self, line: int, text: str, step: Step | None = None) -> None:
        self.problems.append(Problem(self.source, line, text, step))

    def program(self, doc: dict[str, Any], path: Path) -> Program:
        top = self.lines.top
        for key in sorted(set(doc) - {"name", "machine", "positions", "step"}):
            self.fail(top.get(key, 0), f"unknown key {key!r}: a program has name, machine, "
                                       "[positions] and [[step]] tables")
        name = doc.get("name", path.stem)
        if not isinstance(name, str) or not name.strip():
            self.fail(top.get("name", 0), "name must be a non-empty string")
            name = path.stem
        machine = doc.get("machine")
        if not isinstance(machine, str) or not machine:
            self.fail(top.get("machine", 1), 'machine = "unimate2000b" (or "rig"): say which '
                                             "machine the program is for")
            machine = ""
        positions = self.positions(doc.get("positions", {}))
        steps = doc.get("step")
        if not isinstance(steps, list) or not steps:
            self.fail(top.get("step", 0), "no steps: add [[step]] tables (docs/programs.md)")
            steps = []
        if len(self.lines.steps) != _count(steps):  # tables spelt inline: no lines known
            self.lines.steps = []
        lines = {**self.lines.top,
                 **{f"positions.{k}": n for k, n in self.lines.positions.items()}}
        return Program(name.strip(), machine, path, self.steps(steps), positions,
                       MappingProxyType(lines))

    def positions(self, table: object) -> Mapping[str, tuple[float, ...]]:
        out: dict[str, tuple[float, ...]] = {}
        line = self.lines.top.get("positions", 0)
        if not isinstance(table, dict):
            self.fail(line, "positions must be a table: [positions] then name = [joints…]")
            return MappingProxyType(out)
        for name, joints in table.items():
            at = self.lines.positions.get(name, line)
            if not (isinstance(joints, list) and joints and all(_number(v) for v in joints)):
                self.fail(at, f"position {name!r}: give a list of numbers, one per joint "
                              "(mm, deg)")
                continue
            out[name] = tuple(float(v) for v in joints)
        return MappingProxyType(out)

    def steps(self, tables: list[object]) -> tuple[Step, ...]:
        out = []
        for table in tables:
            self.count += 1
            number = self.count
            keys = (self.lines.steps[number - 1] if number <= len(self.lines.steps) else {})
            line = keys.get("", 0)
            if not isinstance(table, dict):
                self.fail(line, f"step {number}: a step is a table ([[step]])")
                continue
            step = self.step(table, Step(number, line, keys=MappingProxyType(keys)))
            if step is not None:
                out.append(step)
        return tuple(out)

    def step(self, table: dict[str, Any], base: Step) -> Step | None:
        kinds = [k for k in KINDS if k in table]
        if len(kinds) != 1:
            what = "none" if not kinds else " and ".join(kinds)
            self.fail(base.line, f"step {base.number}: a step has one of "
                                 f"{', '.join(KINDS)}; this one has {what}")
            if "steps" in table and isinstance(table["steps"], list):
                self.steps(table["steps"])  # numbered all the same: the listing stays put
            return None
        kind = kinds[0]
        label = table.get("label", "")
        if not isinstance(label, str) or len(label) > MAX_LABEL:
            self.fail(base.key_line("label"), f"step {base.number}: label must be text of at "
                                              f"most {MAX_LABEL} characters")
            label = ""
        base = Step(base.number, base.line, label.strip(), base.keys)
        allowed = ({kind, "label"} | (MOVE_FIELDS.get(str(table["move"]), frozenset())
                                      if kind == "move" else _STEP_KEYS[kind]))
        first = len(self.problems)
        unknown_kind = kind == "move" and table["move"] not in MOVE_FIELDS  # said once, below
        for key in sorted(set(table) - allowed) if not unknown_kind else ():
            self.fail(base.key_line(key), f"unknown key {key!r} for a {kind} step; it takes "
                                          f"{', '.join(sorted(allowed))}", base)
        step = getattr(self, f"_{kind}")(table, base)
        if step is not None:  # its problems name it as what it is ("go to 'place'")
            self.problems[first:] = [replace(p, step=step) if p.step is base else p
                                     for p in self.problems[first:]]
        return step

    def _go(self, table: dict[str, Any], base: Step) -> Step | None:
        name = table["go"]
        if not isinstance(name, str) or not name.strip():
            self.fail(base.key_line("go"), 'go = "NAME": the position to go to', base)
            return None
        speed = self.rule(table, "speed", NumberRule("speed fraction", "", *GO_SPEEDS), base,
                          0.5)
        return GoTo(base.number, base.line, base.label, base.keys, name.strip(), speed)

    def _line(self, table: dict[str, Any], base: Step) -> Step | None:
        to = table["line"]
        step = Line(base.number, base.line, base.label, base.keys)
        if isinstance(to, str) and to.strip():
            step = Line(base.number, base.line, base.label, base.keys, position=to.strip())
        elif isinstance(to, list) and len(to) == 6 and all(_number(v) for v in to):
            step = Line(base.number, base.line, base.label, base.keys,
                        pose=tuple(float(v) for v in to))
        else:
            self.fail(base.key_line("line"), 'line = "NAME" (a position) or line = [x, y, z, '
                                             "γ, β, α] (mm, deg)", base)
            return None
        if "speed" in table:  # the machine's Cartesian speed bounds it: checked there
            speed = table["speed"]
            if not _number(speed):
                self.fail(base.key_line("speed"), "speed: a number of mm/s", base)
                return None
            return Line(step.number, step.line, step.label, step.keys, step.position,
                        step.pose, float(speed))
        return step

    def _move(self, table: dict[str, Any], base: Step) -> Step | None:
        kind = table["move"]
        if kind not in MOVE_FIELDS:
            self.fail(base.key_line("move"), f"move = {kind!r}: the kinds are "
                                             f"{', '.join(MOVE_FIELDS)}", base)
            return None
        fields = {k: v for k, v in table.items() if k not in ("move", "label")}
        return Move(base.number, base.line, base.label, base.keys, kind,
                    MappingProxyType(fields))

    def _wait(self, table: dict[str, Any], base: Step) -> Step | None:
        if table["wait"] == OPERATOR:
            return Wait(base.number, base.line, base.label, base.keys, None)
        seconds = self.rule(table, "wait", seconds_rule("wait"), base, None)
        if seconds is None:
            return None
        return Wait(base.number, base.line, base.label, base.keys, seconds)

    def _feed(self, table: dict[str, Any], base: Step) -> Step | None:
        percent = self.rule(table, "feed", FEED_RULE, base, None)
        if percent is None:
            return None
        return Feed(base.number, base.line, base.label, base.keys, percent)

    def _repeat(self, table: dict[str, Any], base: Step) -> Step | None:
        count = self.rule(table, "repeat", count_rule("repeat count", MAX_REPEAT), base, None)
        inner = table.get("steps")
        if not isinstance(inner, list) or not inner:
            self.fail(base.line, "a repeat needs its steps: [[step.steps]] tables after it",
                      base)
            inner = []
        steps = self.steps(inner)
        if count is None or not steps:
            return None
        return Repeat(base.number, base.line, base.label, base.keys, int(count), steps)

    def _comment(self, table: dict[str, Any], base: Step) -> Step | None:
        text = table["comment"]
        if not isinstance(text, str):
            self.fail(base.key_line("comment"), 'comment = "TEXT"', base)
            return None
        return Comment(base.number, base.line, base.label, base.keys, text.strip())

    def rule(self, table: dict[str, Any], key: str, rule: NumberRule, base: Step,
             default: float | None) -> float | None:
        """``table[key]`` by the forms' ``rule``; ``default`` when absent; None (and the
        problem noted) when it breaks the rule."""
        if key not in table:
            return default
        try:
            return parse_number(table[key], rule)
        except FieldError as exc:
            self.fail(base.key_line(key), keyed(key, exc), base)
            return None


def keyed(key: str, exc: Exception) -> str:
    """``exc``'s message, led by ``key`` unless it names it first already."""
    text = str(exc)
    return text if text.startswith(key) else f"{key}: {text}"


def parse_number(value: object, rule: NumberRule) -> float | None:
    """A TOML value by a form field's ``rule``: a number as the operator would type it."""
    if isinstance(value, str) and value.strip() == "" and rule.optional:
        return None
    if not _number(value):
        raise FieldError(f"{rule.what}: {value!r} is not a number; write digits such as 12.5")
    return rule.parse(repr(float(value)) if isinstance(value, float) else str(value))


def _number(value: object) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool)


def _count(tables: list[object]) -> int:
    """Step tables in ``tables``, a repeat's own counted too."""
    return sum(1 + (_count(t["steps"]) if isinstance(t, dict) and isinstance(t.get("steps"),
                                                                             list) else 0)
               for t in tables)
