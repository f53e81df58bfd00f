"""The check of a whole program before it starts: each step planned, in the order it will
run (repeats unrolled), from the end of the step before, with the Moves forms' rules and the
acceptance rules a move is sent under, so a program that passes moves as it was checked.

What is checked: the program is for this machine; the positions its file carries are one
number per joint within the limits; every named position is in the data directory's book
or the file; every field by the forms' rules; every target within the limits and, for a
tool line or an end point, reachable on the arm's branch; every path file readable and
valid; every move accepted (``control.motion.acceptance``). A step whose end cannot be
known in advance (a wait, a feed change, a pulse's open-loop travel) leaves the position
where it was; the rig's initialise ends on its bottom stop (0). Every problem is collected,
each naming its line and step (``Problem``), a step's once however many passes repeat it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from control.motion.acceptance import accept
from control.motion.positions import PositionBook
from control.program import move_steps
from control.program.model import Feed, Program, Visit, Wait, visits
from control.program.parse import Problem, ProgramError
from hw.machine import Machine

DECIMALS = 6  # a step planned again from a start equal to this is the same plan (repeats)


@dataclass(frozen=True)
class CheckedProgram:
    """A program that passed its check on ``machine``: the visits to run from ``start``
    (a step number) and where each visit was planned to end (``ends (V, J)``)."""

    program: Program
    machine: Machine
    book: PositionBook
    start: int
    visits: tuple[Visit, ...]
    ends: np.ndarray

    def position(self, name: str) -> tuple[float, ...]:
        return position_of(self.program, self.book, name)


def position_of(program: Program, book: PositionBook, name: str) -> tuple[float, ...]:
    """The joints of the position ``name``: the book's (taught, home, park), else the
    program file's; ValueError listing the names there are."""
    for p in book.positions:
        if p.name == name:
            return p.joints
    if name in program.positions:
        return program.positions[name]
    known = [p.name for p in book.positions] + [n for n in program.positions
                                                if all(p.name != n for p in book.positions)]
    listed = ", ".join(known) if known else "none"
    raise ValueError(f"no taught position {name!r} — taught: {listed}")


def check(program: Program, machine: Machine, book: PositionBook, here: np.ndarray, *,
          start: int = 1, dt: float | None = None) -> CheckedProgram:
    """``program`` checked from the joints ``here`` (mm, deg), run from step ``start``;
    ProgramError listing every problem."""
    source = str(program.source)
    problems: list[Problem] = []
    if program.machine != machine.name:
        problems.append(Problem(source, program.lines.get("machine", 0),
                                f"the program is for machine {program.machine!r}, not "
                                f"{machine.name!r}: run it with --machine {program.machine}"))
        raise ProgramError(problems)
    problems += _positions(program, machine)
    try:
        order = visits(program, start)
    except ValueError as exc:
        raise ProgramError([*problems, Problem(source, 0, str(exc))]) from None
    ends = _plan_all(program, machine, book, np.asarray(here, dtype=float), order,
                     dt or machine.sample_time_s, problems)
    if problems:
        raise ProgramError(sorted(problems, key=lambda p: (p.step.number if p.step else 0,
                                                           p.line)))
    return CheckedProgram(program, machine, book, start, tuple(order), ends)


def _positions(program: Program, machine: Machine) -> list[Problem]:
    out = []
    for name, joints in program.positions.items():
        try:
            machine.check_targets(joints)
        except ValueError as exc:
            out.append(Problem(str(program.source),
                               program.lines.get(f"positions.{name}", 0),
                               f"position {name!r}: {exc}"))
    return out


def _plan_all(program: Program, machine: Machine, book: PositionBook, here: np.ndarray,
              order: list[Visit], dt: float, problems: list[Problem]) -> np.ndarray:
    """Each visit planned from the end of the one before; the ends ``(V, J)``."""
    def positions(name: str) -> tuple[float, ...]:
        return position_of(program, book, name)

    planned: dict[tuple[int, tuple[float, ...]], tuple[np.ndarray, str, str]] = {}
    said: set[tuple[int, str]] = set()
    ends = np.empty((len(order), machine.n_joints))
    q = here
    for visit in order:
        step = visit.step
        if not isinstance(step, Wait | Feed):
            key = (step.number, tuple(np.round(q, DECIMALS)))
            if key not in planned:
                planned[key] = _plan_one(visit, machine, q, dt, positions, program)
            q, at, text = planned[key]
            if text and (step.number, text) not in said:
                said.add((step.number, text))
                problems.append(Problem(str(program.source), step.key_line(at), text, step))
        ends[visit.index] = q
    return ends


def _plan_one(visit: Visit, machine: Machine, q: np.ndarray, dt: float,
              positions: move_steps.Positions, program: Program
              ) -> tuple[np.ndarray, str, str]:
    """Where the step ends, and the key and text of its problem ('' for none)."""
    try:
        if move_steps.initialises(visit.step, machine):  # on its bottom stop, zeroed
            return np.array(machine.lower, dtype=float), "", ""
        plan = move_steps.plan(visit.step, machine, q, dt, positions, program.source.parent)
        if plan is None:  # there already
            return q, "", ""
        accept(plan, q if plan.path is not None else None, machine, dt)
    except move_steps.StepProblem as exc:
        return q, exc.key, str(exc)
    except ValueError as exc:
        return q, "", str(exc)
    return (np.array(plan.path[-1]) if plan.path is not None else q), "", ""
