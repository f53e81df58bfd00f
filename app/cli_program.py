"""``servodesk run PROGRAM``: a program (``docs/programs.md``) checked whole, then run
headless on a new controller, every move's run saved in the data directory.

The CLI's conventions (``app/cli_move.py``): ``--machine`` (default: the program's own),
``--backend``, ``--data-dir``, ``--lockstep``, ``--json`` (one JSON object: the program, its
run id, each step's result and figures). It exits

- 0: every step completed, every move in position (and saved);
- 1: it ended otherwise (a move not in position, a fault, the E-stop, a step that could not
  run); the runs made so far are saved;
- 2: the program fails its check (every problem on stderr, each naming its line and step),
  or bad input: nothing moved.

Ctrl+C (SIGINT, and SIGTERM) is the E-stop: latched at once, the run of the move in
progress saved, exit 1. ``--reduced`` runs it in reduced speed (T1: the tool at most
250 mm/s, each joint at most its jog speed; a pulse step refused); ``--check`` only checks
(from the machine's home, no controller started); ``--from STEP`` starts at a step number
of the listing; ``--initialise`` zeroes the rig's encoder before the program (as
``servodesk move``). Positions come from the data directory's positions file (the
Positions tab's), then from the program's ``[positions]``.

A ``wait = "operator"`` step asks on stderr and goes on when a line (Enter) comes on stdin;
without a terminal on stdin a program with one is refused at its check (exit 2): a script
cannot press a key.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import sys
import threading
import time
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from app.cli_move import BadInput, EStopOnSignal, check_backend, check_writable, start_client
from app.cli_options import ALL, DEFAULT_MACHINE, global_options, machine_for
from control.program.parse import Problem
from hw.machine import Machine, MachineError

if TYPE_CHECKING:
    from control.client import ControlClient
    from control.motion.positions import PositionBook
    from control.program import CheckedProgram, Program, ProgramOutcome, Runner
    from control.program.runner import Report

DONE, ENDED, BAD_INPUT = 0, 1, 2


class CheckFailed(ValueError):
    """The program fails its check; ``problems`` are every reason."""

    def __init__(self, problems: tuple[Problem, ...]) -> None:
        super().__init__(f"{len(problems)} problem(s)")
        self.problems = problems


def add_parsers(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "run", parents=[global_options(*ALL)],
        help="check a program, then run it headless; save its runs",
        description="Check a program file (docs/programs.md) whole, then run it on a new "
                    "controller, saving every move's run in the data directory. Exit 0 every "
                    "step completed in position, 1 it ended otherwise (a fault, the E-stop: "
                    "Ctrl+C), 2 the program fails its check (nothing moved). The machine is the "
                    "program's (its machine key) unless --machine names another.")
    p.add_argument("program", metavar="PROGRAM", help="the program file (TOML)")
    p.add_argument("--json", action="store_true",
                   help="print one JSON object: the program, its run id, each step's result")
    p.add_argument("--check", action="store_true",
                   help="only check the program (from the machine's home; nothing started)")
    p.add_argument("--from", dest="start", type=int, default=1, metavar="STEP",
                   help="start at this step number of the listing (default 1)")
    p.add_argument("--initialise", action="store_true",
                   help="rig: drive the ram to the bottom stop and zero the encoder before the "
                        "program (every run starts a new controller, not zeroed)")
    p.add_argument("--reduced", action="store_true",
                   help="reduced speed (ISO 10218-1's T1): the controller keeps the tool at most "
                        "250 mm/s and each joint at most its jog speed (default: automatic, full "
                        "speed); a program with a pulse, open-loop duty, is refused")
    p.add_argument("--lockstep", action="store_true",
                   help="simulator only: run the controller as fast as it computes, not in "
                        "real time (scripts, tests)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    try:
        return _run(args)
    except CheckFailed as exc:
        for problem in exc.problems:
            print(problem, file=sys.stderr)
        print(f"servodesk: {args.program}: {len(exc.problems)} problem(s); nothing moved",
              file=sys.stderr)
        return BAD_INPUT
    except BadInput as exc:
        print(f"servodesk: {exc}", file=sys.stderr)
        return BAD_INPUT
    except KeyboardInterrupt:  # before the program started (starting, initialising)
        print("servodesk: interrupted before the program started: the controller is stopped, "
              "every valve closed", file=sys.stderr)
        return ENDED


def _run(args: argparse.Namespace) -> int:
    from control.recorder import default_data_dir

    program = _read(args.program)
    machine = _machine(args, program)
    data_dir = Path(args.data_dir).expanduser() if args.data_dir else default_data_dir()
    book = _book(data_dir, machine)
    if args.check:
        checked = _check(program, machine, book, _resting(machine), args.start, args.reduced)
        print(f"{program.source}: checked, {program.count} steps, {len(checked.visits)} to run "
              f"from step {args.start} on {machine.name}")
        return DONE
    check_backend(args)
    # before anything starts; the rig's initialise puts it on its bottom stop first
    _check(program, machine, book, np.array(machine.lower, dtype=float) if args.initialise
           else _resting(machine), args.start, args.reduced)
    check_writable(data_dir)
    client = start_client(args, machine, data_dir)
    try:
        return _play(args, client, program, book)
    finally:
        client.close()


def _read(path: str) -> Program:
    from control.program import ProgramError, read_program

    try:
        return read_program(path)
    except ProgramError as exc:
        raise CheckFailed(exc.problems) from None


def _machine(args: argparse.Namespace, program: Program) -> Machine:
    """``--machine``, or the program's own when it was left at its default."""
    if args.machine == DEFAULT_MACHINE and program.machine:
        args = argparse.Namespace(**{**vars(args), "machine": program.machine})
    try:
        return machine_for(args)
    except MachineError as exc:
        raise BadInput(str(exc)) from None


