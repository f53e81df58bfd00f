"""``servodesk controller``: one controller, several clients on a Unix socket.

The service starts the control process through an embedded ``ControlClient`` and
relays between it and the clients that attach (``control/attached.py``):

- **commands** from the commanding client to the controller, and from nobody else: the
  others are refused with the reason ("observing: command is held by …; take it first"),
  except the E-stop, which anyone may press (and whose count in shared memory reaches
  the controller whatever this process does); a move's sealed path comes with its command
  and goes on to the controller as it came (``control/rt/sealed.py``);
- **events** from the controller to every client, and ``Commander`` when command changes
  hands (``TakeCommand``/``ReleaseCommand``, explicitly; ``lost`` when its holder leaves or
  falls silent); an operator E-stop is named for the client that pressed it;
- the **heartbeat**, along the commands' path: every client sends one every 50 ms, and
  the service beats the controller's heartbeat word for the commander's alone (while
  nobody commands, its own thread beats it). So a commander that falls silent, or a
  service that freezes, stops the controller's heartbeat as surely as a local client's
  would: it holds within its timeout. A commander that goes (its socket closes) or falls
  silent for ``release_after_s`` loses command; the controller runs on for the others.

Every connection must authenticate and join within ``rendezvous.HANDSHAKE_S``; one silent
for ``SILENT_S`` (or three times ``release_after_s``, if longer) or not reading its events
for ``SEND_S`` is dropped; at most ``MAX_CLIENTS`` connections are served at once (more are
closed at once), and running out of file descriptors is logged and waited out, never the
end of the service. Messages are
typed records in bounded frames (``control/rt/wire.py``), never pickle.

A client's moves are its own (it makes their segments, numbered from its ``id_base``,
and saves their runs); a move whose client has gone by its end is saved here.
"""

from __future__ import annotations

import contextlib
import errno
import itertools
import logging
import os
import queue
import socket
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from control import rendezvous
from control.client import ControlClient, Event
from control.rt import shm
from control.rt.channel import command_name
from control.rt.commands import Command, EmergencyStop, Shutdown, StartMove
from control.rt.events import Commander, Died, EStop, MoveDone, Refused
from control.rt.wire import Broken, Unreadable, Wire
from control.run_keeper import FinishedMove, RunKeeper, RunKept

log = logging.getLogger("servodesk.controller")

EVENTS_QUEUED = 512  # events waiting for a client; more and it is not reading: dropped
SEND_S = 2.0  # an event the client does not take within this: it is not reading, dropped
SILENT_S = 10.0  # a client not heard from this long (it beats every 50 ms) is dropped
MAX_CLIENTS = 64  # connections served at once, joined or joining
BACKOFF_S = 0.2  # after accept fails (no descriptor left), wait this long before trying again
POLL_S = 0.1
OPERATOR_ESTOP = "operator E-stop"  # the controller's reason for a client's E-stop
PRESS_S = 2.0  # the controller's E-stop after a client's press, within this, is that client's


@dataclass(eq=False)
class Peer:
    """An attached client: its connection, the events waiting for it, when it was last heard."""

    number: int
    name: str
    wire: Wire
    outgoing: queue.Queue[object] = field(default_factory=lambda: queue.Queue(EVENTS_QUEUED))
    connected: bool = True
    heard: float = field(default_factory=time.monotonic)

    def put(self, record: object) -> bool:
        """Queue ``record`` for the client; False if it is not reading (and is dropped)."""
        try:
            self.outgoing.put_nowait(record)
        except queue.Full:
            return False
        return True

    def deliver(self) -> None:
        """The sender thread: events out in order until the client goes."""
        while self.connected:
            try:
                record = self.outgoing.get(timeout=POLL_S)
            except queue.Empty:
                continue
            try:
                self.wire.send(record)
            except Broken:
                self.connected = False
                return


