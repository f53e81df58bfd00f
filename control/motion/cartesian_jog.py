"""Cartesian jog: the tool moves by a displacement along a straight line, in the world or
the tool frame, on the branch the arm is on (issue 14).

A displacement is ``[dx, dy, dz, dγ, dβ, dα]``, mm and deg. The translation is
along the frame's x, y, z axes; the rotation is about the frame's x, y, z axes
through the tool point, the three angles taken together as one rotation vector
(dγ about x, dβ about y, dα about z: for one axis at a time, exactly that turn).
With the start pose ``(R0, p0)`` and ``d``, ``ω`` the two halves::

    world:  p(s) = p0 + s·d,       R(s) = Rot(s·ω)·R0
    tool:   p(s) = p0 + s·R0·d,    R(s) = R0·Rot(s·ω)

for s from 0 to 1: a straight line in space and a turn about a fixed axis. A
world-frame dα therefore adds to α, while dγ and dβ turn the tool about the
world's x and y axes (X-Y-Z fixed angles, eq. 4.04, do not add up otherwise).

Timing. s(t) is a trapezoid: it accelerates at the machine's Cartesian jog
acceleration to its Cartesian jog speed (``[kinematics] cartesian_jog_speed``,
``cartesian_jog_accel``, mm and deg; ``docs/machines.md``), whichever of the
translation and the rotation is slower sets the pace, and brakes to a stop
on the end; the duration is rounded up to whole samples. Each sample is
solved by the closed-form inverse (``inverse_batch``) in the slot of the
start joints (``cartesian.start_branch``): no branch flip, ever.

The singularity zone (issue 25), as MoveIt Servo's ``lower_singularity_threshold`` and
``hard_stop_singularity_threshold``, but judged on what the operator's machine allows
rather than on a condition number: ``need`` is the speed each joint would need to keep
the tool on the line at the Cartesian jog speed asked. Where every joint's is within its
``jog_speed`` the jog runs at that speed; where one needs more, the whole profile is
slowed (speed by r, acceleration by r²) until no joint passes its ``jog_speed`` (nor its
``max_accel``); where one would need more than its ``max_speed`` the jog stops. So a
joint travels at most ``max_speed / cartesian_jog_speed`` per unit of the tool's motion
(Swivel 12°, Bend 9° per degree of tool rotation on the Unimate), never the 13-30
times a line through the wrist singularity asks of it. ``zone`` says how close a pose is,
per axis, for the Jog tab's warning and for the servo (``control.servo``).

Refusals (``Unreachable``, nothing planned), at the first sample where:

- no solution exists in the start's slot: out of reach, a joint past a limit,
  or a change of configuration (``cartesian.branch_reason`` names which);
- a joint jumps between samples (a wrap past a limit);
- the wrist comes within ``WRIST_MARGIN_DEG`` of its singularity (Yaw 0°:
  Bend and Swivel line up) while approaching it;
- the wrist point comes within ``SHOULDER_MARGIN_MM`` of the Rotate axis while
  approaching it;
- at the Cartesian jog speed asked a joint would need more than its ``max_speed``
  (the hard stop of the singularity zone below).

``stop_short=True`` (the Jog tab's hold-to-move) instead plans the longest part
of the line that has none of these, ending ``STOP_BACKOFF`` before the first
one, and says in ``stopped`` why it ends there.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import ArrayLike

from control.motion import cartesian
from control.motion.acceptance import check_duration
from control.motion.robot_model import unimate_model
from hw.machine import Joint, Machine
from kinematics import xyz_fixed
from kinematics.unimate import LIMIT_TOL, Unimate2000B, Unreachable

FRAMES = ("world", "tool")
AXES = ("x", "y", "z", "γ", "β", "α")
AXIS_UNITS = ("mm", "mm", "mm", "°", "°", "°")
YAW = 4  # the Yaw joint: sin θ5 = 0 is the wrist singularity
WRIST_MARGIN_DEG = 1.0  # a jog stops before Yaw comes this close to 0°
SHOULDER_MARGIN_MM = 50.0  # or the wrist point this close to the Rotate axis
STOP_BACKOFF = 0.02  # stop_short ends this fraction of the way before the first problem
MIN_JOG = (0.01, 0.001)  # mm, deg: a shorter jog is nothing to plan
MAX_PASSES = 20  # slowdowns for the joints' limits; each one fits the worst ratio
UNLIMITED = 1e6  # mm, deg: limits wide enough to solve a pose past the real ones
GEOMETRY_SPACING = (0.5, 0.1)  # mm, deg: the line is checked this densely before timing
GEOMETRY_SAMPLES = (50, 20_000)


@dataclass(frozen=True)
class CartesianJog:
    """A planned jog. ``t (N,)`` s; ``q (N, 6)`` joints (mm, deg); ``poses (N, 6)`` the
    target pose of each sample (x, y, z mm; γ, β, α deg); ``positions (N, 3)`` mm and
    ``rotations (N, 3, 3)`` the same as a frame; ``displacement (6,)`` what was planned
    (all of what was asked unless stopped short); ``branch`` the ``inverse_batch`` slot;
    ``stopped`` why a ``stop_short`` plan ends early ('' if it does not)."""

    t: np.ndarray
    q: np.ndarray
    poses: np.ndarray
    positions: np.ndarray
    rotations: np.ndarray
    displacement: np.ndarray
    frame: str
    branch: int
    stopped: str = ""

    @property
    def duration(self) -> float:
        return float(self.t[-1])


@dataclass(frozen=True)
class Line:
    """The straight line of a jog (module docstring): start frame, translation and rotation
    vector in the base frame (mm, rad), and the rotation's side (world: left, tool: right)."""

    p0: np.ndarray
    r0: np.ndarray
    d: np.ndarray
    omega: np.ndarray
    tool: bool

    def at(self, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Positions ``(N, 3)`` and rotations ``(N, 3, 3)`` at fractions ``s (N,)``."""
        turn = rotation_about(s[:, None] * self.omega)
        r = self.r0 @ turn if self.tool else turn @ self.r0
        return self.p0 + s[:, None] * self.d, r


def rotation_about(v: np.ndarray) -> np.ndarray:
    """Rotation matrices of rotation vectors ``v (N, 3)`` (rad): Rodrigues' formula."""
    angle = np.linalg.norm(v, axis=-1)
    axis = np.divide(v, angle[:, None], out=np.zeros_like(v), where=angle[:, None] > 0)
    x, y, z = axis.T
    k = np.zeros((len(v), 3, 3))
    k[:, 0, 1], k[:, 0, 2], k[:, 1, 2] = -z, y, -x
    k[:, 1, 0], k[:, 2, 0], k[:, 2, 1] = z, -y, x
    s, c = np.sin(angle)[:, None, None], np.cos(angle)[:, None, None]
    return np.eye(3) + s * k + (1.0 - c) * (k @ k)


@dataclass(frozen=True)
class Zone:
    """How the singularity zone (module docstring) bounds a Cartesian jog from one pose.

    ``need (6, J)``: the speed (mm/s, deg/s) each joint needs for a jog along each axis of
    the frame (x, y, z, γ, β, α; either sign) at the Cartesian jog speed asked; ``scale
    (6,)`` the fraction of that speed each axis runs at (1 full, 0 stopped: a joint past its
    max_speed); ``joint (6,)`` the joint that sets it; ``yaw`` deg (the wrist is singular at
    0°)."""

    need: np.ndarray
    scale: np.ndarray
    joint: np.ndarray
    yaw: float

    @property
    def near(self) -> bool:
        """Some axis runs slower than asked, or stops."""
        return bool((self.scale < 1.0).any())


def frame_jacobian(model: Unimate2000B, q: ArrayLike, frame: str) -> np.ndarray:
    """``(6, 6)``: the tool's velocity (mm/s) and angular velocity (deg/s) along the axes of
    ``frame`` (world or tool) per joint velocity (mm/s, deg/s) at joints ``q (6,)``."""
    jacobian = model.jacobian(q)
    if frame == "world":
        return jacobian
    r = model.forward(q)[:3, :3]
    return np.concatenate([r.T @ jacobian[:3], r.T @ jacobian[3:]])


def joint_speeds(model: Unimate2000B, q: ArrayLike, frame: str, twist: np.ndarray
                 ) -> np.ndarray:
    """Joint velocities ``(..., 6)`` that move the tool at ``twist (..., 6)`` (mm/s, deg/s
    along the axes of ``frame``) from ``q``; inf where the Jacobian is singular."""
    jacobian = frame_jacobian(model, q, frame)
    try:
        return np.linalg.solve(jacobian, np.asarray(twist, dtype=float).T).T
    except np.linalg.LinAlgError:  # exactly singular: no joint speed is enough
        return np.full(np.shape(twist), np.inf)


def zone(q: ArrayLike, machine: Machine, frame: str = "world", speed: float = 1.0) -> Zone:
    """The singularity zone at joints ``q (6,)`` for jogs in ``frame`` at ``speed`` of the
    machine's Cartesian jog speed (``Zone``)."""
    model = unimate_model(machine)
    q = np.asarray(q, dtype=float)
    axis_speed = np.repeat(np.array(machine.cartesian_jog_speed) * speed, 3)
    need = np.abs(joint_speeds(model, q, frame, np.diag(axis_speed)))
    vmax = np.array([j.max_speed for j in machine.joints])
    vjog = np.array([j.jog_speed for j in machine.joints])
    over = need / vjog
    scale = np.where((need > vmax).any(axis=1), 0.0,
                     np.minimum(1.0, 1.0 / np.maximum(over.max(axis=1), 1e-300)))
    return Zone(need, scale, over.argmax(axis=1), float(q[YAW]))


def plan_jog(start: ArrayLike, displacement: ArrayLike, machine: Machine, *,
             frame: str = "world", dt: float | None = None, speed: float = 1.0,
             stop_short: bool = False) -> CartesianJog:
    """The jog from the joints ``start (6,)`` by ``displacement (6,)`` (mm, deg) in ``frame``
    at ``speed`` (0 < speed ≤ 1) of the machine's Cartesian jog speed (and speed² of its
    acceleration: the same jog, slower in time).

    ValueError for bad input (and for a machine without Unimate kinematics);
    ``Unreachable`` (a ValueError) naming the joint or singularity when the line cannot be
    followed, unless ``stop_short`` (module docstring).
    """
    model = unimate_model(machine)
    q0 = cartesian.start_joints(start, machine)
    step = machine.sample_time_s if dt is None else cartesian.positive_seconds(dt, "dt")
    wanted = _displacement(displacement)
    if frame not in FRAMES:
        raise ValueError(f"frame must be one of {', '.join(FRAMES)}, got {frame!r}")
    if not (math.isfinite(speed) and 0.0 < speed <= 1.0):
        raise ValueError(f"speed must be in (0, 1] of the Cartesian jog speed, got {speed}")
    t0 = model.forward(q0)
    fraction, stopped = 1.0, ""
    while True:
        line = line_of(t0, wanted * fraction, frame == "tool")
        plan = _plan_line(line, q0, machine, model, step, speed)
        if isinstance(plan, CartesianJog):
            planned = wanted * fraction
            return CartesianJog(plan.t, plan.q, plan.poses, plan.positions, plan.rotations,
                                planned, frame, plan.branch, stopped)
        at, reason = plan
        stopped = reason
        shorter = fraction * max(at - STOP_BACKOFF, 0.0)
        if not stop_short or _too_short(wanted * shorter):
            where = _where(line, at)
            raise Unreachable(f"Cartesian jog {_shown(wanted * fraction, frame)}: {where}"
                              f"{reason}")
        fraction = shorter


def _plan_line(line: Line, q0: np.ndarray, machine: Machine, model: Unimate2000B, dt: float,
               speed: float) -> CartesianJog | tuple[float, str]:
    """The jog along ``line``, or (fraction along it, reason) of its first problem."""
    vmax = np.array([j.max_speed for j in machine.joints])
    vjog = np.array([j.jog_speed for j in machine.joints])
    amax = np.array([j.max_accel for j in machine.joints])
    length = (float(np.linalg.norm(line.d)), math.degrees(float(np.linalg.norm(line.omega))))
    speeds = np.array(machine.cartesian_jog_speed) * speed
    accels = np.array(machine.cartesian_jog_accel) * speed**2  # slower in time, as a whole
    rate = min(v / d for v, d in zip(speeds, length, strict=True) if d > 0)  # ds/dt, 1/s
    accel = min(a / d for a, d in zip(accels, length, strict=True) if d > 0)  # 1/s²
    steepest = vmax / rate  # |dq/ds| of each joint at its max_speed at the jog speed: the stop
    spacing = max(length[0] / GEOMETRY_SPACING[0], length[1] / GEOMETRY_SPACING[1])
    s = np.linspace(0.0, 1.0, int(np.clip(spacing, *GEOMETRY_SAMPLES)) + 1)
    problem = _solve(line, s, q0, machine, model, steepest)[1]
    if problem is not None:  # found on a sampling of the line before it is timed
        return problem
    least = 2
    for _ in range(MAX_PASSES):
        # before the samples are made: at a crawl they would be gigabytes
        check_duration(_trapezoid_time(rate, accel, dt, least), "the jog",
                       "jog a shorter way, or faster")
        t, s = _trapezoid(rate, accel, dt, least)
        solved, problem = _solve(line, s, q0, machine, model, steepest)
        if problem is not None:
            return problem
        assert solved is not None
        q, poses, positions, rotations, slot = solved
        ratio = cartesian.limit_ratio(q, dt, vjog, amax)  # the zone: slowed to jog_speed
        if ratio <= 1.0 + 1e-9:
            q[0] = q0  # the start as it is, not its pose solved again (round-off)
            return CartesianJog(t, q, poses, positions, rotations, np.zeros(6), "", slot)
        rate /= ratio * (1.0 + 1e-6)
        accel /= (ratio * (1.0 + 1e-6)) ** 2
        least = len(t)  # at least one sample longer: rounding may have kept the same length
    return 1.0, "the joints' speed and acceleration limits could not be met"


_Solved = tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, int]


