"""What the app hands every tab when it builds it. The client comes later, when the controller
is up: the app hands it down with ``TabPage.client_ready``; a client attached to a controller
service is known from the start, and with it whether this TUI may change the files the
controller and the commander read (``Desk.refusal``, ``Desk.typed_path``). ``Desk.story``
logs what only the status shows changing (the feed, a joint leaving its limit)."""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path

from app.event_log import EventLog, LogEntry, entries_of
from app.history import History
from app.widgets.limit_bar import LimitWatch
from control.client import ControlClient
from control.rt.events import Refused
from control.rt.layout import Status
from hw.machine import Machine
from kinematics.unimate import Unimate2000B


class StatusStory:
    """What the controller's status shows changing that no event reports, into the event log:
    the feed override and the feed hold (this TUI's, or another client's commander's), and a
    joint reported at a limit coming back inside it (``LimitWatch``)."""

    def __init__(self, machine: Machine, events: EventLog) -> None:
        self.machine = machine
        self.events = events
        self.limits = LimitWatch(machine.lower, machine.upper)
        self.feed: tuple[float, bool] | None = None  # the override (rounded) and the hold
        self.read = 0  # log entries read for limits

    def update(self, status: Status) -> bool:
        """Log what changed since the last status; True when the last joint reported at a
        limit has just left it (a limit banner may go)."""
        for entry in self.events.since(self.read):
            joint = entry.data.get("joint")
            if entry.kind == "limit" and isinstance(joint, int):
                self.limits.reported(joint, entry.wall)
        self.read = self.events.count
        wall = time.time() - (time.monotonic() - status.wall_ns / 1e9)
        self._feed(status, wall)
        left = self.limits.cleared(status.position, wall)
        for j in left:
            joint = self.machine.joints[j]
            self.events.add(LogEntry(wall, "limit clear", f"{joint.name} back inside its limits "
                                     f"{joint.limit_text()}, at {status.position[j]:.1f}"
                                     f"{joint.symbol}", joint.name, {"joint": j}))
        return bool(left) and not self.limits.at

    def _feed(self, status: Status, wall: float) -> None:
        feed = (round(status.feed_override, 2), status.paused)
        before, self.feed = self.feed, feed
        if before is None or feed == before:
            return
        if feed[1] != before[1]:
            what = ("feed hold: the move decelerates along its path and holds" if feed[1]
                    else "feed resumed")
        else:
            what = f"feed override {before[0]:.0%} → {feed[0]:.0%}"
        self.events.add(LogEntry(wall, "feed", what, data={"override": feed[0],
                                                            "hold": feed[1]}))


@dataclass(frozen=True)
class Desk:
    """The machine and its kinematics, the backend's name, where runs are saved, the
    status history the sampler fills (200 Hz), the session's event log, and the client
    attached to a controller service (None: the app starts its own controller)."""

    machine: Machine
    model: Unimate2000B | None  # the closed-form kinematics; None for a machine without (the rig)
    backend: str  # sim or serial
    data_dir: Path
    history: History
    dt: float  # between a path's rows: the machine's sample time, or the thesis timing's
    events: EventLog = field(default_factory=EventLog)
    attached: ControlClient | None = None
    story: StatusStory = field(init=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "story", StatusStory(self.machine, self.events))

    @property
    def commanding(self) -> bool:
        """Whether this TUI commands: one that started its own controller always does."""
        return self.attached is None or self.attached.commanding

    def refusal(self, what: str) -> str:
        """Why ``what`` (a change to taught positions or gains, which the commander's moves
        use) is refused, logged as a refusal; "" when this TUI commands and may."""
        if self.commanding:
            return ""
        return self._refused(what, f"{self._role()}; take it first")

    def typed_path(self, text: str, what: str) -> Path:
        """The path the operator typed for ``what``, ``~`` expanded. A TUI that does not
        command may name only a path inside the data directory once ``..`` and symlinks are
        resolved (it gets that resolved path): ValueError, logged as a refusal, otherwise."""
        try:
            path = Path(text).expanduser()
        except RuntimeError as exc:  # ~somebody unknown
            raise ValueError(f"{what}: {exc}") from None
        if self.commanding:
            return path
        inside = self.data_dir.resolve()
        try:
            resolved = path.resolve()
        except (OSError, RuntimeError) as exc:  # a symlink loop
            raise ValueError(self._refused(what, f"{text!r}: {exc}")) from None
        if not resolved.is_relative_to(inside):
            raise ValueError(self._refused(what, (
                f"{self._role()}, so only a file inside the data directory {self.data_dir} "
                f"may be named; {text!r} is outside it: choose one inside, or take command "
                "first")))
        return resolved

    def _role(self) -> str:
        return self.attached.role if self.attached is not None else "commanding"

    def log_refusal(self, what: str, reason: str) -> str:
        """Log the refusal of ``what`` (a gain set the check refused, say) as the
        controller's refusals are; its sentence."""
        return self._refused(what, reason)

    def _refused(self, what: str, reason: str) -> str:
        """Log the refusal of ``what`` as the controller's refusals are; its sentence."""
        record = Refused(what, reason)
        for entry in entries_of(record, self.machine):
            self.events.add(entry)
        return record.message
