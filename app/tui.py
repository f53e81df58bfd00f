"""The servodesk TUI: the thesis's ``option`` menu and ``visual`` printer as one Textual app.

It talks to the robot only through ``control.ControlClient``, started in a
worker so the screen is up at once, and closed on every way out (quit, an
exception, the terminal going away). E-stop is bound with priority on every
screen to Escape and to ctrl+e, which arrives as a single byte and so is not
held back by the terminal's escape-sequence timeout (~100 ms for a lone Escape).
"""

from __future__ import annotations

import asyncio
import contextlib
import gc
import importlib
import threading
import time
from collections import deque
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass, replace
from functools import partial
from pathlib import Path
from typing import TYPE_CHECKING, ClassVar, Self, cast

from textual.app import App, ComposeResult
from textual.binding import Binding
from textual.driver import Driver
from textual.screen import ModalScreen
from textual.widgets import Select, TabbedContent, TabPane

from app.controller_start import TUI_CLIENT, ControllerStart
from app.desk import Desk
from app.event_log import LogEntry, entries_of
from app.history import SAMPLE_HZ, History, Sampler
from app.messages import ClientFailed, ClientReady, ControllerEvent, RunsChanged
from app.priority import Priority, raise_priority, raise_priority_under, restore
from app.screens.live import LiveScreen
from app.tabs.tab import TabPage
from app.widgets.dialogs import ConfirmScreen
from app.widgets.header import FaultBanner, StatusHeader
from app.widgets.key_bar import KeyBar
from app.widgets.tab_bar import TabBar
from control.client import ControlClient, ControllerError, Event
from control.motion.positions import Position
from control.motion.robot_model import model_of
from control.recorder import default_data_dir
from control.rt.events import Commander, Died, EStop, Fault, Initialised, Notice, Refused
from control.rt.layout import Mode, Status
from control.timing import Timing
from hw.machine import Machine, load_machine

if TYPE_CHECKING:
    from app.tabs.latency import LatencyTab
    from app.tabs.moves import MovesTab
    from app.tabs.positions import PositionsTab
    from app.tabs.runs import RunsTab

HEADER_HZ = 10.0
# the history's rate while the Scope is hidden: its past is then drawn from 50 samples a
# second (two or more a column of a 10 s window), and the sampler's reads, 2 % of a core at
# SAMPLE_HZ, cost a quarter of that on the other tabs
HIDDEN_SCOPE_HZ = 50.0
FIRST_TAB = "jog"  # the tab shown at start: the only one built before the first frame
BUILD_GAP_S = 0.02  # between two tabs built after it: the keys and the header's turn
STALL_DUPLICATE_S = 2.0  # a stall the Latency tab sees this soon after the controller's notice
SETTLE_S = 1.5  # after a tab's first frames its long-lived objects exist
FREEZE_S = 5.0  # and every so often after: the widgets' line caches keep growing
OBSERVE_ONLY = ("this view observes only; it cannot take command (--observe-only: servodesk "
                "serve without --command)")


@dataclass(frozen=True)
class TabKind:
    """A tab's title (its class's ``TITLE``) and where its class is, imported only when the
    tab is first made: the first frame waits for the first tab's code alone."""

    title: str
    module: str
    name: str

    def load(self) -> type[TabPage]:
        return getattr(importlib.import_module(self.module), self.name)


TABS: tuple[tuple[str, TabKind], ...] = (
    ("jog", TabKind("Jog", "app.tabs.jog", "JogTab")),
    ("moves", TabKind("Moves", "app.tabs.moves", "MovesTab")),
    ("scope", TabKind("Scope", "app.tabs.scope", "ScopeTab")),
    ("status", TabKind("Status", "app.tabs.status", "StatusTab")),
    ("tuning", TabKind("Tuning", "app.tabs.tuning", "TuningTab")),
    ("runs", TabKind("Runs", "app.tabs.runs", "RunsTab")),
    ("latency", TabKind("Latency", "app.tabs.latency", "LatencyTab")),
    ("identify", TabKind("Identify", "app.tabs.identify", "IdentifyTab")),
    ("positions", TabKind("Positions", "app.tabs.positions", "PositionsTab")),
    ("log", TabKind("Log", "app.tabs.log", "LogTab")),
    ("program", TabKind("Program", "app.tabs.program", "ProgramTab")),
)
FAULT_ADVICE = {
    "limit": "Drive it back with the opposite jog key, or run a move that stays inside the "
             "limits.",
    "following_error": "Check the hydraulic supply and the valve, slow the move down or raise "
                       "the gains (Tuning), then run it again.",
    "ui_lost": "The UI missed its heartbeat; it is back now, and every joint holds.",
    "crash": "Every valve is closed. Quit (^Q) and start servodesk again.",
    "initialise": "Check that the ram can move down freely, then run Initialise again (Moves).",
    "path_row": "The move's data was damaged in shared memory; the robot holds. Run the move "
                "again; if it repeats, report it.",
    "overrun": "The controller could not keep its 1 ms ticks (a flooded link, a starved CPU); "
               "the robot holds. Check the I/O board and what else runs, then run the move "
               "again.",
}


