"""Jogs: the hold target moves where the operator asks at a jog speed, never jumps.

Position jog: each press of a position-jog key moves a joint's goal by a step; the
hold target then travels to the goal on a trapezoid: accelerating at the joint's
``max_accel`` up to its ``jog_speed`` (machine file), and braking so it stops on
the goal. So the law never sees a step of the whole jog at once: the largest
step is a ramp the joint can follow, and the duty stays what following that ramp
needs (the bug this replaces: ``9 d d`` moved Up/Down's target 25° at once and
saturated its valve).

Velocity jog (MoveIt Servo's, a pendant's hold-to-move): the client streams each
joint's velocity; the hold target moves at it, changing by at most ``max_accel``,
capped at ``jog_speed``. A stream not renewed within ``DEADMAN_S`` (counted in
samples, so a lockstep clock counts the same) brakes to a stop at ``max_accel``. The
velocities are taken as sent: the feed override is the streamer's to apply (a client's
Cartesian servo tracks a reference along its line, and a controller that scaled what it
sends would only leave that servo lagging its reference at full speed).

Both come to rest ``rest_margin`` inside the soft limits (``rest_range``), and brake
within their braking distance of that edge, never past it: a target on the limit
itself would press the arm on the hard stop, its integrator winding the valve open
against it (issue 25: a 1° step onto 30° latched a feedback fault).

In reduced speed (``control/rt/speed_cap.py``) each sample's wanted velocities (every
joint at its jog speed toward its goal, or at its streamed velocity) are scaled together so
that the tool stays within 250 mm/s with the margin of ``JOG_TRACKING`` (the hold law follows
a creeping target in small jerks); a joint already faster slows at its ``max_accel``.

Inputs: the goal per joint (``move_goal``) or its streamed velocity (``stream``), the
hold target (moved in place). Outputs: the target each tick and the jog velocity per
joint (for the supervisor's following-error limit).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from control.rt.speed_cap import JOG_TRACKING, SpeedCap
from hw.machine import Joint, Machine

DEADMAN_S = 0.150  # a streamed velocity not renewed within this brakes to 0
REST_COUNTS = 3.0  # the least rest margin inside a soft limit, in encoder counts


def rest_margin(joint: Joint) -> float:
    """How far inside a soft limit a jog comes to rest: the joint's goal tolerance (so an arm
    in position never presses on the limit), at least ``REST_COUNTS`` counts."""
    return max(joint.goal_tolerance, REST_COUNTS * abs(joint.encoder.gradient))


def rest_range(joint: Joint) -> tuple[float, float]:
    """The part of the joint's range a jog may bring it to rest in."""
    margin = min(rest_margin(joint), 0.25 * (joint.upper - joint.lower))
    return joint.lower + margin, joint.upper - margin


