"""Joint-space trajectories through via points (issue 6; thesis section 6.4).

The thesis asks for a path "from a minimum of three points" by polynomial or
cubic-spline interpolation (section 6.4, ref. [14]). servodesk fits one
**quintic per segment** between consecutive via points:

- at the first and last point velocity and acceleration are zero (rest to rest);
- at an interior via point the acceleration is zero and the velocity is taken
  from the two neighbouring slopes: zero where the joint reverses or stays
  put there, otherwise the weighted harmonic mean of the slopes (the
  Fritsch–Butland rule scipy's PCHIP uses), capped at ``MONOTONE_CAP`` times
  the smaller slope.

So position, velocity and acceleration are continuous (C²) and every segment
is monotone: a joint never overshoots a via point, a joint that keeps its
value between two via points does not move, and a path whose via points are
inside the limits stays inside them. A clamped cubic spline through the same
points (the other choice the brief names) is C² too but overshoots between via
points and moves joints that should stay put, which a limit check would then
refuse.

Timing: each segment starts at its rest-to-rest minimum-jerk duration, then is
stretched or shrunk until its fastest joint just reaches ``max_speed`` or
``max_accel`` (``TIMING_ITERATIONS`` fixed-point passes, because a segment's
via velocities depend on its neighbours' durations). A final uniform
stretch — which scales every velocity by 1/s and acceleration by 1/s² without
changing the shape — makes the limits hold exactly, and durations are rounded
up to whole samples so every via point lands on a sample.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from hw.machine import Machine

# The quintic with zero end accelerations is monotone while both end velocities are at most
# 15/7 times the segment's mean slope; 2 keeps a margin.
MONOTONE_CAP = 2.0
# Minimum-jerk rest-to-rest segment: peak velocity 1.875·Δq/h, peak acceleration 5.7735·Δq/h².
PEAK_SPEED = 1.875
PEAK_ACCEL = 10.0 / math.sqrt(3.0)
TIMING_ITERATIONS = 40
GRID = 257  # points per segment at which peak speed and acceleration are evaluated
PEAK_MARGIN = 1.001  # a peak between grid points is at most this much above the grid's


@dataclass(frozen=True)
class Trajectory:
    """A sampled joint path. ``t (N,)`` s; ``q``, ``qd``, ``qdd`` ``(N, J)`` in mm or deg,
    per s and per s²; ``via_t (M,)`` s and ``via_index (M,)`` the sample of each via point."""

    t: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray
    via_t: np.ndarray
    via_index: np.ndarray

    @property
    def duration(self) -> float:
        return float(self.t[-1])


def via_path(points: ArrayLike, machine: Machine, *, dt: float | None = None,
             speed_fraction: float = 1.0, durations: ArrayLike | None = None) -> Trajectory:
    """A smooth joint path through ``points (M, J)`` (mm, deg), M ≥ 2, row 0 the start.

    ``speed_fraction`` (0, 1] scales every joint's ``max_speed`` and ``max_accel``.
    ``durations (M − 1,)`` s fixes the segment times instead of timing them; a
    segment too short for a joint's limits is refused with the time it needs.
    ``dt`` defaults to the machine's sample time. Raises ValueError naming the
    via point and joint.
    """
    q = _points(points, machine)
    step = machine.sample_time_s if dt is None else _positive(dt, "dt")
    if not 0.0 < speed_fraction <= 1.0:
        raise ValueError(f"speed_fraction must be in (0, 1], got {speed_fraction}")
    vmax = np.array([j.max_speed for j in machine.joints]) * speed_fraction
    amax = np.array([j.max_accel for j in machine.joints]) * speed_fraction
    if durations is None:
        h = _timed(q, vmax, amax, step)
    else:
        h = _given(q, np.asarray(durations, dtype=float), vmax, amax, step, machine)
    return _sample(q, h, step)


def quintic_coefficients(q: np.ndarray, h: np.ndarray) -> np.ndarray:
    """Segment polynomials in normalised time s ∈ [0, 1], ``(M − 1, J, 6)``, lowest power first.

    ``q (M, J)`` via points, ``h (M − 1,)`` segment durations (s).
    """
    v = via_velocities(q, h)
    p0, p1 = q[:-1], q[1:]
    v0, v1 = v[:-1] * h[:, None], v[1:] * h[:, None]  # slopes per unit of normalised time
    dq = p1 - p0
    zero = np.zeros_like(p0)
    return np.stack([
        p0, v0, zero,
        10.0 * dq - 6.0 * v0 - 4.0 * v1,
        -15.0 * dq + 8.0 * v0 + 7.0 * v1,
        6.0 * dq - 3.0 * v0 - 3.0 * v1,
    ], axis=-1)


def via_velocities(q: np.ndarray, h: np.ndarray) -> np.ndarray:
    """Joint velocity at every via point ``(M, J)`` (units/s): 0 at the ends and where a
    joint reverses or stops, else the Fritsch–Butland weighted harmonic mean of the two
    slopes, capped at MONOTONE_CAP times the smaller one."""
    slope = np.diff(q, axis=0) / h[:, None]
    v = np.zeros_like(q)
    if len(q) > 2:
        m0, m1 = slope[:-1], slope[1:]
        h0, h1 = h[:-1, None], h[1:, None]
        w0, w1 = 2.0 * h1 + h0, h1 + 2.0 * h0
        same = m0 * m1 > 0.0
        safe0, safe1 = np.where(same, m0, 1.0), np.where(same, m1, 1.0)
        mean = (w0 + w1) / (w0 / safe0 + w1 / safe1)
        cap = MONOTONE_CAP * np.minimum(np.abs(safe0), np.abs(safe1))
        v[1:-1] = np.where(same, np.sign(mean) * np.minimum(np.abs(mean), cap), 0.0)
    return v


def peak_ratios(q: np.ndarray, h: np.ndarray, vmax: np.ndarray,
                amax: np.ndarray) -> np.ndarray:
    """Per segment and joint ``(M − 1, J)``: max(peak speed / vmax, √(peak accel / amax)),
    the factor by which the segment's duration must grow (> 1) or may shrink (< 1)."""
    c = quintic_coefficients(q, h)
    s = np.linspace(0.0, 1.0, GRID)
    dv = np.stack([np.zeros_like(s), np.ones_like(s), 2 * s, 3 * s**2, 4 * s**3, 5 * s**4])
    da = np.stack([np.zeros_like(s), np.zeros_like(s), 2 * np.ones_like(s), 6 * s,
                   12 * s**2, 20 * s**3])
    speed = np.abs(c @ dv).max(axis=-1) / h[:, None]
    accel = np.abs(c @ da).max(axis=-1) / h[:, None] ** 2
    return PEAK_MARGIN * np.maximum(speed / vmax, np.sqrt(accel / amax))


