"""Messages on servodesk's sockets: typed records in bounded frames, never pickle.

Between the client and the control process, and between a controller service and its
clients, every message is one frame: a 4-byte big-endian length, then the record as UTF-8
JSON, ``{"type": NAME, "fields": {...}}``. Only the record types a ``Codec`` was given
decode, each rebuilt through its constructor, so its own checks run (a command is checked
when built, ``control/rt/commands.py``): a message can carry data, never code. A frame longer
than the reader's ``limit`` is refused before anything is allocated for it, and a frame
must arrive whole within ``frame_s``; either failure leaves the stream unusable, so the
connection is dropped (``Broken``). A well-framed message that is no known record is
``Unreadable``, and the stream goes on.

A frame may carry file descriptors (``SCM_RIGHTS``, sent with the frame's first byte): a
move's sealed path travels that way (``control/rt/sealed.py``).
"""

from __future__ import annotations

import array
import contextlib
import dataclasses
import json
import os
import select
import socket
import struct
import time
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

HEADER = struct.Struct("!I")
MAX_FDS = 4  # descriptors one frame may carry
FRAME_S = 5.0  # a frame begun must be whole within this


class Broken(ConnectionError):
    """The stream can no longer be trusted (closed, cut mid-frame, a frame over the limit):
    drop the connection."""


class Unreadable(ValueError):
    """A whole frame that is not one of the records this side knows; the stream goes on."""


@dataclass(frozen=True)
class Message:
    """A record received, and the descriptors that came with it (the receiver owns them)."""

    record: object
    fds: tuple[int, ...] = ()

    def close_fds(self) -> None:
        for fd in self.fds:
            with contextlib.suppress(OSError):
                os.close(fd)


class Codec:
    """Records of ``types`` (frozen dataclasses) to JSON bytes and back, by class name."""

    def __init__(self, types: Iterable[type]) -> None:
        self.types = {t.__name__: t for t in types}

    def encode(self, record: object) -> bytes:
        name = type(record).__name__
        if self.types.get(name) is not type(record):
            raise TypeError(f"{name} is not a record this link carries")
        fields = {f.name: getattr(record, f.name) for f in dataclasses.fields(record)}
        return json.dumps({"type": name, "fields": fields}, separators=(",", ":")).encode()

    def decode(self, data: bytes) -> object:
        """The record in ``data``; ``Unreadable`` naming what is wrong with it."""
        try:
            message = json.loads(data)
        except (ValueError, RecursionError) as exc:
            raise Unreadable(f"not JSON: {exc}") from None
        if not (isinstance(message, dict) and isinstance(message.get("fields"), dict)
                and isinstance(message.get("type"), str)):
            raise Unreadable("not a record: expected {\"type\": …, \"fields\": {…}}")
        kind = self.types.get(message["type"])
        if kind is None:
            raise Unreadable(f"{message['type'][:40]!r} is not a record this link carries")
        names = {f.name for f in dataclasses.fields(kind) if f.init}
        given = message["fields"]
        if not set(given) <= names:
            raise Unreadable(f"{kind.__name__} has no field {sorted(set(given) - names)[0]!r}")
        try:
            return kind(**{k: _tuples(v) for k, v in given.items()})
        except (TypeError, ValueError) as exc:
            raise Unreadable(f"{kind.__name__}: {exc}") from None


def _tuples(value: object) -> object:
    """JSON arrays back to the tuples a frozen record holds."""
    if isinstance(value, list):
        return tuple(_tuples(v) for v in value)
    return value


