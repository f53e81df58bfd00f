"""In position at a move's end: ros2_control's joint_trajectory_controller goal tolerances
(``goal_tolerance`` per joint, ``stopped_velocity_tolerance``, ``goal_time``) and LinuxCNC's
in-position, for the controller's settle (``docs/motion.md``).

Inputs: the path's end (the hold target), each sample's positions and time. Output: the
verdict once there is one: ``complete`` when every joint has been within its
``goal_tolerance`` of the end and slower than its ``stopped_speed`` for ``GOAL_WINDOW_S``
(the speed judged over that window too, so one noisy reading neither passes nor fails
it), ``unsettled: …`` naming each joint that is not once ``goal_time`` has passed since
the path's end; and each joint's settle time (``settled_s``, s after the path's end; NaN
while it is out).
"""

from __future__ import annotations

import math
from collections import deque

from hw.machine import GOAL_WINDOW_S, Machine

WINDOW_EDGE_S = GOAL_WINDOW_S - 1e-9  # a window's worth of samples, whatever the rounding


class GoalCheck:
    """The settle of one move, from its path's end ``goal`` at ``start_ns``."""

    def __init__(self, machine: Machine, goal: list[float], start_ns: int, dt: float) -> None:
        self.joints = machine.joints
        self.goal = list(goal)
        self.start_ns = start_ns
        self.goal_time_s = machine.goal_time_s
        self.tolerance = [j.goal_tolerance for j in machine.joints]
        self.stopped = [j.stopped_speed for j in machine.joints]
        self.window = deque(maxlen=max(2, round(GOAL_WINDOW_S / dt) + 1))  # (t s, positions)
        self.settled_s = [math.nan] * len(goal)  # since when each joint is in position
        self.error = [0.0] * len(goal)  # position − goal, the last sample
        self.speed = [math.nan] * len(goal)  # over the window, the last sample
        self.t = 0.0  # s since the path's end, the last sample
        self.verdict = ""

    def elapsed_s(self, now: int) -> float:
        return (now - self.start_ns) / 1e9

    def sample(self, now: int, position: list[float]) -> str:
        """Judge one sample; the move's status once settled or out of time, else ""."""
        t = self.t = self.elapsed_s(now)
        window = self.window
        window.append((t, tuple(position)))
        t0, old = window[0]
        full = len(window) == window.maxlen and t > t0
        for j, q in enumerate(position):
            self.error[j] = q - self.goal[j]
            self.speed[j] = abs(q - old[j]) / (t - t0) if full else math.nan
            inside = abs(self.error[j]) <= self.tolerance[j] and self.speed[j] <= self.stopped[j]
            if not inside:
                self.settled_s[j] = math.nan
            elif self.settled_s[j] != self.settled_s[j]:
                self.settled_s[j] = t
        if all(t - s >= WINDOW_EDGE_S for s in self.settled_s):  # NaN compares False
            self.verdict = "complete"
        elif t >= self.goal_time_s:
            self.verdict = (f"unsettled: {'; '.join(self.out_text(j) for j in self.out())} "
                            f"after {self.goal_time_s:g} s")
        return self.verdict

    def out(self) -> list[int]:
        """The joints not in position; if every one is, those in it for less than a window."""
        out = [j for j, s in enumerate(self.settled_s) if s != s]
        return out or [j for j, s in enumerate(self.settled_s) if self.t - s < WINDOW_EDGE_S]

    def out_text(self, j: int) -> str:
        joint, error, speed, since = self.joints[j], self.error[j], self.speed[j], \
            self.settled_s[j]
        text = f"{joint.name} {abs(error):.2f}{joint.symbol} from its goal"
        if since == since:
            return text + f", in position only for its last {self.t - since:.3f} s"
        if abs(error) <= self.tolerance[j]:
            text += f", moving {speed:.3g} {joint.unit}/s"
        return text

    def record(self) -> dict[str, object]:
        """For the run and ``MoveDone``: each joint's settle time (None: not settled) and its
        error from the goal at the end."""
        return {"goal_time_s": self.goal_time_s,
                "settle_s": tuple(None if s != s else round(s, 4) for s in self.settled_s),
                "goal_error": tuple(round(e, 6) for e in self.error)}