def estop_advice(reason: str, port: str | None) -> str:
    """What to do about a latched E-stop, by its reason."""
    if reason.startswith("E-stop input"):
        return "Release the E-stop button, then press ^R to release the latch."
    if reason.startswith("link fault"):
        where = f" ({port})" if port else ""
        return f"Check the I/O board's cable and power{where}; when the link is back, press ^R."
    if reason.startswith("controller error"):
        return "A fault in the controller: quit (^Q), restart servodesk, and report the message."
    if reason.startswith("feedback fault"):
        return ("Do not trust that joint's reading: check its encoder, cable and valve and the "
                "hydraulic supply before you press ^R.")
    return "Every valve is closed. When it is safe, press ^R to release (the joints then hold)."


class Tabs(Mapping[str, TabPage]):
    """The app's tabs by name, in the order of ``TABS``; each is made (its module imported)
    when first asked for."""

    def __init__(self, desk: Desk) -> None:
        self._desk = desk
        self._kinds = dict(TABS)
        self._made: dict[str, TabPage] = {}

    def __getitem__(self, name: str) -> TabPage:
        tab = self._made.get(name)
        if tab is None:
            tab = self._made[name] = self._kinds[name].load()(self._desk, id=f"tab-{name}")
        return tab

    def __iter__(self) -> Iterator[str]:
        return iter(self._kinds)

    def __len__(self) -> int:
        return len(self._kinds)

    def made(self) -> list[TabPage]:
        """The tabs made so far (the others' code may not be imported yet)."""
        return list(self._made.values())

    def made_tab(self, name: str) -> TabPage | None:
        return self._made.get(name)


class QuitScreen(ConfirmScreen):
    """The question before quitting mid-move or latched (one at a time)."""


