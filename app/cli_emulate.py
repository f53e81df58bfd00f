"""``servodesk emulate``: an emulated I/O board serving the simulator on a pty or TCP port.

The first line on stdout is what to pass to ``--port`` (the pty path or a
``socket://`` URL); on SIGINT or SIGTERM the emulator stops, prints a one-line
JSON summary of its counts on stdout and exits 0. SIGUSR1 presses the board's
E-stop button, SIGUSR2 releases it.

The emulator stands in for a microcontroller, which never waits for a CPU: it takes
SCHED_FIFO ``BOARD_PRIORITY``, below the controller's 80, where the OS allows it. At normal
priority beside a busy neighbour it waited past the 50 ms link timeout every few seconds,
and the controller rightly declared the link lost (after a reset, as at any time);
``--normal-priority`` keeps it there, for a board that is late on purpose.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import sys

from app.cli_options import global_options
from hw.machine import MachineError, load_machine
from hw.serial.emulator import Emulator, Faults

BOARD_PRIORITY = 70  # SCHED_FIFO: above the tests and their burners, below the controller


def add_parsers(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "emulate", parents=[global_options("machine", "seed")],
        help="run the I/O board emulator (the simulator behind a pty or TCP port)",
        description="Serve an emulated I/O board (docs/protocol.md) in front of the simulator, "
                    "so `--backend serial --port URL` can be run without hardware. Prints the "
                    "URL on the first line. SIGUSR1 presses the E-stop, SIGUSR2 releases it. "
                    "--seed seeds the simulator and the injected faults.")
    p.add_argument("--tcp", type=_port, metavar="PORT",
                   help="serve one TCP client on 127.0.0.1:PORT (0: any free port) "
                        "instead of a pseudo-terminal")
    p.add_argument("--glitch-scale", type=_scale, default=1.0, metavar="X",
                   help="multiplies the simulated encoders' wrong-reading rate (0: none)")
    p.add_argument("--corrupt-rate", type=_rate, default=0.0, metavar="R",
                   help="probability that a board-to-host frame has one bit flipped")
    p.add_argument("--corrupt-rx-rate", type=_rate, default=0.0, metavar="R",
                   help="probability that a host-to-board frame has one bit flipped on arrival")
    p.add_argument("--drop-rate", type=_rate, default=0.0, metavar="R",
                   help="probability that a board-to-host frame is never sent")
    p.add_argument("--silent-after", type=_seconds, metavar="S",
                   help="stop answering S seconds after the first configuration (a hung board)")
    p.add_argument("--frozen-after", type=_seconds, metavar="S",
                   help="answer on time but with every encoder word frozen S seconds after the "
                        "first configuration (a stalled multiplexer)")
    p.add_argument("--stuck-bit", type=_stuck_bit, metavar="JOINT:BIT:VALUE",
                   help="that bit of that joint's encoder word always reads VALUE (0 or 1)")
    p.add_argument("--flood", type=_flood, default=0, metavar="N",
                   help="follow every REPORT with N more, valid (a board flooding the link)")
    p.add_argument("--flip-word", type=_flip_word, metavar="JOINT:BIT",
                   help="flip that bit of that joint's encoder word in one REPORT every "
                        "--fault-every seconds (a wrong word, once)")
    p.add_argument("--hold-replies", type=_hold_ms, default=0.0, metavar="MS",
                   help="every --fault-every seconds (after the flipped word, with "
                        "--flip-word) hold back every reply MS ms, then send them at once "
                        "(a late board: the host re-reads the words it has)")
    p.add_argument("--flip-first", type=_flip_word, metavar="JOINT:BIT",
                   help="flip that bit of that joint's encoder word in the first REPORT after "
                        "every configuration (a wrong word with none before it to judge it by)")
    p.add_argument("--normal-priority", action="store_true",
                   help=f"run at normal priority, not SCHED_FIFO {BOARD_PRIORITY} (a board "
                        "that waits for a CPU beside a busy neighbour, late now and then)")
    p.add_argument("--fault-every", type=_period, default=1.0, metavar="S",
                   help="seconds between flipped words and held-back replies, the first S "
                        "after the first configuration (default 1)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from hw.sim.backend import SimBackend

    try:
        machine = load_machine(args.machine)
        plant = SimBackend(machine, seed=args.seed, lockstep=False,
                           glitch_scale=args.glitch_scale)
    except (MachineError, ValueError) as exc:
        print(f"servodesk: {exc}", file=sys.stderr)
        return 2
    for option, value in (("--stuck-bit", args.stuck_bit), ("--flip-word", args.flip_word),
                          ("--flip-first", args.flip_first)):
        if value is not None and value[0] >= machine.n_joints:
            print(f"servodesk: {option} joint {value[0]} is not a joint of {machine.name}: "
                  f"give 0…{machine.n_joints - 1}", file=sys.stderr)
            return 2
    faults = Faults(corrupt_rate=args.corrupt_rate, corrupt_rx_rate=args.corrupt_rx_rate,
                    drop_rate=args.drop_rate, silent_after_s=args.silent_after,
                    frozen_after_s=args.frozen_after, stuck_bit=args.stuck_bit,
                    flood=args.flood, flip_word=args.flip_word, hold_ms=args.hold_replies,
                    fault_every_s=args.fault_every, flip_first=args.flip_first)
    try:
        emulator = Emulator(plant, tcp_port=args.tcp, faults=faults, seed=args.seed)
    except OSError as exc:
        print(f"servodesk: cannot serve the emulator: {exc}", file=sys.stderr)
        return 2
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: emulator.stop())
    signal.signal(signal.SIGUSR1, lambda *_: emulator.board.press_estop())
    signal.signal(signal.SIGUSR2, lambda *_: emulator.board.release_estop())
    if not args.normal_priority:
        _take_realtime()
    print(emulator.url, flush=True)
    pid = os.getpid()
    print(f"emulating the {machine.title} I/O board on {emulator.url}; Ctrl-C stops it, "
          f"kill -USR1 {pid} presses the E-stop, kill -USR2 {pid} releases it",
          file=sys.stderr, flush=True)
    emulator.serve()
    print(json.dumps(emulator.summary()), flush=True)
    return 0


def _take_realtime() -> None:
    """SCHED_FIFO ``BOARD_PRIORITY`` (not inherited by children), or a notice why not."""
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO | os.SCHED_RESET_ON_FORK,
                              os.sched_param(BOARD_PRIORITY))
    except OSError as exc:
        print(f"servodesk emulate: SCHED_FIFO refused ({exc.strerror}): running at normal "
              "priority; on a busy machine the board may fall silent past the link timeout",
              file=sys.stderr, flush=True)


def main(argv: list[str] | None = None) -> int:
    """Run ``emulate`` on its own (``python -c 'from app.cli_emulate import main; main()'``)."""
    parser = argparse.ArgumentParser(
        prog="servodesk", parents=[global_options("machine", "seed", defaults=True)])
    add_parsers(parser.add_subparsers())
    args = parser.parse_args(["emulate", *(sys.argv[1:] if argv is None else argv)])
    return args.func(args)


def _number(text: str, low: float, high: float, what: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not low <= value <= high:  # also refuses NaN
        raise argparse.ArgumentTypeError(f"{text} is not {what}")
    return value


def _rate(text: str) -> float:
    return _number(text, 0.0, 1.0, "a probability in 0…1")


def _port(text: str) -> int:
    return _whole(text, 0, 65535, "a TCP port in 0…65535")


def _scale(text: str) -> float:
    return _number(text, 0.0, 1e6, "a scale in 0…1e6")


def _seconds(text: str) -> float:
    return _number(text, 0.0, 1e6, "a time in 0…1e6 s")


def _whole(text: str, low: int, high: int, what: str) -> int:
    value = _number(text, low, high, what)
    if value != int(value):
        raise argparse.ArgumentTypeError(f"{text} is not a whole number")
    return int(value)


def _flood(text: str) -> int:
    return _whole(text, 0, 100, "a count of extra reports in 0…100")


def _hold_ms(text: str) -> float:
    return _number(text, 0.0, 1000.0, "a time in 0…1000 ms")


def _period(text: str) -> float:
    return _number(text, 0.001, 1e6, "a period in 0.001…1e6 s")


def _flip_word(text: str) -> tuple[int, int]:
    parts = text.split(":")
    if len(parts) != 2:
        raise argparse.ArgumentTypeError(f"{text!r} is not JOINT:BIT (e.g. 1:12)")
    return _whole(parts[0], 0, 63, "a joint index"), _whole(parts[1], 0, 31, "a bit in 0…31")


def _stuck_bit(text: str) -> tuple[int, int, int]:
    parts = text.split(":")
    if len(parts) != 3:
        raise argparse.ArgumentTypeError(f"{text!r} is not JOINT:BIT:VALUE (e.g. 2:12:1)")
    joint = _whole(parts[0], 0, 63, "a joint index")
    bit = _whole(parts[1], 0, 31, "a bit in 0…31")
    value = _whole(parts[2], 0, 1, "0 or 1")
    return joint, bit, value