def _solve(line: Line, s: np.ndarray, q0: np.ndarray, machine: Machine, model: Unimate2000B,
           per_rate: np.ndarray) -> tuple[_Solved | None, tuple[float, str] | None]:
    """Joints, poses, positions, rotations and slot of the line at fractions ``s (N,)``;
    or the first problem (fraction, reason) on it."""
    positions, rotations = line.at(s)
    poses = np.concatenate([positions, np.degrees(xyz_fixed.angles(rotations))], axis=1)
    batch = model.inverse_batch(poses, near=q0)
    try:
        slot = cartesian.start_branch(q0, batch.solutions[0], batch.valid[0])
    except ValueError as exc:
        return None, (0.0, str(exc))
    q = batch.solutions[:, slot]
    problem = _first_problem(q, s, batch.valid, slot, poses, rotations, machine, model,
                             per_rate, q0)
    if problem is not None:
        return None, problem
    return (q, poses, positions, rotations, slot), None


def _trapezoid(rate: float, accel: float, dt: float, least: int
               ) -> tuple[np.ndarray, np.ndarray]:
    """Times ``(N,)`` and fractions ``s (N,)`` of a rest-to-rest trapezoid from 0 to 1 at
    most ``rate`` (1/s) and ``accel`` (1/s²), stretched to end on a whole sample, at least
    ``least`` intervals long."""
    rate, ramp, duration = _trapezoid_shape(rate, accel)
    n = round(_trapezoid_time(rate, accel, dt, least) / dt)
    t = np.arange(n + 1) * dt
    u = t * (duration / (n * dt))  # the trapezoid's own time
    s = np.where(u < ramp, 0.5 * accel * u**2, 0.5 * accel * ramp**2 + rate * (u - ramp))
    s = np.where(u > duration - ramp, 1.0 - 0.5 * accel * (duration - u) ** 2, s)
    s[-1] = 1.0
    return t, np.clip(s, 0.0, 1.0)


