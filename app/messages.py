"""Messages more than one part of the TUI posts or handles: the life of the client and the
controller's events (posted to the app from the client's threads), and a saved run."""

from __future__ import annotations

from dataclasses import dataclass

from textual.message import Message

from control.client import ControlClient, Event


@dataclass
class ControllerEvent(Message):
    """An event of the controller (estop, fault, notice, move_done, died), on the UI thread."""

    event: Event


@dataclass
class ClientReady(Message):
    """The control subprocess is up; ``client`` is ready for commands."""

    client: ControlClient


@dataclass
class ClientFailed(Message):
    """The control subprocess could not be started; ``reason`` says why and what to do."""

    reason: str


class RunsChanged(Message):
    """A run was saved (a move, an identification): the Runs tab should list it."""
