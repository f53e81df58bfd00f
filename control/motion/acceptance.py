"""One set of rules for what a move may ask of the joints (issue 11; ``docs/motion.md``).

The client (``ControlClient.move``, ``run``, ``actuate``), the TUI (through the
client) and the path-file reader all ask this module, so a path is accepted or
refused alike wherever it comes from. The kinds are classified once, in
``control.rt.commands`` (``SMOOTH_KINDS``, ``STEP_KINDS``, ``DUTY_KINDS``), where
the control process can read them too.

- **Every path** is ``(N, J)`` rows (mm, deg), each finite and inside every
  joint's limits.
- **Smooth kinds** (path, ramp, sine, cartesian, via_points, end_point, go_to,
  cartesian_jog)
  keep each joint's ``max_speed`` and ``max_accel``, taken by differences at
  the sample time Δt: speed ``|q(k) − q(k−1)|/Δt``, acceleration
  ``|q(k+1) − 2q(k) + q(k−1)|/Δt²``. The joint rests on the first row before
  the path (it holds there, or the approach settles there) and on the last row
  after it (the controller holds it), so a path that starts or ends moving
  asks for an acceleration too. The differences of a path that keeps the
  limits are averages of its speed and acceleration, so they never exceed
  them; ``SAMPLING_TOLERANCE`` (1 %) covers what rounding adds (times rounded
  to whole samples, a file's numbers written to a few decimals).
- **Step kinds** (step, multi_step) may jump, as the thesis's step inputs did
  (function.c SingleStep, MultiStep): every row finite and inside the limits.
- **Duty kinds** (tracking_actuate, set_pulse) play an open-loop duty
  ``profile (N, J)``: every value finite and in −100…100 %.
- **The start.** A move starts where the robot is: the first row within each
  joint's ``tolerance`` of its position. A path that starts farther away is
  accepted only with the approach of ``MovePlan.approached`` in front (a ramp
  at half of each joint's speed and acceleration limits, then a settle), and
  the approach is held to the smooth rules whatever the move's kind.

- **The move limit.** A move lasts at most ``MAX_MOVE_S`` (600 s), its approach
  included: it is sent and recorded whole (600,001 rows at 1 ms), and a saved run is read
  back within that bound (``control/recorder.py``). Whatever plans a move from a speed (a
  go to, a Cartesian jog) asks ``check_duration`` before it samples the path, so a crawl
  is refused at once, not after gigabytes of samples.

Every refusal is a ``MoveRefused`` (a ValueError) naming the joint, the sample
and its time (for a file, the line), by how much, and how to fix it.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import TYPE_CHECKING

import numpy as np

from control.rt.commands import DUTY_KINDS, MOVE_KINDS, SMOOTH_KINDS, STEP_KINDS
from hw.machine import Joint, Machine
from hw.transmission import Transmission

if TYPE_CHECKING:
    from control.motion.plan import MovePlan

__all__ = ["DUTY_KINDS", "MAX_MOVE_S", "MOVE_KINDS", "SAMPLING_TOLERANCE", "SMOOTH_KINDS",
           "STEP_KINDS", "MoveRefused", "accept", "check_duration", "check_kind", "check_path",
           "check_profile", "check_rows", "check_smooth", "check_speeds", "check_start",
           "longest_samples", "starts_here"]

MAX_MOVE_S = 600.0  # a move is sent and recorded whole: 600,001 rows at 1 ms is the most
SAMPLING_TOLERANCE = 0.01  # a smooth path may exceed max_speed and max_accel by 1 % (rounding)
DUTY_LIMIT_PCT = 100.0

Where = Callable[[int], str]  # sample (or point) index → "sample 12 (t = 0.012 s)"


class MoveRefused(ValueError):
    """A move the rules refuse; the message names joint, sample or line, amount and fix.
    ``index`` is the row (sample or file point) at fault, when there is one."""

    def __init__(self, message: str, index: int | None = None) -> None:
        super().__init__(message)
        self.index = index


def longest_samples(dt: float) -> int:
    """The rows of the longest move at sample time ``dt``, both ends included."""
    return math.floor(MAX_MOVE_S / dt + 1e-9) + 1


def check_duration(seconds: float, what: str, fix: str) -> None:
    """Refuse ``what`` (a go to, a Cartesian jog) if it would last longer than a move may
    (``MAX_MOVE_S``); ``fix`` says what to do instead."""
    if not seconds <= MAX_MOVE_S:  # nan, too: a duration no one can say is no move
        raise MoveRefused(f"{what} would take {seconds:,.3f} s, longer than a move may last "
                          f"(the move limit, {MAX_MOVE_S:g} s): {fix}")


def check_kind(kind: str, *, profile: bool) -> None:
    """Refuse an unknown kind, or a path for a duty kind and a duty profile for any other."""
    if kind not in MOVE_KINDS:
        raise MoveRefused(f"unknown move kind {kind!r} (kinds: {', '.join(sorted(MOVE_KINDS))})")
    if profile and kind not in DUTY_KINDS:
        raise MoveRefused(f"a {kind} move follows a desired path, not a duty profile (duty "
                          f"kinds: {', '.join(sorted(DUTY_KINDS))})")
    if not profile and kind in DUTY_KINDS:
        raise MoveRefused(f"a {kind} move plays a duty profile, not a desired path")


def check_rows(path: np.ndarray, machine: Machine, where: Where) -> None:
    """Every kind: ``path (N, J)`` rows finite and inside every joint's limits, and every
    actuator inside its stops (the Yaw reading includes Bend, its actuator does not)."""
    lower, upper = np.array(machine.lower), np.array(machine.upper)
    bad = np.argwhere(~np.isfinite(path) | (path < lower) | (path > upper))
    if len(bad):
        k, j = (int(i) for i in bad[0])
        try:
            machine.joints[j].check_target(float(path[k, j]), machine.name)
        except ValueError as exc:
            raise MoveRefused(f"{exc} at {where(k)}", k) from None
    transmission = Transmission(machine)
    actuator = transmission.actuators_of(path)
    beyond = np.argwhere((actuator < lower) | (actuator > upper))
    if len(beyond):
        k, j = (int(i) for i in beyond[0])
        joint, partner = machine.joints[j], machine.joints[transmission.coupled_to[j]]
        raise MoveRefused(
            f"{joint.name} {path[k, j]:g}{joint.symbol} with {partner.name} at "
            f"{path[k, transmission.coupled_to[j]]:g}{partner.symbol} puts {joint.name}'s "
            f"actuator at {actuator[k, j]:.1f}{joint.symbol}, past its stops "
            f"{joint.limit_text()} (its reading includes {partner.name}'s) at {where(k)}: "
            f"move {partner.name} first, or choose a {joint.name} target nearer "
            f"{partner.name}'s angle", k)


def check_speeds(t: np.ndarray, q: np.ndarray, machine: Machine, where: Where,
                 fix: str) -> None:
    """Speeds between consecutive rows of ``q (N, J)`` at times ``t (N,)`` s within each
    joint's max_speed (plus ``SAMPLING_TOLERANCE``); ``where(k)`` names row k, the row a too
    fast step arrives at, and ``fix`` says what to do."""
    if len(q) < 2:
        return
    with np.errstate(over="ignore"):  # a step past a float's range is infinitely fast: refused
        speed = np.abs(np.diff(q, axis=0)) / np.diff(t)[:, None]
        ratio = speed / _limits(machine, "max_speed")
    over = np.flatnonzero((ratio > 1.0 + SAMPLING_TOLERANCE).any(axis=1))
    if len(over):
        k = int(over[0])
        j = int(np.argmax(ratio[k]))
        raise MoveRefused(_too_fast(machine, j, q[k + 1, j] - q[k, j], float(t[k + 1] - t[k]),
                                    where(k + 1), fix), k + 1)


def check_smooth(path: np.ndarray, machine: Machine, dt: float, where: Where,
                 kind: str = "path") -> None:
    """Smooth kinds: speed and acceleration by differences at ``dt`` within max_speed and
    max_accel (plus ``SAMPLING_TOLERANCE``), at rest on the first row before and on the last
    row after. The earliest sample at fault is named; a jump is told as a speed."""
    rested = np.concatenate([path[:1], path, path[-1:]])
    speed = np.abs(np.diff(rested, axis=0)) / dt  # (N + 1, J): interval i arrives at row i
    accel = np.abs(np.diff(rested, n=2, axis=0)) / dt**2  # (N, J): at row k
    speed_ratio = speed / _limits(machine, "max_speed")
    accel_ratio = accel / _limits(machine, "max_accel")
    limit = 1.0 + SAMPLING_TOLERANCE
    fast = np.flatnonzero((speed_ratio > limit).any(axis=1))
    hard = np.flatnonzero((accel_ratio > limit).any(axis=1))
    k_fast = int(fast[0]) if len(fast) else len(rested)
    k_hard = int(hard[0]) if len(hard) else len(rested)
    if k_fast == len(rested) and k_hard == len(rested):
        return
    fix = (f"a {kind} move must keep max_speed and max_accel: spread the change over more "
           "time, or send it as a step move (kind 'step') if the jump is meant")
    if k_fast <= k_hard + 1:  # a jump into row k shows first as an acceleration at k − 1
        k = k_fast  # interval k, between rows k − 1 and k (rested rows k and k + 1)
        j = int(np.argmax(speed_ratio[k]))
        raise MoveRefused(_too_fast(machine, j, rested[k + 1, j] - rested[k, j], dt, where(k),
                                    fix), k)
    k = k_hard
    j = int(np.argmax(accel_ratio[k]))
    raise MoveRefused(_too_hard(machine, j, rested, k, dt, where(k), kind), k)


def check_path(path: np.ndarray, kind: str, machine: Machine, dt: float, *,
               approach: int = 0, where: Where | None = None) -> None:
    """The rules of ``kind`` on ``path (N, J)`` at sample time ``dt``; its first ``approach``
    rows are an approach, held to the smooth rules whatever the kind."""
    check_kind(kind, profile=False)
    n = machine.n_joints
    if path.ndim != 2 or path.shape[1] != n or len(path) == 0:
        raise MoveRefused(f"a path is (N, {n}) joint positions, got shape {path.shape}")
    name = where or _sample_names(dt, approach)
    check_rows(path, machine, name)
    if kind in SMOOTH_KINDS:
        check_smooth(path, machine, dt, name, kind)
    elif approach:
        check_smooth(path[:approach + 1], machine, dt, name, "approach")


def check_profile(profile: np.ndarray, machine: Machine) -> None:
    """Duty kinds: ``profile (N, J)`` % every value finite and in −100…100."""
    n = machine.n_joints
    if profile.ndim != 2 or profile.shape[1] != n or len(profile) == 0:
        raise MoveRefused(f"a duty profile is (N, {n}), got {profile.shape}")
    bad = np.argwhere(~np.isfinite(profile) | (np.abs(profile) > DUTY_LIMIT_PCT))
    if len(bad):
        k, j = (int(i) for i in bad[0])
        raise MoveRefused(f"{machine.joints[j].name} duty {profile[k, j]} at sample {k} is not "
                          f"a number in -100…100 %", k)


def starts_here(current: np.ndarray, first: np.ndarray, machine: Machine) -> bool:
    """Whether every joint's ``first`` row is within its tolerance of ``current``."""
    gap = np.abs(np.asarray(first, dtype=float) - np.asarray(current, dtype=float))
    return bool(np.all(gap <= [j.tolerance for j in machine.joints]))


