"""``servodesk controller``: the controller as a service, in the foreground, logging to stderr.

It starts the control process and listens on a Unix socket in the user's runtime directory
(``control/service.py``); ``servodesk --attach`` and ``ControlClient.attach()`` connect to
it, as many as wanted: one commands, the others observe. Ctrl+C or SIGTERM stops it (the
valves closed, every client told).
"""

from __future__ import annotations

import argparse
import logging
import signal
import sys
import time
from pathlib import Path

from app.cli_options import ALL, global_options, machine_for
from app.priority import raise_priority
from control.timing import Timing

log = logging.getLogger("servodesk.controller")


def add_parsers(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "controller", parents=[global_options(*ALL)],
        help="run the controller as a service that TUIs and scripts attach to",
        description="Run the control process in the foreground (logs on stderr) and serve it on "
                    "a Unix socket (owner only): `servodesk --attach` opens a TUI on it, "
                    "`ControlClient.attach()` a script. One client holds command at a time; "
                    "the others observe; any may press E-stop.")
    p.add_argument("--socket", type=Path, metavar="PATH",
                   help="where to listen (default: $XDG_RUNTIME_DIR/servodesk/controller.sock, "
                        "else /tmp/servodesk-UID/controller.sock)")
    p.add_argument("--heartbeat-timeout", type=_seconds, default=0.25, metavar="S",
                   help="the controller holds when the commanding client is silent this long "
                        "(default 0.25)")
    p.add_argument("--release-after", type=_seconds, default=1.0, metavar="S",
                   help="a commanding client silent this long loses command (default 1)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from control.client import ControlClient, ControllerError
    from control.service import ControllerService
    from hw.machine import MachineError

    logging.basicConfig(stream=sys.stderr, level=logging.INFO,
                        format="%(asctime)s servodesk controller: %(message)s")
    if args.backend == "serial" and not args.port:
        print("servodesk controller: --backend serial needs --port URL", file=sys.stderr)
        return 2
    started = time.monotonic()
    # before the control process and the service's threads start, which inherit it: while
    # nobody commands, the service beats the controller's heartbeat, and a UI attached to it
    # never takes a higher priority than this
    priority = raise_priority(who="controller service")
    try:
        timing = Timing(args.timing, args.interrupt_ms, tuple(args.slip))
        client = ControlClient(
            machine_for(args), args.backend, port=args.port, seed=args.seed,
            data_dir=args.data_dir, timing=timing, heartbeat_timeout_s=args.heartbeat_timeout,
            # the service keeps the heartbeat of a client-less controller; past this the
            # service itself is gone and the controller stops
            orphan_timeout_s=args.release_after + 5.0)
    except (MachineError, ControllerError, ValueError, OSError) as exc:
        print(f"servodesk controller: {exc}", file=sys.stderr)
        return 2
    try:
        service = ControllerService(client, args.socket, release_after_s=args.release_after)
    except (RuntimeError, OSError) as exc:
        client.close()
        print(f"servodesk controller: {exc}", file=sys.stderr)
        return 2
    notices = "".join(f"; {notice}" for notice in (priority.notice, client.notice) if notice)
    log.info("listening on %s: %s, %s backend, controller pid %d, service nice %d, ready in "
             "%.2f s%s", service.socket_path, client.machine.title, client.backend, client.pid,
             priority.now, time.monotonic() - started, notices)
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: service.stopped.set())
    while not service.stopped.wait(0.5):
        pass
    service.close()
    log.info("stopped%s", f": {service.why_stopped}" if service.why_stopped else "")
    return 1 if service.why_stopped else 0


def _seconds(text: str) -> float:
    value = float(text)
    if not 0.01 <= value <= 60.0:
        raise argparse.ArgumentTypeError(f"must be 0.01…60 s, got {text}")
    return value
