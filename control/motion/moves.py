"""Desired paths for the thesis's inputs, and the summaries of a finished move by its kind:
a step response (``summary``), the tracking error of a smooth path
(``tracking_summary``) and the response to a sine (``sine_summary``).

Every path is ``(N, J)`` joint positions (mm, deg) at the sample time ``dt``
(s), sample ``k`` at ``t = k·dt``, from ``t = 0`` to ``t = duration``
inclusive. Row 0 is ``start``, the pose the move begins from (the thesis first
drives there with move(), errata #19), so a summary knows the step it was asked
for. With ``machine`` given, every target is checked against the joint limits
(the error names the joint), and ramps and sines against ``max_speed`` and
``max_accel``: they are smooth kinds, and the paths they make pass the rules of
``control.motion.acceptance`` (steps may jump).

Where they depart from the thesis's function.c, to be smooth: a **ramp**'s
change of speed at each end is a parabola at the joint's ``max_accel`` (a
linear segment with parabolic blends), still leaving ``start`` at t = 0 and
reaching ``end`` at ``ramp_time``; a **sine** stops at the last half period
that fits in ``duration`` (at rest, on ``start`` or ``end``) and holds there
for the rest, where the thesis's stopped wherever its array ended.

Settle tail: a step's ``duration`` is the whole run, including the time to
settle. Left out, it is the slowest joint's travel time at ``max_speed`` plus
``SETTLE_TAIL_S``; a ramp's ``total_duration`` likewise defaults to the ramp
time plus ``SETTLE_TAIL_S``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from numbers import Real
from typing import ClassVar

import numpy as np

from hw.machine import Joint, Machine

SETTLE_TAIL_S = 2.0  # hold after arriving: the rig's steps settle within ~1 s (Figs 3.7-3.10)
RISE_LOW, RISE_HIGH = 0.1, 0.9  # rise time is 10 % → 90 % of the step
STEADY_FRACTION = 0.1  # steady-state error: mean over the last 10 % of the run


@dataclass(frozen=True)
class StepSummary:
    """How one joint followed its move. Positions and errors in the joint's unit, times in s.

    Error is desired − actual. Times are measured from the move's start, the
    first sample whose desired value differs from sample 0 (t = 0 if none).
    ``None`` means the response never got there within the run; ``notes``
    say why, and which samples were ignored.
    """

    METRIC: ClassVar[str] = "step"

    joint: str
    unit: str
    initial: float  # desired at t = 0
    final: float  # desired at the end
    step: float  # final − initial
    overshoot: float  # beyond final, in the step's direction (≥ 0)
    overshoot_pct: float  # of |step|
    rise_time_s: float | None  # 10 % → 90 % of the step
    settling_time_s: float | None  # until inside ±tolerance of final for good
    steady_state_error: float  # mean error over the last 10 % of the run
    max_abs_error: float
    rms_error: float
    tolerance: float
    notes: tuple[str, ...] = ()


@dataclass(frozen=True)
class TrackingSummary:
    """How one joint followed a smooth path (ramp, path file, via points, Cartesian, end
    point): its tracking error, desired − actual, in the joint's unit, over the run given
    (the path and the hold after it). ``None`` and NaN where no sample was valid."""

    METRIC: ClassVar[str] = "tracking"

    joint: str
    unit: str
    travel: float  # the span of the desired position
    rms_error: float
    max_abs_error: float
    max_error_time_s: float | None  # when |error| was largest, from the start of the run
    final_error: float  # mean error over the last 10 % of the run
    notes: tuple[str, ...] = ()


@dataclass(frozen=True)
class SineSummary:
    """How one joint followed a sine: the fundamentals of desired and actual at the sine's
    frequency, fitted by least squares (``a + b·cos ωt + c·sin ωt``) over the whole periods
    of the swinging part of the run (the half periods if less than one was recorded).
    ``phase_lag_deg > 0``: the actual lags the desired. ``None`` when nothing could be
    fitted (``notes`` say why)."""

    METRIC: ClassVar[str] = "sine"

    joint: str
    unit: str
    period_s: float | None
    amplitude: float  # of the desired fundamental: half the swing
    amplitude_ratio: float | None  # actual / desired fundamental
    phase_lag_deg: float | None
    periods: float  # how many periods the fit spans
    rms_error: float
    max_abs_error: float
    notes: tuple[str, ...] = ()


Summary = StepSummary | TrackingSummary | SineSummary

# The result table of a move, by its kind (``METRIC``): the Moves tab, ``servodesk move`` and
# ``servodesk runs show``. The columns are short, so the table fits 80 columns; units follow
# the numbers.
SUMMARY_COLUMNS = {
    "step": ("joint", "step", "overshoot", "rise s", "settle s", "steady e", "max |e|"),
    "tracking": ("joint", "travel", "RMS e", "max |e|", "at s", "end e"),
    "sine": ("joint", "amplitude", "ratio", "lag °", "period s", "RMS e", "max |e|"),
}


def summary_columns(rows: Sequence[tuple[str, Summary]]) -> tuple[str, ...]:
    """The table's columns for rows of one kind (a step's when there are none)."""
    return SUMMARY_COLUMNS[rows[0][1].METRIC] if rows else SUMMARY_COLUMNS["step"]


def summary_cells(label: str, s: Summary) -> tuple[str, ...]:
    """One row of the table, as ``SUMMARY_COLUMNS[s.METRIC]`` names them."""
    u = "°" if s.unit == "deg" else f" {s.unit}"
    if isinstance(s, StepSummary):
        return (label, f"{s.step:+.2f}{u}", f"{s.overshoot:.2f}{u} {s.overshoot_pct:.0f}%",
                _cell(s.rise_time_s, ".3f"), _cell(s.settling_time_s, ".3f"),
                _cell(s.steady_state_error, "+.3f", u), _cell(s.max_abs_error, ".3f", u))
    if isinstance(s, TrackingSummary):
        return (label, _cell(s.travel, ".2f", u), _cell(s.rms_error, ".3f", u),
                _cell(s.max_abs_error, ".3f", u), _cell(s.max_error_time_s, ".2f"),
                _cell(s.final_error, "+.3f", u))
    return (label, _cell(s.amplitude, ".2f", u), _cell(s.amplitude_ratio, ".3f"),
            _cell(s.phase_lag_deg, "+.1f"), _cell(s.period_s, ".2f"),
            _cell(s.rms_error, ".3f", u), _cell(s.max_abs_error, ".3f", u))


def _cell(value: float | None, spec: str, unit: str = "") -> str:
    return "–" if value is None or not math.isfinite(value) else f"{value:{spec}}{unit}"


def times(n: int, dt: float) -> np.ndarray:
    """``t (n,)`` in seconds: ``k·dt``."""
    return np.arange(n) * dt


def step(start: Sequence[float], joint: int | str, target: float, duration: float | None = None,
         *, dt: float | None = None, machine: Machine | None = None) -> np.ndarray:
    """One joint steps to ``target`` at t = dt; the others hold (option.c SingleStepInput)."""
    q0 = _start(start, machine)
    j = _joint_index(joint, len(q0), machine)
    goal = q0.copy()
    goal[j] = target
    goal = _targets(_vector(goal, "target", machine), machine)
    path = _held(q0, _samples(_step_duration(q0, goal, duration, machine), _dt(dt, machine)))
    path[1:, j] = goal[j]
    return path


def multi_step(start: Sequence[float], targets: Sequence[float], duration: float | None = None,
               *, dt: float | None = None, machine: Machine | None = None) -> np.ndarray:
    """Every joint steps to its target at once at t = dt (option.c MultiStepInput)."""
    q0 = _start(start, machine)
    goal = _targets(_vector(targets, "targets", machine, len(q0)), machine)
    path = _held(q0, _samples(_step_duration(q0, goal, duration, machine), _dt(dt, machine)))
    path[1:] = goal
    return path


def rig_sequence(start: Sequence[float] | float,
                 steps: Sequence[tuple[Sequence[float] | float, float]], *,
                 dt: float | None = None, machine: Machine | None = None) -> np.ndarray:
    """Step to each position in turn and stay ``dwell_s`` seconds (function.c MultiStep).

    Positions are ``(J,)``, or numbers on a one-joint machine such as the rig.
    The last dwell is the settle tail.
    """
    q0 = _start(start, machine)
    if not steps:
        raise ValueError("a sequence needs at least one (position, dwell_s) step")
    step_dt = _dt(dt, machine)
    rows = [q0[None, :]]
    for i, (position, dwell_s) in enumerate(steps, start=1):
        where = f"step {i}"
        q = _targets(_vector(np.atleast_1d(position), where, machine, len(q0)), machine, where)
        rows.append(_held(q, _samples(dwell_s, step_dt, f"{where} dwell") - 1))
    return np.concatenate(rows)


def ramp(start: Sequence[float], end: Sequence[float], ramp_time: float,
         total_duration: float | None = None, *, dt: float | None = None,
         machine: Machine | None = None, fraction: float = 1.0) -> np.ndarray:
    """From ``start`` to ``end`` in ``ramp_time`` s at constant speed, then hold (function.c
    RampInput).

    With ``machine``, each joint's change of speed at either end is a parabola at
    ``fraction`` (default all) of its ``max_accel`` (a linear segment with parabolic
    blends), so the ramp is a smooth move; a ramp that needs more than that share of
    ``max_speed`` or ``max_accel`` is refused with the ``ramp_time`` it needs. Without a
    machine no limit is known and the corners are the thesis's.
    """
    q0 = _start(start, machine)
    q1 = _targets(_vector(end, "end", machine, len(q0)), machine, "end")
    _positive(ramp_time, "ramp_time")
    total = ramp_time + SETTLE_TAIL_S if total_duration is None else total_duration
    _positive(total, "total_duration")
    if total < ramp_time:
        raise ValueError(f"total_duration {total:g} s is shorter than ramp_time {ramp_time:g} s")
    step_dt = _dt(dt, machine)
    t = times(_samples(total, step_dt, "total_duration"), step_dt)
    if machine is None:
        fraction = np.minimum(t / ramp_time, 1.0)[:, None]
        return q0 + (q1 - q0) * fraction
    if not 0.0 < fraction <= 1.0:
        raise ValueError(f"fraction must be in (0, 1], got {fraction}")
    _check_ramp(q1 - q0, ramp_time, machine, fraction)
    path = np.repeat(q0[None, :], len(t), axis=0)
    for j, joint in enumerate(machine.joints):
        path[:, j] += blended_ramp(t, float(q1[j] - q0[j]), ramp_time,
                                   fraction * joint.max_accel)
    return path


def blended_ramp(t: np.ndarray, change: float, ramp_time: float, accel: float) -> np.ndarray:
    """Travel ``(N,)`` at times ``t`` of a linear segment with parabolic blends: ``change``
    in ``ramp_time`` s, accelerating and braking at ``accel`` (needs ``accel·T² ≥ 4|change|``).
    """
    distance = abs(change)
    if distance == 0.0:
        return np.zeros_like(t)
    # the root of accel·b² − accel·T·b + distance = 0, in the form that keeps its digits
    root = math.sqrt(max(0.0, (accel * ramp_time) ** 2 - 4 * accel * distance))
    blend = 2 * distance / (accel * ramp_time + root)
    cruise = accel * blend
    s = np.clip(t, 0.0, ramp_time)
    travel = np.where(
        s < blend, 0.5 * accel * s**2,
        np.where(s <= ramp_time - blend, 0.5 * accel * blend**2 + cruise * (s - blend),
                 distance - 0.5 * accel * (ramp_time - s) ** 2))
    return math.copysign(1.0, change) * travel


def min_ramp_time(start: Sequence[float], end: Sequence[float], machine: Machine,
                  fraction: float = 1.0) -> float:
    """The shortest ``ramp_time`` (s) from ``start`` to ``end`` within ``fraction`` of every
    joint's ``max_speed`` and ``max_accel`` (trapezoidal speed, or triangular if short)."""
    change = np.abs(np.asarray(end, dtype=float) - np.asarray(start, dtype=float))
    return max((_ramp_time_needed(float(d), fraction * j.max_speed, fraction * j.max_accel)
                for d, j in zip(change, machine.joints, strict=True)), default=0.0)


