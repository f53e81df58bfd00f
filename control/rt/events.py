"""Events from the controller: frozen records, one per kind, sent after the tick's status.

``KIND`` names each for the client's ``Event.kind``; the fields are its payload;
``message`` (a field or a property on every kind) says it in a sentence.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import ClassVar


@dataclass(frozen=True)
class ControllerEvent:
    KIND: ClassVar[str] = "event"

    @property
    def payload(self) -> dict[str, object]:
        return asdict(self)


@dataclass(frozen=True)
class Ready(ControllerEvent):
    """The loop runs; ``notice`` says how it is scheduled."""

    KIND: ClassVar[str] = "ready"
    realtime: bool
    notice: str

    @property
    def message(self) -> str:
        return self.notice


@dataclass(frozen=True)
class Notice(ControllerEvent):
    KIND: ClassVar[str] = "notice"
    message: str


@dataclass(frozen=True)
class Refused(ControllerEvent):
    """A command the controller did not carry out, and why."""

    KIND: ClassVar[str] = "refused"
    command: str
    reason: str

    @property
    def message(self) -> str:
        return f"{self.command} refused: {self.reason}"


@dataclass(frozen=True)
class MoveDone(ControllerEvent):
    """A move ended: complete (in position), unsettled, aborted, refused, interrupted;
    ``saved`` is the run's JSON path when the controller saved it itself (its client gone)."""

    KIND: ClassVar[str] = "move_done"
    move_id: int
    status: str
    recorded: int
    saved: str = ""
    gaps: tuple[tuple[float, float], ...] = ()  # (t s, length s): controller stalls in the run
    feed: tuple[tuple[float, float], ...] = ()  # (t s, override): the feed override as set
    pauses: tuple[tuple[float, float], ...] = ()  # (t s, length s): feed holds
    supply: tuple[tuple[float, float], ...] = ()  # (t s, MPa): the supply pressure every 0.1 s
    # a closed-loop move's settle after its path (control/rt/settle.py): path_end_s, goal_time_s,
    # settle_s per joint (s after the path's end; None: never in position), goal_error per joint
    settle: dict[str, object] = field(default_factory=dict)
    # (t s, mode): the speed mode the move started in, then a change during it (to reduced)
    speed_mode: tuple[tuple[float, str], ...] = ()

    @property
    def timeline(self) -> dict[str, object]:
        return {"gaps": self.gaps, "feed": self.feed, "pauses": self.pauses,
                "supply": self.supply, "settle": self.settle, "speed_mode": self.speed_mode}

    @property
    def message(self) -> str:
        return self.status


@dataclass(frozen=True)
class Initialised(ControllerEvent):
    """The rig's initialise ended (section 3.5): zeroed at the bottom, or why not."""

    KIND: ClassVar[str] = "initialised"
    status: str

    @property
    def message(self) -> str:
        return self.status


@dataclass(frozen=True)
class Fault(ControllerEvent):
    """Something stopped motion: ``kind`` is limit, following_error, feedback, path_row,
    overrun, ui_lost, …; ``joint`` is -1 when no joint is to blame."""

    KIND: ClassVar[str] = "fault"
    kind: str
    joint: int
    message: str


@dataclass(frozen=True)
class EStop(ControllerEvent):
    """The E-stop latched or was released."""

    KIND: ClassVar[str] = "estop"
    latched: bool
    reason: str

    @property
    def message(self) -> str:
        return self.reason


@dataclass(frozen=True)
class Crash(ControllerEvent):
    """The control process failed outside the loop (at start, or for good)."""

    KIND: ClassVar[str] = "crash"
    message: str
    traceback: str


@dataclass(frozen=True)
class MoveStarted(ControllerEvent):
    """The client sent a move (raised in the client, not sent): its id, kind and length."""

    KIND: ClassVar[str] = "move_start"
    move_id: int
    move_kind: str
    seconds: float

    @property
    def message(self) -> str:
        return f"move {self.move_id} started: {self.move_kind}, {self.seconds:.1f} s"


@dataclass(frozen=True)
class CoefficientsApplied(ControllerEvent):
    """The client replaced the hold or track set (raised in the client, not sent); ``override``
    is the reason given for a set the gain check refused, "" when it passed."""

    KIND: ClassVar[str] = "coefficients"
    which: str
    name: str
    summary: str
    override: str = ""

    @property
    def message(self) -> str:
        how = (f"gain check overridden ({self.override}): {self.summary}" if self.override
               else f"gain check passed: {self.summary}")
        return f"{self.which} set {self.name!r} applied; {how}"


@dataclass(frozen=True)
class Died(ControllerEvent):
    """The client's watchdog: the control process is gone (raised in the client, not sent)."""

    KIND: ClassVar[str] = "died"
    message: str


@dataclass(frozen=True)
class Commander(ControllerEvent):
    """Who holds command of a controller service ("" nobody) and why that changed
    (``control/service.py``): sent to every attached client. ``change`` is what happened to
    command: ``taken``, ``released`` (by its holder), ``lost`` (its holder left or fell
    silent)."""

    KIND: ClassVar[str] = "commander"
    holder: str
    reason: str
    change: str = ""

    @property
    def message(self) -> str:
        return self.reason


EVENTS = (Ready, Notice, Refused, MoveDone, Initialised, Fault, EStop, Crash, MoveStarted,
          CoefficientsApplied, Died, Commander)  # what a channel carries back