def _trapezoid_shape(rate: float, accel: float) -> tuple[float, float, float]:
    """The rate the trapezoid reaches (1/s), its ramp's time and its duration (s); an endless
    one when ``accel`` is too small for a float (a speed below 1e-154)."""
    if rate * rate >= accel:  # never reaches the rate: a triangle
        rate = math.sqrt(accel)
    if rate == 0.0:
        return 0.0, math.inf, math.inf
    ramp = rate / accel
    return rate, ramp, 1.0 / rate + ramp


def _trapezoid_time(rate: float, accel: float, dt: float, least: int) -> float:
    """How long ``_trapezoid`` lasts: its duration stretched to whole samples of ``dt``, at
    least ``least`` of them."""
    duration = _trapezoid_shape(rate, accel)[2]
    if not math.isfinite(duration):
        return duration
    return max(math.ceil(duration / dt - 1e-9), least) * dt


def _first_problem(q: np.ndarray, s: np.ndarray, valid: np.ndarray, slot: int,
                   poses: np.ndarray, rotations: np.ndarray, machine: Machine,
                   model: Unimate2000B, per_rate: np.ndarray, q0: np.ndarray
                   ) -> tuple[float, str] | None:
    """(fraction, reason) of the first sample the jog must not reach (module docstring),
    or None. ``per_rate (J,)`` is each joint's max_speed divided by the jog's ds/dt: the
    largest |dq/ds| it may have at the Cartesian jog speed asked (the zone's hard stop)."""
    n = len(q)
    ok = valid[:, slot]
    bad = np.zeros(n, dtype=bool)
    reasons: dict[str, np.ndarray] = {}
    reasons["slot"] = ~ok
    reasons["jump"] = cartesian.jumps(np.where(ok[:, None], q, q0), machine) & ok
    yaw = np.abs(q[:, YAW])
    closer = np.zeros(n, dtype=bool)
    closer[1:] = yaw[1:] < yaw[:-1]
    reasons["wrist"] = ok & closer & (yaw < WRIST_MARGIN_DEG)
    wrist = poses[:, :3] - model.ly * rotations[:, :, 2]  # eq. 4.14
    radius = np.hypot(wrist[:, 0], wrist[:, 1])
    nearer = np.zeros(n, dtype=bool)
    nearer[1:] = radius[1:] < radius[:-1]
    reasons["shoulder"] = nearer & (radius < SHOULDER_MARGIN_MM)
    ds = np.diff(s)
    slope = np.zeros_like(q)
    moving = ds > 1e-12
    slope[1:][moving] = np.abs(np.diff(q, axis=0)[moving]) / ds[moving, None]
    slope[0] = slope[1] if n > 1 else 0.0  # the first step's slope is the start's: a stop there
    over = slope / per_rate
    reasons["rate"] = ok & (over > 1.0).any(axis=1)
    for mask in reasons.values():
        bad |= mask
    if not bad.any():
        return None
    k = int(np.flatnonzero(bad)[0])
    if reasons["slot"][k]:
        why = _slot_reason(model, poses[k], slot, valid[k], q[k - 1] if k else q0, machine)
    elif reasons["jump"][k]:
        why = _jump_reason(q, k, machine)
    elif reasons["wrist"][k]:
        why = (f"wrist singularity: Yaw would come within {WRIST_MARGIN_DEG:g}° of 0° "
               f"({q[k, YAW]:.2f}°), where Bend and Swivel line up and no joint motion keeps "
               "the tool on the line; jog Yaw away from 0° in joint mode, or jog another way")
    elif reasons["shoulder"][k]:
        why = (f"shoulder singularity: the wrist point would pass {radius[k]:.0f} mm from the "
               f"Rotate axis (the jog stops {SHOULDER_MARGIN_MM:g} mm from it), where Rotate is "
               "undetermined")
    else:
        j = int(np.argmax(over[k]))
        joint = machine.joints[j]
        near = (f"near the wrist singularity (Yaw {q[k, YAW]:.2f}°, singular at 0°)"
                if abs(q[k, YAW]) < 10 * WRIST_MARGIN_DEG else "near a singularity")
        need = over[k, j] * joint.max_speed
        why = (f"{joint.name} would need {need:.0f}{_unit(joint)}/s, over its max_speed "
               f"{joint.max_speed:g}{_unit(joint)}/s, to keep the tool on the line at the "
               f"Cartesian jog speed, {near}: jog another way or move the arm away from it in "
               "joint mode")
    return float(s[k]), why