def sine(start: Sequence[float], end: Sequence[float], period: float, duration: float, *,
         dt: float | None = None, machine: Machine | None = None) -> np.ndarray:
    """``start + (end − start)/2·(1 − cos 2πt/T)``: at ``end`` at T/2, back at T (function.c
    Sinewave), for the whole half periods that fit in ``duration``; then it holds where that
    leaves it (at rest on ``start`` or ``end``) until ``duration``."""
    q0 = _start(start, machine)
    q1 = _targets(_vector(end, "end", machine, len(q0)), machine, "end")
    _positive(period, "period")
    swing = np.abs(q1 - q0)
    _check_speed(np.pi * swing / period, machine, "period", period)  # peak speed
    _check_accel(2 * np.pi**2 * swing / period**2, machine, "period", period)  # peak accel
    step_dt = _dt(dt, machine)
    t = times(_samples(duration, step_dt), step_dt)
    halves = math.floor(duration / (period / 2) + 1e-9)
    if halves == 0:
        raise ValueError(f"duration {duration:g} s is shorter than half the period "
                         f"({period / 2:g} s): the sine would stop mid-swing; make duration at "
                         f"least {period / 2:g} s")
    phase = np.minimum(t, halves * period / 2)
    return q0 + (q1 - q0) / 2.0 * (1.0 - np.cos(2.0 * np.pi * phase / period))[:, None]


