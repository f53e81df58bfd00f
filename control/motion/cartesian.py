"""Cartesian paths with a constant tool orientation, thesis section 6.4, and pose files.

A path runs from the current pose A through at least one intermediate point to
an end point, given as tool positions (x, y, z) only: "the γ and β angles do
not change along the path. The α angle has to change in accordance to the
Rotate joint angle in a 1:1 relationship" (section 6.4).

What that means with X-Y-Z fixed angles (section 4.3, eq. 4.04). The tool
rotation is ``R = Rz(α)·Ry(β)·Rx(γ)``. Turning the Rotate joint by Δθ1 turns
the whole arm about the base z axis, so ``R → Rz(Δθ1)·R = Rz(α + Δθ1)·Ry(β)·Rx(γ)``:
γ and β stay, α grows by Δθ1. The 1:1 rule is therefore

    R(P) = Rz(θ1(P) − θ1_A) · R_A,   i.e.   α(P) = α_A + θ1(P) − θ1_A,

the tool keeps its attitude *relative to the arm*: Yaw and Swivel stay
constant along the path and Bend makes up for Up/Down (θ2 + θ4 constant).

θ1 at a point P follows from the arm plane. The wrist point w = P − Ly·a lies
in the plane through the z axis at angle θ1 (eq. 4.14), and with the
orientation turning with θ1 the tool point's distance from that plane is a
constant e of the start configuration. With P's horizontal polar coordinates
(r, φ):

    r·sin(θ1 − φ) = e   ⇒   θ1(P) = φ + asin(e / r)    (or π − asin, as at A),

    e = r_A·sin(θ1_A − φ_A).

The thesis's "α_B from (x_B, y_B, α_A)" is this formula; taking θ1 = φ alone
(α_B = α_A + φ_B − φ_A) is exact only when the tool point lies in the arm
plane (e = 0); on the Unimate e is typically hundreds of millimetres.

Interpolation: a cubic spline in space through A and the points (scipy's
``CubicSpline``, clamped: zero velocity at both ends), knots at chord-length
times. Timing: the joint path from the inverse kinematics is sampled densely,
its joint velocities and accelerations found by differences, and the knot
times stretched uniformly until every joint keeps ``max_speed`` and
``max_accel``; the knots are then put on whole samples (so each via point is a
sample) and the spline through them checked again, stretching further if the
rounding made a joint too fast.

Branch continuity: the start takes the inverse-kinematics branch (the
``inverse_batch`` slot) nearest the current joints; every later sample must
have a valid solution in that same slot, continuous with the previous sample.
Otherwise the path is refused before it starts, naming the first bad sample,
its time and pose, and why (out of reach, a joint limit, a branch change).

Pose files (``read_poses``): CSV with a header, columns ``x, y, z`` (mm) and
optionally ``t`` (s from the start of the move) and ``gamma, beta, alpha``
(deg). Each row is a via point after the start. Given orientation columns must
agree with the rule above (they are checked, not used). Malformed lines are
reported by line number, in the style of ``control/motion/path_files.py``, and a
file is bounded before it is parsed as a path file is: each via point is a sample
of the path, so at most one per sample of the longest move allowed.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike

from control.motion.file_fields import csv_lines, field_number, move_file_bound, read_text_file
from control.motion.path_files import MAX_MOVE_S
from control.motion.robot_model import unimate_model
from hw.machine import Machine
from kinematics import unimate, xyz_fixed
from kinematics.unimate import Unimate2000B

NOMINAL_SPEED = 100.0  # mm/s of the chord-length knots before timing; only the shape matters
FINE_SPACING_MM = 0.5  # timing samples along the path at least this dense
FINE_SAMPLES = (1000, 20000)
# A revolute joint moving more than this between two consecutive samples has wrapped to
# its other ±360° copy or changed branch (a real move covers a fraction of a degree).
JUMP_DEG = 90.0
JUMP_MM = 100.0
START_TOL = 1e-6  # the start joints must solve their own pose to this (mm, deg)
ORIENTATION_TOL_DEG = 0.01  # a pose file's orientation must match the rule to this
TIME_NAMES = ("t", "time")
POSE_NAMES = {"x": 0, "y": 1, "z": 2, "gamma": 3, "γ": 3, "beta": 4, "β": 4, "alpha": 5, "α": 5}
_BRANCH_PARTS = ("Rotate branch (arm in front of or behind the base)",
                 "wrist branch (sign of Yaw)", "Up/Down root")


class PoseFileError(ValueError):
    """A pose file cannot be used; the message names the file and line."""


@dataclass(frozen=True)
class CartesianPath:
    """A section 6.4 path. ``t (N,)`` s; ``q (N, 6)`` joints (mm, deg) to follow;
    ``poses (N, 6)`` the target pose of each sample (x, y, z mm; γ, β, α deg);
    ``via_t``, ``via_index`` ``(M + 1,)`` time and sample of the start and each
    via point; ``branch`` the ``inverse_batch`` slot the whole path uses."""

    t: np.ndarray
    q: np.ndarray
    poses: np.ndarray
    via_t: np.ndarray
    via_index: np.ndarray
    branch: int

    @property
    def duration(self) -> float:
        return float(self.t[-1])


@dataclass(frozen=True)
class PosePoints:
    """Via points of a pose file: ``xyz (M, 3)`` mm, ``t (M,)`` s or None,
    ``orientation (M, 3)`` γ, β, α deg or None, ``lines`` each row's line number."""

    source: str
    xyz: np.ndarray
    t: np.ndarray | None
    orientation: np.ndarray | None
    lines: tuple[int, ...]


