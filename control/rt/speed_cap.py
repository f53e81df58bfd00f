"""Reduced speed (ISO 10218-1's T1): how fast a motion may go while the operator stands near.

In reduced mode every motion the controller makes keeps each joint at most its
``jog_speed`` (machine file) and the tool point at most ``TOOL_SPEED`` (250 mm/s). The
controller enforces it from the velocities it commands, never from a figure a client sends.

The tool's speed is bounded, not computed: the tool point moves at
``|Σ q̇_j · (z_j × r_j)| ≤ Σ |q̇_j| · L_j(q)``, where ``L_j`` is the lever of joint ``j``:
1 mm/mm for a prismatic joint, and for a revolute one the longest its arm to the tool point
can be, in mm per rad. Along the DH chain (eq. 4.03) the tool point sits at
``a_i x_i + Σ_{k>i} (d_k z_{k-1} + a_k x_k)`` from joint i's axis (its own ``d_i`` lies along
the axis), so ``L_i ≤ |a_i| + Σ_{k>i} (|a_k| + |d_k|)``, with a prismatic row's ``d_k`` as
the joint stands now. The bound costs a few multiplications a tick, where the tool point's
speed from forward kinematics would cost a batch FK (60 to 200 ms for a 60 s path on the
two-core VM, ``benchmarks/speed_mode.py``; a tick is 1 ms), and ``control.rt`` may not use
the kinematics package. It is conservative (about 1.4 times the true speed at the Unimate's
home): a reduced motion is slower than it need be, never faster. A machine without a DH
table (the rig) has no tool but its joints: a prismatic joint is its own tool (the rig's
ram).

Inputs: each joint's velocity (units/s) and position (mm, deg). Outputs: the bound on the
tool's speed, and the largest fraction of a motion's velocity the limits allow.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from hw.machine import Machine

TOOL_SPEED = 250.0  # mm/s: ISO 10218-1 5.7's reduced speed at the tool centre point
# The hold law follows a jog's creeping target in small stick-slip jerks (no feed-forward):
# over 0.2 s the simulated arm's tool ran up to 1.25 times the commanded speed
# (benchmarks/speed_mode.py), so a jog is commanded within TOOL_SPEED / JOG_TRACKING.
JOG_TRACKING = 1.25
MODES = ("reduced", "automatic")
DEG = math.pi / 180.0


class SpeedCap:
    def __init__(self, machine: Machine, tool_speed: float = TOOL_SPEED) -> None:
        joints = machine.joints
        self.n = len(joints)
        self.tool_speed = tool_speed
        self.jog_speed = [j.jog_speed for j in joints]
        self.reduced = False
        # lever of each joint: constant mm (per rad) and the prismatic joints whose extension adds
        self.lever_mm = [1.0 if j.kind == "prismatic" else 0.0 for j in joints]
        self.extensions: list[list[tuple[int, float]]] = [[] for _ in joints]  # (joint, d0)
        rows = machine.dh
        for i, row in enumerate(rows):
            if joints[row.joint].kind == "prismatic":
                continue
            self.lever_mm[row.joint] = abs(row.a)
            for later in rows[i + 1:]:
                self.lever_mm[row.joint] += abs(later.a)
                if joints[later.joint].kind == "prismatic":
                    self.extensions[row.joint].append((later.joint, later.d))
                else:
                    self.lever_mm[row.joint] += abs(later.d)
        self.per_unit = [1.0 if j.kind == "prismatic" else DEG for j in joints]  # rad per deg
        self.levers = [0.0] * self.n

    @property
    def mode(self) -> str:
        return MODES[0] if self.reduced else MODES[1]

    def lever(self, position: Sequence[float]) -> list[float]:
        """Each joint's lever at ``position``: tool mm per joint unit (mm or deg)."""
        levers = self.levers
        for j in range(self.n):
            reach = self.lever_mm[j]
            for k, d0 in self.extensions[j]:
                reach += abs(d0 + position[k])
            levers[j] = reach * self.per_unit[j]
        return levers

    def tool_bound(self, velocity: Sequence[float], position: Sequence[float]) -> float:
        """The most the tool point can move at (mm/s) with the joints at ``velocity``."""
        levers = self.lever(position)
        return sum(abs(v) * lever for v, lever in zip(velocity, levers, strict=True))

    def fraction(self, velocity: Sequence[float], position: Sequence[float],
                 tracking: float = 1.0) -> float:
        """The largest ``s`` (at most 1) for which ``s × velocity`` keeps every joint within its
        jog_speed and the tool within ``tool_speed / tracking`` (``tracking``: how much faster
        than commanded the arm may run, following it)."""
        s = 1.0
        for v, limit in zip(velocity, self.jog_speed, strict=True):
            if abs(v) * s > limit:
                s = limit / abs(v)
        tool = self.tool_bound(velocity, position)
        if tool * s * tracking > self.tool_speed:
            s = self.tool_speed / (tool * tracking)
        return s
