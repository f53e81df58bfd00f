"""Where a controller service listens, how a client proves it is its user's, and what they say
first: the records a client and ``servodesk controller`` exchange besides commands and events.

The socket lives in the user's runtime directory (``$XDG_RUNTIME_DIR/servodesk``, else
``/tmp/servodesk-<uid>``), a directory only its owner may enter (0700), the socket and the
key beside it readable by the owner alone (0600). A connection must also answer a challenge
with that key (``multiprocessing.connection``'s HMAC handshake), so a process that can reach
the socket but cannot read the key is refused.
"""

from __future__ import annotations

import os
import secrets
import stat
from dataclasses import dataclass
from multiprocessing.connection import Client, Connection
from pathlib import Path

SOCKET_NAME = "controller.sock"
KEY_NAME = "controller.key"
ID_SPAN = 1_000_000  # move ids per client: client k numbers its moves from k * ID_SPAN


def runtime_dir() -> Path:
    """The directory of this user's controller socket."""
    base = os.environ.get("XDG_RUNTIME_DIR")
    if base and Path(base).is_dir():
        return Path(base) / "servodesk"
    return Path("/tmp") / f"servodesk-{os.getuid()}"


def default_socket() -> Path:
    return runtime_dir() / SOCKET_NAME


def key_path(socket_path: Path) -> Path:
    return socket_path.with_name(KEY_NAME)


def private_dir(path: Path) -> None:
    """Create ``path`` (0700) or check that an existing one is this user's and private."""
    path.mkdir(mode=0o700, parents=True, exist_ok=True)
    info = path.lstat()
    if not stat.S_ISDIR(info.st_mode) or info.st_uid != os.getuid():
        raise PermissionError(f"{path} is not a directory of this user: remove it or set "
                              "XDG_RUNTIME_DIR to a private directory")
    if stat.S_IMODE(info.st_mode) != 0o700:
        path.chmod(0o700)


def new_key(socket_path: Path) -> bytes:
    """A fresh key, written owner-only beside the socket."""
    key = secrets.token_bytes(32)
    path = key_path(socket_path)
    path.unlink(missing_ok=True)
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
    with os.fdopen(fd, "wb") as file:
        file.write(key)
    return key


def connect(socket_path: str | Path | None = None) -> Connection:
    """A connection to the controller service at ``socket_path``, authenticated; a clear
    error if none runs there."""
    path = Path(socket_path) if socket_path is not None else default_socket()
    try:
        key = key_path(path).read_bytes()
        return Client(str(path), family="AF_UNIX", authkey=key)
    except (FileNotFoundError, ConnectionRefusedError) as exc:
        raise ConnectionError(f"no controller service at {path} ({exc.strerror or exc}): start "
                              "one with `servodesk controller`, or give its socket") from None


@dataclass(frozen=True)
class Join:
    """A client's first message: who it is, for the other clients' headers."""

    name: str
    pid: int


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
