"""Feed override and feed hold: how fast the path being followed advances (LinuxCNC's feed).

The path's time is scaled by ``rate`` (0…1): each tick the move's phase advances
``rate`` rows, the desired position is interpolated between rows, and the desired
velocity (and with it the feed-forward) is ``rate`` times the path's. So position
and velocity stay continuous whatever the override. ``rate`` follows its target
(the override, or 0 while paused) no faster than the joints allow: along the path
the acceleration ``rate′·v`` stays within half of each joint's ``max_accel`` (the
other half is the path's own), so a pause decelerates along the path to a stop.

Inputs: the operator's override and pause, the path's velocity per joint at the
current phase. Outputs: ``rate``, and what the run records (``changes``: the
override against the move's time; ``pauses``: when and how long it was held).
"""

from __future__ import annotations

from hw.machine import Machine


class FeedRate:
    def __init__(self, machine: Machine, dt: float) -> None:
        self.dt = dt
        self.half_accel = [0.5 * j.max_accel for j in machine.joints]
        self.override = 1.0
        self.paused = False
        self.rate = 1.0
        self.changes: list[tuple[float, float]] = []  # the move's: (move time s, override) as set
        self.pauses: list[tuple[float, float]] = []  # the move's: (move time s, length s)
        self.paused_at = 0.0

    @property
    def target(self) -> float:
        return 0.0 if self.paused else self.override

    @property
    def steady(self) -> bool:
        """Following the path at full speed: the loop's fast path."""
        return self.rate == 1.0 and not self.paused

    def start_move(self, changes: list[tuple[float, float]],
                   pauses: list[tuple[float, float]]) -> None:
        """A new move, recording into its ``changes`` and ``pauses``: not paused; it starts at
        the override (from rest, as every path)."""
        self.paused = False
        self.rate = self.override
        self.changes, self.pauses = changes, pauses
        if self.override != 1.0:
            changes.append((0.0, self.override))

    def end_move(self, t: float) -> None:
        """The move ended at its time ``t``: a hold still on is recorded up to then."""
        self.resume(t)
        self.changes, self.pauses = [], []

    def set_override(self, value: float, t: float) -> None:
        self.override = value
        self.changes.append((round(t, 4), value))

    def pause(self, t: float) -> None:
        if not self.paused:
            self.paused, self.paused_at = True, t

    def resume(self, t: float) -> None:
        if self.paused:
            self.paused = False
            self.pauses.append((round(self.paused_at, 4), round(t - self.paused_at, 4)))

    def advance(self, path_velocity: list[float]) -> None:
        """Move ``rate`` toward its target, as fast as the path's velocity ``(J,)`` (units/s
        at rate 1, at the current phase) lets the joints decelerate or accelerate."""
        target, rate = self.target, self.rate
        if rate == target:
            return
        step = 1.0
        for a, v in zip(self.half_accel, path_velocity, strict=True):
            if v != 0.0:
                step = min(step, a / abs(v) * self.dt)
        self.rate = min(rate + step, target) if target > rate else max(rate - step, target)