def _slot_reason(model: Unimate2000B, pose: np.ndarray, slot: int, valid: np.ndarray,
                 previous: np.ndarray, machine: Machine) -> str:
    """Why the jog's slot has no solution at ``pose``: the joints past their limits when the
    slot's solution exists beyond them (solved without limits, nearest ``previous``), else
    out of reach or a change of configuration (``cartesian.branch_reason``)."""
    free = replace(model, lower=(-UNLIMITED,) * 6, upper=(UNLIMITED,) * 6)
    beyond = free.inverse_batch(pose[None], near=previous)
    if beyond.valid[0, slot]:
        q = beyond.solutions[0, slot]
        parts = [f"{j.name} would be {v:.1f}{' mm' if j.unit == 'mm' else '°'}, past its "
                 f"limits {j.limit_text()}"
                 for j, v in zip(machine.joints, q, strict=True)
                 if not j.lower - LIMIT_TOL <= v <= j.upper + LIMIT_TOL]
        if parts:
            return "joint limit: " + "; ".join(parts)
    return cartesian.branch_reason(model, pose, slot, valid, previous)


def _jump_reason(q: np.ndarray, k: int, machine: Machine) -> str:
    """A joint whose solution wraps between samples k − 1 and k: it would pass a limit."""
    j = int(np.argmax(np.abs(q[k] - q[k - 1]) / np.where(
        [jt.kind == "prismatic" for jt in machine.joints], cartesian.JUMP_MM,
        cartesian.JUMP_DEG)))
    joint = machine.joints[j]
    limit = joint.upper if q[k - 1, j] > q[k, j] else joint.lower
    return (f"joint limit: {joint.name} would pass its limit {limit:g}{joint.symbol} (from "
            f"{q[k - 1, j]:.2f}{joint.symbol} it would have to wrap to {q[k, j]:.2f}"
            f"{joint.symbol})")


