"""Position jog: the hold target moves to where the operator asked at a jog speed, never jumps.

Each press of a position-jog key moves a joint's goal by a step; the hold target
then travels to the goal on a trapezoid: accelerating at the joint's
``max_accel`` up to its ``jog_speed`` (machine file), and braking so it stops on
the goal. So the law never sees a step of the whole jog at once: the largest
step is a ramp the joint can follow, and the duty stays what following that ramp
needs (the bug this replaces: ``9 d d`` moved Up/Down's target 25° at once and
saturated its valve).

Inputs: the goal per joint (``move_goal``), the hold target (moved in place).
Outputs: the target each tick and the jog velocity per joint (for the
supervisor's following-error limit).
"""

from __future__ import annotations

import math

from hw.machine import Machine


class PositionJog:
    def __init__(self, machine: Machine, dt: float) -> None:
        n = self.n = machine.n_joints
        self.dt = dt
        self.speed = [j.jog_speed for j in machine.joints]
        self.accel = [j.max_accel for j in machine.joints]
        self.goal = [0.0] * n
        self.velocity = [0.0] * n
        self.moving = False

    def stop_at(self, target: list[float]) -> None:
        """Hold still at ``target``: goals there, velocities zero."""
        self.goal[:] = target
        for j in range(self.n):
            self.velocity[j] = 0.0
        self.moving = False

    def move_goal(self, j: int, goal: float) -> None:
        self.goal[j] = goal
        self.moving = True

    def advance(self, target: list[float]) -> None:
        """One tick: each target a step toward its goal, at most ``jog_speed``, changing by
        at most a·dt a tick, and never faster than it can still stop from in whole ticks:
        braking from k·a·dt covers a·dt²·k(k+1)/2, so k = (√(1 + 8r/(a·dt²)) − 1)/2 for
        the distance r left."""
        dt, moving = self.dt, False
        for j in range(self.n):
            remaining = self.goal[j] - target[j]
            v = self.velocity[j]
            if remaining == 0.0 and v == 0.0:
                continue
            dv = self.accel[j] * dt
            k = (math.sqrt(1.0 + 8.0 * abs(remaining) / (dv * dt)) - 1.0) / 2.0
            wanted = math.copysign(min(self.speed[j], k * dv), remaining)
            v += max(-dv, min(dv, wanted - v))
            step = v * dt
            if step * remaining >= remaining * remaining:  # this tick reaches the goal
                target[j], v = self.goal[j], 0.0
            else:
                target[j] += step
                moving = True
            self.velocity[j] = v
        self.moving = moving
