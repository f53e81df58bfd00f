"""A shadow controller ticked in the spin before each deadline, so the live tick runs warm.

After the loop sleeps, the same Python code runs cold on a VM: its caches and branch
predictors served other work meanwhile, and a tick right after a 1 ms sleep took about
1.9x the same tick back to back (``benchmarks/loop.py``, live / tight). The loop spins
the last ``spin_ns`` before each deadline anyway (``hw.backend.RealClock``); a shadow
tick run there (the part a tick times, ``Controller.compute``: up to the valves written)
warms the very code the live tick runs next, on CPU already spent.

The shadow shares no mutable state with the live controller: it is a ``Controller`` of
the same machine and loop settings on a simulator of its own (lockstep: its time steps
only when it ticks), with its own control words in a private buffer and its own
socketpair, whose far end nobody writes to, for a channel. It never touches the live
backend, shared memory, channel or outbox, so what the live tick reads, decides and
writes is bit for bit the same with or without it (tests/control/test_warm_up.py).
A warm-up tick not expected to end before the deadline (``Estimate``) is skipped; one
that overruns its estimate (the machine took the CPU meanwhile) delays the live tick's
start, counted in ``late``. One that raises turns the warm-up off for good.
"""

from __future__ import annotations

import socket
import time
from dataclasses import replace

from control.rt.channel import controller_end
from control.rt.commands import Reset
from control.rt.layout import ControlLayout
from control.rt.loop import Controller
from hw.backend import RealClock, StepClock
from hw.machine import MachineError
from hw.sim.backend import SimBackend

MARGIN_NS = 10_000  # a warm-up tick must be expected to end this long before the deadline
SPREAD = 2  # expected: its mean length and this many mean deviations (TCP's timeout estimate)
RESET = Reset()
FOREVER_NS = 10**15  # the shadow's client is never lost: nobody writes its words


class WarmUp:
    """Beside ``live``: ``before(deadline)`` sleeps until the live clock's spin window, then
    ticks the shadow back to back while the next tick is expected to end ``MARGIN_NS``
    before ``deadline``, starting as late as lets as many end, so that the last ends just
    before the live tick begins (spinning cools the code too). A window's first tick runs
    cold, its next ones warm: each kind has its ``Estimate``, and a live tick after a window
    with no warm-up counts as a cold one, so the estimate follows the machine's load even
    while every window is skipped. On a lockstep clock (tests) there is no window: the
    shadow ticks once a cycle. Counters: ``windows``, ``ran`` (shadow ticks), ``skipped``
    (windows with no room for one), ``late`` (windows whose last shadow tick ended past the
    deadline) and ``late_max_ns`` (by how much, at most)."""

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
        self.live_latency = live.latency  # read only: the live tick's compute
        clock = live.clock
        self.spin_ns = clock.spin_ns if isinstance(clock, RealClock) else None
        self.cold = Estimate(float(self.spin_ns or 0))  # no room until ticks are seen
        self.warm = Estimate(float(self.spin_ns or 0))
        self.was_skipped = False
        self.windows = self.ran = self.skipped = self.late = self.late_max_ns = 0
        self.error = ""

    @classmethod
    def beside(cls, live: Controller) -> WarmUp | None:
        """A warm-up for ``live`` when its clock spins before each deadline and the simulator
        runs its machine (a shadow of iron needs one), else None."""
        clock = live.clock
        if not (isinstance(clock, RealClock) and clock.spin_ns > 0):
            return None
        try:
            return cls(live)
        except MachineError:
            return None

    def before(self, deadline: int) -> None:
        """Wait for the spin window before ``deadline`` (the live clock's time) and tick the
        shadow through it while another tick fits; the caller then spins to ``deadline``."""
        if self.spin_ns is None:
            self.tick()
            return
        if self.was_skipped:  # the live tick since ran cold
            self.cold.add(self.live_latency.compute_ns)
        now = time.monotonic_ns
        early = deadline - self.spin_ns - now()
        if early > 0:
            time.sleep(early / 1e9)
        self.windows += 1
        start = now()
        cold = self.cold.bound()
        self.was_skipped = deadline - start < cold
        if self.was_skipped:
            self.skipped += 1
            return
        warm = min(self.warm.bound(), cold)
        begin = deadline - cold - (deadline - start - cold) // warm * warm
        while now() < begin:  # the ticks end as close to the deadline as they fit
            pass
        start = now()
        self.tick()
        end = now()
        self.cold.add(end - start)
        while deadline - end >= min(self.warm.bound(), self.cold.bound()) and not self.error:
            start = end
            self.tick()
            end = now()
            self.warm.add(end - start)
        if end > deadline:
            self.late += 1
            self.late_max_ns = max(self.late_max_ns, end - deadline)

    def tick(self) -> None:
        """One shadow tick, as ``Controller.cycle`` ticks the live one; an error turns it off."""
        shadow, step = self.shadow, self.step
        try:
            step.sleep_until(shadow.deadline)
            shadow.compute(step.now_ns())
            if shadow.guards.latched:  # a fault of its own simulator: hold again, to warm
                shadow.on_reset(RESET)  # the code the live loop runs when all is well
            shadow.outbox.queue.clear()  # its events (and status) go nowhere
            shadow.tick_count += 1
            shadow.deadline = shadow.latency.next_deadline(shadow.deadline, step.now_ns())
        except Exception as exc:  # the shadow's own bug: the live loop goes on without it
            self.error = f"{type(exc).__name__}: {exc}"
        self.ran += 1

    def report(self) -> str:
        """The counters, one line: ``warm-up: windows W, ran R, skipped S, late L, max M ns``."""
        return (f"warm-up: windows {self.windows}, ran {self.ran}, skipped {self.skipped}, "
                f"late {self.late}, max {self.late_max_ns} ns")

    def close(self) -> None:
        self.shadow.release()
        self.backend.close()
        for end in self.ends:
            end.close()


class Estimate:
    """How long a tick may take (ns): its mean and mean deviation, smoothed as TCP smooths
    round trips (RFC 6298), ``bound`` the mean plus ``SPREAD`` deviations plus ``MARGIN_NS``:
    a busy machine's scattered ticks widen it until no warm-up fits."""

    def __init__(self, mean_ns: float) -> None:
        self.mean = mean_ns
        self.deviation = 0.0

    def add(self, ns: float) -> None:
        error = ns - self.mean
        self.mean += error / 8
        self.deviation += (abs(error) - self.deviation) / 4

    def bound(self) -> float:
        return self.mean + SPREAD * self.deviation + MARGIN_NS
