"""Excitation profiles for ``tracking_actuate`` (thesis section 6.3): steps, PRBS, chirp.

Each profile drives one joint open loop (``(N, J)`` duty in %, the other joints
at 0 %), as ``ControlClient.actuate`` plays it; ``combine`` runs several
joints' profiles at once. Duty is controller output: positive moves towards
larger readings (the loop applies the valve polarity).

Profiles are shaped in **velocity** and turned into duty through the joint's
velocity line (``sysid.DeadbandModel``: the machine file's prior
``sysid.nominal`` — deadband at the minimum PWM of section 5.4.1, 100 % duty ≈
``max_speed`` — or an identified model): ``u = ±(d± + |v| / k±)``. So every
nonzero duty clears the minimum PWM, and a velocity pattern that returns to
its start is balanced even though the joint is faster one way (Up/Down with
gravity, In/Out with its rod side at supply).

Sizing rule (the joint must not reach an end stop, wherever the truth lies):

1. Nominal travel stays inside half the room: PRBS bits are flipped when the
   nominal position would leave ``BALANCE`` of the travel available on that
   side; the chirp's velocity is a cosine, so the position swings
   ``±v/(2π·f)`` about the start, and its lowest frequency f₀ makes that
   swing fit in it; steps alternate direction at each level.
2. The worst case must stay inside the limits less a clearance. It integrates
   the duty with the velocity line off against us by ``margin`` in gain
   (default ×1.5, the machine file's ``max_speed`` is a rough figure) and by
   ``slack`` in deadband (default 3 % duty, section 5.4.1's minimum PWM was
   measured in 1 % steps): moving the bad way, gain ×margin and deadband
   −slack; moving back, gain ÷margin and deadband +slack. The nominal
   budgets of rule 1 are divided by the worst case's ratio to the nominal
   speed at the amplitude, so rule 2 rarely refuses a default profile. The
   clearance is ``CLEARANCE_FRACTION`` of the range plus the stopping distance
   ``v²/(2·max_accel)`` at the worst-case peak speed. A profile whose
   worst case leaves that window is refused, naming the joint and the reach.

A coupled encoder (the Yaw reading includes Bend) is checked in both the
actuator's coordinate (where the simulator's and the robot's stops act) and
the reading (where the loop's limits act).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike

from control.identify.sysid import DeadbandModel, nominal
from hw.machine import Joint, Machine
from hw.transmission import Transmission

MARGIN = 1.5  # the velocity line's gain may be off by this factor either way
SLACK = 3.0  # and its deadband by this much duty (%)
BALANCE = 0.5  # nominal travel keeps to this share of the room on each side
CLEARANCE_FRACTION = 0.03  # of each joint's range, kept free at both ends
ABOVE_DEADBAND = 2.0  # % of duty a profile's smallest level clears the deadband by
DEFAULT_SPEED = 0.3  # default amplitude: the duty giving this share of max_speed (nominal)
# Maximal-length LFSR feedback taps (bit positions, 1-based) by register length.
LFSR_TAPS = {5: (5, 3), 6: (6, 5), 7: (7, 6), 8: (8, 6, 5, 4), 9: (9, 5), 10: (10, 7),
             11: (11, 9), 12: (12, 11, 10, 4), 13: (13, 12, 11, 8), 14: (14, 13, 12, 2),
             15: (15, 14), 16: (16, 15, 13, 4)}


@dataclass(frozen=True)
class Excitation:
    """A duty profile and its sizing. ``duty (N, J)`` % at ``dt`` s; ``start (J,)`` the
    readings it was sized from; ``low``, ``high`` ``(N, J)`` worst-case travel from the
    start (joint units, actuator coordinates); ``meta`` what to record with the run."""

    kind: str
    joints: tuple[int, ...]
    dt: float
    duty: np.ndarray
    start: np.ndarray
    low: np.ndarray
    high: np.ndarray
    meta: Mapping[str, object] = field(default_factory=dict)

    @property
    def duration(self) -> float:
        return len(self.duty) * self.dt


def steps(machine: Machine, joint: int | str, start: ArrayLike, *,
          amplitude: float | None = None, levels: int = 6, hold_s: float = 0.3,
          model: DeadbandModel | None = None, margin: float = MARGIN,
          slack: float = SLACK, dt: float | None = None) -> Excitation:
    """Figure 3.2's staircase: ``levels`` speeds up to ``amplitude`` (% duty), each held
    ``hold_s`` one way, then the other way, so the steady velocity-vs-duty line can be read."""
    plan = _Plan.of(machine, joint, start, amplitude, model, margin, slack, dt)
    n_hold = _samples(hold_s, plan.dt, "hold_s")
    if levels < 1:
        raise ValueError(f"levels must be at least 1, got {levels}")
    speeds = np.linspace(plan.v_floor, plan.v_top, levels)
    pattern = np.ravel(np.column_stack([speeds, -speeds]))
    return plan.excitation("steps", plan.duty(np.repeat(pattern, n_hold)),
                           {"levels": levels, "hold_s": hold_s})


def prbs(machine: Machine, joint: int | str, start: ArrayLike, *,
         amplitude: float | None = None, duration: float = 4.0, bit_s: float = 0.08,
         seed: int = 1, model: DeadbandModel | None = None, margin: float = MARGIN,
         slack: float = SLACK, dt: float | None = None) -> Excitation:
    """Pseudo-random binary sequence: signs from a maximal-length LFSR, one per ``bit_s``,
    each bit's speed drawn uniformly between just above the deadband and ``amplitude``
    (multi-level, so the whole velocity line is seen); a bit is flipped when the nominal
    travel would leave ``BALANCE`` of the room (bounded-integral design). The default bit,
    80 ms, is about the slowest joint's velocity settling time (Rotate's 15 Hz oil column
    at ζ ≈ 0.3), so every bit shows the transient and the steady speed; 50 ms bits fit the
    Unimate's joints 1–2 % worse, 30 ms bits 2–3 % worse."""
    plan = _Plan.of(machine, joint, start, amplitude, model, margin, slack, dt)
    n_bit = _samples(bit_s, plan.dt, "bit_s")
    n_bits = math.ceil(_samples(duration, plan.dt, "duration") / n_bit)
    signs = lfsr_signs(n_bits, seed)
    speeds = np.random.default_rng(seed).uniform(plan.v_floor, plan.v_top, n_bits)
    room_low, room_high = (r * BALANCE / plan.worst_ratio() for r in plan.room())
    x = 0.0
    for i in range(n_bits):
        step = signs[i] * speeds[i] * n_bit * plan.dt
        if not -room_low <= x + step <= room_high:
            signs[i] = -signs[i]
            step = -step
        x += step
    velocity = np.repeat(signs * speeds, n_bit)
    return plan.excitation("prbs", plan.duty(velocity),
                           {"duration_s": duration, "bit_s": bit_s, "seed": seed})