class ControllerService:
    """Serve ``client``'s controller on ``socket_path`` until ``stop`` (or its death)."""

    def __init__(self, client: ControlClient, socket_path: str | Path | None = None, *,
                 release_after_s: float = 1.0) -> None:
        self.client = client
        self.socket_path = Path(socket_path) if socket_path is not None else \
            rendezvous.default_socket()
        self.release_after_s = release_after_s
        self.drop_after_s = max(SILENT_S, 3 * release_after_s)  # a commander is released first
        self.stopped = threading.Event()
        self.why_stopped = ""
        self._lock = threading.RLock()
        self._peers: dict[int, Peer] = {}
        self._holder: Peer | None = None
        self._numbers = itertools.count(1)
        self._slots = threading.BoundedSemaphore(MAX_CLIENTS)
        self._moves: dict[int, tuple[Peer, str]] = {}  # move id: its client, its segment
        self._pressed: tuple[str, float] = ("", 0.0)  # who sent the last E-stop, and when
        self._claim()
        self._key = rendezvous.new_key(self.socket_path)  # first: who sees the socket can log in
        self._socket = self._listen()
        client.on_event = self._from_controller
        self._threads = [threading.Thread(target=self._accept, name="service-accept", daemon=True),
                         threading.Thread(target=self._watch_clients, name="service-watch",
                                          daemon=True)]
        for thread in self._threads:
            thread.start()

    def _claim(self) -> None:
        """The socket's directory; refused if a service listens there already (a socket file
        no one listens on is a dead service's: removed)."""
        rendezvous.socket_dir(self.socket_path.parent)
        if self.socket_path.exists():
            with contextlib.suppress(ConnectionError, OSError), \
                    socket.socket(socket.AF_UNIX) as probe:
                probe.connect(str(self.socket_path))
                raise RuntimeError(f"a controller service already listens on {self.socket_path}: "
                                   "attach to it (servodesk --attach) or stop it first")
            self.socket_path.unlink()

    def _listen(self) -> socket.socket:
        """Bind the socket owner-only (created 0600)."""
        sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        old = os.umask(0o177)
        try:
            sock.bind(str(self.socket_path))
        finally:
            os.umask(old)
        sock.listen(16)
        sock.settimeout(POLL_S)  # accept wakes to see ``stopped``
        return sock

    # -- connections -------------------------------------------------------------------------

    def _accept(self) -> None:
        starved = False
        while not self.stopped.is_set():
            try:
                sock, _ = self._socket.accept()
            except TimeoutError:
                continue
            except OSError as exc:
                if self.stopped.is_set():
                    return
                if not starved:
                    log.error("cannot accept a client (%s)%s; trying again every %g s",
                              exc.strerror or exc, ": out of file descriptors" if exc.errno in
                              (errno.EMFILE, errno.ENFILE) else "", BACKOFF_S)
                starved = True
                self.stopped.wait(BACKOFF_S)
                continue
            if starved:
                log.warning("accepting clients again")
                starved = False
            if not self._slots.acquire(blocking=False):
                log.warning("refused a connection: %d at once already", MAX_CLIENTS)
                sock.close()
                continue
            threading.Thread(target=self._serve, args=(sock,), name="service-client",
                             daemon=True).start()

    def _serve(self, sock: socket.socket) -> None:
        sock.settimeout(SEND_S)  # sends: a client that does not read is not waited for long
        wire = Wire(sock, rendezvous.CODEC, rendezvous.REQUEST_LIMIT)
        peer = None
        try:
            peer = self._join(wire)
            if peer is not None:
                self._listen_to(peer)
        finally:
            if peer is not None:
                self._leave(peer, f"{peer.name} left")
            wire.close()
            self._slots.release()

    def _listen_to(self, peer: Peer) -> None:
        sender = threading.Thread(target=peer.deliver, name="service-events", daemon=True)
        sender.start()
        while not self.stopped.is_set() and peer.connected:
            if not peer.wire.poll(POLL_S):
                continue
            try:
                message = peer.wire.recv()
            except Unreadable as exc:
                peer.put(Refused("message", f"unreadable: {exc}"))
                continue
            except Broken:
                break
            peer.heard = time.monotonic()
            try:
                self._request(peer, message.record, message.fds)
            finally:
                message.close_fds()
        peer.connected = False
        sender.join(timeout=1.0)

    def _join(self, wire: Wire) -> Peer | None:
        """Authenticate (both ways, the key beside the socket) and greet a new client, all
        within the handshake's time."""
        deadline = time.monotonic() + rendezvous.HANDSHAKE_S
        try:
            rendezvous.authenticate(wire, self._key, deadline, serving=True)
            join = rendezvous.receive(wire, rendezvous.Join, deadline, "join")
        except (Broken, PermissionError, TimeoutError) as exc:  # a stranger, or silent
            log.warning("refused a connection: %s", exc)
            return None
        client = self.client
        with self._lock:
            number = next(self._numbers)
            peer = Peer(number, f"{join.name} #{number} (pid {join.pid})", wire)
            holder = self._holder.name if self._holder else ""
            hello = rendezvous.Hello(
                client=peer.name, control_segment=client.segment_name,
                machine=str(client.machine.path), backend=client.backend,
                port=client.port, dt=client.dt, timing=client.timing.name,
                interrupt_ms=client.timing.interrupt_ms, slips=client.timing.slips,
                data_dir=str(client.data_dir), id_base=number * rendezvous.ID_SPAN,
                controller_pid=client.pid, service_pid=os.getpid(), realtime=client.realtime,
                notice=client.notice, holder=holder)
            try:
                wire.send(hello)
            except Broken:
                return None
            self._peers[number] = peer
        log.info("%s attached (%d attached)", peer.name, len(self._peers))
        return peer

    def _leave(self, peer: Peer, why: str) -> None:
        with self._lock:
            peer.connected = False
            self._peers.pop(peer.number, None)
            if self._holder is peer:
                self._release(f"{why}: command released, the controller holds",
                              f"interrupted: the commanding client ({peer.name}) left", "lost")
        log.info("%s (%d attached)", why, len(self._peers))

    # -- requests from a client ---------------------------------------------------------------

    def _request(self, peer: Peer, record: object, fds: tuple[int, ...]) -> None:
        if isinstance(record, rendezvous.Heartbeat):
            if self._holder is peer:
                self.client.beat()  # the commander's heartbeat, on to the controller
        elif isinstance(record, rendezvous.TakeCommand):
            self._take(peer)
        elif isinstance(record, rendezvous.ReleaseCommand):
            with self._lock:
                if self._holder is peer:
                    self._release(f"{peer.name} released command; the controller holds",
                                  "aborted: command released", "released")
                else:
                    peer.put(Refused("release command", "this client does not hold command"))
        elif isinstance(record, Command):
            self._relay(peer, record, fds)
        else:
            peer.put(Refused(command_name(record), "not a command this service knows"))

    def _take(self, peer: Peer) -> None:
        with self._lock:
            holder = self._holder
            if holder is not None and holder is not peer:
                peer.put(Refused("take command", f"{holder.name} holds command; it must release "
                                 "it first"))
                return
            self._holder = peer
            self.client.heartbeat_on = False  # the commander's heartbeats beat it now
            self.client.beat()
            self._broadcast(Commander(peer.name, f"{peer.name} took command", "taken"))

    def _release(self, reason: str, move_ends: str, change: str) -> None:
        """Nobody holds command (``change``: released, or lost): the controller holds (a
        running move ends ``move_ends``), and this service keeps its heartbeat."""
        self._holder = None
        self.client.heartbeat_on = True
        with contextlib.suppress(Exception):
            self.client.hold(move_ends)
        self._broadcast(Commander("", reason, change))
        log.info("%s", reason)

    def _relay(self, peer: Peer, command: Command, fds: tuple[int, ...]) -> None:
        with self._lock:
            holder = self._holder
            if isinstance(command, Shutdown):
                reason = "the controller service stops where it runs (Ctrl+C or SIGTERM)"
            elif holder is peer or isinstance(command, EmergencyStop):
                reason = ""
            else:
                reason = (f"observing: command is held by {holder.name}; take it first"
                          if holder else "observing: nobody holds command; take it first")
            if not reason and isinstance(command, StartMove):
                self._moves[command.move_id] = (peer, command.segment)
            if isinstance(command, EmergencyStop):  # the latch it brings says who pressed
                self._pressed = (peer.name, time.monotonic())
            if not reason:
                try:
                    # the descriptors go on with the command; the embedded client closes them
                    self.client.send(command, tuple(os.dup(fd) for fd in fds))
                    if holder is peer:
                        self.client.beat()
                    return
                except Exception as exc:  # the controller is gone, or not reading
                    reason = str(exc)
        peer.put(Refused(command_name(command), reason))
        if isinstance(command, StartMove):
            peer.put(MoveDone(command.move_id, f"refused: {reason}", 0))

    # -- events from the controller -----------------------------------------------------------

    def _from_controller(self, event: Event) -> None:
        record = event.record
        if isinstance(record, Died):
            self.why_stopped = record.message
            log.error("%s", record.message)
            self.stopped.set()
            return
        if isinstance(record, MoveDone):
            self._move_done(record)
        if isinstance(record, EStop):
            record = self._who_pressed(record)
        self._broadcast(record)

    def _who_pressed(self, estop: EStop) -> EStop:
        """An operator E-stop, named for the client whose EmergencyStop came just before it
        (the E-stop word in shared memory says nobody: the controller latches on it first, and
        again on the command relayed behind it, which is named however the two arrive)."""
        with self._lock:
            if not estop.latched:
                self._pressed = ("", 0.0)  # the next press is another's
                return estop
            name, when = self._pressed
        if estop.reason != OPERATOR_ESTOP or not name or time.monotonic() - when > PRESS_S:
            return estop
        return EStop(True, f"{OPERATOR_ESTOP} from {name}")

    def _broadcast(self, record: object) -> None:
        with self._lock:
            for peer in list(self._peers.values()):
                if not peer.put(record):
                    log.warning("%s does not read its events: disconnected", peer.name)
                    peer.connected = False  # its reader thread ends, and it leaves

    def _move_done(self, done: MoveDone) -> None:
        """Save the run of a move whose client has gone (else the client saves it), on the
        embedded client's run keeper: this is its monitor thread, which must not wait."""
        with self._lock:
            owner, segment = self._moves.pop(done.move_id, (None, ""))
        if owner is None or owner.connected or done.saved:
            return
        ended = f"move {done.move_id} of {owner.name} ended ({done.status}) after it left"
        save_departed(segment, done, self.client.keeper,
                      lambda outcome: log.info("%s: %s", ended, outcome))

    def _watch_clients(self) -> None:
        """Drop a client silent for ``drop_after_s``; a commander silent for
        ``release_after_s`` loses command first."""
        while not self.stopped.wait(POLL_S):
            self.client.poll_events()  # broadcast already; the queue must not grow for ever
            now = time.monotonic()
            with self._lock:
                holder = self._holder
                if holder is not None and now - holder.heard > self.release_after_s:
                    self._release(f"{holder.name} silent for {self.release_after_s:g} s: "
                                  "command released, the controller holds",
                                  f"interrupted: the commanding client ({holder.name}) fell "
                                  "silent", "lost")
                for peer in self._peers.values():
                    if peer.connected and now - peer.heard > self.drop_after_s:
                        log.warning("%s silent for %g s: disconnected", peer.name,
                                    self.drop_after_s)
                        peer.connected = False

    # -- the end ----------------------------------------------------------------------------------

    def close(self) -> None:
        """Tell the clients, stop listening (socket and key removed), stop the controller."""
        self._broadcast(Refused("service", "the controller service is stopping"))
        self.stopped.set()
        with contextlib.suppress(OSError):
            self._socket.close()
        for path in (self.socket_path, rendezvous.key_path(self.socket_path)):
            path.unlink(missing_ok=True)
        for thread in self._threads:
            thread.join(timeout=1.0)
        with self._lock:
            peers = list(self._peers.values())
        for peer in peers:
            peer.connected = False
            peer.wire.close()
        self.client.close()


def save_departed(name: str, done: MoveDone, keeper: RunKeeper,
                  said: Callable[[str], None]) -> None:
    """Hand the run in move segment ``name`` to ``keeper``, which saves it where its client
    saved runs and unlinks the segment; ``said`` is told what became of it, in words."""
    try:
        segment = shm.attach(name)
    except OSError as exc:
        said(f"its segment is gone ({exc})")
        return
    try:
        move = FinishedMove.in_segment(segment, done.status, done.timeline)
    except (UnicodeDecodeError, ValueError) as exc:
        shm.release(segment, unlink=False)
        said(f"not saved ({exc}); its segment is kept for the next start to recover")
        return
    keeper.hand(move, lambda kept: said(_outcome(kept)))


def _outcome(kept: RunKept) -> str:
    if kept.files is not None:
        return f"saved {kept.files.json}"
    return f"not saved ({kept.problem}); its segment is kept for the next start to recover"