def _unit(joint: Joint) -> str:
    """What follows a number of the joint's unit: ' mm' or '°'."""
    return " mm" if joint.unit == "mm" else "°"


def line_of(t0: np.ndarray, displacement: np.ndarray, tool: bool) -> Line:
    """The line from the pose ``t0 (4, 4)`` by ``displacement (6,)`` (mm, deg) in the tool
    frame or the world's (module docstring)."""
    r0, p0 = t0[:3, :3], t0[:3, 3]
    d, omega = displacement[:3], np.radians(displacement[3:])
    return Line(p0=p0, r0=r0, d=r0 @ d if tool else d, omega=omega, tool=tool)


def _where(line: Line, at: float) -> str:
    """Where along the line a problem is, for the message."""
    if at <= 0.0:
        return "at the start: "
    p, _ = line.at(np.array([at]))
    x, y, z = p[0]
    return f"at {at:.0%} of the way (x y z = {x:.1f} {y:.1f} {z:.1f} mm): "


def _shown(d: np.ndarray, frame: str) -> str:
    parts = [f"{axis} {v:+g}{'' if unit == '°' else ' '}{unit}"
             for axis, v, unit in zip(AXES, d, AXIS_UNITS, strict=True) if v]
    return f"{', '.join(parts) or 'nothing'} ({frame} frame)"