def hold_path(q: Sequence[float], duration: float, *, dt: float | None = None,
              machine: Machine | None = None) -> np.ndarray:
    """Stay at ``q`` for ``duration`` s."""
    q0 = _start(q, machine, "hold position")
    return _held(q0, _samples(duration, _dt(dt, machine)))


def summary(t: np.ndarray, desired: np.ndarray, actual: np.ndarray, joints: Sequence[Joint],
            tolerance: float | Sequence[float] | None = None) -> list[StepSummary]:
    """Per joint: overshoot, rise and settling time, steady-state, max and RMS error.

    ``t (N,)`` s, ``desired`` and ``actual`` ``(N, J)``; ``tolerance`` (units)
    is the settle band, by default each joint's ``tolerance``. Samples where
    actual (or desired) is NaN are ignored, with a note.
    """
    t, desired, actual = _response(t, desired, actual, joints)
    n_joints = len(joints)
    bands = ([j.tolerance for j in joints] if tolerance is None
             else _vector(np.broadcast_to(tolerance, (n_joints,)), "tolerance", n=n_joints))
    return [_joint_summary(t, desired[:, j], actual[:, j], joint, float(bands[j]))
            for j, joint in enumerate(joints)]


def tracking_summary(t: np.ndarray, desired: np.ndarray, actual: np.ndarray,
                     joints: Sequence[Joint]) -> list[TrackingSummary]:
    """Per joint: the tracking error's RMS and maximum (and when), and its mean at the end.

    ``t (N,)`` s, ``desired`` and ``actual`` ``(N, J)``; samples where either is NaN are
    ignored, with a note."""
    t, desired, actual = _response(t, desired, actual, joints)
    return [_tracking(t, desired[:, j], actual[:, j], joint) for j, joint in enumerate(joints)]


