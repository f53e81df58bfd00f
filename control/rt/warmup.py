"""A shadow controller ticked, a piece at a time, in the window before each deadline, so the
live tick runs on warm code.

After the loop sleeps, the same Python code runs cold on a VM: its caches and branch
predictors served other work meanwhile, and a tick right after a 1 ms sleep took about
twice the same tick back to back (``benchmarks/loop.py``, live / tight). In the last
``warm_up_pct`` of each period (a machine-file setting) the control process spins rather
than sleeps, and ticks a shadow there: the very code the live tick runs next.

The shadow shares no mutable state with the live controller: it is a ``Controller`` of
the same machine and loop settings on a simulator of its own (lockstep: its time steps
only when it ticks), with its own control words in a private buffer and its own
socketpair, whose far end nobody writes to, for a channel. It never touches the live
backend, shared memory, channel or outbox, so what the live tick reads, decides and
writes is bit for bit the same with or without it (tests/control/test_warm_up.py).

The live tick's timing comes first. A shadow tick is cut in pieces (its plant's step, then
``Controller.stages``, then its bookkeeping), and a piece starts only when the longest it
took lately (``Peak``) and a margin still end before the deadline; the next window goes
on where this one stopped. So a piece runs late only when it takes longer than it has
lately (the machine took the CPU meanwhile); such windows are counted (``late``). A piece
that raises turns the warm-up off for good.
"""

from __future__ import annotations

import socket
import time
from collections.abc import Callable
from dataclasses import replace

from control.rt.channel import controller_end
from control.rt.commands import Reset
from control.rt.layout import ControlLayout
from control.rt.loop import Controller
from hw.backend import RealClock, StepClock
from hw.machine import MachineError
from hw.sim.backend import SimBackend

MARGIN_NS = 15_000  # a piece must be expected to end this long before the deadline
DECAY = 256  # a piece's peak falls by 1/DECAY of its excess over each shorter run
SEED_TICKS = 20  # back-to-back shadow ticks timed at the start, before any window
SEED_FACTOR = 3  # a cold piece (a window's first) may take this many times a warm one
RESET = Reset()
FOREVER_NS = 10**15  # the shadow's client is never lost: nobody writes its words