@dataclass(frozen=True)
class _ArmFrame:
    """The start configuration's data for the 1:1 rule (module docstring), angles in rad."""

    theta1: float  # θ1_A
    alpha: float  # α_A
    offset: float  # e, mm
    behind: bool  # θ1 − φ near π rather than 0 (cos < 0) at A
    origin: np.ndarray  # tool position at A, (3,) mm
    gamma_beta: tuple[float, float]  # γ_A, β_A

    def rotate_angle(self, xyz: np.ndarray) -> np.ndarray:
        """θ1 (rad, continuous from θ1_A) at tool points ``xyz (N, 3)``; NaN where r < |e|."""
        r = np.hypot(xyz[:, 0], xyz[:, 1])
        phi = np.arctan2(xyz[:, 1], xyz[:, 0])
        with np.errstate(invalid="ignore", divide="ignore"):
            lean = np.arcsin(self.offset / r)
        raw = phi + (np.pi - lean if self.behind else lean)
        if np.isnan(raw).any():
            return raw
        turned = np.unwrap(raw)
        return turned + 2 * np.pi * np.round((self.theta1 - turned[0]) / (2 * np.pi))

    def poses(self, xyz: np.ndarray, theta1: np.ndarray) -> np.ndarray:
        """Target poses ``(N, 6)``: γ, β of A, α = α_A + θ1 − θ1_A (deg)."""
        out = np.empty((len(xyz), 6))
        out[:, :3] = xyz
        out[:, 3:5] = np.degrees(self.gamma_beta)
        out[:, 5] = np.degrees(self.alpha + theta1 - self.theta1)
        return out


