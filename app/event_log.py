"""The session's event log: what happened to the robot and what the operator did about it.

Every E-stop (with its reason, and who pressed it when several clients attach) and
release, fault, limit and its clearing, move start and end (its status, its stalls), feed
override and feed hold, gain change and refusal, change of command (taken, released,
lost), taught position, link or UI loss and return, loop stall, controller death, and the
session's start and end becomes a ``LogEntry``: kept in memory for the Log tab and the
header, and appended as one JSON object a line to ``events.jsonl`` in the session's folder
of the data directory by a writer thread, so the UI thread never waits on the disk::

    {"time": "2026-11-21T13:21:05.123Z", "kind": "E-stop", "joint": null,
     "what": "latched: operator E-stop", "data": {"latched": true, ...}}
"""

from __future__ import annotations

import contextlib
import json
import os
import queue
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from datetime import UTC, datetime
from pathlib import Path

from control.rt.events import (
    CoefficientsApplied,
    Commander,
    ControllerEvent,
    Died,
    EStop,
    Fault,
    Initialised,
    MoveDone,
    MoveStarted,
    Notice,
    Refused,
)
from hw.machine import Machine

CAPACITY = 5_000  # entries kept in memory; the file keeps them all
SESSIONS = "sessions"  # the data directory's folder of session folders
FILE = "events.jsonl"
SERIOUS = frozenset({"E-stop", "fault", "limit", "link lost", "UI lost", "stall",
                     "controller died", "command lost"})
HELD_START_S = 1.0  # a move's start waits at most this for the end of the move before it


@dataclass(frozen=True)
class LogEntry:
    """One thing that happened: when (Unix time, s), what kind, to which joint ("" for none),
    in a sentence, and the record's fields."""

    wall: float
    kind: str
    what: str
    joint: str = ""
    data: dict[str, object] = field(default_factory=dict)

    @property
    def clock(self) -> str:
        """Local time of day, to the millisecond."""
        return datetime.fromtimestamp(self.wall).strftime("%H:%M:%S.%f")[:-3]

    @property
    def move_id(self) -> int | None:
        """The move a move start or end names (None for another entry)."""
        move_id = self.data.get("move_id") if self.kind in ("move start", "move end") else None
        return move_id if isinstance(move_id, int) else None

    @property
    def serious(self) -> bool:
        return self.kind in SERIOUS

    def line(self) -> str:
        """One line: time, kind, joint, what."""
        joint = f" {self.joint}" if self.joint else ""
        return f"{self.clock} {self.kind}{joint}: {self.what}"

    def to_json(self) -> str:
        stamp = datetime.fromtimestamp(self.wall, UTC).isoformat(timespec="milliseconds")
        return json.dumps({"time": stamp.replace("+00:00", "Z"), "kind": self.kind,
                           "joint": self.joint or None, "what": self.what, "data": self.data},
                          ensure_ascii=False, default=str)


def entries_of(record: ControllerEvent, machine: Machine, wall: float | None = None
               ) -> list[LogEntry]:
    """The log entries a controller or client event makes (none for one not worth logging)."""
    now = time.time() if wall is None else wall

    def entry(kind: str, what: str, joint: int = -1) -> LogEntry:
        name = machine.joints[joint].name if 0 <= joint < machine.n_joints else ""
        return LogEntry(now, kind, what, name, record.payload)

    match record:
        case EStop(latched=True, reason=reason):
            out = [entry("E-stop", f"latched: {reason}")]
            if reason.startswith("link fault"):
                out.append(entry("link lost", reason))
            return out
        case EStop(latched=False, reason=reason):
            return [entry("release", f"E-stop released: {reason}")]
        case Fault(kind="limit", joint=joint, message=text):
            return [entry("limit", text, joint)]
        case Fault(kind="ui_lost", message=text):
            return [entry("UI lost", text)]
        case Fault(kind=kind, joint=joint, message=text):
            return [entry("fault", f"{kind}: {text}", joint)]
        case MoveStarted():
            return [entry("move start", record.message)]
        case MoveDone(move_id=move_id, status=status, gaps=gaps):
            listed = ", ".join(f"{length:.3f} s at t = {t:.2f} s" for t, length in gaps)
            stalls = f"; stalls {listed}" if gaps else ""
            return [entry("move end", f"move {move_id}: {status}{stalls}")]
        case CoefficientsApplied():
            return [entry("gains", record.message)]
        case Notice(message=text) if text.startswith("controller stalled"):
            return [entry("stall", text)]
        case Notice(message=text) if text.startswith("link re-established"):
            return [entry("link back", text)]
        case Notice(message=text) if text.startswith("client is back"):
            return [entry("UI back", text)]
        case Notice(message=text):
            return [entry("notice", text)]
        case Refused():
            return [entry("refused", record.message)]
        case Initialised(status=status):
            return [entry("initialise", status)]
        case Died(message=text):
            return [entry("controller died", text)]
        case Commander(change="lost", reason=reason):
            return [entry("command lost", reason)]
        case Commander(reason=reason):
            return [entry("command", reason)]
    return []


