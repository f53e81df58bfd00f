"""Where a controller service listens, how a client proves it is its user's, and what they say
first: the records a client and ``servodesk controller`` exchange besides commands and events.

The socket lives in the user's runtime directory (``$XDG_RUNTIME_DIR/servodesk``, else
``/tmp/servodesk-<uid>``), a directory only its owner may enter (0700, when servodesk makes
it; a directory given with ``--socket`` keeps its own mode), the socket and the key beside it
(``<socket>.key``, one per socket) readable by the owner alone (0600); a client uses a key
only from a regular file of its own user's (``read_key``). Each side of a
connection must also answer the other's challenge with that key (HMAC-SHA256), within
``HANDSHAKE_S``, so a process that can reach the socket but cannot read the key is refused,
and one that never answers is dropped. Every message is a typed record in a bounded frame
(``control/rt/wire.py``), never pickle.
"""

from __future__ import annotations

import contextlib
import hashlib
import hmac
import os
import secrets
import socket
import stat
import time
from dataclasses import dataclass
from pathlib import Path
from typing import TypeVar

from control.rt.commands import COMMANDS
from control.rt.events import EVENTS
from control.rt.wire import Broken, Codec, Unreadable, Wire

SOCKET_NAME = "controller.sock"
ID_SPAN = 1_000_000  # move ids per client: client k numbers its moves from k * ID_SPAN
HANDSHAKE_S = 5.0  # both challenges answered, and the client's join sent, within this
REQUEST_LIMIT = 64 * 1024  # bytes of one message to the service: a command, a join
EVENT_LIMIT = 1 << 20  # bytes of one message from it: an event with a 600 s move's timeline
NAME_TEXT = 80  # characters of a client's name
KEY_BYTES = 32  # of the key beside the socket
R = TypeVar("R")


def runtime_dir() -> Path:
    """The directory of this user's controller socket."""
    base = os.environ.get("XDG_RUNTIME_DIR")
    if base and Path(base).is_dir():
        return Path(base) / "servodesk"
    return Path("/tmp") / f"servodesk-{os.getuid()}"


def default_socket() -> Path:
    return runtime_dir() / SOCKET_NAME


def key_path(socket_path: Path) -> Path:
    """The key of the service on ``socket_path``: one per socket, so two services in one
    directory never share (or remove) each other's."""
    return socket_path.with_name(socket_path.name + ".key")


def socket_dir(path: Path) -> None:
    """Make the socket's directory owner-only (0700) if it does not exist. One that exists keeps
    its mode (``--socket`` may name a shared directory such as /tmp), but must be a directory in
    which other users cannot replace this user's files: this user's own, or sticky."""
    with contextlib.suppress(FileExistsError):
        path.mkdir(mode=0o700, parents=True)
    info = path.lstat()
    if not stat.S_ISDIR(info.st_mode):
        raise PermissionError(f"{path} is not a directory: give the socket another place")
    if info.st_uid not in (os.getuid(), 0):  # its owner may replace anything in it
        raise PermissionError(f"{path} belongs to another user (uid {info.st_uid}): give the "
                              "socket a directory of your own")
    if (info.st_uid != os.getuid() and not info.st_mode & stat.S_ISVTX
            and info.st_mode & (stat.S_IWGRP | stat.S_IWOTH)):
        raise PermissionError(f"{path} is a directory others may write in: give the socket "
                              "a private directory")


def new_key(socket_path: Path) -> bytes:
    """A fresh key, written owner-only beside the socket."""
    key = secrets.token_bytes(KEY_BYTES)
    path = key_path(socket_path)
    path.unlink(missing_ok=True)
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW, 0o600)
    with os.fdopen(fd, "wb") as file:
        file.write(key)
    return key


def read_key(socket_path: Path) -> bytes:
    """The key of the service on ``socket_path``: a regular file of this user's, read to its
    bound (``PermissionError`` otherwise). One another user wrote proves nothing: who made
    ``/tmp/servodesk-<uid>`` before this user did chose the key, answered the handshake with
    it and was sent the client's commands; a link to ``/dev/zero`` there was read until
    memory ran out."""
    fd = os.open(key_path(socket_path), os.O_RDONLY | os.O_NONBLOCK)  # a FIFO: no wait
    try:
        info = os.fstat(fd)
        if not stat.S_ISREG(info.st_mode) or info.st_uid != os.getuid():
            raise PermissionError(f"{key_path(socket_path)} is not a key file of this user's")
        return os.read(fd, KEY_BYTES)
    finally:
        os.close(fd)


