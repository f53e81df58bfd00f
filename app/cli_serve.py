"""``servodesk serve``: the TUI in a web browser (``textual-serve``), on a controller service.

It attaches to the ``servodesk controller`` listening on ``--socket`` (default the user's), or
starts one (a subprocess given ``--machine``, ``--backend``, ``--port``, ``--data-dir``,
``--seed``, ``--timing``; stopped when serve stops). Every browser session runs its own
``python -m app --attach SOCKET``: observe-only (^K refused with the reason), or, with
``--command``, taking command at start (refused, with who holds it, if another client does).
Any session's E-stop latches. It listens on 127.0.0.1 unless told otherwise: from another
machine, forward the port over SSH (``ssh -L 8000:127.0.0.1:8000 host``). Its gate
(``app/web_gate.py``) wants the token it prints at start, a websocket from its own page (Origin)
at a name of this machine (Host), and no more than ``--max-sessions`` sessions at once.
"""

from __future__ import annotations

import argparse
import shlex
import signal
import subprocess
import sys
import time
from pathlib import Path

from app.cli_options import ALL, global_options

TEMPLATES = Path(__file__).with_name("serve_templates")  # textual-serve's page, offline
CONTROLLER_START_S = 60.0  # a cold start on a loaded machine imports numpy, scipy…
CONTROLLER_STOP_S = 30.0
MAX_SESSIONS = 4  # each a TUI process of about 85 MB beside the controller service


def add_parsers(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "serve", parents=[global_options(*ALL, scope="for a controller started here")],
        help="the TUI in a web browser, on a controller service",
        description="Serve the TUI to web browsers (textual-serve): each browser session is a "
                    "TUI attached to the controller service on --socket, started here if none "
                    "runs. Sessions observe only, unless --command: then each takes command "
                    "at start (one at a time holds it). Any session's E-stop latches. Bound to "
                    "127.0.0.1: from elsewhere, forward it (ssh -L 8000:127.0.0.1:8000 host). "
                    "Open the address it prints: the page wants its token (new each start).")
    p.add_argument("--socket", type=Path, metavar="PATH",
                   help="the controller service's socket (default: the user's, as for "
                        "`servodesk controller`); one is started there if none listens")
    p.add_argument("--host", default="127.0.0.1",
                   help="address to listen on (default 127.0.0.1: this machine only; reach it "
                        "from elsewhere through SSH port forwarding)")
    p.add_argument("--http-port", type=int, default=8000, metavar="N",
                   help="TCP port of the web page (default 8000; --port is the I/O board's)")
    p.add_argument("--command", action="store_true",
                   help="each browser session takes command at start (default: observe only; "
                        "E-stop works either way)")
    p.add_argument("--max-sessions", type=_sessions, default=MAX_SESSIONS, metavar="N",
                   help=f"browser sessions open at once, each a TUI process (default "
                        f"{MAX_SESSIONS}); one more is refused until one closes")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from app.web_gate import Gate, GatedServer
    from control import rendezvous

    if args.backend == "serial" and not args.port:
        print("servodesk serve: --backend serial needs --port URL", file=sys.stderr)
        return 2
    socket = args.socket or rendezvous.default_socket()
    controller: subprocess.Popen[bytes] | None = None
    title = _title(socket)
    if title is None:
        controller = subprocess.Popen(_controller_argv(args, socket), stdin=subprocess.DEVNULL,
                                      start_new_session=True)  # serve stops it, after the TUIs
        try:
            title = _wait_for(controller, socket)
        except RuntimeError as exc:
            _stop(controller)
            print(f"servodesk serve: {exc}", file=sys.stderr)
            return 2
    role = "--take-command" if args.command else "--observe-only"
    command = shlex.join([sys.executable, "-m", "app", "--attach", str(socket), role])
    gate = Gate.listening_on(args.host)
    server = GatedServer(command, host=args.host, port=args.http_port,
                         title=f"servodesk: {title}", templates_path=TEMPLATES, gate=gate,
                         max_sessions=args.max_sessions)
    print(f"servodesk serve: {gate.page_url(args.host, args.http_port)} ({title}; controller "
          f"{'started here' if controller else 'attached'} at {socket}; sessions "
          f"{'take command' if args.command else 'observe only'}, at most "
          f"{args.max_sessions} at once)", file=sys.stderr, flush=True)
    try:
        server.serve()
    except OSError as exc:  # the port is taken, the address is not this machine's
        print(f"servodesk serve: cannot listen on {args.host}:{args.http_port}: {exc}",
              file=sys.stderr)
        return 2
    finally:
        if controller is not None:
            _stop(controller)
    print(f"servodesk serve: stopped ({server.ended} open session"
          f"{'' if server.ended == 1 else 's'} ended)", file=sys.stderr)
    return 0


def _sessions(text: str) -> int:
    value = int(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be 1 or more, got {text}")
    return value


def _title(socket: Path) -> str | None:
    """The machine of the controller service at ``socket``; None if none listens there."""
    from control.client import ControlClient, ControllerError

    try:
        probe = ControlClient.attach(socket, name="servodesk serve")
    except (OSError, ControllerError):  # none listens, or a stale socket
        return None
    try:
        return f"{probe.machine.title}, {probe.backend}"
    finally:
        probe.close()


def _controller_argv(args: argparse.Namespace, socket: Path) -> list[str]:
    """``servodesk controller`` with serve's machine, backend and timing."""
    argv = [sys.executable, "-m", "app", "--machine", str(args.machine), "--backend",
            args.backend, "--seed", str(args.seed), "--timing", args.timing,
            "--interrupt-ms", str(args.interrupt_ms)]
    for slip in args.slip:
        argv += ["--slip", slip]
    if args.port:
        argv += ["--port", args.port]
    if args.data_dir:
        argv += ["--data-dir", str(args.data_dir)]
    return [*argv, "controller", "--socket", str(socket)]


def _wait_for(controller: subprocess.Popen[bytes], socket: Path) -> str:
    """Wait until the controller started here answers on ``socket``; its machine."""
    deadline = time.monotonic() + CONTROLLER_START_S
    while time.monotonic() < deadline:
        if controller.poll() is not None:
            raise RuntimeError(f"the controller did not start (exit {controller.returncode}; "
                               "its reason is above)")
        if socket.exists() and (title := _title(socket)) is not None:
            return title
        time.sleep(0.05)
    raise RuntimeError(f"the controller did not listen on {socket} within "
                       f"{CONTROLLER_START_S:g} s")


def _stop(controller: subprocess.Popen[bytes]) -> None:
    """SIGTERM (valves closed, clients told), a kill if it does not end."""
    if controller.poll() is None:
        controller.send_signal(signal.SIGTERM)
        try:
            controller.wait(timeout=CONTROLLER_STOP_S)
        except subprocess.TimeoutExpired:
            controller.kill()
            controller.wait()