def check_start(first: np.ndarray, current: np.ndarray, machine: Machine) -> None:
    """A move starts where the robot is: ``first`` within each joint's tolerance of
    ``current``."""
    for j, joint in enumerate(machine.joints):
        here, there = float(current[j]), float(first[j])
        if abs(there - here) <= joint.tolerance:
            continue
        s = joint.symbol
        if not joint.lower <= here <= joint.upper:
            raise MoveRefused(
                f"{joint.name} is at {here:.4g}{s}, outside its limits {joint.limit_text()} by "
                f"more than its tolerance {joint.tolerance:g}{s}: no move can start there; "
                "jog it back inside its limits first")
        raise MoveRefused(
            f"{joint.name} is at {here:.4g}{s} and the path starts at {there:.4g}{s}, "
            f"{abs(there - here):.4g}{s} away (tolerance {joint.tolerance:g}{s}): a move "
            "starts where the robot is; run it with ControlClient.run or move, which put an "
            "approach in front")


def accept(plan: MovePlan, current: np.ndarray | None, machine: Machine,
           dt: float) -> MovePlan:
    """``plan`` as it may run from ``current (J,)`` (the joints now; None for a duty profile):
    a duty profile checked; a path checked, with the approach from ``current`` in front when
    it starts elsewhere. MoveRefused if not."""
    if plan.path is None and plan.profile is None:
        raise MoveRefused(f"plan {plan.title!r} has neither a path nor a duty profile")
    if plan.path is None:
        check_kind(plan.kind, profile=True)
        check_profile(np.asarray(plan.profile, dtype=np.float64), machine)
        _check_rows_allowed(len(plan.profile), plan.kind, dt)
        return plan
    check_kind(plan.kind, profile=False)
    path = np.asarray(plan.path, dtype=np.float64)
    n = machine.n_joints
    if path.ndim != 2 or path.shape[1] != n or len(path) == 0:
        raise MoveRefused(f"a path is (N, {n}) joint positions, got shape {path.shape}")
    check_rows(path, machine, _sample_names(dt, 0))  # named as the caller's samples
    if current is None:
        raise MoveRefused("a path needs the joints' current position to start from")
    here = np.asarray(current, dtype=np.float64)
    plan = plan.approached(here, machine, dt)
    _check_rows_allowed(len(plan.path), plan.kind, dt, plan.approach)
    check_start(plan.path[0], here, machine)
    check_path(np.asarray(plan.path, dtype=np.float64), plan.kind, machine, dt,
               approach=plan.approach)
    return plan