def connect(socket_path: str | Path | None = None, timeout_s: float = HANDSHAKE_S) -> Wire:
    """A connection to the controller service at ``socket_path``, both sides authenticated,
    within ``timeout_s``: ``ConnectionError`` if none runs there, ``TimeoutError`` if it does
    not answer in time."""
    path = Path(socket_path) if socket_path is not None else default_socket()
    deadline = time.monotonic() + timeout_s
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    try:
        key = read_key(path)
        sock.settimeout(timeout_s)
        sock.connect(str(path))
        sock.settimeout(None)  # sends wait for a slow service; reads are bounded by the wire
    except (FileNotFoundError, ConnectionRefusedError) as exc:
        sock.close()
        raise ConnectionError(f"no controller service at {path} ({exc.strerror or exc}): start "
                              "one with `servodesk controller`, or give its socket") from None
    except BaseException:
        sock.close()
        raise
    wire = Wire(sock, CODEC, EVENT_LIMIT, frame_s=timeout_s)
    try:
        authenticate(wire, key, deadline, serving=False)
    except BaseException:
        wire.close()
        raise
    return wire


def authenticate(wire: Wire, key: bytes, deadline: float, *, serving: bool) -> None:
    """Each side proves it holds ``key`` by answering the other's random challenge, the service
    first: ``PermissionError`` for a wrong answer, ``TimeoutError`` past ``deadline``."""
    mine = secrets.token_hex(32)
    if serving:
        wire.send(Challenge(mine))
        _check(receive(wire, Answer, deadline, "answer"), key, mine, "client")
        theirs = receive(wire, Challenge, deadline, "challenge")
        wire.send(Answer(_digest(key, theirs.nonce, "service")))
    else:
        theirs = receive(wire, Challenge, deadline, "challenge")
        wire.send(Answer(_digest(key, theirs.nonce, "client")))
        wire.send(Challenge(mine))
        _check(receive(wire, Answer, deadline, "answer"), key, mine, "service")


def _digest(key: bytes, nonce: str, role: str) -> str:
    return hmac.new(key, f"{role}:{nonce}".encode(), hashlib.sha256).hexdigest()


def _check(answer: Answer, key: bytes, nonce: str, role: str) -> None:
    if not hmac.compare_digest(answer.digest.encode(), _digest(key, nonce, role).encode()):
        raise PermissionError(f"the {role} does not hold this socket's key")


def receive(wire: Wire, kind: type[R], deadline: float, what: str) -> R:
    """The next record, which must be a ``kind``, by ``deadline`` (``TimeoutError``)."""
    if not wire.poll(deadline - time.monotonic()):
        raise TimeoutError(f"no {what} from the other side in time")
    try:
        message = wire.recv()
    except Unreadable as exc:
        raise Broken(f"a {what} expected: {exc}") from None
    message.close_fds()
    if not isinstance(message.record, kind):
        raise Broken(f"a {what} expected, got {type(message.record).__name__}")
    return message.record


@dataclass(frozen=True)
class Join:
    """A client's first message: who it is, for the other clients' headers."""

    name: str
    pid: int

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not 0 < len(self.name) <= NAME_TEXT \
                or not self.name.isprintable():
            raise ValueError(f"a client's name is 1…{NAME_TEXT} printable characters")
        if isinstance(self.pid, bool) or not isinstance(self.pid, int) or self.pid < 0:
            raise ValueError(f"a client's pid is a whole number, got {self.pid!r}")


@dataclass(frozen=True)
class Hello:
    """The service's answer: what the client needs to work beside the controller."""

    client: str  # the name the others see
    control_segment: str
    machine: str  # the machine file's path
    backend: str
    port: str | None
    dt: float
    timing: str
    interrupt_ms: float
    slips: tuple[str, ...]
    data_dir: str
    id_base: int
    controller_pid: int
    service_pid: int  # the service's process: an attached TUI never outranks it
    realtime: bool
    notice: str
    holder: str  # who holds command now ("" nobody)


@dataclass(frozen=True)
class TakeCommand:
    """Ask for command: granted unless another client holds it."""


@dataclass(frozen=True)
class ReleaseCommand:
    """Give command back: the controller holds every joint, and another client may take it."""


@dataclass(frozen=True)
class Heartbeat:
    """A client is alive (every 50 ms): the service relays the commander's to the controller,
    and drops a client it has not heard from in a while."""


@dataclass(frozen=True)
class Challenge:
    nonce: str  # hex


@dataclass(frozen=True)
class Answer:
    digest: str  # hex HMAC-SHA256 of the challenge under the socket's key

    def __post_init__(self) -> None:
        if not isinstance(self.digest, str):
            raise ValueError("an answer is a hex digest")


CODEC = Codec(COMMANDS + EVENTS + (Join, Hello, TakeCommand, ReleaseCommand, Heartbeat,
                                   Challenge, Answer))
