"""The hardware boundary: the small interface every backend implements.

Like ros2_control's ``SystemInterface``: a lifecycle (``open``/``close``), a
``read`` of the raw encoder words of all joints and a ``write`` of the signed
valve duty per joint, plus the E-stop input, a fault line and link counters.
A backend also owns its time base: real time, or a lockstep clock that a
simulator advances as fast as it can compute (at real time while the robot only holds).

Only the control subprocess calls a backend while it runs. The loop calls
``read`` and ``write`` once per tick with preallocated lists, so an
implementation must not allocate on that path.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass, fields
from typing import Protocol, runtime_checkable

from hw.machine import Machine


@dataclass
class LinkCounters:
    """Counts of link and I/O events since ``open``; mutated in place by the backend."""

    frames_tx: int = 0
    frames_rx: int = 0
    crc_errors: int = 0
    truncated: int = 0
    garbage_bytes: int = 0
    out_of_order: int = 0
    link_lost: int = 0
    watchdog_trips: int = 0

    def as_dict(self) -> dict[str, int]:
        return {f.name: getattr(self, f.name) for f in fields(self)}


@runtime_checkable
class Clock(Protocol):
    """Monotonic time base of a backend, in nanoseconds."""

    def now_ns(self) -> int: ...

    def sleep_until(self, deadline_ns: int) -> None:
        """Return at or after ``deadline_ns`` (absolute, same clock as ``now_ns``)."""
        ...


class RealClock:
    """Wall time: ``time.monotonic_ns`` and an absolute sleep with an optional final spin.

    Python 3.11's ``time.sleep`` uses ``clock_nanosleep``; the last ``spin_ns``
    before the deadline are spent polling the clock so wake-up lateness stays
    in microseconds rather than the scheduler's slack.
    """

    def __init__(self, spin_ns: int = 0) -> None:
        self.spin_ns = spin_ns

    def now_ns(self) -> int:
        return time.monotonic_ns()

    def sleep_until(self, deadline_ns: int) -> None:
        remaining = deadline_ns - time.monotonic_ns() - self.spin_ns
        if remaining > 0:
            time.sleep(remaining / 1e9)
        while time.monotonic_ns() < deadline_ns:
            pass


class StepClock:
    """Lockstep time for simulation: sleeping jumps straight to the deadline, so a move
    computes as fast as the loop can; while ``idle`` (the control loop says so each tick:
    nothing to step, the robot holding) a sleep first waits out the same time on the wall
    clock, so a controller that merely holds paces at real time instead of spinning a core.
    Simulated time is the deadlines either way: what a tick computes does not depend on it."""

    def __init__(self, start_ns: int = 0) -> None:
        self._now = start_ns
        self.idle = False

    def now_ns(self) -> int:
        return self._now

    def sleep_until(self, deadline_ns: int) -> None:
        if self.idle and deadline_ns > self._now:
            time.sleep((deadline_ns - self._now) / 1e9)
        self._now = max(self._now, deadline_ns)


@runtime_checkable
class Backend(Protocol):
    """What the control loop needs from an I/O board or a simulator."""

    machine: Machine
    clock: Clock
    counters: LinkCounters
    sample_ns: int
    """When the words the last ``read`` returned were sampled, on ``clock``. It changes with
    every new sample and only then: a ``read`` that returns the last sample's words again (a
    serial board whose answer is late) leaves it as it was, so that the encoder input judges
    each sample once, never a late answer's words once a tick."""
    supply_mpa: float
    """The hydraulic supply pressure at the last ``read``, MPa; NaN when the backend cannot
    measure it (the I/O board has no pressure input; the simulator knows it)."""

    def open(self) -> None:
        """Connect and bring every valve to closed (0 % duty)."""
        ...

    def close(self) -> None:
        """Close every valve and release the device; safe to call twice."""
        ...

    def reconnect(self) -> None:
        """The operator's way back after a fault: reopen the device (raise OSError if it fails)."""
        ...

    def read(self, raw: list[int]) -> None:
        """Fill ``raw`` (one entry per joint) with the newest raw encoder words; set
        ``sample_ns`` to when they were sampled."""
        ...

    def write(self, duty_pct: Sequence[float]) -> None:
        """Command signed valve duty per joint, percent in [-100, 100]."""
        ...

    @property
    def estop(self) -> bool:
        """True while the E-stop input is pressed (the valves are then closed regardless)."""
        ...

    @property
    def fault(self) -> str:
        """Empty when healthy, else a one-line reason (``"link lost: no frame for 62 ms"``)."""
        ...