def _timed(q: np.ndarray, vmax: np.ndarray, amax: np.ndarray, dt: float) -> np.ndarray:
    """Segment durations (s) at which the fastest joint of each segment meets its limits."""
    dq = np.abs(np.diff(q, axis=0))
    h = np.maximum(PEAK_SPEED * dq / vmax, np.sqrt(PEAK_ACCEL * dq / amax)).max(axis=1)
    h = np.maximum(h, dt)
    for _ in range(TIMING_ITERATIONS):
        ratio = peak_ratios(q, h, vmax, amax).max(axis=1)
        if np.all(np.abs(ratio - 1.0) < 1e-4):
            break
        h = np.maximum(h * ratio, dt)
    return _whole_samples(q, h, vmax, amax, dt)


def _whole_samples(q: np.ndarray, h: np.ndarray, vmax: np.ndarray, amax: np.ndarray,
                   dt: float) -> np.ndarray:
    """``h`` stretched uniformly until no limit is exceeded, then rounded up to whole samples."""
    while True:
        worst = float(peak_ratios(q, h, vmax, amax).max())
        if worst > 1.0:
            h = h * worst * (1.0 + 1e-9)
        h = np.ceil(h / dt - 1e-9) * dt
        if float(peak_ratios(q, h, vmax, amax).max()) <= 1.0 + 1e-9:
            return h