def _too_short(d: np.ndarray) -> bool:
    return bool(np.linalg.norm(d[:3]) < MIN_JOG[0] and np.linalg.norm(d[3:]) < MIN_JOG[1])


def _displacement(displacement: ArrayLike) -> np.ndarray:
    d = np.asarray(displacement, dtype=float)
    if d.shape != (6,) or not np.isfinite(d).all():
        raise ValueError("a Cartesian jog is 6 finite numbers [dx, dy, dz (mm), dγ, dβ, dα "
                         f"(deg)], got {np.asarray(displacement).tolist()}")
    if _too_short(d):
        raise ValueError(f"a Cartesian jog of {d.tolist()} moves nothing: give at least "
                         f"{MIN_JOG[0]:g} mm or {MIN_JOG[1]:g}°")
    return d


@dataclass(frozen=True)
class Step:
    """One Cartesian step asked for: ``displacement (6,)`` mm and deg in ``frame``, at
    ``speed`` of the Cartesian jog speed."""

    displacement: tuple[float, ...]
    frame: str
    speed: float = 1.0

    def follows(self, other: Step) -> bool:
        """The same frame, speed and direction as ``other``: the two make one straight line,
        one step's end the other's start (a world axis or a tool axis, turned or moved along,
        stays the same axis), so they run as one jog."""
        a, b = np.array(self.displacement), np.array(other.displacement)
        along = float(a @ b)  # parallel and the same way: Cauchy-Schwarz with equality
        return (self.frame == other.frame and self.speed == other.speed and along > 0.0
                and math.isclose(along * along, float(a @ a) * float(b @ b), rel_tol=1e-12))