def _book(data_dir: Path, machine: Machine) -> PositionBook:
    from control.motion.positions import PositionsError, load_positions, positions_file

    try:
        return load_positions(positions_file(data_dir, machine), machine)
    except PositionsError as exc:
        raise BadInput(f"positions: {exc}") from None


def _resting(machine: Machine) -> np.ndarray:
    """Where a check without a controller starts: the machine's home, else mid-range."""
    if machine.home is not None:
        return np.array(machine.home, dtype=float)
    return np.array([(j.lower + j.upper) / 2 for j in machine.joints])


def _check(program: Program, machine: Machine, book: PositionBook, here: np.ndarray, start: int,
           reduced: bool) -> CheckedProgram:
    from control.program import ProgramError, check
    from control.program.model import Move, Wait

    try:
        checked = check(program, machine, book, here, start=start)
    except ProgramError as exc:
        raise CheckFailed(exc.problems) from None
    pulses = [v.step for v in checked.visits if isinstance(v.step, Move)
              and v.step.kind == "pulse"]
    if reduced and pulses:
        raise CheckFailed(tuple(
            Problem(str(program.source), step.line, "a pulse is open-loop duty, which reduced "
                    "speed cannot hold to 250 mm/s: leave --reduced out to run it", step)
            for step in {s.number: s for s in pulses}.values()))
    if not sys.stdin.isatty():
        waits = [v.step for v in checked.visits
                 if isinstance(v.step, Wait) and v.step.operator]
        if waits:
            raise CheckFailed(tuple(
                Problem(str(program.source), step.line, "waits for the operator, and stdin is "
                        "not a terminal: run it from a terminal, or wait = SECONDS", step)
                for step in {s.number: s for s in waits}.values()))
    return checked


