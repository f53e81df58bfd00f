"""What every tab shares: the desk the app hands down (machine, kinematics, data directory,
history) and the client once the controller is up, and a refresh timer that runs only while
the tab is visible (hidden tabs cost nothing, and Pilot sees the app idle)."""

from __future__ import annotations

from collections.abc import Callable
from typing import ClassVar

from textual.containers import Container
from textual.timer import Timer

from app.desk import Desk
from app.widgets.staged import Staged
from control.client import ControlClient, ControllerError
from control.rt.layout import Mode, Status
from hw.machine import Machine
from kinematics.unimate import Unimate2000B


class TabPage(Staged, Container):
    """A tab's content. ``REFRESH_HZ > 0`` calls ``refresh_live`` at that rate while shown;
    its ``LATER`` parts are drawn after the rest the first time (``Staged``)."""

    REFRESH_HZ: ClassVar[float] = 0.0
    TITLE: ClassVar[str] = ""

    def __init__(self, desk: Desk, *, id: str | None = None) -> None:
        super().__init__(id=id)
        self.desk = desk
        self.connection: ControlClient | None = None  # kept after a death: its sets still save
        self.client_problem = ""
        self._timer: Timer | None = None
        self.visible_now = False

    @property
    def machine(self) -> Machine:
        return self.desk.machine

    @property
    def model(self) -> Unimate2000B | None:
        """The machine's closed-form kinematics, None for a machine without (the rig)."""
        return self.desk.model

    @property
    def client(self) -> ControlClient | None:
        """The client while the controller is alive, else None."""
        client = self.connection
        return client if client is not None and not client.dead else None

    def status(self) -> Status | None:
        """The controller's newest status, or None before it started or after it died."""
        client = self.client
        if client is None:
            return None
        try:
            return client.status()
        except (ControllerError, ValueError, TimeoutError):  # closed or died while we asked
            return None

    def move_in_progress(self) -> str:
        """Why a move must not start now: one of another tab or client runs, or stands in feed
        hold, and a new one would supersede it (the arm moving off from a feed hold); ""
        when none does."""
        status = self.status()
        if status is None or not (status.moving or status.mode == Mode.INITIALISE):
            return ""
        if status.paused:
            return ("a move stands in feed hold (another tab's or client's): resume it (^F) or "
                    "hold (^G) first")
        return "a move is running (another tab's or client's): wait for it, or hold (^G)"

    def command(self, what: str, call: Callable[[ControlClient], object]) -> bool:
        """``call(client)`` (``ControlClient.hold``, ``lambda client: client.jog(duty)``); if
        the controller cannot take it, say why and what to do instead of raising."""
        client = self.client
        if client is None:
            self.notify(f"{what}: the controller is not running — "
                        + (self.client_problem or "wait for it to start"), severity="error")
            return False
        try:
            call(client)
        except (ControllerError, ValueError, OSError) as exc:
            self.notify(f"{what}: {exc}", severity="error")
            return False
        return True

    def on_mount(self) -> None:
        if self.REFRESH_HZ > 0:
            self._timer = self.set_interval(1.0 / self.REFRESH_HZ, self.refresh_live, pause=True)
        self.hide_later()
        if self.visible_now:  # shown before it was mounted: its showing revealed nothing
            self.reveal_later()

    def shown(self) -> None:
        """The tab became the visible one."""
        self.visible_now = True
        if self._timer is not None:
            self._timer.resume()
        self.refresh_live()
        self.reveal_later()

    def hidden(self) -> None:
        """Another tab became visible; no key may reach this one's widgets any more."""
        self.visible_now = False
        if self._timer is not None:
            self._timer.pause()
        focused = self.app.focused
        if focused is not None and self in focused.ancestors_with_self:
            self.app.set_focus(None)

    def client_ready(self, client: ControlClient) -> None:
        """The controller is up (called once, by the app)."""
        self.connection = client

    def estop(self, latched: bool) -> None:
        """The E-stop latched (sent by the operator, or reported by the controller), or was
        released: a tab forgets whatever the operator had asked for before the latch."""

    def client_down(self, problem: str) -> None:
        """The controller did not start, or died: ``problem`` says what to do."""
        self.client_problem = problem

    def refresh_live(self) -> None:
        """Redraw from the controller's status (only while visible)."""

    def focus_main(self) -> None:
        """Put the keyboard focus where this tab's keys work."""
