"""The recent past of the controller for the live plots: a ring buffer fed by a sampler thread.

``client.status()`` is a seqlock read of a few microseconds, so a thread can
take it at 200 Hz without touching the UI's event loop (and without keeping
Textual's Pilot from seeing the app idle). The Scope tab copies the visible
window out at its own frame rate.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from control.rt.layout import Status

SAMPLE_HZ = 200.0
CAPACITY = 24_000  # two minutes at SAMPLE_HZ


@dataclass(frozen=True)
class Window:
    """A copy of the last samples: ``t: (N,)`` controller time in s; the rest ``(N, J)``."""

    t: np.ndarray
    position: np.ndarray
    desired: np.ndarray
    duty: np.ndarray

    def __len__(self) -> int:
        return len(self.t)


class History:
    """Fixed-size ring of (time, position, desired, duty) for ``n`` joints; thread-safe."""

    def __init__(self, n: int, capacity: int = CAPACITY) -> None:
        self.n = n
        self.capacity = capacity
        self._t = np.zeros(capacity)
        self._data = np.zeros((capacity, 3, n))
        self._count = 0
        self._lock = threading.Lock()

    def __len__(self) -> int:
        return min(self._count, self.capacity)

    def append(self, status: Status) -> None:
        with self._lock:
            i = self._count % self.capacity
            self._t[i] = status.time_s
            self._data[i, 0] = status.position
            self._data[i, 1] = status.desired
            self._data[i, 2] = status.duty
            self._count += 1

    def extend(self, t: np.ndarray, position: np.ndarray, desired: np.ndarray,
               duty: np.ndarray) -> None:
        """Append many samples at once (benchmarks, tests)."""
        t = np.asarray(t)[-self.capacity:]
        rows = np.stack([position, desired, duty], axis=1)[-self.capacity:]
        with self._lock:
            index = (self._count + np.arange(len(t))) % self.capacity
            self._t[index] = t
            self._data[index] = rows
            self._count += len(t)

    def clear(self) -> None:
        with self._lock:
            self._count = 0

    def window(self, seconds: float, end: float | None = None) -> Window:
        """The samples of the last ``seconds`` (ending at controller time ``end``, or now)."""
        with self._lock:
            size = min(self._count, self.capacity)
            if size == 0:
                empty = np.zeros((0, self.n))
                return Window(np.zeros(0), empty, empty, empty)
            order = (np.arange(self._count - size, self._count) % self.capacity)
            t = self._t[order]
            last = t[-1] if end is None else end
            lo = int(np.searchsorted(t, last - seconds, side="left"))
            hi = int(np.searchsorted(t, last, side="right"))
            index = order[lo:hi]
            t = t[lo:hi]
            data = self._data[index]
        return Window(t, data[:, 0], data[:, 1], data[:, 2])

    @property
    def latest_time(self) -> float:
        with self._lock:
            if not self._count:
                return 0.0
            return float(self._t[(self._count - 1) % self.capacity])


class Sampler:
    """A daemon thread that reads the status at ``rate_hz`` into ``history``.

    ``read`` returns the newest status (``client.status``); a reading with the
    same tick as the last one is not stored twice. ``latest`` holds the newest
    status for the UI; ``error`` the reason the thread stopped, if it failed.
    """

    def __init__(self, read: Callable[[], Status], history: History,
                 rate_hz: float = SAMPLE_HZ) -> None:
        self.read = read
        self.history = history
        self.period = 1.0 / rate_hz
        self.latest: Status | None = None
        self.error = ""
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="servodesk-sampler", daemon=True)

    def start(self) -> None:
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        if self._thread.is_alive() and self._thread is not threading.current_thread():
            self._thread.join(timeout=1.0)

    def _run(self) -> None:
        last_tick = -1
        while not self._stop.wait(self.period):
            try:
                status = self.read()
            except Exception as exc:  # the segment went away: the client was closed
                self.error = f"{type(exc).__name__}: {exc}"
                return
            self.latest = status
            if status.tick != last_tick:
                last_tick = status.tick
                self.history.append(status)