def _play(args: argparse.Namespace, client: ControlClient, program: Program, book: PositionBook
          ) -> int:
    from control.program import Runner, visits
    from control.program.model import Move
    from control.program.runner import initialise_rig
    from control.rt.layout import Flag

    machine = client.machine
    first = next(iter(visits(program, args.start)), None)
    if not client.status().flags & Flag.HOMED:
        starts_zeroed = (first is None or (isinstance(first.step, Move)
                         and first.step.kind == "initialise"))
        if args.initialise:
            _say("initialising: driving down to the bottom stop…")
            ok, status = initialise_rig(client)
            if not ok:
                print(f"servodesk: initialise: {status}", file=sys.stderr)
                return ENDED
        elif not starts_zeroed:
            raise BadInput(f"--initialise: the {machine.title}'s encoder is not zeroed (every "
                           "`servodesk run` starts a new controller); add --initialise, or "
                           "begin the program with move = \"initialise\"")
    checked = _check(program, machine, book, np.array(client.status().position), args.start,
                     args.reduced)
    estop = EStopOnSignal(client)
    started = time.monotonic()
    try:
        runner = Runner(client, checked, on_report=_Progress(estop).report)
        _Operator(runner).start()
        _say(f"running {program.name} ({len(checked.visits)} steps from step {args.start}), "
             f"run {runner.run_id}; Ctrl+C is the E-stop")
        runner.run()
        outcome = None
        while outcome is None:
            outcome = runner.wait(0.05)
    finally:
        estop.restore()
    _summary(args, outcome, checked, time.monotonic() - started)
    saved = all(r.move is None or r.move.files is not None for r in outcome.results)
    return DONE if outcome.complete and saved else ENDED


class _Progress:
    """Each step's start and result on stderr, as it happens."""

    def __init__(self, estop: EStopOnSignal) -> None:
        self.estop = estop
        self.announced = False

    def report(self, report: Report) -> None:
        from control.program.model import Wait
        from control.program.runner import MoveStarted, StepDone, StepStarted

        if self.estop.pressed and not self.announced:
            self.announced = True
            _say("servodesk: E-stop: every valve closed and latched; saving the run recorded so "
                 "far")
        if isinstance(report, StepStarted):
            step = report.visit.step
            ask = (": press Enter to go on" if isinstance(step, Wait) and step.operator
                   else "")
            _say(f"{report.visit.where}: {step.title}{ask}")
        elif isinstance(report, MoveStarted):
            handle = report.handle
            seconds = handle.samples * float(handle.meta["sample_time_s"])
            _say(f"  moving: {handle.plan.title}, {seconds:.2f} s; Ctrl+C is the E-stop")
        elif isinstance(report, StepDone):
            result = report.result
            _say(f"  {result.status} ({result.seconds:.2f} s)")


def _say(line: str) -> None:
    """Progress on stderr; a reader gone (``… 2>&1 | head``) stops the progress, not the
    program."""
    with contextlib.suppress(OSError):
        print(line, file=sys.stderr, flush=True)


class _Operator(threading.Thread):
    """Reads stdin (a terminal: ``_check`` refuses operator waits otherwise): each line is
    the operator's go-on for a ``wait = "operator"``."""

    def __init__(self, runner: Runner) -> None:
        super().__init__(name="operator", daemon=True)
        self.runner = runner

    def run(self) -> None:
        if not sys.stdin.isatty():
            return
        for _ in sys.stdin:
            self.runner.proceed()


def _summary(args: argparse.Namespace, outcome: ProgramOutcome, checked: CheckedProgram,
             wall_s: float) -> None:
    program = checked.program
    steps = [r.figures() for r in outcome.results]
    moved_s = sum(r.seconds for r in outcome.results if r.move is not None)
    controller_s = sum(r.seconds for r in outcome.results)
    if args.json:
        print(json.dumps({
            "program": program.name, "file": str(program.source), "machine": program.machine,
            "run_id": outcome.run_id, "speed_mode": "reduced" if args.reduced else "automatic",
            "state": outcome.state.value,
            "complete": outcome.complete, "reason": outcome.reason, "from_step": checked.start,
            "steps": steps, "steps_run": len(steps), "steps_planned": len(checked.visits),
            "moves_s": round(moved_s, 3), "total_s": round(controller_s, 3),
            "wall_s": round(wall_s, 3),
        }, ensure_ascii=False, allow_nan=False))
        return
    print(f"program {program.name}, run {outcome.run_id}: {outcome.state.value} "
          f"({outcome.reason})")
    for result in outcome.results:
        run = (f"  run {result.move.files.stem}" if result.move is not None
               and result.move.files is not None else "")
        print(f"{result.visit.where:>16}  {result.visit.step.title:<28}  {result.status}  "
              f"{result.seconds:.2f} s{run}")
    print(f"{len(steps)} of {len(checked.visits)} steps, {controller_s:.2f} s on the "
          f"controller's clock ({moved_s:.2f} s moving), {wall_s:.2f} s here")
