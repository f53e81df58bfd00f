"""The ``servodesk`` command line: one entry point, a subcommand per job.

With no subcommand it opens the TUI on the chosen machine and backend.

A subcommand whose reader goes away (``servodesk ik … --json | head``) stops
quietly, without a BrokenPipeError traceback, and exits 141: 128 + SIGPIPE, the
status the shell reports for a command SIGPIPE killed (``yes | head``), so a
pipeline under ``set -o pipefail`` still sees that the output was cut short.
"""

from __future__ import annotations

import argparse
import os
import signal
import sys

from app import (
    cli_controller,
    cli_emulate,
    cli_kinematics,
    cli_machine,
    cli_move,
    cli_program,
    cli_runs,
    cli_serve,
)
from app.cli_options import ALL, global_options, machine_for
from control.timing import Timing


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="servodesk",
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
    sub = parser.add_subparsers(title="commands (none: open the TUI)", metavar="COMMAND")
    for module in (cli_kinematics, cli_machine, cli_emulate, cli_controller, cli_serve, cli_move,
                   cli_program, cli_runs):
        module.add_parsers(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if hasattr(args, "func"):
        return run_command(args)
    if args.backend == "serial" and not args.port:
        parser.error("--backend serial needs --port URL (a device, the emulator's pty path or "
                     "socket://HOST:PORT)")
    if (args.observe_only or args.take_command) and args.attach is None:
        parser.error("--observe-only and --take-command are for a TUI on a controller service: "
                     "add --attach")
    if args.observe_only and args.take_command:
        parser.error("--observe-only and --take-command exclude each other")
    from app.tui import ServodeskApp, attached_app
    from control.client import ControllerError
    from hw.machine import MachineError

    try:
        timing = Timing(args.timing, args.interrupt_ms, tuple(args.slip))
    except ValueError as exc:
        parser.error(str(exc))
    try:
        app = (attached_app(args.attach, observe_only=args.observe_only,
                            take_command=args.take_command) if args.attach is not None else
               ServodeskApp(machine_for(args), args.backend, args.port, args.data_dir,
                            seed=args.seed, client_options={"timing": timing}))
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