def _check_rows_allowed(rows: int, kind: str, dt: float, approach: int = 0) -> None:
    """The move limit on a move of ``rows`` samples at ``dt``, ``approach`` of them its
    approach."""
    with_approach = f" with its {approach * dt:.1f} s approach" if approach else ""
    check_duration((rows - 1) * dt, f"the {kind} move{with_approach}",
                   "split it into shorter moves")


def _limits(machine: Machine, name: str) -> np.ndarray:
    return np.array([getattr(j, name) for j in machine.joints])


def _sample_names(dt: float, approach: int) -> Where:
    """Samples named as the caller's path counts them; the approach's as its own."""
    def name(k: int) -> str:
        if k < approach:
            return f"sample {k} of the approach in front of the path"
        i = k - approach
        return f"sample {i} (t = {i * dt:.3f} s)"
    return name


def _too_fast(machine: Machine, j: int, change: float, interval: float, where: str,
              fix: str) -> str:
    joint = machine.joints[j]
    change, interval = float(change), float(interval)  # Python floats: past their range is inf
    speed = abs(change) / interval
    return (f"{joint.name} moves {change:+.4g} {joint.unit} in {interval:.4g} s at {where}: "
            f"{speed:.4g} {joint.unit}/s, {speed / joint.max_speed:.3g} times its max_speed "
            f"{joint.max_speed:g} {joint.unit}/s (machine {machine.name}); that change needs at "
            f"least {abs(change) / joint.max_speed:.3g} s: {fix}")


