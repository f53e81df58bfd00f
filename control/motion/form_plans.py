"""The plans of the Moves forms, from their field values and where the joints are.

The Moves tab (``app.tabs.move_forms``, ``end_point_form``, ``path_forms``) and
``servodesk move`` both turn what was typed into a ``MovePlan`` here, so the same
fields make the same move, refused with the same reasons. ``current (J,)`` is where the
joints are; positions in mm and deg, times in s, ``dt`` the sample time. Each function
raises ValueError naming the field or the joint and the fix; a field left blank is None.
``ControlClient.run`` puts the approach in front (``MovePlan.approached``).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from control.motion import moves
from control.motion.acceptance import check_duration
from control.motion.path_files import PathPoints, resample
from control.motion.plan import APPROACH_SPEED, MovePlan, moving_joints
from hw.machine import Machine
from kinematics import Unreachable
from kinematics.unimate import Unimate2000B


def with_start(current: np.ndarray, j: int, start: float | None) -> np.ndarray:
    """``current`` with joint ``j`` at ``start`` (blank: where it is)."""
    q = np.array(current, dtype=float)
    if start is not None:
        q[j] = start
    return q


def step(machine: Machine, current: np.ndarray, j: int, target: float,
         start: float | None = None, duration: float | None = None, *, dt: float) -> MovePlan:
    """One joint steps to ``target``; the others hold (option.c SingleStepInput)."""
    q0 = with_start(current, j, start)
    path = moves.step(q0, j, target, duration, dt=dt, machine=machine)
    joint = machine.joints[j]
    return MovePlan("step", f"step {joint.name} to {target:g}{joint.symbol}", path,
                    meta={"joint": joint.name, "start": float(q0[j]), "target": float(target)},
                    moving=(j,))


def multi_step(machine: Machine, current: np.ndarray, targets: Sequence[float | None],
               duration: float | None = None, *, dt: float) -> MovePlan:
    """Every joint steps to its target at once (option.c MultiStepInput); a blank target
    (None) is where the joint is."""
    targets = [float(current[j]) if t is None else t for j, t in enumerate(targets)]
    path = moves.multi_step(current, targets, duration, dt=dt, machine=machine)
    return MovePlan("multi_step", "multi-step", path,
                    meta={"targets": [float(t) for t in targets]}, moving=moving_joints(path))


def sequence(machine: Machine, current: np.ndarray, steps: Sequence[tuple[float, float]], *,
             dt: float) -> MovePlan:
    """The rig's sequence: each ``(position, dwell s)`` in turn (function.c MultiStep)."""
    path = moves.rig_sequence(current, steps, dt=dt, machine=machine)
    return MovePlan("multi_step", f"sequence of {len(steps)} steps", path,
                    meta={"steps": [[float(p), float(d)] for p, d in steps]}, moving=(0,))


def ramp(machine: Machine, current: np.ndarray, j: int, end: float, ramp_time: float,
         start: float | None = None, total: float | None = None, *, dt: float) -> MovePlan:
    """From ``start`` to ``end`` in ``ramp_time``, then hold (function.c RampInput)."""
    q0 = with_start(current, j, start)
    q1 = with_start(q0, j, end)
    path = moves.ramp(q0, q1, ramp_time, total, dt=dt, machine=machine)
    joint = machine.joints[j]
    return MovePlan("ramp", f"ramp {joint.name} to {end:g}{joint.symbol}", path,
                    meta={"joint": joint.name, "start": float(q0[j]), "end": float(end),
                          "ramp_time": ramp_time},
                    moving=(j,))


def sine(machine: Machine, current: np.ndarray, j: int, end: float, period: float,
         duration: float, start: float | None = None, *, dt: float) -> MovePlan:
    """``start + (end − start)/2·(1 − cos 2πt/T)`` for ``duration`` (function.c Sinewave)."""
    q0 = with_start(current, j, start)
    q1 = with_start(q0, j, end)
    path = moves.sine(q0, q1, period, duration, dt=dt, machine=machine)
    joint = machine.joints[j]
    return MovePlan("sine", f"sine {joint.name} {q0[j]:g}↔{end:g}{joint.symbol}", path,
                    meta={"joint": joint.name, "start": float(q0[j]), "end": float(end),
                          "period": period, "duration": duration},
                    moving=(j,))


def go_to(machine: Machine, current: np.ndarray, target: Sequence[float], speed: float, *,
          dt: float) -> MovePlan:
    """A joint-space quintic move from ``current`` to ``target`` at ``speed`` of every joint's
    max_speed and max_accel (0 < speed ≤ 1); ValueError for a target outside the limits, a
    bad speed, or a move longer than the move limit (``acceptance.MAX_MOVE_S``: refused
    before it is sampled)."""
    from control.motion.trajectory import via_path

    q = machine.check_targets(tuple(float(v) for v in target))
    if not 0.0 < speed <= 1.0:
        raise ValueError(f"speed must be in (0, 1] of each joint's max_speed, got {speed}")
    # a joint resting just past a limit (the rig on its stop) starts on it; one farther out
    # is refused by the acceptance rules ("jog it back inside its limits first")
    start = np.clip(current, machine.lower, machine.upper)
    fix = "raise the speed, or go part of the way first"
    check_duration(_least_time(machine, start, np.array(q), speed), "the go to", fix)
    path = via_path(np.vstack([start, q]), machine, dt=dt, speed_fraction=speed).q
    check_duration((len(path) - 1) * dt, "the go to", fix)
    return MovePlan("go_to", "go to", path, meta={"target": list(q), "speed_fraction": speed},
                    moving=moving_joints(path))