def cartesian_path(start: ArrayLike, points: ArrayLike, machine: Machine, *,
                   dt: float | None = None, times: ArrayLike | None = None,
                   speed_fraction: float = 1.0) -> CartesianPath:
    """Section 6.4 path from the joints ``start (6,)`` through tool positions ``points (M, 3)``
    (mm, M ≥ 2: at least one intermediate point and the end).

    ``times (M,)`` s from the start fixes when each point is reached (refused if
    a joint would exceed its limits); without it the path is as fast as the
    joints' ``max_speed`` and ``max_accel`` times ``speed_fraction`` allow.
    Raises ValueError naming the first bad point and why.
    """
    from scipy.interpolate import CubicSpline  # on first use: a Cartesian jog never needs it

    model = unimate_model(machine)
    q0 = start_joints(start, machine)
    xyz = _via_xyz(points)
    step = machine.sample_time_s if dt is None else positive_seconds(dt, "dt")
    if not 0.0 < speed_fraction <= 1.0:
        raise ValueError(f"speed_fraction must be in (0, 1], got {speed_fraction}")
    frame = arm_frame(q0, model)
    knots_xyz = np.vstack([model.pose(q0)[:3], xyz])
    knots = _knots(knots_xyz, times)
    vmax = np.array([j.max_speed for j in machine.joints]) * speed_fraction
    amax = np.array([j.max_accel for j in machine.joints]) * speed_fraction
    if times is None:
        spline = CubicSpline(knots, knots_xyz, bc_type="clamped")
        length = float(np.linalg.norm(np.diff(knots_xyz, axis=0), axis=1).sum())
        u = np.linspace(0.0, float(knots[-1]), int(np.clip(length / FINE_SPACING_MM,
                                                             *FINE_SAMPLES)))
        q, _, _ = _solve(spline(u), _Where(u, knots, timed=False), frame, q0, machine, model)
        scale = max(limit_ratio(q, u[1] - u[0], vmax, amax), 1e-6)  # > 0: it is multiplied
    else:
        scale = 1.0
    while True:
        # knots on whole samples, so every via point is a sample of the path
        steps = np.maximum(np.round(np.diff(knots) * scale / step), 1.0)
        via_index = np.concatenate([[0], np.cumsum(steps)]).astype(int)
        via_t = via_index * step
        spline = CubicSpline(via_t, knots_xyz, bc_type="clamped")
        t = np.arange(via_index[-1] + 1) * step
        q, poses, branch = _solve(spline(t), _Where(t, via_t, timed=True), frame, q0, machine,
                                  model)
        ratio = limit_ratio(q, step, vmax, amax)
        if ratio <= 1.0 + 1e-9:
            break
        if times is not None:
            raise ValueError(_too_fast(q, step, vmax, amax, ratio, machine))
        scale *= ratio * (1.0 + 1e-6)
    return CartesianPath(t=t, q=q, poses=poses, via_t=via_t, via_index=via_index,
                         branch=branch)


def path_from_poses(points: PosePoints, start: ArrayLike, machine: Machine, *,
                    dt: float | None = None, speed_fraction: float = 1.0) -> CartesianPath:
    """``cartesian_path`` from a pose file's points, after checking its orientation columns."""
    model = unimate_model(machine)
    q0 = start_joints(start, machine)
    if len(points.xyz) < 2:
        raise PoseFileError(f"{points.source}: {len(points.xyz)} via point(s): a path needs an "
                            "intermediate point and an end point (section 6.4)")
    if points.orientation is not None:
        _check_orientation(points, arm_frame(q0, model))
    try:
        return cartesian_path(q0, points.xyz, machine, dt=dt, times=points.t,
                              speed_fraction=speed_fraction)
    except ValueError as exc:
        raise PoseFileError(f"{points.source}: {exc}") from None


def arm_frame(q0: np.ndarray, model: Unimate2000B) -> _ArmFrame:
    """The 1:1 rule's constants of the start joints ``q0 (6,)`` (module docstring)."""
    p = model.pose(q0)
    theta1 = math.radians(float(q0[1]))
    r, phi = math.hypot(p[0], p[1]), math.atan2(p[1], p[0])
    return _ArmFrame(
        theta1=theta1, alpha=math.radians(float(p[5])), offset=r * math.sin(theta1 - phi),
        behind=math.cos(theta1 - phi) < 0.0,
        origin=p[:3].copy(),
        gamma_beta=(math.radians(float(p[3])), math.radians(float(p[4]))),
    )


def _solve(xyz: np.ndarray, where: _Where, frame: _ArmFrame, q0: np.ndarray,
           machine: Machine, model: Unimate2000B) -> tuple[np.ndarray, np.ndarray, int]:
    """Joints ``(N, 6)``, target poses ``(N, 6)`` and the branch slot of tool points
    ``xyz (N, 3)``, all on the start's branch. Refuses the first bad sample, described by
    ``where``."""
    theta1 = frame.rotate_angle(xyz)
    near_axis = np.flatnonzero(np.isnan(theta1))
    if len(near_axis):
        k = int(near_axis[0])
        raise ValueError(where(k, xyz) + f": the tool would pass within "
                         f"{abs(frame.offset):.0f} mm of the Rotate axis, where no Rotate "
                         "angle keeps the tool's orientation")
    poses = frame.poses(xyz, theta1)
    batch = model.inverse_batch(poses, near=q0)
    slot = start_branch(q0, batch.solutions[0], batch.valid[0])
    q = batch.solutions[:, slot]
    ok = batch.valid[:, slot]
    jump = jumps(q, machine)
    bad = np.flatnonzero(~ok | jump)
    if len(bad):
        k = int(bad[0])
        why = (jump_reason(q, k, machine) if ok[k]
               else branch_reason(model, poses[k], slot, batch.valid[k],
                                   q[k - 1] if k else q0))
        raise ValueError(where(k, xyz) + ": " + why)
    return q, poses, slot


