"""Messages that flow up to the app: the controller's events and the life of the client."""

from __future__ import annotations

from collections.abc import Callable

from textual.message import Message

from control.client import ControlClient, Event


class ControllerEvent(Message):
    """An event of the controller (estop, fault, notice, move_done, died), on the UI thread."""

    def __init__(self, event: Event) -> None:
        super().__init__()
        self.event = event


class ClientReady(Message):
    """The control subprocess is up; ``client`` is ready for commands."""

    def __init__(self, client: ControlClient) -> None:
        super().__init__()
        self.client = client


class ClientFailed(Message):
    """The control subprocess could not be started; ``reason`` says why and what to do."""

    def __init__(self, reason: str) -> None:
        super().__init__()
        self.reason = reason


class RunsChanged(Message):
    """A run was saved (or exported): the Runs tab should list it."""


class Deferred(Message):
    """A call to make on the UI thread, posted from a worker or the client's monitor thread."""

    def __init__(self, callback: Callable[..., object], *args: object, **kwargs: object) -> None:
        super().__init__()
        self.callback = callback
        self.args = args
        self.kwargs = kwargs