def _too_hard(machine: Machine, j: int, rested: np.ndarray, k: int, dt: float, where: str,
              kind: str) -> str:
    """Row ``k`` of the path (``rested`` is it with a rest row at each end) changes speed
    beyond joint ``j``'s max_accel."""
    joint: Joint = machine.joints[j]
    a, b, c = (float(rested[i, j]) for i in (k, k + 1, k + 2))  # Python floats: no warnings
    before, after = (b - a) / dt, (c - b) / dt
    accel = abs(after - before) / dt
    u = joint.unit
    if k == 0:
        what = f"starts from rest at {after:+.4g} {u}/s"
    elif k == len(rested) - 3:
        what = (f"is still moving at {before:+.4g} {u}/s on its last sample, where the "
                "controller holds it")
    else:
        what = f"changes speed from {before:+.4g} to {after:+.4g} {u}/s"
    return (f"{joint.name} {what} at {where}: {accel:.4g} {u}/s², {accel / joint.max_accel:.3g} "
            f"times its max_accel {joint.max_accel:g} {u}/s² (machine {machine.name}); that "
            f"change needs at least {abs(after - before) / joint.max_accel:.3g} s: a {kind} "
            "move must keep max_speed and max_accel: ease into and out of every change of "
            "speed, and start and end at rest (a ramp, a sine or via points do), or send it as "
            "a step move (kind 'step') if the jump is meant")