class ServodeskApp(App[None]):
    """The operator's workstation for one machine and backend."""

    # the whole screen's rules, the form fields' (tabs use their classes too), each tab's
    CSS_PATH: ClassVar = ["servodesk.tcss", "widgets/fields.tcss",
                          *[f"tabs/{name}.tcss" for name, _ in TABS]]
    TITLE = "servodesk"
    # the screen's classes the stylesheets lay the tabs out by: 80×24 is -narrow -short,
    # 120×36 -medium -tall, 160×48 -wide -tall (tests/app/test_tui_sizes.py)
    HORIZONTAL_BREAKPOINTS: ClassVar = [(0, "-narrow"), (110, "-medium"), (150, "-wide")]
    VERTICAL_BREAKPOINTS: ClassVar = [(0, "-short"), (30, "-tall")]
    BINDINGS: ClassVar = [
        Binding("escape,ctrl+e", "estop", "E-STOP", priority=True, key_display="Esc/^E"),
        Binding("ctrl+r", "reset", "release E-stop…", priority=True),
        Binding("ctrl+s", "run_move", "run move", priority=True),
        Binding("ctrl+g", "hold", "hold", tooltip="abort any move, hold every joint where it is",
                priority=True),
        Binding("ctrl+l", "dismiss_fault", "dismiss fault", priority=True),
        Binding("ctrl+f", "feed_hold", "feed hold/resume", priority=True,
                tooltip="decelerate the move along its path and hold; again to resume"),
        Binding("ctrl+down", "feed(-1)", "feed −10 %", priority=True, key_display="^↓"),
        Binding("ctrl+up", "feed(1)", "feed +10 %", priority=True, key_display="^↑"),
        Binding("ctrl+t", "teach", "teach", tooltip="name where the joints are now "
                "(Positions tab)"),
        Binding("ctrl+y", "speed_mode", "T1/AUTO", priority=True, key_display="^Y",
                tooltip="reduced speed (T1: the tool at most 250 mm/s) at once, or automatic "
                "(full speed) after asking"),
        *[Binding(f"f{i + 1}", f"show_tab('{name}')", f"{kind.title} tab", show=False,
                  priority=True) for i, (name, kind) in enumerate(TABS)],
        # not priority: in a text field ^K is the field's (delete to the end), not a command
        Binding("ctrl+k", "take_command", "take command",
                tooltip="command the controller servodesk controller runs (the others observe)"),
        Binding("ctrl+o", "release_command", "release command", priority=True,
                tooltip="the controller holds; another client may take command"),
        Binding("ctrl+q", "quit", "quit", priority=True),
        # priority: from a Moves field too, to see its path (Home goes to a field's start)
        Binding("ctrl+a", "arm_view", "arm view", priority=True, tooltip="the arm live in 3D "
                "on the whole screen, with the Moves tab's path and the named positions"),
        # the focus moves as the app takes the key, so the keys typed after it go to the next
        # field (a focus key left to the screen moved it only after the keys behind it)
        Binding("tab", "focus_next", "next field", show=False, priority=True),
        Binding("shift+tab", "focus_previous", "previous field", show=False, priority=True),
    ]

    def get_driver_class(self) -> type[Driver]:
        """Textual's driver, but on a Linux terminal one that resumes only from its own
        suspend (``app/terminal_driver.py``)."""
        from app.terminal_driver import TerminalDriver

        driver = super().get_driver_class()
        return TerminalDriver if issubclass(TerminalDriver, driver) else driver

    def __init__(self, machine: str | Path | Machine = "unimate2000b", backend: str = "sim",
                 port: str | None = None, data_dir: str | Path | None = None,
                 lockstep: bool = False, *, seed: int = 0, sim_options: dict | None = None,
                 client_options: dict | None = None, client: ControlClient | None = None,
                 observe_only: bool = False, take_command: bool = False,
                 starting: ControllerStart | None = None, build_behind: bool = True) -> None:
        """``client``: one already attached to a controller service (``attached_app``),
        used instead of starting a controller; ``observe_only``: this TUI never takes command
        (^K says why); ``take_command``: it takes command as soon as it is attached;
        ``starting``: the controller already being started for this app (``servodesk``);
        ``build_behind``: the tabs not shown are built once the screen is live (False: each
        when first shown or needed, as the tests that open few tabs want)."""
        super().__init__()
        self._attached = client
        self._starting = starting
        self.observe_only = observe_only
        self._take_at_start = take_command
        self.build_behind = build_behind
        self.machine = machine if isinstance(machine, Machine) else load_machine(machine)
        self.model = model_of(self.machine)  # MachineError for a DH table of another form
        self.backend = backend
        self.port = port
        self.data_dir = Path(data_dir) if data_dir is not None else default_data_dir()
        self.lockstep = lockstep
        self.seed = seed
        self.sim_options = sim_options
        self.client_options = client_options or {}
        self.history = History(self.machine.n_joints)
        timing = self.client_options.get("timing") or Timing()
        self.desk = Desk(self.machine, self.model, backend, self.data_dir, self.history,
                         timing.sample_time_s(self.machine), attached=client)
        self.timing_text = "" if timing.name == "servodesk" else timing.describe(self.machine)
        self.client: ControlClient | None = None
        self.priority: Priority | None = None  # the UI thread's, raised while the app runs
        self.client_problem = ""
        self.sampler: Sampler | None = None
        self._client_lock = threading.Lock()
        # the client calls that may wait seconds (^K, ^O, ^Y), oldest first: the first is made
        self._calls: deque[Callable[[], object]] = deque()
        self._calls_lock = threading.Lock()
        self._client_closing = False
        self._estop_pending = False
        self._active: TabPage | None = None
        self._settled: set[str] = set()
        self.tabs = Tabs(self.desk)
        self._building: dict[str, asyncio.Event] = {}  # tabs being mounted: set once mounted
        self._wanted = FIRST_TAB  # the tab last chosen (shown once it is built)
        self._rest_started = False  # the tabs not shown are being built (once live)
        self._quitting = False  # asked to quit: no tab is built from now on
        self._positions: tuple[Position, ...] | None = None  # as the Positions tab last read
        self._early: list[ClientReady | ClientFailed | ControllerEvent] | None = []
        self.fault_kind = ""
        self.feed_pct = 100  # the feed override as this TUI last set it, in %
        self._feed_sent = {100}  # what it has sent since the status last showed its own value
        self.estop_latched = False  # an E-stop sent or reported, until the controller releases it
        self._estop_banner = ""  # the latched E-stop's banner, which nothing lesser replaces
        self._estop_reason = ""

    @classmethod
    def attached(cls, socket: str | Path | None = None, *, observe_only: bool = False,
                 take_command: bool = False, build_behind: bool = True) -> Self:
        """This app on a client attached to ``servodesk controller`` at ``socket``
        (``attached_app``); a subclass's (the tests') app, or one that builds its tabs only
        when first shown (``build_behind`` as ``__init__``'s), attaches the same way."""
        client = ControlClient.attach(socket or None, name="servodesk TUI")
        try:
            return cls(client.machine, client.backend, client.port, client.data_dir,
                       client_options={"timing": client.timing}, client=client,
                       observe_only=observe_only, take_command=take_command,
                       build_behind=build_behind)
        except BaseException:
            client.close()
            raise

    # -- layout --------------------------------------------------------------------------------

    def get_default_screen(self) -> LiveScreen:
        return LiveScreen(id="_default")  # an update draws the rows it changed, not the screen

    def compose(self) -> ComposeResult:
        backend = self.backend + (f" {self.port}" if self.port else "")
        if self.lockstep:
            backend += " (lockstep)"
        if self.timing_text:
            backend += f"  ·  {self.timing_text}"
        yield StatusHeader(self.machine.title, backend, id="header")
        yield FaultBanner(id="fault")
        # only the first tab is made and built (composed, styled, mounted) before the first
        # frame: the others once the screen is live, or when first shown (``_build``)
        with TabBar(id="tabs"):
            for i, (name, kind) in enumerate(TABS):
                with TabPane(f"F{i + 1} {kind.title}", id=f"pane-{name}"):
                    if name == FIRST_TAB:
                        yield self.tabs[name]
        yield KeyBar()

    def on_mount(self) -> None:
        # kept, not queried: a controller event may still arrive while the screen is torn down
        self.header = self.query_one(StatusHeader)
        self.banner = self.query_one(FaultBanner)
        self.banner.display = False
        gc.freeze()  # see _freeze_long_lived; no collection: the controller may be up already
        self.set_interval(1.0 / HEADER_HZ, self._refresh_header)
        self.set_interval(FREEZE_S, self._freeze_long_lived)
        self._activate(FIRST_TAB)
        if self.priority is not None and self.priority.notice:
            self.notify(self.priority.notice, title="UI", severity="warning", timeout=10)
        early, self._early = self._early or [], None
        for message in early:  # the controller was quicker than the screen
            self._dispatch_client_message(message)

    def _held_back(self, message: ClientReady | ClientFailed | ControllerEvent) -> bool:
        """Keep a message of the client that came before the screen was mounted; drop one
        that comes once the app is closing (its screen's widgets are gone, and unmounting
        closes the client). A controller ready as the operator quit crashed the exit."""
        if not self.is_running:
            return True
        if self._early is None:
            return False
        self._early.append(message)
        return True

    def _dispatch_client_message(self, message: ClientReady | ClientFailed | ControllerEvent
                                 ) -> None:
        if isinstance(message, ClientReady):
            self.on_client_ready(message)
        elif isinstance(message, ClientFailed):
            self.on_client_failed(message)
        else:
            self.on_controller_event(message)

    def on_load(self) -> None:
        gc.freeze()  # what is imported so far: building the screen collects only its own
        # before any thread or process the UI starts; attached, never above the service's
        self.priority = (raise_priority() if self._attached is None
                         else raise_priority_under(self._attached.service_pid))
        self.start_client()  # the controller starts while the screen is built
        self.desk.events.open(self.data_dir, self.machine.name, self._log_problem)

    def _log_problem(self, problem: str) -> None:
        """The event log's file cannot be written (from its writer thread)."""
        with contextlib.suppress(RuntimeError):  # the app has closed
            self.call_from_thread(self.notify, f"{problem}; the Log tab still lists this "
                                  "session's events", severity="warning", timeout=10)

    def record_event(self, entry: LogEntry) -> None:
        """Add ``entry`` to the session's event log; the header shows the newest."""
        self.desk.events.add(entry)
        self.header.latest = entry

    def tab(self, name: str) -> TabPage:
        return self.tabs[name]

    def built_tabs(self) -> list[TabPage]:
        """The tabs built so far (shown at least once): the others have no widgets yet."""
        return [tab for tab in self.tabs.made() if tab.is_attached]

    async def _build(self, name: str) -> TabPage:
        """Mount tab ``name`` in its pane (hidden until chosen) and tell it what the others
        were told while it was not built: the client, its death, a latched E-stop."""
        if self.tabs.made_tab(name) is None:  # its module imported off the event loop: the
            await asyncio.to_thread(dict(TABS)[name].load)  # keys are served meanwhile
            if self._quitting:  # ^Q came meanwhile and did not wait: no pane to mount into
                return self.tab(name)
        tab = self.tab(name)
        if name in self._building:  # chosen while the background mounts it: once it is
            await self._building[name].wait()
        elif not tab.is_attached:
            done = self._building[name] = asyncio.Event()
            try:
                await self.query_one(f"#pane-{name}", TabPane).mount(tab)
            finally:
                del self._building[name]
                done.set()
            if self.client is not None:
                tab.client_ready(self.client)
            if self.client_problem:
                tab.client_down(self.client_problem)
            if self.estop_latched:
                tab.estop(latched=True)
            if self._positions is not None:
                self._offer_positions(tab, self._positions)
            if name == "moves" and self._positions is None:
                await self._build("positions")  # it reads the named positions the forms offer
        return tab

    def _start_building(self) -> None:
        if self.build_behind and not self._rest_started:
            self._rest_started = True
            self.run_worker(self._build_the_rest(), group="build")

    async def _build_the_rest(self) -> None:
        """Build the tabs not shown yet, one at a time, keys and frames served between: a
        tab is then ready when first chosen, and neither the first frame nor the first live
        one waited for them. A worker, not a callback: a callback holds the screen's (or
        the app's) messages until it returns, so nothing was painted (or no key served)
        while every tab was built."""
        for name, _ in TABS:
            if not self.is_running or self._quitting:
                return
            await self._build(name)
            await asyncio.sleep(BUILD_GAP_S)

    async def _build_and_show(self, name: str) -> None:
        await self._build(name)
        if self._wanted == name and self.is_running:
            self._activate(name)

    # -- the client's life ---------------------------------------------------------------------

    def _start_client_blocking(self) -> None:
        if self._attached is not None:
            self._attached.on_event = self._event_from_thread
            self.client = self._attached
            self._post(ClientReady(self._attached))
            return
        try:
            client = ControlClient(
                self.machine, self.backend, port=self.port, seed=self.seed,
                lockstep=self.lockstep, data_dir=self.data_dir, sim_options=self.sim_options,
                on_event=self._event_from_thread,
                **{**TUI_CLIENT, **self.client_options})
        except Exception as exc:  # ControllerError, a bad port, no shared memory…
            self._client_started(exc)
            return
        self._client_started(client)

    def _client_started(self, client: ControlClient | Exception) -> None:
        """The controller is up, or why it is not (from the thread that started it)."""
        if isinstance(client, Exception):
            self._post(ClientFailed(self._startup_advice(client)))
            return
        with self._client_lock:
            if self._client_closing:
                client.close()
                return
            self.client = client
        self._post(ClientReady(client))

    def start_client(self) -> None:
        if self._starting is not None:  # started before the screen was imported
            self._starting.hand_over(self._client_started, self._event_from_thread)
            return
        self.run_worker(self._start_client_blocking, thread=True, group="client",
                        name="start controller")

    def _startup_advice(self, exc: Exception) -> str:
        text = f"{type(exc).__name__}: {exc}" if not isinstance(exc, ControllerError) else str(exc)
        if self.backend == "serial":
            return (f"{text}. Check --port (a device, the emulator's pty path or "
                    "socket://HOST:PORT) and that the I/O board is powered; then restart.")
        return f"{text}. Quit (^Q) and start servodesk again; if it repeats, report this message."

    def _event_from_thread(self, event: Event) -> None:
        self._post(ControllerEvent(event))

    def _post(self, message: object) -> None:
        """Post from any thread; a message after the app has closed is dropped."""
        with contextlib.suppress(RuntimeError):
            self.post_message(message)  # type: ignore[arg-type]

    def on_client_ready(self, message: ClientReady) -> None:
        if self._held_back(message):
            return
        client = message.client
        self.sampler = Sampler(client.status, self.history)
        self._pace_sampler()
        self.sampler.start()
        self._link(state="live", command=_role(client))
        if self._estop_pending:
            self._send_estop()
        if client.notice:
            self.notify(client.notice, title="controller", timeout=6)
        if self._take_at_start:
            self.action_take_command()
        for tab in self.built_tabs():
            tab.client_ready(client)
        if self._active is not None:
            self._active.refresh_live()

    def on_client_failed(self, message: ClientFailed) -> None:
        if self._held_back(message):
            return
        self._client_down(message.reason)
        self._link(state="failed", reason="controller did not start")
        self._start_building()
        self.record_event(LogEntry(time.time(), "fault", f"start: {message.reason}"))
        self._fault("start", f"The controller did not start: {message.reason}")

    def shutdown_client(self) -> None:
        """Stop sampling and close the client (valves closed, memory unlinked); idempotent."""
        with self._client_lock:
            self._client_closing = True
            client, self.client = self.client, None
        if self.sampler is not None:
            self.sampler.stop()
        if client is not None:
            client.close()

    def on_unmount(self) -> None:
        self.shutdown_client()
        self.desk.events.close()
        if self.priority is not None:
            restore(self.priority)

    # -- events from the controller ------------------------------------------------------------

    def on_controller_event(self, message: ControllerEvent) -> None:
        if self._held_back(message):  # also the events of closing the client, after the screen
            return
        event = message.event
        if (isinstance(event.record, EStop) and event.record.latched and self._estop_banner
                and event.record.reason == self._estop_reason):
            return  # latched again for the same reason (the E-stop word, then its command)
        arrived = time.time() - (time.monotonic() - event.wall)
        for entry in entries_of(event.record, self.machine, arrived):
            self.record_event(entry)
        match event.record:
            case EStop(latched=True, reason=reason):
                self.estop_latched = True
                self._estop_tabs(latched=True)
                self._estop_reason = reason
                self._estop_banner = f"E-STOP latched: {reason}. {estop_advice(reason, self.port)}"
                self._fault("estop", self._estop_banner)
            case EStop(latched=False):
                self.estop_latched = False
                self._estop_banner = ""
                self._estop_tabs(latched=False)
                self._link(estop_sent=False)
                if self.fault_kind == "estop":
                    self.action_dismiss_fault()
                self.notify("E-stop released: every joint holds where it is")
            case Fault(kind=kind, message=text):
                advice = FAULT_ADVICE.get(kind, "")
                if kind == "ui_lost" and (stopped := self.desk.events.move_just_stopped(
                        "interrupted: client silent")) is not None:
                    advice += f" It stopped move {stopped}: run it again."
                self._fault(kind, f"{text}. {advice}".strip())
            case Died(message=text):
                self._died()
                self._fault("died", text)
            case Notice() | Refused() as record:
                self.notify(record.message, title="controller", timeout=6)
            case Commander(reason=reason):
                self._link(command=_role(self.client))
                self.notify(reason, title="command", timeout=6)
            case Initialised(status=status):
                moves = cast("MovesTab", self.tab("moves"))
                if moves.is_attached:
                    moves.initialised(status)
                self.notify(f"initialise: {status}")

    def _fault(self, kind: str, message: str) -> None:
        """Show ``message`` in the banner. While the E-stop is latched its reason stays on
        top: a lesser fault (the client silent, a limit) is added below it, never in its place."""
        if self.estop_latched and self._estop_banner and kind not in ("estop", "died"):
            kind, message = "estop", f"{self._estop_banner}\nAlso: {message}"
        self.fault_kind = kind
        self.banner.message = message
        self.refresh_bindings()

    def on_latency_tab_stalled(self, message: LatencyTab.Stalled) -> None:
        """The Latency tab's watch saw a stall; the controller's own notice of a stall
        during a move says more (the move, its time), so one of those just now stands."""
        now = time.time()
        if any(e.kind == "stall" and e.data.get("message") and now - e.wall < STALL_DUPLICATE_S
               for e in self.desk.events.entries[-20:]):
            return
        self.record_event(LogEntry(now, "stall", message.what,
                                   data={"late_max_us": message.late_max_us}))

    def on_runs_changed(self, message: RunsChanged) -> None:
        cast("RunsTab", self.tab("runs")).mark_stale()

    def on_moves_tab_run_unsaved(self, message: MovesTab.RunUnsaved) -> None:
        cast("RunsTab", self.tab("runs")).keep_unsaved(message.run)

    def on_positions_tab_changed(self, message: PositionsTab.Changed) -> None:
        self._positions = message.positions  # for the forms of a Moves tab built later
        self._offer_positions(self, message.positions)

    @staticmethod
    def _offer_positions(where: ServodeskApp | TabPage, positions: tuple[Position, ...]
                         ) -> None:
        """Offer the named positions to the via-points forms in ``where``."""
        from app.tabs.path_forms import ViaPointsForm  # the Moves tab's: loaded with it

        for form in where.query(ViaPointsForm):
            form.offer(positions)

    def on_moves_tab_hold_requested(self, message: MovesTab.HoldRequested) -> None:
        self.action_hold()

    def on_moves_tab_feed_requested(self, message: MovesTab.FeedRequested) -> None:
        if message.steps:
            self.action_feed(message.steps)
        else:
            self.action_feed_hold()

    def _freeze_long_lived(self) -> None:
        """Exempt the widgets and caches built so far from full garbage collections.

        A full collection holds the GIL while it scans every tracked object: with the
        whole UI in view that is 0.1-0.4 s, long enough to starve the client's heartbeat
        thread (the controller then aborts the move and holds). Done at start and once
        after each tab's first frames, full collections scan only what is new since: a
        few tens of ms. Frozen objects are still freed by reference counting.

        The widgets' caches of rendered lines (Textual's Strips, each with its FIFOCaches) grow
        by thousands of objects a second while tabs are switched in a real terminal; unfrozen,
        the full collections they trigger every second or two scanned 40,000-330,000 objects in
        0.1-1 s each and silenced the heartbeat each time (a tmux soak beside a CPU burner).
        Freezing every ``FREEZE_S`` as well keeps what they scan to a few seconds' growth. A
        reference cycle that dies after it was frozen is never collected: the price of it.
        """
        gc.collect(1)
        gc.freeze()

    # -- header --------------------------------------------------------------------------------

    def _died(self) -> None:
        self._client_down("it died: quit (^Q) and start servodesk again")
        self._link(state="dead", reason="controller died")

    def _client_down(self, problem: str) -> None:
        self.client_problem = problem
        for tab in self.built_tabs():
            tab.client_down(problem)

    def _link(self, **changes: object) -> None:
        self.header.link = replace(self.header.link, **changes)  # type: ignore[arg-type]

    def _refresh_header(self) -> None:
        if not self.is_running or not self.header.is_mounted:  # the screen may be torn down
            return
        client = self.client
        if client is not None and client.dead and self.header.link.state == "live":
            self._died()
        if self.sampler is not None and self.sampler.latest is not None:
            self.header.status = self.sampler.latest
            self._start_building()  # the screen is live: the rest may take their turns
            if self.desk.story.update(self.sampler.latest) and self.fault_kind == "limit":
                self.action_dismiss_fault()  # the joint has left its limit
        self.header.latest = self.desk.events.latest  # a tab's refusal logs without the app

    # -- tabs ----------------------------------------------------------------------------------

    def on_tabbed_content_tab_activated(self, event: TabbedContent.TabActivated) -> None:
        if not self.screen_stack:  # a switch still queued as the app closes
            return
        name = (event.pane.id or "pane-jog").removeprefix("pane-")
        self._activate(name)
        self.call_after_refresh(self._focus_active)

    def _activate(self, name: str) -> None:
        tab = self.tab(name)
        self._wanted = name
        if tab is self._active:
            return
        if self._active is not None:
            self._active.hidden()
            self._active = None
        if not tab.is_attached or name in self._building:  # first shown: once mounted
            self.run_worker(self._build_and_show(name), group="build")
            return
        self._active = tab
        self._pace_sampler()
        tab.shown()
        self.refresh_bindings()
        self.call_after_refresh(self._focus_active)
        if name not in self._settled:
            self._settled.add(name)
            self.set_timer(SETTLE_S, self._freeze_long_lived)

    def _pace_sampler(self) -> None:
        """Sample the status at full rate while the Scope shows, slower otherwise."""
        if self.sampler is not None:
            scope = self._active is not None and self._active is self.tabs.made_tab("scope")
            self.sampler.period = 1.0 / (SAMPLE_HZ if scope else HIDDEN_SCOPE_HZ)

    def _focus_active(self) -> None:
        """Focus where the visible tab's keys work, once its pane is displayed (a hidden
        widget cannot take the focus, and a late call must not focus a tab left since).

        The app chooses the tab; the focus must not choose it again: TabbedContent shows
        the pane its TabPane.Focused names, and that message can arrive after the operator
        has chosen another tab (F2 just after start), switching back to this one."""
        tab = self._active
        if tab is None or isinstance(self.screen, ModalScreen):
            return
        if self.focused is not None and tab in self.focused.ancestors:
            return  # the operator chose a field of it already: the keys typed next go there
        with self.prevent(TabPane.Focused):
            tab.focus_main()

    def _shown(self, name: str) -> bool:
        """Whether tab ``name`` is the one shown."""
        return self._active is not None and self._active is self.tabs.made_tab(name)

    def action_show_tab(self, name: str) -> None:
        if len(self.screen_stack) > 1 and not isinstance(self.screen, ModalScreen):
            self.pop_screen()  # the arm's full view (^A): the tab is what was asked for
        self.query_one("#tabs", TabbedContent).active = f"pane-{name}"
        self._activate(name)

    # -- safety actions ------------------------------------------------------------------------

    def action_estop(self) -> None:
        """Latch every valve closed, now. Works on every screen, dialogs included."""
        self._send_estop()
        self._link(estop_sent=True)
        self.estop_latched = True
        self._estop_tabs(latched=True)
        while isinstance(self.screen, ModalScreen):
            self.pop_screen()
        for select in self.screen.query(Select).results(Select):
            select.expanded = False  # the Esc that latched would have closed an open list

    def _estop_tabs(self, latched: bool) -> None:
        for tab in self.built_tabs():
            tab.estop(latched)

    def _send_estop(self) -> None:
        client = self.client
        if client is None or client.dead:
            self._estop_pending = client is None  # sent as soon as the controller is up
            return
        try:
            client.estop()
            self._estop_pending = False
        except (ControllerError, OSError, ValueError):
            self._estop_pending = False  # the controller is gone: the board's watchdog holds

    def action_reset(self) -> None:
        """Release the E-stop latch, after a deliberate confirmation."""
        if isinstance(self.screen, ModalScreen):
            return
        client = self._live_client("release the E-stop")
        if client is None:
            return
        if not self.estop_latched and not client.latched:  # no question, no reset mid-move
            self.notify("No E-stop is latched: nothing to release (^R releases a latched "
                        "E-stop).", severity="warning")
            return
        if refusal := self.desk.refusal("release the E-stop"):  # an observer: before asking
            self.notify(refusal, severity="error", timeout=8)
            return

        def answer(yes: bool | None) -> None:
            if not yes:
                return
            client = self.client
            if client is None:
                self.notify("no controller to release: it is not running", severity="error")
                return
            try:
                client.reset()
            except ControllerError as exc:
                self.notify(str(exc), severity="error")
                return
            self._link(estop_sent=False)

        self.push_screen(ConfirmScreen(
            "Release the E-stop?",
            "The valves open again and every joint holds where it is now. Make sure the "
            "robot's envelope is clear.", "Release"), answer)

    def _live_client(self, what: str) -> ControlClient | None:
        """The client while its controller runs; else None, and the operator is told why and
        what to do (as a tab's ``command`` tells it), before any question is asked."""
        client = self.client
        if client is None or client.dead:
            problem = self.client_problem or (client.dead if client is not None else "")
            self.notify(f"{what}: the controller is not running — "
                        + (problem or "wait for it to start"), severity="error")
            return None
        return client

    def action_hold(self) -> None:
        """Abort any move and hold every joint where it is (the thesis's default mode)."""
        client = self._live_client("hold")
        if client is None:
            return
        try:
            client.hold()
        except ControllerError as exc:
            self.notify(str(exc), severity="error")

    def action_feed_hold(self) -> None:
        """Feed hold on the running move, or resume a held one (the header says which)."""
        client = self._live_client("feed hold")
        if client is None:
            return
        try:
            if client.status().paused:
                client.resume()
            else:
                client.pause()
        except ControllerError as exc:
            self.notify(str(exc), severity="error")

    def action_feed(self, steps: int) -> None:
        """Feed override up or down by 10 % (0…100 %), for this move and the next: from the
        override in force, which a program's feed step or another client may have set, or
        from this TUI's own count while the status has yet to show its last keys' values."""
        client = self._live_client("feed override")
        if client is None:
            return
        try:
            shown = round(client.status().feed_override * 100)
            if shown not in self._feed_sent:  # set by another: step from it
                self.feed_pct = shown
            pct = min(max(self.feed_pct + 10 * steps, 0), 100)
            client.feed_override(pct / 100)
        except (ControllerError, TimeoutError) as exc:  # dead, or died mid-record
            self.notify(str(exc), severity="error")
            return
        caught_up = shown == self.feed_pct  # every value sent before is in force or passed
        self._feed_sent = {shown, pct} if caught_up else {*self._feed_sent, pct}
        self.feed_pct = pct

    async def action_quit(self) -> None:
        """Quit; first ask, when a move is running or the E-stop is latched."""
        if isinstance(self.screen, QuitScreen):
            return
        concern = self._quit_concern()
        if not concern:
            await self._exit_once_built()
            return

        def answer(yes: bool | None) -> None:
            if yes:
                self.call_next(self._exit_once_built)

        self.push_screen(QuitScreen("Quit servodesk?", concern, "Quit"), answer)

    async def _exit_once_built(self) -> None:
        """Exit once no tab is half mounted: a tab whose mount the exit overtook found its
        own widgets gone (a traceback and exit status 1 for ^Q just after the start)."""
        self._quitting = True
        while self._building:
            await next(iter(self._building.values())).wait()
        self.exit()

    def _quit_concern(self) -> str:
        """Why quitting now deserves a second thought ("" when it does not)."""
        client = self.client
        if client is None or client.dead:
            return ""
        try:
            status = client.status()
        except (ControllerError, TimeoutError, ValueError):
            return ""
        if status.moving or status.mode == Mode.INITIALISE:
            total = status.move_total
            done = f" ({status.move_done / total:.0%} done)" if total else ""
            return (f"Move {status.move_id} is running{done}. Quitting stops the controller: "
                    "every valve closes at once, wherever the arm is, and the move is lost.")
        if self.estop_latched or status.estop:
            reason = f": {self._estop_reason}" if self._estop_reason else ""
            return (f"The E-stop is latched{reason}. Quitting closes the controller with every "
                    "valve still closed; the reason stays in this session's events.jsonl "
                    f"({self.desk.events.path or 'not written'}).")
        return ""

    def action_take_command(self) -> None:
        """Command the service's controller (refused, with who holds it, if another does)."""
        if self.observe_only:
            self.notify(OBSERVE_ONLY, severity="error", timeout=6)
            return
        self._command_change(_take_in_reduced_speed)

    def action_release_command(self) -> None:
        """Give command back: the controller holds; another client may take it."""
        self._command_change(lambda client: client.release_command())

    def _command_change(self, change: Callable[[ControlClient], None]) -> None:
        client = self.client
        if client is None or not client.role:
            return
        self._in_order(partial(self._change_command, client, change))

    def _change_command(self, client: ControlClient,
                        change: Callable[[ControlClient], None]) -> None:
        try:
            change(client)
        finally:
            self._from_worker(partial(self._link, command=_role(client)))

    def _in_order(self, call: Callable[[], object]) -> None:
        """Make ``call`` off the UI's thread, after the calls asked for before it: each may
        wait seconds (a take for a frozen service's answer, a switch for a refused mode to
        show), and no key, Esc's E-stop included, may wait with it. Its ControllerError or
        ValueError is told."""
        with self._calls_lock:
            self._calls.append(call)
            first = len(self._calls) == 1
        if first:
            self.run_worker(self._make_calls, thread=True, group="calls", name="client calls")

    def _make_calls(self) -> None:
        while True:
            with self._calls_lock:
                call = self._calls[0]
            try:
                call()
            except (ControllerError, ValueError) as exc:
                self._from_worker(partial(self.notify, str(exc), severity="error"))
            with self._calls_lock:
                self._calls.popleft()
                if not self._calls:
                    return

    def action_speed_mode(self) -> None:
        """Reduced speed (T1) at once; automatic (full speed) only after asking, and only for
        the commanding client (an observer's switch is refused with who commands)."""
        if isinstance(self.screen, ConfirmScreen):
            return
        client = self._live_client("speed mode")
        if client is None:
            return
        if client.speed_mode == "automatic":
            self._set_speed(client, "reduced")
            return
        if not client.commanding:
            self.notify(f"speed mode: {client.role}; take command first (^K)", severity="error")
            return

        def answer(yes: bool | None) -> None:
            if yes:
                self._set_speed(client, "automatic")

        self.push_screen(ConfirmScreen(
            "Switch to automatic (full speed)?",
            "Moves, jogs and go-tos then run at the machine's full speed, no longer held to "
            "250 mm/s at the tool. Make sure nobody is inside the robot's envelope.",
            "Automatic"), answer)

    def _set_speed(self, client: ControlClient, mode: str) -> None:
        """Switch in order off the UI's thread: the switch waits (up to 2 s) for the status to
        show the mode, which a refused one never does."""
        self._in_order(partial(client.set_speed_mode, mode))

    def _from_worker(self, call: Callable[[], object]) -> None:
        """Run ``call`` on the UI's thread, from a worker's; not once the app is closing: its
        screen is being torn down, and a header without its lines raised NoMatches."""
        def live() -> None:
            if self.is_running and self.header.is_mounted:
                call()

        with contextlib.suppress(RuntimeError):  # the app closed meanwhile
            self.call_from_thread(live)

    def action_dismiss_fault(self) -> None:
        self.fault_kind = ""
        self.banner.message = ""
        self.refresh_bindings()

    async def action_teach(self) -> None:
        """Teach where the joints are under a name, from any tab."""
        if isinstance(self.screen, ModalScreen):
            return
        positions = cast("PositionsTab", await self._build("positions"))
        positions.action_teach()

    def action_arm_view(self) -> None:
        """The arm's view on the whole screen, showing the move running or previewed; or
        back to the tabs from it."""
        from app.screens.arm import ArmScreen  # loaded when first shown, not before

        if isinstance(self.screen, ArmScreen):
            self.pop_screen()
            return
        if isinstance(self.screen, ModalScreen):
            return
        moves = cast("MovesTab | None", self.tabs.made_tab("moves"))
        plan = None if moves is None else moves.plan_running or moves.previewed
        self.push_screen(ArmScreen(self.machine, self.model, self._latest_status, plan,
                                   self._positions or ()))

    def _latest_status(self) -> Status | None:
        return self.sampler.latest if self.sampler is not None else None

    def action_run_move(self) -> None:
        """Run the move filled in on the Moves tab (whichever widget has the focus)."""
        if self._shown("moves") and not isinstance(self.screen, ModalScreen):
            # behind the keys typed before ^S, still in the focused field's queue: run what
            # the operator typed, not what the field had taken when ^S came
            (self.focused or self).call_later(self._active.action_run)

    def check_action(self, action: str, parameters: tuple[object, ...]) -> bool | None:
        if action == "dismiss_fault":
            return bool(self.fault_kind)
        if action == "run_move":
            return self._shown("moves")
        if action in ("take_command", "release_command"):
            return self._attached is not None
        return True


def _take_in_reduced_speed(client: ControlClient) -> None:
    """Take command of a service's controller and put it in reduced speed (T1), as the TUI
    starts: the one who commands chooses automatic, after asking."""
    client.take_command()
    client.set_speed_mode("reduced")


def _role(client: ControlClient | None) -> str:
    """The header's word on command: "" for a client that started its own controller."""
    return client.role if client is not None else ""


def attached_app(socket: str | Path | None = None, *, observe_only: bool = False,
                 take_command: bool = False) -> ServodeskApp:
    """The TUI on the controller ``servodesk controller`` runs at ``socket`` (default: the
    user's); it observes until the operator takes command (^K), or always
    (``observe_only``), or takes it at once (``take_command``)."""
    return ServodeskApp.attached(socket, observe_only=observe_only, take_command=take_command)
