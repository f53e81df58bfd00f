"""The session's event log: what happened to the robot and what the operator did about it.

Every E-stop (with its reason) and release, fault, limit, move start and end
(its status, its stalls), gain change, link or UI loss and return, loop stall
and controller death becomes a ``LogEntry``: kept in memory for the Log tab
and the header, and appended as one JSON object a line to ``events.jsonl`` in
the session's folder of the data directory by a writer thread, so the UI
thread never waits on the disk::

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
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path

from control.rt.events import (
    CoefficientsApplied,
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
                     "controller died"})


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
    return []


class EventLog:
    """The session's entries, newest last, and their file (``open``), written by a thread."""

    def __init__(self, capacity: int = CAPACITY) -> None:
        self.capacity = capacity
        self.entries: list[LogEntry] = []
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
        return self.path

    def add(self, entry: LogEntry) -> LogEntry:
        """Keep ``entry`` and queue it for the file; never waits."""
        self.entries.append(entry)
        if len(self.entries) > self.capacity:
            del self.entries[: len(self.entries) - self.capacity]
        self.count += 1
        if not self.problem:
            self._queue.put(entry)
        return entry

    @property
    def latest(self) -> LogEntry | None:
        return self.entries[-1] if self.entries else None

    def since(self, count: int) -> list[LogEntry]:
        """The entries added after the first ``count`` (those still kept)."""
        new = self.count - count
        return self.entries[-new:] if new > 0 else []

    def close(self, timeout: float = 1.0) -> None:
        """Write what is queued and stop the writer."""
        if self._writer is not None:
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