class Wire:
    """One end of a stream socket carrying ``codec``'s records.

    ``limit`` bounds a frame received, in bytes. ``send`` may be called from one thread
    while another receives. Sending blocks while the peer does not read (as long as the
    socket's own timeout, if it has one); ``offer`` sends only what the socket takes now."""

    def __init__(self, sock: socket.socket, codec: Codec, limit: int,
                 frame_s: float = FRAME_S) -> None:
        self.sock = sock
        self.codec = codec
        self.limit = limit
        self.frame_s = frame_s
        self._poll = select.poll()
        self._poll.register(sock.fileno(), select.POLLIN)

    def fileno(self) -> int:
        return self.sock.fileno()

    def poll(self, timeout_s: float = 0.0) -> bool:
        """Whether a frame has begun to arrive (or the peer closed), within ``timeout_s``."""
        return bool(self._poll.poll(max(timeout_s, 0.0) * 1e3))

    def send(self, record: object, fds: Sequence[int] = ()) -> None:
        """Send ``record`` (and ``fds``, which stay the caller's to close)."""
        self.send_frame(self.frame(record), fds)

    def send_bytes(self, body: bytes, fds: Sequence[int] = ()) -> None:
        self.send_frame(HEADER.pack(len(body)) + body, fds)

    def frame(self, record: object) -> bytes:
        """``record`` as it goes on the wire: its length, then its JSON."""
        body = self.codec.encode(record)
        return HEADER.pack(len(body)) + body

    def send_frame(self, frame: bytes, fds: Sequence[int] = ()) -> None:
        """Send all of ``frame``, waiting while the peer does not read; ``fds`` go with its
        first byte."""
        try:
            sent = self.sock.sendmsg([frame], _rights(fds))
            if sent < len(frame):
                self.sock.sendall(frame[sent:])
        except (OSError, ValueError) as exc:  # ValueError: the socket was closed here
            raise Broken(f"cannot send: {exc}") from None

    def offer(self, frame: bytes, fds: Sequence[int] = ()) -> int:
        """Send what of ``frame`` the socket takes now, never waiting (on a socket with no
        timeout): the bytes sent, 0 if none; ``fds`` go with the first byte."""
        try:
            return self.sock.sendmsg([frame], _rights(fds), socket.MSG_DONTWAIT)
        except BlockingIOError:
            return 0
        except (OSError, ValueError) as exc:
            raise Broken(f"cannot send: {exc}") from None

    def recv(self) -> Message:
        """The next record; ``Broken`` if the stream ended or cannot be trusted, ``Unreadable``
        (its descriptors closed) for a whole frame that is no record of ours."""
        body, fds = self.recv_bytes()
        try:
            return Message(self.codec.decode(body), fds)
        except Unreadable:
            Message(None, fds).close_fds()
            raise

    def recv_bytes(self) -> tuple[bytes, tuple[int, ...]]:
        deadline = time.monotonic() + self.frame_s
        fds: list[int] = []
        try:
            header = self._read(HEADER.size, deadline, fds)
            (size,) = HEADER.unpack(header)
            if size > self.limit:
                raise Broken(f"a frame of {size} bytes, over this link's limit of {self.limit}")
            return self._read(size, deadline, fds), tuple(fds)
        except BaseException:
            Message(None, tuple(fds)).close_fds()
            raise

    def _read(self, size: int, deadline: float, fds: list[int]) -> bytes:
        """Exactly ``size`` bytes by ``deadline``; descriptors that come with them into ``fds``."""
        data = bytearray()
        room = socket.CMSG_SPACE(MAX_FDS * array.array("i").itemsize)
        while len(data) < size:
            if not self._poll.poll(max(deadline - time.monotonic(), 0.0) * 1e3):
                raise Broken(f"a frame cut short: {len(data)} of {size} bytes in "
                             f"{self.frame_s:g} s")
            try:
                chunk, ancillary, flags, _ = self.sock.recvmsg(
                    size - len(data), room, socket.MSG_DONTWAIT | socket.MSG_CMSG_CLOEXEC)
            except (BlockingIOError, InterruptedError):
                continue
            except (OSError, ValueError) as exc:
                raise Broken(f"cannot receive: {exc}") from None
            fds.extend(_descriptors(ancillary))
            if flags & socket.MSG_CTRUNC:
                raise Broken(f"more than {MAX_FDS} descriptors with one frame")
            if not chunk:
                raise Broken("the peer closed the connection")
            data += chunk
        return bytes(data)

    def close(self) -> None:
        with contextlib.suppress(OSError):
            self.sock.close()


def _rights(fds: Sequence[int]) -> list[tuple[int, int, array.array]]:
    """The ancillary data that passes ``fds`` (``SCM_RIGHTS``)."""
    return [(socket.SOL_SOCKET, socket.SCM_RIGHTS, array.array("i", fds))] if fds else []


def _descriptors(ancillary: list[tuple[int, int, bytes]]) -> list[int]:
    fds: list[int] = []
    for level, kind, data in ancillary:
        if level == socket.SOL_SOCKET and kind == socket.SCM_RIGHTS:
            whole = len(data) - len(data) % array.array("i").itemsize
            fds.extend(array.array("i", data[:whole]))
    return fds
