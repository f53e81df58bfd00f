"""The always-visible top of the screen: who and how the controller is, the latest entry of
the event log, a large E-stop lamp, and the fault banner that says what happened and what to
do."""

from __future__ import annotations

import time
from dataclasses import dataclass
from datetime import datetime

from rich.text import Text
from textual.app import ComposeResult
from textual.containers import Horizontal, Vertical
from textual.reactive import reactive
from textual.widgets import Static

from app.event_log import LogEntry
from app.widgets.fitting import clip_words, fit_parts
from app.widgets.live_text import LiveLines, LiveText
from control.rt.layout import Flag, Mode, Status

MODE_NAMES = {
    Mode.HOLD: "HOLD",
    Mode.FOLLOW_TRACK: "FOLLOW TRACK",
    Mode.MANUAL_ACTUATE: "MANUAL",
    Mode.TRACKING_ACTUATE: "TRACKING ACTUATE",
    Mode.INITIALISE: "INITIALISE",
}
STALE_S = 0.5  # a status older than this means the controller stopped publishing
LATE_WARN_US = 100.0
LATEST_ROOM = 24  # columns the latest event keeps before the machine's name is shortened


@dataclass(frozen=True)
class Link:
    """What the header knows about the controller besides its status."""

    state: str = "starting"  # starting, live, dead, failed
    reason: str = ""
    estop_sent: bool = False
    command: str = ""  # attached to a controller service: "commanding", or who holds command


class EStopLamp(LiveText):
    """A large lamp: green RUN, red E-STOP LATCHED, yellow STARTING, red CONTROLLER DOWN."""

    DEFAULT_CSS = """
    EStopLamp {
        width: 30;
        height: 3;
        content-align: center middle;
        text-align: center;
        text-style: bold;
    }
    EStopLamp.lamp-run {
        background: $success-darken-2;
        color: $text;
    }
    EStopLamp.lamp-estop {
        background: red;
        color: white;
    }
    EStopLamp.lamp-starting {
        background: $warning-darken-2;
        color: $text;
    }
    EStopLamp.lamp-down {
        background: darkred;
        color: white;
    }
    """

    def light(self, title: str, hint: str, lamp: str) -> None:
        if not self.has_class(lamp):
            self.set_classes(lamp)
        self.show(Text.assemble((title, "bold"), "\n", hint, justify="center"))


