"""A program written back as its TOML file (``docs/programs.md``): what a Program tab saves
after the operator reorders, deletes or inserts steps. ``parse_program`` reads the text
back to the same steps (``tests/control/program/test_dump.py``)."""

from __future__ import annotations

import json
import math

from control.program.model import Comment, Feed, GoTo, Line, Move, Program, Repeat, Step, Wait


def dump_program(program: Program) -> str:
    """The TOML text of ``program``: its name, machine, positions and steps, in order."""
    lines = [f"name = {_value(program.name)}", f"machine = {_value(program.machine)}"]
    if program.positions:
        lines += ["", "[positions]"]
        lines += [f"{_value(name)} = {_value(list(joints))}"
                  for name, joints in program.positions.items()]
    for step in program.steps:
        lines += _step(step, "step")
    return "\n".join(lines) + "\n"


def _step(step: Step, table: str) -> list[str]:
    lines = ["", f"[[{table}]]", *(f"{key} = {_value(value)}" for key, value in _keys(step))]
    if step.label:
        lines.append(f"label = {_value(step.label)}")
    if isinstance(step, Repeat):
        for inner in step.steps:
            lines += _step(inner, f"{table}.steps")
    return lines


def _keys(step: Step) -> list[tuple[str, object]]:
    """The step's keys, its kind's first."""
    if isinstance(step, GoTo):
        return [("go", step.position), ("speed", step.speed)]
    if isinstance(step, Line):
        to: object = step.position or list(step.pose)
        return [("line", to)] + ([("speed", step.speed)] if step.speed is not None else [])
    if isinstance(step, Move):
        return [("move", step.kind), *step.fields.items()]
    if isinstance(step, Wait):
        return [("wait", "operator" if step.operator else step.seconds)]
    if isinstance(step, Feed):
        return [("feed", step.percent)]
    if isinstance(step, Repeat):
        return [("repeat", step.count)]
    assert isinstance(step, Comment)
    return [("comment", step.text)]


def _value(value: object) -> str:
    """A TOML literal: JSON's strings and numbers are TOML's (a float keeps its point)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        if not math.isfinite(value):
            raise ValueError(f"{value} cannot be written to a program")
        return repr(value)
    if isinstance(value, list | tuple):
        return "[" + ", ".join(_value(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{" + ", ".join(f"{_value(str(k))} = {_value(v)}" for k, v in value.items()) + "}"
    return json.dumps(value, ensure_ascii=False).replace("\x7f", "\\u007f")  # TOML: no raw DEL