def chirp(machine: Machine, joint: int | str, start: ArrayLike, *,
          amplitude: float | None = None, duration: float = 4.0, f0: float | None = None,
          f1: float = 10.0, model: DeadbandModel | None = None, margin: float = MARGIN,
          slack: float = SLACK, dt: float | None = None) -> Excitation:
    """Logarithmic frequency sweep of the velocity, a cosine from ``f0`` to ``f1`` Hz at
    constant speed amplitude v; ``f0`` defaults to the lowest frequency whose swing about the
    start, ``±v/(2π·f₀)``, fits in ``BALANCE`` of the room."""
    plan = _Plan.of(machine, joint, start, amplitude, model, margin, slack, dt)
    n = _samples(duration, plan.dt, "duration")
    lowest = plan.worst_ratio() * plan.v_top / (2.0 * math.pi * BALANCE * min(plan.room()))
    f_start = lowest if f0 is None else float(f0)
    if not 0.0 < f_start < f1 < 0.5 / plan.dt:
        raise ValueError(f"chirp needs 0 < f0 < f1 < {0.5 / plan.dt:g} Hz, got f0 {f_start:.3g}, "
                         f"f1 {f1:g} (the default f0 is {lowest:.3g} Hz for "
                         f"{plan.joint.name}'s room)")
    t = np.arange(n) * plan.dt
    rate = math.log(f1 / f_start) / duration
    phase = 2.0 * math.pi * f_start * np.expm1(rate * t) / rate
    return plan.excitation("chirp", plan.duty(plan.v_top * np.cos(phase)),
                           {"duration_s": duration, "f0_hz": f_start, "f1_hz": f1})


