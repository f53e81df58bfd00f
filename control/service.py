"""``servodesk controller``: one controller, several clients on a Unix socket.

The service starts the control process through an embedded ``ControlClient`` and
relays between it and the clients that attach (``control/attached.py``):

- **commands** from the commanding client to the controller, and from nobody else: the
  others are refused with the reason ("observing: command is held by …; take it first"),
  except the E-stop, which anyone may press (and whose count in shared memory reaches
  the controller whatever this process does);
- **events** from the controller to every client, and ``Commander`` when command changes
  hands (``TakeCommand``/``ReleaseCommand``, explicitly);
- the **heartbeat**: the commander's heartbeat thread writes it; while nobody holds
  command the service writes it. A commander that goes (its socket closes) or falls
  silent for ``release_after_s`` loses command: the controller holds (a silent one trips
  its usual 250 ms watch first) and runs on for the others, and anyone may take command.

A client's moves are its own (it makes their segments, numbered from its ``id_base``,
and saves their runs); a move whose client has gone by its end is saved here.
"""

from __future__ import annotations

import contextlib
import itertools
import logging
import os
import queue
import socket
import threading
import time
from dataclasses import dataclass, field
from multiprocessing.connection import Connection, answer_challenge, deliver_challenge
from pathlib import Path

from control import rendezvous, shm
from control.channel import command_name
from control.client import ControlClient, Event
from control.commands import Command, EmergencyStop, Shutdown, StartMove
from control.events import Commander, Died, MoveDone, Refused
from control.layout import MoveLayout
from control.recorder import save_run
from control.runs import decode_meta, run_from_segment

log = logging.getLogger("servodesk.controller")

JOIN_S = 5.0  # a connection must authenticate and say who it is within this
EVENTS_QUEUED = 512  # events waiting for a client; more and it is not reading: dropped
POLL_S = 0.1


@dataclass(eq=False)
class Peer:
    """An attached client: its connection, and the events waiting for it."""

    number: int
    name: str
    conn: Connection
    outgoing: queue.Queue[object] = field(default_factory=lambda: queue.Queue(EVENTS_QUEUED))
    connected: bool = True

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
                self.conn.send(record)
            except (OSError, ValueError):
                return


