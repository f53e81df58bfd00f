"""Programs: steps taught once and played many times (``docs/programs.md``): read a program
file, check it whole, run it through a ``ControlClient``."""

from control.program.check import CheckedProgram, check
from control.program.dump import dump_program
from control.program.model import Program, Visit, visits
from control.program.parse import Problem, ProgramError, parse_program, read_program
from control.program.runner import ProgramOutcome, Runner, RunnerState, StepResult

__all__ = ["CheckedProgram", "Problem", "Program", "ProgramError", "ProgramOutcome", "Runner",
           "RunnerState", "StepResult", "Visit", "check", "dump_program", "parse_program",
           "read_program", "visits"]