def combine(*profiles: Excitation, machine: Machine) -> Excitation:
    """Several joints' profiles at once (shorter ones padded with 0 %), re-checked where a
    reading includes another excited joint (the Yaw reading includes Bend)."""
    if not profiles:
        raise ValueError("combine needs at least one profile")
    joints = [j for p in profiles for j in p.joints]
    if len(set(joints)) != len(joints):
        raise ValueError("combine: two profiles drive the same joint")
    if len({p.dt for p in profiles}) != 1:
        raise ValueError("combine: the profiles have different sample times")
    if any(not np.array_equal(p.start, profiles[0].start) for p in profiles):
        raise ValueError("combine: the profiles were sized from different start positions; "
                         "size them all from where the run will start")
    n = max(len(p.duty) for p in profiles)
    duty = sum(_pad(p.duty, n, 0.0) for p in profiles)
    low = sum(_pad(p.low, n, None) for p in profiles)
    high = sum(_pad(p.high, n, None) for p in profiles)
    start = profiles[0].start
    for j in joints:
        _check_reading(machine, j, start, low, high, profiles[0].dt)
    return Excitation("combined", tuple(sorted(joints)), profiles[0].dt, duty, start, low,
                      high, {"profiles": [dict(p.meta) for p in profiles]})


def lfsr_signs(n: int, seed: int = 1) -> np.ndarray:
    """``n`` signs (±1.0) of a maximal-length LFSR sequence, register long enough that the
    sequence does not repeat within ``n``; ``seed`` picks the starting state."""
    order = max(5, math.ceil(math.log2(n + 1)))
    if order not in LFSR_TAPS:
        raise ValueError(f"{n} bits need a {order}-bit register; at most 16 bits (65535) "
                         "are supported: use a longer bit time")
    taps, mask = LFSR_TAPS[order], (1 << order) - 1
    state = seed % mask + 1
    out = np.empty(n)
    for i in range(n):
        feedback = 0
        for p in taps:
            feedback ^= (state >> (p - 1)) & 1
        state = ((state << 1) | feedback) & mask
        out[i] = 1.0 if feedback else -1.0
    return out


def worst_case(model: DeadbandModel, duty: ArrayLike, dt: float, margin: float = MARGIN,
               slack: float = SLACK) -> tuple[np.ndarray, np.ndarray]:
    """Lowest and highest travel from the start ``(N,)`` each (units) for ``duty (N,)`` if
    the velocity line is off by ``margin`` and ``slack`` against us (module docstring, rule 2)."""
    u = np.asarray(duty, dtype=float)
    pos, neg = np.maximum(u, 0.0), np.maximum(-u, 0.0)
    fast_pos = margin * model.k_pos * np.maximum(pos - model.d_pos + slack, 0.0)
    slow_pos = model.k_pos / margin * np.maximum(pos - model.d_pos - slack, 0.0)
    fast_neg = margin * model.k_neg * np.maximum(neg - model.d_neg + slack, 0.0)
    slow_neg = model.k_neg / margin * np.maximum(neg - model.d_neg - slack, 0.0)
    high = np.cumsum(fast_pos - slow_neg) * dt
    low = np.cumsum(slow_pos - fast_neg) * dt
    return low, high


def clearance(joint: Joint, peak_speed: float) -> float:
    """Room kept free at each end (units): a share of the range plus the stopping distance."""
    return CLEARANCE_FRACTION * (joint.upper - joint.lower) + peak_speed**2 / (2 * joint.max_accel)


