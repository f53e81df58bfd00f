"""The guards: the E-stop latch and the soft limits (sections 5.1, 6.3).

Inputs: believed joint positions and controller output per joint, whether the
mode is closed loop. Outputs: the latch (``latched``, ``reason``), and duty
zeroed on a joint driven into its limit, in every mode: open loop within two
counts of the limit; closed loop once a joint is past it (the law holds a
target on the limit itself), with a fault event naming the joint.
"""

from __future__ import annotations

from control.rt.events import Fault
from control.rt.outbox import Outbox
from hw.machine import Machine


class Guards:
    def __init__(self, machine: Machine, outbox: Outbox) -> None:
        joints = self.joints = machine.joints
        self.n = machine.n_joints
        self.outbox = outbox
        self.lower = [j.lower for j in joints]
        self.upper = [j.upper for j in joints]
        self.count = [abs(j.encoder.gradient) for j in joints]
        self.latched = False
        self.reason = ""
        self.limit_reported = [False] * self.n

    def latch(self, reason: str) -> None:
        self.latched = True
        self.reason = reason

    def release(self) -> None:
        self.latched = False
        self.reason = ""

    def rearm(self) -> None:
        """A new move or mode: limits may be reported again."""
        self.limit_reported = [False] * self.n

    def clamp(self, j: int, q: float, homed: bool) -> float:
        """Soft limits: no desired position ever leaves the joint's range (once homed)."""
        if not homed:
            return q
        return min(self.upper[j], max(self.lower[j], q))

    def stop_at_limits(self, position: list[float], duty: list[float], closed_loop: bool) -> None:
        """A joint at (open loop) or past (closed loop) a limit gets no more duty that way."""
        inside = -1.0 if closed_loop else 2.0  # counts inside the limit where duty stops
        for j in range(self.n):
            q, u = position[j], duty[j]
            margin = inside * self.count[j]
            if (q >= self.upper[j] - margin and u > 0) or (q <= self.lower[j] + margin and u < 0):
                duty[j] = 0.0
                if not self.limit_reported[j]:
                    self.limit_reported[j] = True
                    joint = self.joints[j]
                    where = "reached" if not closed_loop else "is past"
                    self.outbox.put(Fault(
                        "limit", j, f"{joint.name} at {q:.1f}{joint.symbol} {where} its limit "
                                    f"{joint.limit_text()}: its valve is closed toward it"))