def _least_time(machine: Machine, start: np.ndarray, target: np.ndarray, speed: float) -> float:
    """The shortest a go to from ``start`` to ``target`` at ``speed`` can take: its slowest
    joint's minimum-jerk time, where the trajectory's timing starts and which it only
    stretches (``control.motion.trajectory``)."""
    from control.motion.trajectory import PEAK_ACCEL, PEAK_SPEED

    change = np.abs(target - start)
    vmax = np.array([j.max_speed for j in machine.joints]) * speed
    amax = np.array([j.max_accel for j in machine.joints]) * speed
    return float(np.max(np.maximum(PEAK_SPEED * change / vmax,
                                   np.sqrt(PEAK_ACCEL * change / amax))))


def pulse(machine: Machine, duty: float, duration: float, *, dt: float) -> MovePlan:
    """Open loop: ``duty`` % on the first joint for ``duration`` s (function.c SetPulse)."""
    profile = np.zeros((round(duration / dt) + 1, machine.n_joints))
    profile[:, 0] = duty
    return MovePlan("set_pulse", f"pulse {duty:g} % for {duration:g} s", profile=profile,
                    meta={"duty": duty, "duration": duration}, moving=(0,))


def end_point_solutions(model: Unimate2000B, pose: np.ndarray, current: np.ndarray,
                        current_pose: str = "") -> np.ndarray:
    """Every in-limit solution ``(k, 6)`` of ``pose``, nearest ``current`` first; ValueError
    saying why there is none and what to do (``current_pose``: how to get the current pose,
    which is always reachable)."""
    try:
        return model.inverse(pose, near=current)
    except Unreachable as exc:
        raise ValueError(f"unreachable: {exc}. Change the position or the angles (the current "
                         f"pose is always reachable{current_pose}).") from None


def end_point(machine: Machine, current: np.ndarray, pose: np.ndarray, solutions: np.ndarray,
              k: int, ramp_time: float | None = None, *, dt: float) -> MovePlan:
    """A joint-space ramp to solution ``k`` of ``pose`` (blank ``ramp_time``: at
    ``APPROACH_SPEED`` of the slowest joint's max speed, at least 0.5 s)."""
    q = solutions[max(0, min(k, len(solutions) - 1))]
    if ramp_time is None:
        speeds = np.array([APPROACH_SPEED * j.max_speed for j in machine.joints])
        ramp_time = max(0.5, float(np.max(np.abs(q - current) / speeds)))
    path = moves.ramp(current, q, ramp_time, dt=dt, machine=machine)
    return MovePlan("end_point", f"end point, solution {k + 1}", path,
                    meta={"pose": np.asarray(pose).tolist(), "solution": q.tolist(),
                          "solution_index": int(k), "ramp_time": ramp_time},
                    moving=moving_joints(path),
                    note=f"joint-space ramp to solution {k + 1} in {ramp_time:.2f} s")


def path_file(machine: Machine, current: np.ndarray, points: PathPoints, source: str, *,
              dt: float) -> MovePlan:
    """The path of a file read by ``path_files.read_path``, at the sample time; the joints the
    file leaves out stay where they are now (``current``, on a limit if just past it). A
    saved run plays as the kind it was (``control/motion/replay.py``)."""
    hold = np.clip(current, machine.lower, machine.upper)
    path = resample(points.held_at(hold), dt)
    meta = {"file": str(Path(source).expanduser().resolve())}
    if points.run:
        meta["replays"] = points.run
    title = f"replay of {points.run}" if points.run else f"path {Path(source).name}"
    return MovePlan(points.kind, title, path, meta=meta, moving=moving_joints(path))


def via_point_rows(text: str, machine: Machine, cartesian: bool) -> np.ndarray:
    """The points typed one per line ``(M, J)``, or ``(M, 3)`` x y z when ``cartesian``;
    ValueError naming the line and the fix."""
    width = 3 if cartesian else machine.n_joints
    what = "x y z (mm)" if cartesian else f"{width} joint positions"
    rows = []
    for n, line in enumerate(text.splitlines(), 1):
        parts = line.replace(",", " ").split()
        if not parts:
            continue
        try:
            row = [float(p) for p in parts]
        except ValueError:
            raise ValueError(f"point line {n}: {line.strip()!r} is not numbers; "
                             f"type {what}") from None
        if len(row) != width or not all(math.isfinite(v) for v in row):
            raise ValueError(f"point line {n}: {len(row)} numbers; type {what}")
        rows.append(row)
    if not rows:
        raise ValueError(f"type at least one point, one per line: {what}")
    return np.array(rows)


def via_points(machine: Machine, current: np.ndarray, points: np.ndarray, fraction: float,
               cartesian: bool, *, dt: float) -> MovePlan:
    """A smooth path from ``current`` through ``points``: joint space (section 6.4's via
    points) or, ``cartesian``, on the tool's x y z with γ and β held."""
    from control.motion.cartesian import cartesian_path  # scipy's splines: loaded on first use
    from control.motion.trajectory import via_path

    meta = {"points": points.tolist(), "speed_fraction": fraction}
    if cartesian:
        path = cartesian_path(current, points, machine, dt=dt, speed_fraction=fraction).q
        return MovePlan("cartesian", f"Cartesian path through {len(points)} points", path,
                        meta=meta, moving=moving_joints(path))
    path = via_path(np.vstack([current, points]), machine, dt=dt, speed_fraction=fraction).q
    return MovePlan("via_points", f"path through {len(points)} via points", path, meta=meta,
                    moving=moving_joints(path))