@dataclass(frozen=True)
class _Plan:
    """One joint's profile in the making: its velocity line and the speeds to use."""

    machine: Machine
    index: int
    joint: Joint
    start: np.ndarray
    model: DeadbandModel
    margin: float
    slack: float
    dt: float
    v_floor: float  # units/s of the smallest level: ABOVE_DEADBAND over the deadband
    v_top: float  # units/s of the amplitude, the slower direction's

    @classmethod
    def of(cls, machine: Machine, joint: int | str, start: ArrayLike, amplitude: float | None,
           model: DeadbandModel | None, margin: float, slack: float,
           dt: float | None) -> _Plan:
        j = machine.joint_index(joint) if isinstance(joint, str) else int(joint)
        spec = machine.joints[j]
        q0 = np.asarray(start, dtype=float)
        if q0.shape != (machine.n_joints,) or not np.isfinite(q0).all():
            raise ValueError(f"start must be {machine.n_joints} finite readings, got {q0}")
        line = model or nominal(spec)
        if margin < 1.0 or slack < 0.0:
            raise ValueError(f"margin must be at least 1 and slack at least 0 %, got "
                             f"{margin:g} and {slack:g}")
        deadband = max(line.d_pos, line.d_neg)
        if amplitude is None:
            amplitude = deadband + DEFAULT_SPEED * spec.max_speed / min(line.k_pos, line.k_neg)
        if not deadband + ABOVE_DEADBAND < amplitude <= 100.0:
            raise ValueError(
                f"{spec.name}: amplitude {amplitude:g} % does not clear its minimum PWM "
                f"({line.d_pos:.3g} % one way, {line.d_neg:.3g} % the other): the joint would "
                f"not move; use more than {deadband + ABOVE_DEADBAND:.3g} % (at most 100 %)")
        v_top = min(line.k_pos * (amplitude - line.d_pos), line.k_neg * (amplitude - line.d_neg))
        v_floor = min(line.k_pos, line.k_neg) * ABOVE_DEADBAND
        step = machine.sample_time_s if dt is None else float(dt)
        return cls(machine, j, spec, q0, line, margin, slack, step, v_floor, v_top)

    def duty(self, velocity: np.ndarray) -> np.ndarray:
        """The duty ``(N,)`` % giving ``velocity (N,)`` on the line, ±(d± + |v| / k±), and 0
        below the smallest level, rounded to the valve's resolution so the valve plays exactly
        what is recorded (the UPP card truncates duty to whole 1 % steps, section 1.3.1)."""
        m = self.model
        v = np.where(np.abs(velocity) < self.v_floor, 0.0, velocity)  # a chirp's zero crossings
        u = np.where(v > 0, m.d_pos + v / m.k_pos, np.where(v < 0, -m.d_neg + v / m.k_neg, 0.0))
        step = self.machine.valve_resolution_pct
        return np.clip(np.round(u / step) * step, -100.0, 100.0)

    def worst_ratio(self) -> float:
        """How much faster than nominal the worst case moves at the amplitude (≥ 1)."""
        m = self.model
        u_pos, u_neg = m.d_pos + self.v_top / m.k_pos, m.d_neg + self.v_top / m.k_neg
        fast = max(self.margin * m.k_pos * (u_pos - m.d_pos + self.slack),
                   self.margin * m.k_neg * (u_neg - m.d_neg + self.slack))
        return fast / self.v_top

    def actuator_start(self) -> float:
        """The joint's start in actuator coordinates (a coupled reading undone)."""
        return float(Transmission(self.machine).actuators_of(self.start)[self.index])

    def room(self) -> tuple[float, float]:
        """Travel available below and above the start (units), less the clearance at the
        amplitude's nominal speed, in both the reading and the actuator coordinate."""
        gap = clearance(self.joint, self.worst_ratio() * self.v_top)
        reading = float(self.start[self.index])
        lows = [reading - self.joint.lower, self.actuator_start() - self.joint.lower]
        highs = [self.joint.upper - reading, self.joint.upper - self.actuator_start()]
        return max(min(lows) - gap, 0.0), max(min(highs) - gap, 0.0)

    def excitation(self, kind: str, duty: np.ndarray, meta: dict) -> Excitation:
        """The profile as an ``Excitation``, refused if its worst case reaches a limit."""
        low, high = worst_case(self.model, duty, self.dt, self.margin, self.slack)
        n, j = len(duty), self.index
        table = np.zeros((n, self.machine.n_joints))
        table[:, j] = duty
        lows, highs = np.zeros_like(table), np.zeros_like(table)
        lows[:, j], highs[:, j] = low, high
        _check_actuator(self.joint, self.actuator_start(), low, high, self.dt,
                        f"(worst case: gain ×{self.margin:g}, deadband ±{self.slack:g} %)")
        _check_reading(self.machine, j, self.start, lows, highs, self.dt)
        record = {"excitation": kind, "joint": self.joint.name, "margin": self.margin,
                  "slack_pct": self.slack,
                  "amplitude_pct": float(np.abs(duty).max()), **meta}
        return Excitation(kind, (j,), self.dt, table, self.start, lows, highs, record)