def start_branch(q0: np.ndarray, solutions: np.ndarray, valid: np.ndarray) -> int:
    """The ``inverse_batch`` slot of the start joints ``q0``: of the start pose's
    ``solutions (8, 6)`` the valid one nearest ``q0``."""
    travel = np.where(valid, unimate.distance(solutions, q0), np.inf)
    slot = int(np.argmin(travel))
    if not valid[slot] or travel[slot] > START_TOL:
        raise ValueError(f"the start joints {np.round(q0, 3).tolist()} do not solve their own "
                         "pose in the closed-form inverse (a wrist singularity with a joint "
                         "on its limit?): jog a joint off its limit first")
    return slot


def jumps(q: np.ndarray, machine: Machine) -> np.ndarray:
    """``(N,)`` True where a joint jumps from the previous sample (a wrap or branch flip)."""
    bound = np.array([JUMP_MM if j.kind == "prismatic" else JUMP_DEG for j in machine.joints])
    jump = np.zeros(len(q), dtype=bool)
    jump[1:] = (np.abs(np.diff(q, axis=0)) > bound).any(axis=1)
    return jump


def jump_reason(q: np.ndarray, k: int, machine: Machine) -> str:
    j = int(np.argmax(np.abs(q[k] - q[k - 1]) / np.array(
        [JUMP_MM if jt.kind == "prismatic" else JUMP_DEG for jt in machine.joints])))
    joint = machine.joints[j]
    return (f"{joint.name} would jump from {q[k - 1, j]:.2f}{joint.symbol} to "
            f"{q[k, j]:.2f}{joint.symbol}: the path takes it past its limits "
            f"{joint.limit_text()} (or through a singularity); choose other points")


def branch_reason(model: Unimate2000B, pose: np.ndarray, slot: int, valid: np.ndarray,
                   previous: np.ndarray) -> str:
    """Why the path's branch has no valid solution at ``pose``."""
    if valid.any():
        other = int(np.flatnonzero(valid)[0])
        changed = [name for bit, name in zip((4, 2, 1), _BRANCH_PARTS, strict=True)
                   if (slot & bit) != (other & bit)]
        return ("the arm would have to change configuration here (" + ", ".join(changed)
                + f": inverse-kinematics slot {slot} → {other}); a path never switches branch "
                "mid-way: choose points the current configuration can reach")
    try:
        model.inverse(pose, near=previous)
    except unimate.Unreachable as exc:
        return str(exc)
    return "no solution inside the joint limits on the path's branch"


@dataclass(frozen=True)
class _Where:
    """Describes sample k of a path for messages: ``u (N,)`` spline time of each sample,
    ``knots`` the via points' spline times; ``timed`` when spline time is the move's time
    (the final pass), not yet when the path is still being timed."""

    u: np.ndarray
    knots: np.ndarray
    timed: bool

    def __call__(self, k: int, xyz: np.ndarray) -> str:
        x, y, z = xyz[k]
        i = int(np.clip(np.searchsorted(self.knots, self.u[k], side="right") - 1, 0,
                        len(self.knots) - 2))
        frac = (self.u[k] - self.knots[i]) / (self.knots[i + 1] - self.knots[i])
        start = "the start" if i == 0 else f"via point {i}"
        when = f"sample {k}, t = {self.u[k]:.3f} s, " if self.timed else ""
        return (f"path point at {frac:.0%} of the way from {start} to via point {i + 1} "
                f"({when}x y z = {x:.1f} {y:.1f} {z:.1f} mm)")


