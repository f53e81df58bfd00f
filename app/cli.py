"""The ``servodesk`` command line: one entry point, a subcommand per job.

With no subcommand it opens the TUI on the chosen machine and backend.

A subcommand whose reader goes away (``servodesk ik … --json | head``) stops
quietly, without a BrokenPipeError traceback, and exits 141: 128 + SIGPIPE, the
status the shell reports for a command SIGPIPE killed (``yes | head``), so a
pipeline under ``set -o pipefail`` still sees that the output was cut short.

The TUI starts its controller as soon as its options are read, before the screen's code is
imported (``app.controller_start``), and takes the UI's priority (``app.priority``) before
anything else: its imports are most of its start, and a busy machine slowed them threefold.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import signal
import sys
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, NoReturn

from app.priority import raise_priority, restore

if TYPE_CHECKING:
    from textual.app import App

    from app.controller_start import ControllerStart
    from control.timing import Timing
    from hw.machine import Machine


# Each command's name: the module that adds its parser (``add_parsers``) and runs it.
COMMANDS = {"fk": "cli_kinematics", "ik": "cli_kinematics", "machine": "cli_machine",
            "emulate": "cli_emulate", "controller": "cli_controller", "serve": "cli_serve",
            "move": "cli_move", "run": "cli_program", "runs": "cli_runs"}


def build_parser(command: str | None = None,
                 cls: type[argparse.ArgumentParser] = argparse.ArgumentParser
                 ) -> argparse.ArgumentParser:
    """``servodesk``'s whole parser; with ``command``, one with only that command's module's
    commands (its imports only: ``parse_for_command``)."""
    from importlib import import_module

    names = list(dict.fromkeys(COMMANDS.values())) if command is None else [COMMANDS[command]]
    parser = tui_parser(cls)
    sub = parser.add_subparsers(title="commands (none: open the TUI)", metavar="COMMAND")
    for name in names:
        import_module(f"app.{name}").add_parsers(sub)
    return parser


class Unsure(Exception):
    """The TUI's own options do not account for the command line: the whole parser must."""


class _Unsure(argparse.ArgumentParser):
    """A parser that says it cannot read a command line rather than exiting on it."""

    def error(self, message: str) -> NoReturn:
        raise Unsure(message)


class _TuiParser(_Unsure):
    """The TUI's own options alone: no help of its own (the whole parser's lists the commands)."""


def tui_parser(cls: type[argparse.ArgumentParser] = argparse.ArgumentParser
               ) -> argparse.ArgumentParser:
    """``servodesk``'s own options (the global ones and the TUI's), without its commands."""
    from app.cli_options import ALL, global_options

    parser = cls(
        prog="servodesk", add_help=cls is not _TuiParser,  # help lists the commands too
        description="Terminal workstation for real-time control of hydraulic manipulators "
                    "(Unimate 2000B, single-axis test rig).",
        parents=[global_options(*ALL, defaults=True)],
    )
    parser.add_argument("--attach", nargs="?", const="", metavar="SOCKET",
                        help="open the TUI on the controller `servodesk controller` runs (its "
                             "socket; default the one in the user's runtime directory) instead "
                             "of starting one; it observes until you take command (^K)")
    parser.add_argument("--observe-only", action="store_true",
                        help="with --attach: this TUI never takes command (^K says why)")
    parser.add_argument("--take-command", action="store_true",
                        help="with --attach: take command at start (refused, with who holds it, "
                             "if another client does)")
    return parser


def parse_for_tui(argv: list[str] | None) -> argparse.Namespace | None:
    """The arguments of a command line that opens the TUI, read without importing
    the commands' modules (a third of the TUI's start on a busy machine); None when it names a
    command, asks for help or is wrong: the whole parser then reads it and says so."""
    try:
        args, rest = tui_parser(_TuiParser).parse_known_args(argv)
    except Unsure:
        return None
    return None if rest else args