class StatusHeader(Horizontal):
    """Machine, backend and the latest logged event; link health, control mode, loop lateness;
    the E-stop lamp."""

    DEFAULT_CSS = """
    StatusHeader {
        height: 3;
        background: $panel;
    }
    #header-text {
        width: 1fr;
        padding: 0 1;
    }
    #header-text > * {
        height: 1;
    }
    """

    # its lines repaint themselves when they change: the header itself never needs to
    status: reactive[Status | None] = reactive(None, always_update=True, repaint=False)
    link: reactive[Link] = reactive(Link, repaint=False)
    latest: reactive[LogEntry | None] = reactive(None)

    def __init__(self, machine_title: str, backend: str, *, id: str | None = None) -> None:
        super().__init__(id=id)
        self.machine_title = machine_title
        self.backend = backend
        self._lines: tuple[LiveText, LiveText, EStopLamp] | None = None  # once mounted
        self._identity_width = -1

    def compose(self) -> ComposeResult:
        with Vertical(id="header-text"):
            yield LiveText(id="header-identity")
            # drawn by the changed cells: the numbers of the loop line, not the lamp beside it
            yield LiveLines(id="header-health")
            yield LiveLines(id="header-loop")
        yield EStopLamp(id="estop-lamp")

    def on_mount(self) -> None:
        self._lines = (self.query_one("#header-health", LiveText),
                       self.query_one("#header-loop", LiveText), self.query_one(EStopLamp))
        self._show()

    def watch_status(self) -> None:
        self._show()

    def watch_link(self) -> None:
        self._show()

    def watch_latest(self) -> None:
        if self.is_mounted:
            self._show_identity()

    def on_resize(self) -> None:
        self._show()

    def _show_identity(self) -> None:
        line = self.query_one("#header-identity", LiveText)
        self._identity_width = line.size.width
        line.show(self._identity(line.size.width))

    def _identity(self, width: int) -> Text:
        """Machine and backend, then the latest event ended at a word (80 columns: the
        machine's title and the backend shortened, so the event keeps room to be read)."""
        full = Text.assemble(("servodesk", "bold"), f"  {self.machine_title}  ·  ",
                             ("backend ", "dim"), self.backend)
        entry = self.latest
        if entry is None:
            return clip_words(full, width)
        if width - full.cell_len >= LATEST_ROOM:
            text = full + Text("   latest ", "dim")
        else:  # the backend's kind (sim, board) and as much of the title as a quarter holds
            text = Text.assemble(clip_words(Text(self.machine_title), max(width // 4, 14)),
                                 " · ", self.backend.split()[0], (" ▸ ", "dim"))
        text.append(entry.line(), "bold yellow" if entry.serious else "")
        return clip_words(text, width)

    def _show(self) -> None:
        if self._lines is None:
            return
        health, loop, lamp = self._lines
        status, link = self.status, self.link
        if health.size.width != self._identity_width:  # the screen or the lamp resized
            self._show_identity()
        health.show(clip_words(self._health(status, link), health.size.width))
        loop.show(self._loop(status, loop.size.width))
        self._lamp(lamp, status, link)

    def _lamp(self, lamp: EStopLamp, status: Status | None, link: Link) -> None:
        if link.state in ("dead", "failed"):
            lamp.light("CONTROLLER DOWN", "valves closed · restart", "lamp-down")
        elif status is not None and status.estop:
            lamp.light("E-STOP LATCHED", "^R to release", "lamp-estop")
        elif link.estop_sent:
            lamp.light("E-STOP SENT", "waiting for the controller", "lamp-estop")
        elif status is None:
            lamp.light("STARTING", "Esc/^E: E-STOP", "lamp-starting")
        else:
            lamp.light("RUN", "Esc/^E: E-STOP", "lamp-run")

    def _health(self, status: Status | None, link: Link) -> Text:
        text = Text("link ", style="dim")
        if link.state == "starting":
            text.append("starting the controller…", "yellow")
            return text
        if link.state in ("dead", "failed"):
            text.append("DOWN", "bold red")
            text.append(f"  {link.reason}", "red")
            return text
        if status is None:
            text.append("waiting for the first status", "yellow")
            return text
        age = time.monotonic() - status.wall_ns / 1e9
        if status.flags & Flag.LINK_FAULT:
            text.append("FAULT", "bold red")
        elif age > STALE_S:
            text.append(f"STALLED {age:.1f} s", "bold red")
        elif status.flags & Flag.UI_LOST:
            text.append("controller lost the UI's heartbeat", "bold yellow")
        else:
            text.append("ok", "bold green")
        counters = status.link
        if counters.get("frames_rx"):
            errors = sum(counters.get(k, 0) for k in
                         ("crc_errors", "truncated", "out_of_order", "link_lost"))
            text.append(f"  rx {counters['frames_rx']} · errors {errors}",
                        "yellow" if errors else "dim")
        text.append("   mode ", "dim")
        if status.estop or link.estop_sent:  # the controller holds, and nothing moves it
            text.append("E-STOP", "bold red")
        else:
            text.append(MODE_NAMES.get(status.mode, str(status.mode)), "bold cyan")
        # reduced speed (T1) or automatic, the controller's; automatic in the warning colour
        text.append(*(("  T1 250 mm/s", "bold green") if status.speed_mode == "reduced"
                      else ("  AUTO", "bold black on yellow")))
        if status.move_total and not status.estop:
            pct = 100.0 * status.move_done / status.move_total
            text.append(f"  move {status.move_id} {pct:3.0f} %", "cyan")
        if status.settling:  # the path is over: the move holds its end until in position
            text.append("  settling", "bold yellow")
        if status.paused:
            text.append("  FEED HOLD", "bold yellow")
        if status.feed_override != 1.0:
            text.append(f"  feed {status.feed_override:.0%}", "bold yellow")
        if not status.homed:
            text.append("   NOT INITIALISED", "bold yellow")
        if link.command == "commanding":
            text.append("   COMMANDING", "bold green")
        elif link.command:
            text.append(f"   {link.command}", "bold magenta")
        return text

    def _loop(self, status: Status | None, width: int) -> Text:
        """Lateness, compute and overruns first; the max, tick and clock as room allows."""
        if status is None:
            return Text("loop ", style="dim")
        late_style = "bold yellow" if status.late_max_us > LATE_WARN_US else ""
        parts = [(Text("loop ", style="dim"), 0),
                 (Text(f"late {status.late_last_us:5.1f} µs", late_style), 0),
                 (Text(f" (max {status.late_max_us:.0f})", "dim"), 2),
                 (Text(f"  compute {status.compute_last_us:5.1f} µs"), 1),
                 (Text(f"  overruns {status.overruns}", "bold red" if status.overruns else ""),
                  0 if status.overruns else 3),
                 (Text(f"  tick {status.tick}  t {status.time_s:8.2f} s", "dim"), 5)]
        if status.flags & Flag.REALTIME:
            parts.append((Text("  SCHED_FIFO", "green"), 4))
        return fit_parts(parts, width)


class FaultBanner(Static):
    """The latest fault in plain words: what happened, and what to do, each line with the time
    it first appeared (a lesser fault added below a latched E-stop keeps the E-stop's time on
    its line). Hidden when clear."""

    DEFAULT_CSS = """
    FaultBanner {
        height: auto;
        max-height: 4;
        padding: 0 1;
        background: $error-darken-2;
        color: white;
        text-style: bold;
    }
    """

    message: reactive[str] = reactive("")

    def __init__(self, *, id: str | None = None) -> None:
        super().__init__(id=id)
        self.shown_at: dict[str, float] = {}  # each line shown, and when it first was

    def watch_message(self, message: str) -> None:
        self.display = bool(message)
        now = time.time()
        lines = message.splitlines()
        self.shown_at = {line: self.shown_at.get(line, now) for line in lines}
        text = Text()
        for i, line in enumerate(lines):
            clock = datetime.fromtimestamp(self.shown_at[line]).strftime("%H:%M:%S")
            text.append_text(Text.assemble("\n" if i else "", ("⚠ " if not i else "  ", "bold"),
                                           (clock, "not bold"), "  ", line))
        if lines:
            text.append("   (^L dismiss)", "dim")
        self.update(text)