def limit_ratio(q: np.ndarray, h: float, vmax: np.ndarray, amax: np.ndarray) -> float:
    """max over joints of max(|q̇|/vmax, √(|q̈|/amax)) from differences at spacing ``h`` (s)."""
    return float(joint_ratios(q, h, vmax, amax).max())


def joint_ratios(q: np.ndarray, h: float, vmax: np.ndarray, amax: np.ndarray) -> np.ndarray:
    """Per joint ``(J,)`` the factor of limit_ratio."""
    if len(q) < 3:
        return np.zeros(q.shape[1])
    speed = np.abs(np.diff(q, axis=0)).max(axis=0) / h
    accel = np.abs(np.diff(q, n=2, axis=0)).max(axis=0) / h**2
    return np.maximum(speed / vmax, np.sqrt(accel / amax))


def _too_fast(q: np.ndarray, h: float, vmax: np.ndarray, amax: np.ndarray, ratio: float,
              machine: Machine) -> str:
    j = int(np.argmax(joint_ratios(q, h, vmax, amax)))
    joint = machine.joints[j]
    return (f"the given times are too fast for {joint.name} (it would need {ratio:.3g} times "
            f"its max_speed or max_accel, {joint.max_speed:g} {joint.unit}/s, "
            f"{joint.max_accel:g} {joint.unit}/s²): stretch the times by at least {ratio:.3g}")


def _knots(xyz: np.ndarray, times: ArrayLike | None) -> np.ndarray:
    """Spline knots (s): chord-length times at NOMINAL_SPEED, or 0 and the given times."""
    chords = np.linalg.norm(np.diff(xyz, axis=0), axis=1)
    if np.any(chords == 0.0):
        i = int(np.flatnonzero(chords == 0.0)[0])
        what = "the start" if i == 0 else f"via point {i}"
        raise ValueError(f"via point {i + 1} is at the same position as {what}: remove it")
    if times is None:
        return np.concatenate([[0.0], np.cumsum(chords) / NOMINAL_SPEED])
    t = np.asarray(times, dtype=float)
    if t.shape != (len(xyz) - 1,):
        raise ValueError(f"times must have one entry per via point ({len(xyz) - 1}), "
                         f"got shape {t.shape}")
    knots = np.concatenate([[0.0], t])
    if not np.all(np.isfinite(t)) or np.any(np.diff(knots) <= 0):
        raise ValueError(f"times must increase from after 0 s, got {t.tolist()}")
    return knots


def start_joints(start: ArrayLike, machine: Machine) -> np.ndarray:
    q0 = np.asarray(start, dtype=float)
    if q0.shape != (machine.n_joints,) or not np.isfinite(q0).all():
        raise ValueError(f"start must be {machine.n_joints} finite joint values, got {q0}")
    try:
        machine.check_targets(tuple(q0))
    except ValueError as exc:
        raise ValueError(f"start: {exc}") from None
    return q0


def _via_xyz(points: ArrayLike) -> np.ndarray:
    xyz = np.asarray(points, dtype=float)
    if xyz.ndim != 2 or xyz.shape[1] != 3 or len(xyz) < 2:
        raise ValueError(f"points must be (M, 3) x, y, z in mm with M ≥ 2 (an intermediate "
                         f"point and the end, section 6.4), got shape {xyz.shape}")
    bad = np.flatnonzero(~np.isfinite(xyz).all(axis=1))
    if len(bad):
        raise ValueError(f"via point {bad[0] + 1} is {xyz[bad[0]].tolist()}: not finite")
    return xyz


def positive_seconds(value: float, name: str) -> float:
    if not (math.isfinite(value) and value > 0):
        raise ValueError(f"{name} must be a positive number of seconds, got {value}")
    return float(value)


# -- pose files ------------------------------------------------------------------------


def read_poses(path: str | Path, machine: Machine) -> PosePoints:
    """Read a pose CSV for ``machine`` (module docstring), bounded as a path file is;
    PoseFileError names the file and line."""
    bound = move_file_bound("a pose file", machine.sample_time_s, MAX_MOVE_S,
                            f"use fewer via points, on a path of at most {MAX_MOVE_S:g} s")
    path, text = read_text_file(path, bound, PoseFileError)
    return parse_poses(text, str(path))