class PositionJog:
    def __init__(self, machine: Machine, dt: float, cap: SpeedCap | None = None) -> None:
        n = self.n = machine.n_joints
        self.dt = dt
        self.cap = cap or SpeedCap(machine)
        self.scale = 1.0  # this sample's fraction of the jog speeds (reduced speed)
        self.unscaled = [0.0] * n  # the velocities wanted before it (units/s)
        self.speed = [j.jog_speed for j in machine.joints]
        self.accel = [j.max_accel for j in machine.joints]
        ranges = [rest_range(j) for j in machine.joints]
        self.lower = [low for low, _ in ranges]
        self.upper = [high for _, high in ranges]
        self.goal = [0.0] * n
        self.velocity = [0.0] * n
        self.streamed = [False] * n  # following a streamed velocity, not a goal
        self.wanted = [0.0] * n  # the streamed velocity (units/s), capped at jog_speed
        self.deadman_samples = max(1, round(DEADMAN_S / dt))
        self.renew_left = 0  # samples until the stream counts as stopped
        self.moving = False

    def stop_at(self, target: list[float]) -> None:
        """Hold still at ``target``: goals there, velocities zero, any stream ended."""
        self.goal[:] = target
        for j in range(self.n):
            self.velocity[j] = 0.0
            self.wanted[j] = 0.0
            self.streamed[j] = False
        self.renew_left = 0
        self.moving = False

    def move_goal(self, j: int, goal: float) -> None:
        """Joint ``j`` to ``goal``, kept inside its rest range; a goal already outside it (the
        arm held there) is not moved further out."""
        old = self.goal[j]
        if goal > self.upper[j]:
            goal = max(self.upper[j], min(goal, old))
        elif goal < self.lower[j]:
            goal = min(self.lower[j], max(goal, old))
        self.goal[j] = goal
        self.streamed[j] = False
        self.wanted[j] = 0.0
        self.moving = True

    def stream(self, velocity: Sequence[float]) -> None:
        """Each joint's streamed velocity (units/s), for the next ``DEADMAN_S``; a joint at 0
        that is not being streamed keeps its position jog."""
        for j, v in enumerate(velocity):
            if v == 0.0 and not self.streamed[j]:
                continue
            self.streamed[j] = True
            self.wanted[j] = max(-self.speed[j], min(self.speed[j], v))
        self.renew_left = self.deadman_samples
        self.moving = True

    def advance(self, target: list[float]) -> None:
        """One sample: each target a step toward its goal (or at its streamed velocity), at most
        ``jog_speed``, changing by at most a·dt a sample, and never faster than it can still
        stop from in whole samples before its goal or the edge of its rest range: braking from
        k·a·dt covers a·dt²·k(k+1)/2, so k = (√(1 + 8r/(a·dt²)) − 1)/2 for the distance r."""
        if self.renew_left:
            self.renew_left -= 1
            if not self.renew_left:  # the deadman: the stream stopped arriving
                self.wanted[:] = [0.0] * self.n
        self.scale = self.reduced_scale(target) if self.cap.reduced else 1.0
        moving = False
        for j in range(self.n):
            if self.streamed[j]:
                moving |= self.follow_stream(j, target)
            else:
                moving |= self.follow_goal(j, target)
        self.moving = moving

    def reduced_scale(self, target: list[float]) -> float:
        """The fraction of every joint's wanted velocity (its jog speed toward its goal, or its
        streamed velocity) that keeps the tool within the reduced speed at ``target``."""
        unscaled = self.unscaled
        for j in range(self.n):
            if self.streamed[j]:
                unscaled[j] = self.wanted[j]
            else:
                unscaled[j] = self.speed[j] if self.goal[j] != target[j] else 0.0
        return self.cap.fraction(unscaled, target, JOG_TRACKING)

    def braking_speed(self, j: int, distance: float) -> float:
        """The fastest joint ``j`` may go with ``distance`` left to stop in."""
        dv = self.accel[j] * self.dt
        return (math.sqrt(1.0 + 8.0 * max(distance, 0.0) / (dv * self.dt)) - 1.0) / 2.0 * dv

    def follow_goal(self, j: int, target: list[float]) -> bool:
        remaining = self.goal[j] - target[j]
        v = self.velocity[j]
        if remaining == 0.0 and v == 0.0:
            return False
        dv = self.accel[j] * self.dt
        wanted = math.copysign(min(self.scale * self.speed[j],
                                   self.braking_speed(j, abs(remaining))), remaining)
        v += max(-dv, min(dv, wanted - v))
        step = v * self.dt
        if step * remaining >= remaining * remaining:  # this sample reaches the goal
            target[j], self.velocity[j] = self.goal[j], 0.0
            return False
        target[j] += step
        self.velocity[j] = v
        return True

    def follow_stream(self, j: int, target: list[float]) -> bool:
        q, v, lower, upper = target[j], self.velocity[j], self.lower[j], self.upper[j]
        wanted = max(-self.braking_speed(j, q - lower),
                     min(self.braking_speed(j, upper - q), self.scale * self.wanted[j]))
        dv = self.accel[j] * self.dt
        v += max(-dv, min(dv, wanted - v))
        moved = q + v * self.dt
        inside = max(min(lower, q), min(max(upper, q), moved))  # never further out than an edge
        if inside != moved:
            v = 0.0
        target[j] = self.goal[j] = inside
        self.velocity[j] = v
        if v == 0.0 and self.wanted[j] == 0.0:
            self.streamed[j] = False  # stopped: a position jog goes on from here
            return False
        return True
