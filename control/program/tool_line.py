"""A program's straight tool line: from where the joints are to a pose (or a named
position's pose) on a straight line in the world, the tool turning about one fixed axis, on
the branch the arm is on: the Cartesian jog's line (``control.motion.cartesian_jog``) from
the start pose to the end pose, at a tool speed in mm/s (Unimate only).

The line's speed is at most the machine's Cartesian speed (``[kinematics]
cartesian_jog_speed``); its rotation keeps the same fraction of the Cartesian turn speed,
and near the wrist singularity it slows as a jog does. A line to a taught position whose
joints lie on another branch would end at its pose with other joints: refused, saying so.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from control.motion.cartesian_jog import MIN_JOG, plan_jog
from control.motion.fields import FieldError, NumberRule
from control.motion.plan import MovePlan, moving_joints
from control.motion.robot_model import unimate_model
from hw.machine import Machine
from kinematics import xyz_fixed

KIND = "cartesian"  # a smooth path on the tool's line: summarised as one


def speed_rule(machine: Machine) -> NumberRule:
    """A line's tool speed: above 0, at most the machine's Cartesian speed (mm/s)."""
    return NumberRule("line speed", " mm/s", 0.0, machine.cartesian_jog_speed[0],
                      strict_low=True, context=f"the Cartesian speed of machine {machine.name}")


def tool_line(machine: Machine, here: np.ndarray, pose: tuple[float, ...],
              to: tuple[float, ...] | None, speed: float | None, *, dt: float) -> MovePlan:
    """The line from the joints ``here`` to ``pose`` (x y z mm, γ β α deg), or to the pose of
    the joints ``to``; ``speed`` mm/s (None: the machine's Cartesian speed). ValueError
    naming why (no kinematics, out of reach, a limit, a singularity, another branch)."""
    from control.program.move_steps import StepProblem

    model = unimate_model(machine)
    top = machine.cartesian_jog_speed[0]
    try:
        mm_s = top if speed is None else speed_rule(machine).parse(repr(float(speed)))
    except FieldError as exc:
        raise StepProblem("speed", f"speed: {exc}") from None
    assert mm_s is not None
    start = np.clip(np.asarray(here, dtype=float), machine.lower, machine.upper)
    end = model.pose(np.asarray(to, dtype=float)) if to is not None else np.asarray(pose)
    t0 = model.forward(start)
    turn = xyz_fixed.rotation(*np.radians(end[3:])) @ t0[:3, :3].T
    displacement = np.concatenate([end[:3] - t0[:3, 3],
                                   np.degrees(Rotation.from_matrix(turn).as_rotvec())])
    if (np.linalg.norm(displacement[:3]) < MIN_JOG[0]
            and np.linalg.norm(displacement[3:]) < MIN_JOG[1]):
        path = np.vstack([start, start])  # there already: the line is a hold in place
    else:
        path = plan_jog(start, displacement, machine, frame="world", dt=dt,
                        speed=mm_s / top).q
    if to is not None:
        goal = np.array([j.goal_tolerance for j in machine.joints])
        off = np.abs(path[-1] - np.asarray(to)) > goal
        if off.any():
            names = ", ".join(machine.joints[j].name for j in np.flatnonzero(off))
            raise ValueError(f"the line reaches the position's pose on the arm's branch, but "
                             f"with other joints ({names}): the position is on another branch; "
                             f"go to it in joint space (go = …) instead")
    meta = {"end_pose": [float(v) for v in end], "line_speed_mm_s": mm_s}
    if to is not None:
        meta["end_joints"] = [float(v) for v in to]
    return MovePlan(KIND, f"line to ({', '.join(f'{v:.1f}' for v in end)}) at {mm_s:g} mm/s",
                    path, meta=meta, moving=moving_joints(path))