def parse_poses(text: str, source: str = "<csv>") -> PosePoints:
    """Parse the text of a pose CSV: a header, then one via point per line."""
    reader = csv_lines(text, source, PoseFileError)
    first = next(reader, None)
    if first is None:
        raise PoseFileError(f"{source}: empty file: expected a header such as t,x,y,z")
    header_line, header = first[0], [c.strip() for c in first[1]]
    time_col, pose_cols = _pose_columns(header, source, header_line)
    times, rows, lines = [], [], []
    for number, row in reader:
        if len(row) != len(header):
            raise PoseFileError(f"{source}: line {number}: {len(row)} field(s), the header has "
                                f"{len(header)}")
        values = [math.nan] * 6
        for col, k in pose_cols.items():
            values[k] = _number(row[col], source, number, col + 1)
        if time_col is not None:
            t = _number(row[time_col], source, number, time_col + 1)
            previous = times[-1] if times else 0.0
            if t <= previous:
                raise PoseFileError(f"{source}: line {number}: time {t:g} s must be after "
                                    f"{previous:g} s (times count from the start of the move)")
            times.append(t)
        rows.append(values)
        lines.append(number)
    if not rows:
        raise PoseFileError(f"{source}: no via points after the header")
    table = np.array(rows)
    return PosePoints(source=source, xyz=table[:, :3],
                      t=np.array(times) if time_col is not None else None,
                      orientation=table[:, 3:] if 3 in pose_cols.values() else None,
                      lines=tuple(lines))


def _pose_columns(header: list[str], source: str, line: int) -> tuple[int | None, dict[int, int]]:
    time_col, cols = None, {}
    allowed = "t, x, y, z, gamma, beta, alpha"
    for col, raw in enumerate(header):
        name = raw.split("[", 1)[0].strip().lower()
        if name in TIME_NAMES:
            if time_col is not None:
                raise PoseFileError(f"{source}: line {line}: two time columns")
            time_col = col
        elif name in POSE_NAMES:
            if POSE_NAMES[name] in cols.values():
                raise PoseFileError(f"{source}: line {line}: column {raw!r} appears twice")
            cols[col] = POSE_NAMES[name]
        else:
            raise PoseFileError(f"{source}: line {line}: column {col + 1} {raw!r} is not one of "
                                f"{allowed}")
    have = set(cols.values())
    if not {0, 1, 2} <= have:
        raise PoseFileError(f"{source}: line {line}: the header needs x, y and z columns")
    if have & {3, 4, 5} and not {3, 4, 5} <= have:
        raise PoseFileError(f"{source}: line {line}: give gamma, beta and alpha together, or "
                            "none (section 6.4 keeps the start orientation)")
    return time_col, cols


def _number(text: str, source: str, line: int, field: int) -> float:
    return field_number(text, source, line, field, PoseFileError)


def _check_orientation(points: PosePoints, frame: _ArmFrame) -> None:
    """Every row's γ, β, α must be the start orientation turned with Rotate (section 6.4)."""
    assert points.orientation is not None
    theta1 = frame.rotate_angle(np.vstack([frame.origin, points.xyz]))[1:]
    expected = frame.poses(points.xyz, theta1)[:, 3:]
    given = xyz_fixed.rotation(*np.radians(points.orientation).T)
    want = xyz_fixed.rotation(*np.radians(expected).T)
    cos = (np.einsum("nij,nij->n", given, want) - 1.0) / 2.0
    angle = np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))
    bad = np.flatnonzero(~(angle <= ORIENTATION_TOL_DEG))
    if len(bad):
        k = int(bad[0])
        g, b, a = points.orientation[k]
        eg, eb, ea = expected[k]
        raise PoseFileError(
            f"{points.source}: line {points.lines[k]}: orientation γ β α = {g:g} {b:g} {a:g}° "
            f"is not the start orientation turned with Rotate ({eg:.3f} {eb:.3f} {ea:.3f}°, "
            f"{angle[k]:.3g}° away): section 6.4 keeps γ and β and turns α with Rotate; drop "
            "the gamma, beta and alpha columns to let servodesk compute them")