def parse_for_command(argv: list[str] | None) -> argparse.Namespace | None:
    """The arguments of a command line that names a command, read by a parser of that
    command's module alone: the other commands' imports are most of a command's start
    (``servodesk machine rig`` 0.56 s to 0.24 s, median of 9 at load 5). A word that names a
    command may be an option's value (``--data-dir runs move …``): then that word's parser
    cannot read the line, and the next such word is tried. None when no word names a
    command, help is asked before it, or no such parser reads the line (a usage error): the
    whole parser then reads it and says so. What one command's parser reads, the whole one
    reads the same: the same options put the command in the same place, and there it has
    the same subparsers."""
    words = sys.argv[1:] if argv is None else argv
    for word in words:
        if word in ("-h", "--help", "--"):
            return None
        if word in COMMANDS:
            with contextlib.suppress(Unsure):
                return build_parser(word, _Unsure).parse_args(words)
    return None


def main(argv: list[str] | None = None) -> int:
    priority = raise_priority()  # the TUI's from its first import; a command runs at its own
    # (one that commands a real-time controller takes it again: cli_move.start_client)
    try:
        args = (parse_for_tui(argv) or parse_for_command(argv)
                or build_parser().parse_args(argv))
        if not hasattr(args, "func"):
            return tui(args)
    finally:
        restore(priority)
    return run_command(args)


def tui(args: argparse.Namespace) -> int:
    """Open the TUI as ``args`` ask; its exit code."""
    from app.cli_options import machine_for
    from control.timing import Timing

    def error(message: str) -> NoReturn:
        build_parser().error(message)  # the usage of servodesk and its commands

    if args.backend == "serial" and not args.port:
        error("--backend serial needs --port URL (a device, the emulator's pty path or "
                     "socket://HOST:PORT)")
    if (args.observe_only or args.take_command) and args.attach is None:
        error("--observe-only and --take-command are for a TUI on a controller service: "
                     "add --attach")
    if args.observe_only and args.take_command:
        error("--observe-only and --take-command exclude each other")
    try:
        timing = Timing(args.timing, args.interrupt_ms, tuple(args.slip))
    except ValueError as exc:
        error(str(exc))
    if args.attach is not None:
        return run_tui(lambda: _attached(args))
    from app.controller_start import ControllerStart
    from control.recorder import default_data_dir
    from hw.machine import MachineError

    try:
        machine = machine_for(args)
    except MachineError as exc:
        print(f"servodesk: {exc}", file=sys.stderr)
        return 2
    data_dir = Path(args.data_dir) if args.data_dir is not None else default_data_dir()
    # the controller starts now, on the other core, while the screen's code is imported
    starting = ControllerStart(machine, args.backend, args.port, data_dir, args.seed,
                               {"timing": timing})
    try:
        return run_tui(lambda: _own(args, machine, data_dir, timing, starting))
    finally:
        starting.close()


def _attached(args: argparse.Namespace) -> App:
    from app.tui import attached_app

    return attached_app(args.attach, observe_only=args.observe_only,
                        take_command=args.take_command)


def _own(args: argparse.Namespace, machine: Machine, data_dir: Path, timing: Timing,
         starting: ControllerStart) -> App:
    from app.tui import ServodeskApp

    return ServodeskApp(machine, args.backend, args.port, data_dir, seed=args.seed,
                        client_options={"timing": timing}, starting=starting)


def run_tui(make: Callable[[], App]) -> int:
    """Make the TUI and run it until it quits; its exit code."""
    from control.client import ControllerError
    from hw.machine import MachineError

    try:
        app = make()
    except (MachineError, ConnectionError, ControllerError, OSError) as exc:
        print(f"servodesk: {exc}", file=sys.stderr)
        return 2
    try:
        app.run()
    finally:
        app.shutdown_client()
    return 0 if app.return_code in (None, 0) else app.return_code


def run_command(args: argparse.Namespace) -> int:
    """Run a subcommand; 141 if its output's reader has gone (module docstring)."""
    try:
        code = args.func(args)
        sys.stdout.flush()  # the last output, while a closed pipe can still be caught here
    except BrokenPipeError:
        # the interpreter flushes stdout again on its way out: let that write go nowhere
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        os.close(devnull)
        return 128 + signal.SIGPIPE
    return code


if __name__ == "__main__":
    sys.exit(main())
