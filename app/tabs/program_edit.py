"""The Program tab's edits of a program's order: a step moved up or down within its block,
deleted, or a go to a position inserted after it. Each edit gives a new ``Program``
numbered and lined again as its file will be (``dump_program`` then ``parse_program``), so
what the tab lists, checks and runs is what a save writes; an edit whose result is no
program (a repeat left without steps) is refused with the reason (``ProgramError``)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace
from types import MappingProxyType

from control.program import Program, dump_program, parse_program
from control.program.model import GoTo, Repeat, Step

Path_ = tuple[int, ...]  # a step's place: its index in each block, outermost first


def places(program: Program) -> dict[int, Path_]:
    """Each step's number → its place in the program's blocks."""
    out: dict[int, Path_] = {}

    def walk(steps: tuple[Step, ...], at: Path_) -> None:
        for i, step in enumerate(steps):
            out[step.number] = (*at, i)
            if isinstance(step, Repeat):
                walk(step.steps, (*at, i))

    walk(program.steps, ())
    return out


def number_at(program: Program, place: Path_) -> int | None:
    """The number of the step at ``place`` (None: no step there)."""
    return next((n for n, p in places(program).items() if p == place), None)


def renumbered(program: Program) -> Program:
    """``program`` as its file reads back: steps numbered and lined in order."""
    return parse_program(dump_program(program), str(program.source))


def move_step(program: Program, number: int, delta: int) -> tuple[Program, int]:
    """Step ``number`` one place up (``delta`` −1) or down (+1) in its block (a repeat moves
    with its steps); the new program and the step's new number. ValueError at a block's end."""
    place = places(program)[number]

    def swap(block: list[Step], i: int) -> list[Step]:
        j = i + delta
        if not 0 <= j < len(block):
            where = "first" if delta < 0 else "last"
            raise ValueError(f"step {number} is the {where} of its block: it cannot move "
                             f"{'up' if delta < 0 else 'down'}")
        block[i], block[j] = block[j], block[i]
        return block

    edited = renumbered(_in_block(program, place, swap))
    moved = number_at(edited, (*place[:-1], place[-1] + delta))
    assert moved is not None
    return edited, moved


def delete_step(program: Program, number: int) -> tuple[Program, int | None]:
    """The program without step ``number`` (a repeat with its steps); the number of the step
    now in its place, or of the one before (None: no step left)."""
    place = places(program)[number]
    edited = _in_block(program, place, lambda block, i: block[:i] + block[i + 1:])
    if not edited.steps:
        return edited, None
    edited = renumbered(edited)
    for candidate in (place, (*place[:-1], place[-1] - 1), place[:-1]):
        found = number_at(edited, candidate) if candidate else None
        if found is not None:
            return edited, found
    return edited, 1


def insert_go_to(program: Program, after: int | None, position: str, speed: float,
                 joints: tuple[float, ...] | None = None) -> tuple[Program, int]:
    """A go to ``position`` at ``speed`` inserted after step ``after`` in its block (None: at
    the end); ``joints`` (a taught position's) are carried in the program's ``[positions]``
    so it runs where that position is not taught. The new program and the new step's
    number."""
    step = GoTo(0, 0, position=position, speed=speed)
    positions = program.positions
    if joints is not None:
        positions = MappingProxyType({**positions, position: tuple(joints)})
    program = replace(program, positions=positions)
    if after is None:
        edited = renumbered(replace(program, steps=(*program.steps, step)))
        return edited, edited.count  # the last step in the listing
    place = places(program)[after]
    edited = renumbered(_in_block(program, place,
                                  lambda block, i: [*block[:i + 1], step, *block[i + 1:]]))
    new = number_at(edited, (*place[:-1], place[-1] + 1))
    assert new is not None
    return edited, new


def _in_block(program: Program, place: Path_,
              change: Callable[[list[Step], int], list[Step]]) -> Program:
    """``program`` with ``change(block, index)`` applied to the block that holds ``place``."""
    def edit(steps: tuple[Step, ...], at: Path_) -> tuple[Step, ...]:
        block = list(steps)
        if len(at) == 1:
            return tuple(change(block, at[0]))
        outer = block[at[0]]
        assert isinstance(outer, Repeat)
        block[at[0]] = replace(outer, steps=edit(outer.steps, at[1:]))
        return tuple(block)

    return replace(program, steps=edit(program.steps, place))