class ControllerService:
    """Serve ``client``'s controller on ``socket_path`` until ``stop`` (or its death)."""

    def __init__(self, client: ControlClient, socket_path: str | Path | None = None, *,
                 release_after_s: float = 1.0) -> None:
        self.client = client
        self.socket_path = Path(socket_path) if socket_path is not None else \
            rendezvous.default_socket()
        self.release_after_s = release_after_s
        self.stopped = threading.Event()
        self.why_stopped = ""
        self._lock = threading.RLock()
        self._peers: dict[int, Peer] = {}
        self._holder: Peer | None = None
        self._commander_beat = (0, 0.0)  # the heartbeat word as last seen changing, and when
        self._numbers = itertools.count(1)
        self._moves: dict[int, tuple[Peer, str]] = {}  # move id: its client, its segment
        self._claim()
        self._key = rendezvous.new_key(self.socket_path)  # first: who sees the socket can log in
        self._socket = self._listen()
        client.on_event = self._from_controller
        self._threads = [threading.Thread(target=self._accept, name="service-accept", daemon=True),
                         threading.Thread(target=self._watch_commander, name="service-watch",
                                          daemon=True)]
        for thread in self._threads:
            thread.start()

    def _claim(self) -> None:
        """The socket's directory, private; refused if a service listens there already (a
        socket file no one listens on is a dead service's: removed)."""
        rendezvous.private_dir(self.socket_path.parent)
        if self.socket_path.exists():
            with contextlib.suppress(ConnectionError, OSError), \
                    socket.socket(socket.AF_UNIX) as probe:
                probe.connect(str(self.socket_path))
                raise RuntimeError(f"a controller service already listens on {self.socket_path}: "
                                   "attach to it (servodesk --attach) or stop it first")
            self.socket_path.unlink()

    def _listen(self) -> socket.socket:
        """Bind the socket owner-only (created 0600 in the 0700 directory)."""
        sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        old = os.umask(0o177)
        try:
            sock.bind(str(self.socket_path))
        finally:
            os.umask(old)
        sock.listen(8)
        sock.settimeout(POLL_S)  # accept wakes to see ``stopped``
        return sock

    # -- connections -------------------------------------------------------------------------

    def _accept(self) -> None:
        while not self.stopped.is_set():
            try:
                sock, _ = self._socket.accept()
            except TimeoutError:
                continue
            except OSError:
                return
            sock.settimeout(None)
            conn = Connection(sock.detach())
            threading.Thread(target=self._serve, args=(conn,), name="service-client",
                             daemon=True).start()

    def _serve(self, conn: Connection) -> None:
        peer = self._join(conn)
        if peer is None:
            conn.close()
            return
        sender = threading.Thread(target=peer.deliver, name="service-events", daemon=True)
        sender.start()
        try:
            while not self.stopped.is_set() and peer.connected:
                if not conn.poll(POLL_S):
                    continue
                try:
                    record = conn.recv()
                except (EOFError, OSError):
                    break
                except Exception as exc:  # a message that does not unpickle is no command
                    peer.put(Refused("message", f"unreadable: {type(exc).__name__}: {exc}"))
                    continue
                self._request(peer, record)
        except OSError:
            pass
        finally:
            self._leave(peer, f"{peer.name} left")
            sender.join(timeout=1.0)
            conn.close()

    def _join(self, conn: Connection) -> Peer | None:
        """Authenticate (both ways, the key beside the socket) and greet a new client."""
        try:
            deliver_challenge(conn, self._key)
            answer_challenge(conn, self._key)
            if not conn.poll(JOIN_S):
                raise TimeoutError(f"no join within {JOIN_S:g} s")
            join = conn.recv()
            if not isinstance(join, rendezvous.Join):
                raise ValueError(f"a join expected, got {type(join).__name__}")
        except Exception as exc:  # a wrong key, a stranger, a client gone at once
            log.warning("refused a connection: %s: %s", type(exc).__name__, exc)
            return None
        client = self.client
        with self._lock:
            number = next(self._numbers)
            peer = Peer(number, f"{join.name} #{number} (pid {join.pid})", conn)
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
                conn.send(hello)
            except OSError:
                return None
            self._peers[number] = peer
        log.info("%s attached (%d attached)", peer.name, len(self._peers))
        return peer

    def _leave(self, peer: Peer, why: str) -> None:
        with self._lock:
            peer.connected = False
            self._peers.pop(peer.number, None)
            if self._holder is peer:
                self._release(f"{why}: command released, the controller holds")
        log.info("%s (%d attached)", why, len(self._peers))

    # -- requests from a client ---------------------------------------------------------------

    def _request(self, peer: Peer, record: object) -> None:
        if isinstance(record, rendezvous.TakeCommand):
            self._take(peer)
        elif isinstance(record, rendezvous.ReleaseCommand):
            with self._lock:
                if self._holder is peer:
                    self._release(f"{peer.name} released command; the controller holds")
                else:
                    peer.put(Refused("release command", "this client does not hold command"))
        elif isinstance(record, Command):
            self._relay(peer, record)
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
            self.client.heartbeat_on = False  # the commander's heartbeat thread beats now
            self._commander_beat = (self.client.heartbeat_ns, time.monotonic())
            self._broadcast(Commander(peer.name, f"{peer.name} took command"))

    def _release(self, reason: str) -> None:
        """Nobody holds command: the controller holds, this service keeps its heartbeat."""
        self._holder = None
        self.client.heartbeat_on = True
        with contextlib.suppress(Exception):
            self.client.hold()
        self._broadcast(Commander("", reason))
        log.info("%s", reason)

    def _relay(self, peer: Peer, command: Command) -> None:
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
            if not reason:
                try:
                    self.client.send(command)
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
        self._broadcast(record)

    def _broadcast(self, record: object) -> None:
        with self._lock:
            for peer in list(self._peers.values()):
                if not peer.put(record):
                    log.warning("%s does not read its events: disconnected", peer.name)
                    peer.connected = False  # its reader thread ends, and it leaves

    def _move_done(self, done: MoveDone) -> None:
        """Save the run of a move whose client has gone (else the client saves it)."""
        with self._lock:
            owner, segment = self._moves.pop(done.move_id, (None, ""))
        if owner is None or owner.connected or done.saved:
            return
        log.info("move %d of %s ended (%s) after it left: %s", done.move_id, owner.name,
                 done.status, save_departed(segment, done))

    def _watch_commander(self) -> None:
        """A commander whose heartbeat stops for ``release_after_s`` loses command."""
        while not self.stopped.wait(POLL_S):
            self.client.poll_events()  # broadcast already; the queue must not grow for ever
            with self._lock:
                holder = self._holder
                if holder is None:
                    continue
                beat, since = self._commander_beat
                now, seen = time.monotonic(), self.client.heartbeat_ns
                if seen != beat:
                    self._commander_beat = (seen, now)
                elif now - since > self.release_after_s:
                    self._release(f"{holder.name} silent for {self.release_after_s:g} s: "
                                  "command released, the controller holds")

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
            with contextlib.suppress(OSError):
                peer.conn.close()
        self.client.close()


def save_departed(name: str, done: MoveDone) -> str:
    """Save the run in move segment ``name`` where its client saved runs, and unlink the
    segment; what became of it, in words."""
    try:
        segment = shm.attach(name)
    except OSError as exc:
        return f"its segment is gone ({exc})"
    saved = False
    try:
        layout = MoveLayout.read_header(segment.buf)
        meta = decode_meta(layout.read_meta(segment.buf))
        run = run_from_segment(segment.buf, layout, meta, done.status, done.timeline)
        files = save_run(run, Path(str(meta["data_dir"])))
        saved = True
        return f"saved {files.json}"
    except (OSError, KeyError, TypeError, ValueError) as exc:
        return f"not saved ({exc}); its segment is kept for the next start to recover"
    finally:
        shm.release(segment, unlink=saved)