class StepQueue:
    """Cartesian steps asked for while one runs (issue 25 item 4): each is planned from where
    the ones before it end, and queued if the arm can make it; one it cannot make is refused
    with its reason, and the ones after it are planned from the same end. ``next`` hands out
    the steps in order, the ones along the same line as one jog (``Step.follows``), so held-
    down step keys run as one smooth move rather than a stop after each step."""

    def __init__(self, machine: Machine, dt: float) -> None:
        self.machine = machine
        self.dt = dt
        self.steps: list[Step] = []
        self.end: np.ndarray | None = None  # joints where the queued steps end

    def add(self, after: ArrayLike, step: Step) -> str:
        """Queue ``step`` to run after the running jog ending at joints ``after (6,)`` and the
        steps queued; '' if queued, else why the arm cannot make it (nothing queued)."""
        start = np.asarray(after, dtype=float) if self.end is None else self.end
        try:
            plan = plan_jog(start, step.displacement, self.machine, frame=step.frame,
                            dt=self.dt, speed=step.speed)
        except ValueError as exc:
            return str(exc)
        self.steps.append(step)
        self.end = plan.q[-1]
        return ""

    def next(self) -> Step | None:
        """The next jog to send: the first step and the ones along its line after it, added."""
        if not self.steps:
            return None
        first, n = self.steps[0], 1
        while n < len(self.steps) and self.steps[n].follows(first):
            n += 1
        total = np.sum([s.displacement for s in self.steps[:n]], axis=0)
        del self.steps[:n]
        if not self.steps:
            self.end = None
        return Step(tuple(float(v) for v in total), first.frame, first.speed)

    def clear(self) -> None:
        self.steps.clear()
        self.end = None

    @property
    def total(self) -> tuple[float, ...]:
        """Every queued step added up (mm, deg), for the operator."""
        if not self.steps:
            return (0.0,) * 6
        return tuple(float(v) for v in np.sum([s.displacement for s in self.steps], axis=0))