class EventLog:
    """The session's entries, newest last, and their file (``open``), written by a thread."""

    def __init__(self, capacity: int = CAPACITY) -> None:
        self.capacity = capacity
        self.entries: list[LogEntry] = []
        self.open_moves: set[int] = set()  # moves whose start is logged and end is not yet
        self._held: list[LogEntry] = []  # starts that came before the end of the move before
        self.count = 0  # entries ever added (the list keeps the last ``capacity``)
        self.path: Path | None = None
        self.problem = ""  # why the file is not being written, once it is not
        self._queue: queue.SimpleQueue[LogEntry | None] = queue.SimpleQueue()
        self._writer: threading.Thread | None = None
        self._on_problem: Callable[[str], None] | None = None

    def open(self, data_dir: Path, machine: str,
             on_problem: Callable[[str], None] | None = None) -> Path:
        """Start writing to ``<data_dir>/sessions/<YYYYMMDD-HHMMSS>-<machine>-<pid>/events.jsonl``
        (UTC; the folder is made by the writer thread); entries added before are written first.
        ``on_problem`` is called once, from the writer thread, if the file cannot be written."""
        stamp = datetime.now(UTC).strftime("%Y%m%d-%H%M%S")
        folder = Path(data_dir) / SESSIONS / f"{stamp}-{machine}-{os.getpid()}"
        self.path = folder / FILE
        self._on_problem = on_problem
        self._writer = threading.Thread(target=self._write, args=(self.path,),
                                        name="servodesk-event-log", daemon=True)
        self._writer.start()
        self.add(LogEntry(time.time(), "session", f"session started: {machine}, pid "
                          f"{os.getpid()}", data={"folder": str(folder)}))
        return self.path

    def add(self, entry: LogEntry) -> LogEntry:
        """Keep ``entry`` and queue it for the file; never waits.

        Entries go in the order the controller's events happened. A move's start is raised
        by the client as it sends the move, its end by the controller: the next move can be
        sent (the status shows the last one over) before the last one's end has come back.
        So a move's start that comes while the move before is still open waits for that
        end (at most ``HELD_START_S``) and follows it."""
        if entry.kind == "move start" and self.open_moves:
            self._held.append(entry)
            return entry
        self._keep(entry)
        if entry.kind == "move end" and entry.move_id is not None:
            self.open_moves.discard(entry.move_id)
            if not self.open_moves:
                self._release_held(after=entry.wall)
        self._release_stale(entry.wall)
        return entry

    def _release_stale(self, now: float) -> None:
        """Log the held starts whose move's end did not come within ``HELD_START_S``."""
        if self._held and now - self._held[0].wall >= HELD_START_S:
            self.open_moves.clear()  # an end that did not come in time is not waited for
            self._release_held()

    def _release_held(self, after: float | None = None) -> None:
        """Log the held starts, ``after`` the end they waited for (at its time, when that is
        later than theirs: by the thread that took it, not on the controller's clock)."""
        held, self._held = self._held, []
        for entry in held:
            late = after is not None and entry.wall < after
            self._keep(replace(entry, wall=after) if late else entry)

    def _keep(self, entry: LogEntry) -> None:
        if entry.kind == "move start" and entry.move_id is not None:
            self.open_moves.add(entry.move_id)
        self.entries.append(entry)
        if len(self.entries) > self.capacity:
            del self.entries[: len(self.entries) - self.capacity]
        self.count += 1
        if not self.problem:
            self._queue.put(entry)

    @property
    def latest(self) -> LogEntry | None:
        self._release_stale(time.time())
        return self.entries[-1] if self.entries else None

    def move_just_stopped(self, status: str, within_s: float = 1.0) -> int | None:
        """The move whose end, ``status``, was logged within ``within_s`` of the newest entry
        (the controller ends a move and then says why: its fault comes right after), or
        None when no move was stopped so."""
        if not self.entries:
            return None
        newest = self.entries[-1].wall
        for entry in reversed(self.entries[-8:]):
            if newest - entry.wall > within_s:
                break
            status_of = entry.data.get("status")
            if entry.kind == "move end" and isinstance(status_of, str) \
                    and status_of.startswith(status):
                return entry.move_id
        return None

    def since(self, count: int) -> list[LogEntry]:
        """The entries added after the first ``count`` (those still kept)."""
        self._release_stale(time.time())
        new = self.count - count
        return self.entries[-new:] if new > 0 else []

    def close(self, timeout: float = 1.0) -> None:
        """Log the session's end, write what is queued and stop the writer."""
        if self._writer is not None:
            self._release_held()
            self.add(LogEntry(time.time(), "session", "session ended: servodesk closed"))
            self._queue.put(None)
            self._writer.join(timeout)
            self._writer = None

    def _write(self, path: Path) -> None:
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            with path.open("a", encoding="utf-8") as f:
                while (entry := self._queue.get()) is not None:
                    f.write(entry.to_json() + "\n")
                    f.flush()  # a crash of the app loses no line already logged
        except OSError as exc:
            self.problem = f"the event log cannot be written to {path}: {exc.strerror or exc}"
            if self._on_problem is not None:
                with contextlib.suppress(Exception):
                    self._on_problem(self.problem)