def _given(q: np.ndarray, h: np.ndarray, vmax: np.ndarray, amax: np.ndarray, dt: float,
           machine: Machine) -> np.ndarray:
    """Check user segment durations against the limits; refuse naming segment and joint."""
    if h.shape != (len(q) - 1,):
        raise ValueError(f"durations must have {len(q) - 1} entries (one per segment), "
                         f"got shape {h.shape}")
    if not np.all(np.isfinite(h) & (h > 0)):
        raise ValueError(f"durations must be positive seconds, got {h.tolist()}")
    h = np.round(h / dt) * dt
    if np.any(h < dt):
        raise ValueError(f"a segment is shorter than one sample ({dt:g} s)")
    ratio = peak_ratios(q, h, vmax, amax)
    if ratio.max() > 1.0 + 1e-9:
        seg, j = np.unravel_index(int(np.argmax(ratio)), ratio.shape)
        joint = machine.joints[j]
        raise ValueError(
            f"segment from via point {seg} to {seg + 1} ({h[seg]:g} s) is too fast for "
            f"{joint.name}: it needs {ratio[seg, j]:.3g} times its max_speed or max_accel "
            f"({joint.max_speed:g} {joint.unit}/s, {joint.max_accel:g} {joint.unit}/s²); "
            f"make it at least {h[seg] * ratio[seg, j]:.3g} s")
    return h


def _sample(q: np.ndarray, h: np.ndarray, dt: float) -> Trajectory:
    """Evaluate the segments at ``k·dt`` from the first via point to the last."""
    c = quintic_coefficients(q, h)
    knots = np.concatenate([[0.0], np.cumsum(h)])
    via_index = np.round(knots / dt).astype(int)
    t = np.arange(via_index[-1] + 1) * dt
    seg = np.clip(np.searchsorted(via_index, np.arange(len(t)), side="right") - 1, 0, len(h) - 1)
    s = (t - knots[seg]) / h[seg]
    powers = s[:, None] ** np.arange(6)
    cs = c[seg]
    pos = np.einsum("njk,nk->nj", cs, powers)
    dpow = np.arange(6) * np.concatenate([np.zeros((len(s), 1)), powers[:, :-1]], axis=1)
    ddpow = np.arange(6) * np.arange(-1, 5) * np.concatenate(
        [np.zeros((len(s), 2)), powers[:, :-2]], axis=1)
    vel = np.einsum("njk,nk->nj", cs, dpow) / h[seg, None]
    acc = np.einsum("njk,nk->nj", cs, ddpow) / h[seg, None] ** 2
    pos[via_index] = q  # exact at the via points
    return Trajectory(t=t, q=pos, qd=vel, qdd=acc, via_t=t[via_index], via_index=via_index)


def _points(points: ArrayLike, machine: Machine) -> np.ndarray:
    """Via points as ``(M, J)`` floats inside the limits, consecutive ones distinct."""
    q = np.asarray(points, dtype=float)
    n = machine.n_joints
    if q.ndim != 2 or q.shape[1] != n or len(q) < 2:
        raise ValueError(f"via points must be (M, {n}) with M ≥ 2 (start, …, end), "
                         f"got shape {q.shape}")
    for i, row in enumerate(q):
        bad = np.flatnonzero(~np.isfinite(row))
        if len(bad):
            raise ValueError(f"via point {i}: {machine.joints[bad[0]].name} is {row[bad[0]]}, "
                             "not a number")
        try:
            machine.check_targets(tuple(row))
        except ValueError as exc:
            raise ValueError(f"via point {i}: {exc}") from None
    same = np.flatnonzero(np.all(np.diff(q, axis=0) == 0.0, axis=1))
    if len(same):
        i = int(same[0])
        raise ValueError(f"via points {i} and {i + 1} are the same position: remove one "
                         "(hold there with a hold move instead)")
    return q


def _positive(value: float, name: str) -> float:
    if not (math.isfinite(value) and value > 0):
        raise ValueError(f"{name} must be a positive number of seconds, got {value}")
    return float(value)