def sine_summary(t: np.ndarray, desired: np.ndarray, actual: np.ndarray,
                 joints: Sequence[Joint], period: float | None = None) -> list[SineSummary]:
    """Per joint: amplitude ratio and phase lag of the actual's fundamental to the desired's.

    ``period`` (s) is the sine's; without it, it is estimated from the desired's crossings
    of its mid-range (every half period)."""
    t, desired, actual = _response(t, desired, actual, joints)
    return [_sine(t, desired[:, j], actual[:, j], joint, period)
            for j, joint in enumerate(joints)]


def _response(t: np.ndarray, desired: np.ndarray, actual: np.ndarray, joints: Sequence[Joint]
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The arrays of a response as float64, their shapes checked."""
    t = np.asarray(t, dtype=np.float64)
    desired = np.asarray(desired, dtype=np.float64)
    actual = np.asarray(actual, dtype=np.float64)
    n_joints = len(joints)
    if t.ndim != 1 or desired.shape != (len(t), n_joints) or actual.shape != desired.shape:
        raise ValueError(f"expected t (N,), desired and actual (N, {n_joints}); got "
                         f"{t.shape}, {desired.shape}, {actual.shape}")
    return t, desired, actual


def _valid(t: np.ndarray, d: np.ndarray, y: np.ndarray, notes: list[str]) -> np.ndarray:
    valid = np.isfinite(d) & np.isfinite(y)
    if valid.any() and not valid.all():
        notes.append(f"{int((~valid).sum())} of {len(t)} samples with NaN ignored")
    return valid


def _tracking(t: np.ndarray, d: np.ndarray, y: np.ndarray, joint: Joint) -> TrackingSummary:
    notes: list[str] = []
    valid = _valid(t, d, y, notes)
    if not valid.any():
        nan = math.nan
        return TrackingSummary(joint.name, joint.unit, nan, nan, nan, None, nan,
                               ("no valid samples",))
    e = (d - y)[valid]
    worst = int(np.argmax(np.abs(e)))
    tail = e[-max(1, math.ceil(STEADY_FRACTION * len(e))):]
    return TrackingSummary(
        joint=joint.name, unit=joint.unit, travel=float(np.ptp(d[valid])),
        rms_error=float(np.sqrt(np.mean(e**2))), max_abs_error=float(abs(e[worst])),
        max_error_time_s=float(t[valid][worst] - t[0]), final_error=float(np.mean(tail)),
        notes=tuple(notes))


def _sine(t: np.ndarray, d: np.ndarray, y: np.ndarray, joint: Joint,
          period: float | None) -> SineSummary:
    notes: list[str] = []
    valid = _valid(t, d, y, notes)
    tt, dd, yy = t[valid], d[valid], y[valid]
    e = dd - yy
    errors = ((float(np.sqrt(np.mean(e**2))), float(np.max(np.abs(e)))) if len(e)
              else (math.nan, math.nan))
    fit = _fundamentals(tt, dd, yy, period, notes)
    if fit is None:
        return SineSummary(joint.name, joint.unit, period, float(np.ptp(dd)) / 2 if len(dd)
                           else math.nan, None, None, 0.0, *errors, notes=tuple(notes))
    period, periods, wanted, got = fit
    lag = math.degrees(float(np.angle(wanted) - np.angle(got)))
    lag = (lag + 180.0) % 360.0 - 180.0  # in (−180, 180]: the lag, not a whole turn more
    return SineSummary(joint.name, joint.unit, period, float(abs(wanted)),
                       float(abs(got) / abs(wanted)) if abs(wanted) > 0 else None, lag,
                       periods, *errors, notes=tuple(notes))


def _fundamentals(t: np.ndarray, d: np.ndarray, y: np.ndarray, period: float | None,
                  notes: list[str]) -> tuple[float, float, complex, complex] | None:
    """The period, the periods fitted and the complex amplitudes (``b − ic`` of
    ``b·cos ωt + c·sin ωt``) of desired and actual over the swinging part of the run."""
    moving = np.flatnonzero(np.diff(d) != 0)
    if len(moving) == 0:
        notes.append("the desired position does not swing: nothing to fit")
        return None
    first, last = int(moving[0]), int(moving[-1]) + 1  # the samples the swing spans
    swing = float(t[last] - t[first])
    if period is None:
        period = _period_of(t[first:last + 1], d[first:last + 1])
    if not period or period <= 0 or swing < period / 2 * (1 - 1e-9):
        notes.append("less than half a period recorded: not fitted")
        return None
    periods = math.floor(swing / period + 1e-9) or 0.5  # whole periods, or the half
    window = (t >= t[first]) & (t <= t[first] + periods * period + 1e-9)
    tau = t[window] - t[first]
    w = 2 * math.pi / period
    basis = np.column_stack([np.ones_like(tau), np.cos(w * tau), np.sin(w * tau)])
    (_, bd, cd), (_, by, cy) = np.linalg.lstsq(
        basis, np.column_stack([d[window], y[window]]), rcond=None)[0].T
    return period, float(periods), complex(bd, -cd), complex(by, -cy)


def _period_of(t: np.ndarray, d: np.ndarray) -> float:
    """A swing's period from its crossings of the middle of its range (two a period); twice
    its length when it never crosses back (half a period)."""
    middle = (float(d.max()) + float(d.min())) / 2
    side = np.sign(d - middle)
    crossings = t[1:][(side[1:] != side[:-1]) & (side[1:] != 0)]
    if len(crossings) < 2:
        return 2.0 * float(t[-1] - t[0])
    return 2.0 * float(np.mean(np.diff(crossings)))


def _joint_summary(t: np.ndarray, d: np.ndarray, y: np.ndarray, joint: Joint,
                   tol: float) -> StepSummary:
    valid = np.isfinite(d) & np.isfinite(y)
    notes: list[str] = []
    if not valid.any():
        nan = math.nan
        return StepSummary(joint=joint.name, unit=joint.unit, initial=nan, final=nan, step=nan,
                           overshoot=nan, overshoot_pct=nan, rise_time_s=None,
                           settling_time_s=None, steady_state_error=nan, max_abs_error=nan,
                           rms_error=nan, tolerance=tol, notes=("no valid samples",))
    if not valid.all():
        notes.append(f"{int((~valid).sum())} of {len(t)} samples with NaN ignored")
    initial, final = float(d[valid][0]), float(d[valid][-1])
    size = final - initial
    changed = valid & (d != initial)
    start = int(np.argmax(changed)) if changed.any() else 0
    tail = np.arange(len(t)) >= len(t) - max(1, math.ceil(STEADY_FRACTION * len(t)))
    tt, yy, e = t[valid], y[valid], (d - y)[valid]
    moving = tt >= t[start]
    t0 = float(t[start])
    overshoot, rise = 0.0, None
    if size != 0.0:
        overshoot = float(np.max(np.sign(size) * (yy[moving] - final), initial=0.0))
        rise = _rise_time(tt, (yy - initial) / size, notes)
    else:
        notes.append("no step: rise time undefined")
    settling = _settling_time(tt[moving], yy[moving] - final, tol, t0, notes)
    steady = e[tail[valid]]
    if len(steady) == 0:
        notes.append("no valid samples in the last 10 %")
    return StepSummary(
        joint=joint.name, unit=joint.unit, initial=initial, final=final, step=size,
        overshoot=overshoot, overshoot_pct=100.0 * overshoot / abs(size) if size else 0.0,
        rise_time_s=rise, settling_time_s=settling,
        steady_state_error=float(np.mean(steady)) if len(steady) else math.nan,
        max_abs_error=float(np.max(np.abs(e))), rms_error=float(np.sqrt(np.mean(e**2))),
        tolerance=tol, notes=tuple(notes),
    )


def _rise_time(t: np.ndarray, progress: np.ndarray, notes: list[str]) -> float | None:
    """Time from 10 % to 90 % of the step; ``progress`` is 0 at initial, 1 at final."""
    low = _first_crossing(t, progress, RISE_LOW)
    high = _first_crossing(t, progress, RISE_HIGH)
    if low is None or high is None:
        notes.append("did not reach 90 % of the step")
        return None
    return high - low


def _first_crossing(t: np.ndarray, x: np.ndarray, level: float) -> float | None:
    """First time ``x`` reaches ``level``, interpolated between samples."""
    above = np.flatnonzero(x >= level)
    if len(above) == 0:
        return None
    i = int(above[0])
    if i == 0:
        return float(t[0])
    return _interpolate(t[i - 1], t[i], x[i - 1], x[i], level)


def _settling_time(t: np.ndarray, deviation: np.ndarray, tol: float, t0: float,
                   notes: list[str]) -> float | None:
    """Time from ``t0`` until |deviation| ≤ tol from then on, interpolated at the band edge."""
    outside = np.flatnonzero(np.abs(deviation) > tol)
    if len(outside) == 0:
        return 0.0
    i = int(outside[-1])
    if i == len(deviation) - 1:
        notes.append(f"did not settle within ±{tol:g} by the end of the run")
        return None
    edge = tol if deviation[i] > 0 else -tol
    return _interpolate(t[i], t[i + 1], deviation[i], deviation[i + 1], edge) - t0


def _interpolate(t1: float, t2: float, x1: float, x2: float, level: float) -> float:
    return float(t1 + (level - x1) / (x2 - x1) * (t2 - t1)) if x2 != x1 else float(t2)


def _dt(dt: float | None, machine: Machine | None) -> float:
    if dt is None:
        if machine is None:
            raise ValueError("give the sample time dt (s) or the machine")
        return machine.sample_time_s
    _positive(dt, "dt")
    return float(dt)


def _samples(duration: float, dt: float, name: str = "duration") -> int:
    """Samples from t = 0 to t = duration inclusive."""
    _positive(duration, name)
    if duration < dt:
        raise ValueError(f"{name} {duration:g} s is shorter than one sample ({dt:g} s)")
    return round(duration / dt) + 1


def _positive(value: float, name: str) -> None:
    if isinstance(value, bool) or not isinstance(value, Real) or not 0 < value < math.inf:
        raise ValueError(f"{name} must be a positive number of seconds, got {value}")


def _vector(values: Sequence[float] | np.ndarray, name: str, machine: Machine | None = None,
            n: int | None = None) -> np.ndarray:
    """A finite ``(J,)`` vector; the error names the joint when the machine is known."""
    q = np.asarray(values, dtype=np.float64)
    n = len(q) if n is None else n
    if q.shape != (n,):
        raise ValueError(f"{name} must have {n} joint values, got shape {q.shape}")
    bad = np.flatnonzero(~np.isfinite(q))
    if len(bad):
        j = int(bad[0])
        label = machine.joints[j].name if machine is not None else f"joint {j}"
        raise ValueError(f"{name}: {label} value {q[j]} is not a number")
    return q


def _start(start: Sequence[float] | np.ndarray, machine: Machine | None,
           what: str = "start") -> np.ndarray:
    """The pose a move begins from. A joint resting within its tolerance beyond a limit (the
    rig on its bottom stop reads −0.1 mm) starts on the limit; further out is an error."""
    n = machine.n_joints if machine is not None else None
    q = _vector(np.atleast_1d(start), what, machine, n)
    if machine is not None:
        slack = np.array([j.tolerance for j in machine.joints])
        lower, upper = np.array(machine.lower), np.array(machine.upper)
        near = (q >= lower - slack) & (q <= upper + slack)
        q = np.where(near, np.clip(q, lower, upper), q)
    return _targets(q, machine, what)


def _targets(q: np.ndarray, machine: Machine | None, what: str = "") -> np.ndarray:
    """``q`` if every joint is inside its limits; the error names the joint (and ``what``)."""
    if machine is not None:
        try:
            machine.check_targets(tuple(q))
        except ValueError as exc:
            raise ValueError(f"{what}: {exc}" if what else str(exc)) from None
    return q


def _joint_index(joint: int | str, n: int, machine: Machine | None) -> int:
    if isinstance(joint, str):
        if machine is None:
            raise ValueError(f"joint {joint!r} given by name: pass machine= too")
        return machine.joint_index(joint)
    if not 0 <= int(joint) < n:
        raise ValueError(f"joint index {joint} is outside 0…{n - 1}")
    return int(joint)


def _held(q: np.ndarray, n: int) -> np.ndarray:
    return np.repeat(q[None, :], n, axis=0)


def _step_duration(q0: np.ndarray, goal: np.ndarray, duration: float | None,
                   machine: Machine | None) -> float:
    """``duration``, or the slowest joint's travel at max_speed plus the settle tail."""
    if duration is not None:
        return duration
    if machine is None:
        raise ValueError("give the duration (s) or the machine (to derive it from max_speed)")
    speeds = np.array([j.max_speed for j in machine.joints])
    return float(np.max(np.abs(goal - q0) / speeds)) + SETTLE_TAIL_S


def _check_speed(speed: np.ndarray, machine: Machine | None, knob: str, value: float) -> None:
    """Refuse a path faster than a joint's max_speed; the error says how slow to make it."""
    if machine is None:
        return
    for joint, v in zip(machine.joints, speed, strict=True):
        if v > joint.max_speed:
            need = value * v / joint.max_speed
            raise ValueError(
                f"{joint.name} would move at {v:g} {joint.unit}/s, above its max_speed "
                f"{joint.max_speed:g} {joint.unit}/s (machine {machine.name}): make {knob} at "
                f"least {need:.3g} s")


def _check_accel(accel: np.ndarray, machine: Machine | None, knob: str, value: float) -> None:
    """Refuse a sine whose peak acceleration (∝ 1/T²) is above a joint's max_accel."""
    if machine is None:
        return
    for joint, a in zip(machine.joints, accel, strict=True):
        if a > joint.max_accel:
            need = value * math.sqrt(a / joint.max_accel)
            raise ValueError(
                f"{joint.name} would accelerate at {a:.4g} {joint.unit}/s², above its "
                f"max_accel {joint.max_accel:g} {joint.unit}/s² (machine {machine.name}): make "
                f"{knob} at least {need:.3g} s")


def _check_ramp(change: np.ndarray, ramp_time: float, machine: Machine,
                fraction: float) -> None:
    """Refuse a blended ramp beyond ``fraction`` of a joint's max_speed or max_accel, with
    the time it needs."""
    share = "" if fraction == 1.0 else f"{fraction:.0%} of "
    for joint, d in zip(machine.joints, np.abs(change), strict=True):
        speed, accel = fraction * joint.max_speed, fraction * joint.max_accel
        need = _ramp_time_needed(float(d), speed, accel)
        if ramp_time < need * (1 - 1e-9):
            u = joint.unit
            raise ValueError(
                f"{joint.name} cannot ramp {d:g} {u} in {ramp_time:g} s (that is {d / ramp_time:g} "
                f"{u}/s on average) within {share}its max_speed and max_accel ({speed:g} {u}/s, "
                f"{accel:g} {u}/s², machine {machine.name}): make ramp_time at least "
                f"{need:.3g} s")


def _ramp_time_needed(distance: float, speed: float, accel: float) -> float:
    """Shortest time for ``distance`` from rest to rest within ``speed`` and ``accel``."""
    if distance * accel <= speed**2:
        return 2.0 * math.sqrt(distance / accel)  # triangular: never reaches ``speed``
    return distance / speed + speed / accel