def _check_actuator(spec: Joint, start: float, low: np.ndarray, high: np.ndarray, dt: float,
                    why: str) -> None:
    """Refuse a worst-case travel ``(N,)`` reaching the actuator's stops less the clearance."""
    _refuse_outside(spec, start + float(low.min()), start + float(high.max()),
                    clearance(spec, _peak_speed(low, high, dt)), why)


def _check_reading(machine: Machine, j: int, start: np.ndarray, low: np.ndarray,
                   high: np.ndarray, dt: float) -> None:
    """Refuse a worst-case reading of joint ``j`` (its travel plus a coupled joint's) past
    its limits less the clearance."""
    spec = machine.joints[j]
    transmission = Transmission(machine)
    lows, highs = transmission.reading_bounds(low, high)
    lo, hi = lows[:, j], highs[:, j]
    c = transmission.coupled_to[j]
    why = ("(worst case)" if c < 0
           else f"(worst case of its reading, which includes {machine.joints[c].name})")
    _refuse_outside(spec, float(start[j]) + float(lo.min()), float(start[j]) + float(hi.max()),
                    clearance(spec, _peak_speed(lo, hi, dt)), why)


def _refuse_outside(spec: Joint, lowest: float, highest: float, gap: float, why: str) -> None:
    if lowest >= spec.lower + gap and highest <= spec.upper - gap:
        return
    middle = (spec.lower + spec.upper) / 2
    raise ValueError(
        f"{spec.name}: the profile could reach {lowest:.4g}…{highest:.4g}{spec.symbol} {why}, "
        f"beyond {spec.limit_text()} less {gap:.3g}{spec.symbol} clearance: lower the "
        f"amplitude, shorten the profile, or start nearer the middle ({middle:g}{spec.symbol})")


def _peak_speed(low: np.ndarray, high: np.ndarray, dt: float) -> float:
    """Fastest worst-case speed (units/s) of travel envelopes ``(N,)``."""
    steps = np.abs(np.concatenate([np.diff(low, prepend=0.0), np.diff(high, prepend=0.0)]))
    return float(steps.max()) / dt


def _pad(a: np.ndarray, n: int, value: float | None) -> np.ndarray:
    """``a (k, J)`` extended to ``n`` rows with ``value`` (None: its last row)."""
    if len(a) == n:
        return a
    tail = a[-1:] if value is None else np.full((1, a.shape[1]), value)
    return np.vstack([a, np.repeat(tail, n - len(a), axis=0)])


def _samples(seconds: float, dt: float, name: str) -> int:
    if not (math.isfinite(seconds) and seconds >= dt):
        raise ValueError(f"{name} must be at least one sample ({dt:g} s), got {seconds}")
    return round(seconds / dt)
