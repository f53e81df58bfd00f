"""The arm's view on the whole screen (the app's ^A): the machine live, the desired pose as a
ghost, the Moves tab's previewed or running path and the named positions.

Esc stays the E-stop here as everywhere; ^A again or ``q`` goes back to the tabs.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import ClassVar

from textual.app import ComposeResult
from textual.binding import Binding
from textual.screen import Screen

from app.widgets.arm_view import ArmView
from app.widgets.key_bar import KeyBar
from control.motion.plan import MovePlan
from control.motion.positions import Position
from control.rt.layout import Status
from hw.machine import Machine
from kinematics.unimate import Unimate2000B


class ArmScreen(Screen[None]):
    """``source`` gives the newest status; ``plan`` the move to show (None: none)."""

    DEFAULT_CSS = """
    ArmScreen #arm-full {
        height: 1fr;
    }
    """
    BINDINGS: ClassVar = [
        Binding("q", "app.pop_screen", "back to the tabs"),  # ^A too: the app's
    ]

    def __init__(self, machine: Machine, model: Unimate2000B | None,
                 source: Callable[[], Status | None], plan: MovePlan | None,
                 positions: tuple[Position, ...]) -> None:
        super().__init__()
        self.machine = machine
        self.model = model
        self.source = source
        self.plan = plan
        self.positions = positions

    def compose(self) -> ComposeResult:
        yield ArmView(self.machine, self.model, self.source, id="arm-full")
        yield KeyBar()

    def on_mount(self) -> None:
        view = self.query_one(ArmView)
        view.show_positions(self.positions)
        if self.plan is not None and self.plan.path is not None:
            view.show_plan(self.plan.path, self.plan.kind)
        view.focus()
