"""The guards: the E-stop latch, soft limits and following error (sections 5.1, 6.3).

Inputs: believed joint positions, desired positions and controller output per
joint, the mode, the clock. Outputs: the latch (``latched``, ``reason``), duty
zeroed on a joint driven into its limit, and a ``Trip`` when a joint is
farther than its following error from its target and not closing.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from control.events import Fault
from control.outbox import Outbox
from hw.machine import Machine

MS = 1_000_000


@dataclass(frozen=True)
class Trip:
    """Following error on ``joint``: the controller aborts the move, or latches if holding."""

    joint: int
    message: str


class Guards:
    def __init__(self, machine: Machine, outbox: Outbox, window_ns: int) -> None:
        joints = self.joints = machine.joints
        self.n = machine.n_joints
        self.outbox = outbox
        self.window_ns = window_ns
        self.lower = [j.lower for j in joints]
        self.upper = [j.upper for j in joints]
        self.limit_margin = [2 * abs(j.encoder.gradient) for j in joints]  # two encoder counts
        self.ferror = [j.following_error for j in joints]
        self.latched = False
        self.reason = ""
        self.limit_reported = [False] * self.n
        self.snapshot = [math.inf] * self.n
        self.next_check_ns = 0

    def latch(self, reason: str) -> None:
        self.latched = True
        self.reason = reason

    def release(self) -> None:
        self.latched = False
        self.reason = ""

    def rearm(self) -> None:
        """A new move or mode: limits may be reported again, following error starts afresh."""
        self.limit_reported = [False] * self.n
        self.snapshot = [math.inf] * self.n

    def clamp(self, j: int, q: float, homed: bool) -> float:
        """Soft limits: no desired position ever leaves the joint's range (once homed)."""
        if not homed:
            return q
        return min(self.upper[j], max(self.lower[j], q))

    def stop_at_limits(self, position: list[float], duty: list[float]) -> None:
        """Open loop: a joint driven into its limit gets no more duty that way."""
        for j in range(self.n):
            q, u = position[j], duty[j]
            margin = self.limit_margin[j]
            if (q >= self.upper[j] - margin and u > 0) or (q <= self.lower[j] + margin and u < 0):
                duty[j] = 0.0
                if not self.limit_reported[j]:
                    self.limit_reported[j] = True
                    joint = self.joints[j]
                    self.outbox.put(Fault(
                        "limit", j, f"{joint.name} at {q:.1f}{joint.symbol} reached its limit "
                                    f"{joint.limit_text()}: motion stopped on that joint"))

    def following_error(self, desired: list[float], position: list[float],
                        now: int) -> Trip | None:
        """FERROR, checked once a window: beyond the joint's limit and not closing by 10 %."""
        if now < self.next_check_ns:
            return None
        self.next_check_ns = now + self.window_ns
        for j in range(self.n):
            error = abs(desired[j] - position[j])
            if error > self.ferror[j] and error > 0.9 * self.snapshot[j]:
                joint = self.joints[j]
                return Trip(j, f"following error: {joint.name} is {error:.1f}{joint.symbol} from "
                               f"its target (limit {self.ferror[j]:g}{joint.symbol}) and not "
                               "closing")
            self.snapshot[j] = error
        return None
