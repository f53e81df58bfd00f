"""The controller started as soon as the command line is read, before the screen's code is
imported: its process starts on the other core while Textual loads (half a second of the
start), and the app takes the client, or why it failed, once it runs
(``ServodeskApp(starting=...)``). Until then the controller's events wait here, in order."""

from __future__ import annotations

import threading
from collections.abc import Callable
from pathlib import Path

from control.client import ControlClient, Event
from hw.machine import Machine

Result = ControlClient | Exception  # the client, or why it did not start
TUI_CLIENT = {"speed_mode": "reduced"}  # the TUI's controller starts in T1, until asked


class ControllerStart:
    """A ``ControlClient`` being made in a thread of its own; ``hand_over`` gives it (and the
    events it sent meanwhile) to whoever runs it, ``close`` closes it if nobody took it."""

    def __init__(self, machine: Machine, backend: str, port: str | None, data_dir: Path,
                 seed: int, options: dict) -> None:
        self._lock = threading.Lock()
        self._events: list[Event] = []
        self._result: Result | None = None
        self._on_result: Callable[[Result], None] | None = None
        self._on_event: Callable[[Event], None] | None = None
        self._closed = False
        self._thread = threading.Thread(
            target=self._start, args=(machine, backend, port, data_dir, seed, options),
            name="servodesk-start-controller", daemon=True)
        self._thread.start()

    def _start(self, machine: Machine, backend: str, port: str | None, data_dir: Path,
               seed: int, options: dict) -> None:
        result: Result
        try:
            result = ControlClient(machine, backend, port=port, seed=seed, data_dir=data_dir,
                                   on_event=self._event, **{**TUI_CLIENT, **options})
        except Exception as exc:  # ControllerError, a bad port, no shared memory…
            result = exc
        with self._lock:
            closed, self._result, on_result = self._closed, result, self._on_result
        if closed and isinstance(result, ControlClient):
            result.close()
        elif on_result is not None:
            on_result(result)

    def _event(self, event: Event) -> None:
        with self._lock:
            on_event = self._on_event
            if on_event is None:
                self._events.append(event)
                return
        on_event(event)

    def hand_over(self, on_result: Callable[[Result], None],
                  on_event: Callable[[Event], None]) -> None:
        """From now on ``on_event`` gets the controller's events (those kept first) and
        ``on_result`` the client or the exception, now if it is known, else from the thread."""
        with self._lock:
            kept, self._events = self._events, []
            for event in kept:
                on_event(event)
            self._on_event, self._on_result, result = on_event, on_result, self._result
        if result is not None:
            on_result(result)

    def close(self) -> None:
        """Close the client if it was never handed over (the app did not run)."""
        with self._lock:
            self._closed = True
            result = None if self._on_result is not None else self._result
        if isinstance(result, ControlClient):
            result.close()