class WarmUp:
    """Beside ``live``: ``before(deadline)`` sleeps until the window before ``deadline``
    (``warm_up_pct`` of the period, at least the live clock's spin), then runs shadow
    pieces back to back while the next one's ``Peak`` and ``MARGIN_NS`` fit before the
    deadline. On a lockstep clock (tests) there is no window: a whole shadow tick runs
    once a cycle. Counters: ``windows``, ``ran`` (whole shadow ticks), ``pieces``,
    ``skipped`` (windows with no room for a piece), ``late`` (windows whose last piece
    ended past the deadline) and ``late_max_ns`` (by how much, at most)."""

    def __init__(self, live: Controller) -> None:
        machine, layout = live.machine, ControlLayout(live.n)
        self.buffer = bytearray(layout.size)
        layout.write_header(memoryview(self.buffer))
        self.ends = socket.socketpair()
        self.backend = SimBackend(machine, lockstep=True)
        self.step: StepClock = self.backend.clock
        config = replace(live.config, heartbeat_timeout_ns=FOREVER_NS,
                         orphan_timeout_ns=FOREVER_NS)
        self.shadow = Controller(machine, self.backend, controller_end(self.ends[1]),
                                 memoryview(self.buffer), config)
        self.backend.open()
        self.shadow.start()
        self.shadow.deadline = self.step.now_ns() + config.period_ns
        self.woke = 0
        self.pieces: tuple[Callable[[], None], ...] = (
            self.advance, *(self.stage(s) for s in self.shadow.stages), self.end)
        self.next = 0  # the piece the next window starts with
        clock = live.clock
        self.window_ns = (max(clock.spin_ns, round(config.period_ns * machine.warm_up_pct / 100))
                          if isinstance(clock, RealClock) else None)
        self.error = ""
        self.windows = self.ran = self.pieces_run = self.skipped = 0
        self.late = self.late_max_ns = 0
        self.peaks = self.seed()
        self.ran = self.pieces_run = 0  # the seed's ticks are not the windows'

    @classmethod
    def beside(cls, live: Controller) -> WarmUp | None:
        """A warm-up for ``live`` when its clock is real, its machine file gives a window
        (``warm_up_pct``), and the simulator runs its machine (a shadow of iron needs one),
        else None."""
        if not (isinstance(live.clock, RealClock) and live.machine.warm_up_pct > 0):
            return None
        try:
            return cls(live)
        except MachineError:
            return None

    def seed(self) -> list[Peak]:
        """Every piece's ``Peak`` from ``SEED_TICKS`` shadow ticks back to back: its median
        time (the first runs of fresh code take far longer), times ``SEED_FACTOR`` for a
        cold one; the windows learn the rest. An error is kept (``error``): the loop drops
        the warm-up at its first window."""
        times: list[list[int]] = [[0] for _ in self.pieces]
        now = time.monotonic_ns
        for _ in range(SEED_TICKS):
            for k in range(len(self.pieces)):
                start = now()
                self.run_piece(k)
                times[k].append(now() - start)
        return [Peak(SEED_FACTOR * sorted(ns)[len(ns) // 2]) for ns in times]

    def stage(self, stage: Callable[[int], None]) -> Callable[[], None]:
        return lambda: stage(self.woke)

    def advance(self) -> None:
        """The shadow's next tick begins: its time steps to its deadline, its plant with it."""
        shadow = self.shadow
        self.step.sleep_until(shadow.deadline)
        self.woke = self.step.now_ns()
        self.backend.advance()

    def end(self) -> None:
        """The shadow's tick ends as ``Controller.tick`` ends, its events dropped; a fault of
        its own simulator is reset, to warm the code of a loop that holds."""
        shadow = self.shadow
        if shadow.guards.latched:
            shadow.on_reset(RESET)
        shadow.outbox.queue.clear()  # its events (and status) go nowhere
        shadow.tick_count += 1
        shadow.deadline = shadow.latency.next_deadline(shadow.deadline, self.step.now_ns())
        self.ran += 1

    def before(self, deadline: int) -> None:
        """Wait for the window before ``deadline`` (the live clock's time) and run shadow
        pieces through it while the next fits; the caller then spins to ``deadline``."""
        if self.window_ns is None:
            for _ in self.pieces:
                self.run_piece(self.next)
            return
        now = time.monotonic_ns
        early = deadline - self.window_ns - now()
        if early > 0:
            time.sleep(early / 1e9)
        self.windows += 1
        peaks, k = self.peaks, self.next
        start = now()
        if start + peaks[k].bound() > deadline:
            self.skipped += 1
            if start + peaks[k].floor + MARGIN_NS <= deadline:  # the peak keeps it out
                peaks[k].no_room()
            return
        while start + peaks[k].bound() <= deadline and not self.error:
            self.run_piece(k)
            end = now()
            peaks[k].add(end - start)
            k, start = self.next, end
        if start > deadline:
            self.late += 1
            self.late_max_ns = max(self.late_max_ns, start - deadline)

    def run_piece(self, k: int) -> None:
        """Piece ``k``, unless one failed; an error turns the warm-up off (the shadow's own
        bug)."""
        if self.error:
            return
        try:
            self.pieces[k]()
        except Exception as exc:
            self.error = f"{type(exc).__name__}: {exc}"
        self.pieces_run += 1
        self.next = (k + 1) % len(self.pieces)

    def report(self) -> str:
        """The counters, one line: ``warm-up: windows W, ran R, pieces P, skipped S, late L,
        max M ns``."""
        return (f"warm-up: windows {self.windows}, ran {self.ran}, pieces {self.pieces_run}, "
                f"skipped {self.skipped}, late {self.late}, max {self.late_max_ns} ns")

    def close(self) -> None:
        self.shadow.release()
        self.backend.close()
        for end in self.ends:
            end.close()


class Peak:
    """How long a piece may take (ns): the longest it took lately. A longer run raises it at
    once; a shorter one lowers it by ``1/DECAY`` of the difference, so a cold run's length
    (a window's first piece) is remembered over hundreds of warm ones. A window with no room
    for it lowers it toward ``floor`` (its seed: ``SEED_FACTOR`` times its warm time), so
    one stall of the machine does not keep it out of every window after."""

    def __init__(self, floor_ns: float) -> None:
        self.floor = self.peak = floor_ns

    def add(self, ns: float) -> None:
        self.peak = ns if ns >= self.peak else self.peak - (self.peak - ns) / DECAY

    def no_room(self) -> None:
        if self.peak > self.floor:
            self.peak -= (self.peak - self.floor) / 16

    def bound(self) -> float:
        return self.peak + MARGIN_NS
