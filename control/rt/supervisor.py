"""The supervisor: is each joint doing what its valve tells it? (``docs/supervisor.md``)

A hydraulic joint moves at a speed set by its valve: nothing below the
valve's minimum PWM (section 5.4.1), about ``max_speed`` at full duty. The
supervisor compares what each actuator did over the last ``window_s`` with what
its duty should have done, and trusts neither the readings nor the law:

- **Following error** (closed loop, LinuxCNC's ``MIN_FERROR + FERROR × speed``):
  the error limit is ``max(min_following_error, following_error·|v|/max_speed)``
  for desired speed ``v``. A joint beyond it at both ends of the window is
  faulted if its duty was zero all the while and its error did not close by two
  counts (gains zeroed), or if its duty should have moved it and it did not move
  at least ``closing_fraction`` of that (a jammed valve, a blocked joint).
  A step of any size saturates the valve and closes at the speed that gives,
  however far; a joint lagging a path its gains cannot follow, or coming back
  from an overshoot while its integrator unwinds, is doing what its duty says
  and is not faulted. (A duty with the wrong sign drives the joint to its soft
  limit, where the guard closes the valve toward it: then the duty is zero.)
- **Feedback** (every mode, once the encoders are homed): a valve held well open
  (minimum PWM plus ``open_margin_pct``, one way) for the whole window while
  the reading stays within a count of where it was (frozen words, a cut cable,
  a seized joint, no supply), or moves the other way (a swapped wire, a
  reading that lies), is a feedback fault: every valve closes and the E-stop
  latches. A joint resting on a soft limit (within its rest margin, ``control/rt/jog.py``)
  with its valve pushing it that way is held by the limit's stop, not frozen: a target on
  the limit leaves the arm a count short of it, the integrator winding the valve open
  against the stop (issue 25), so a still reading there is no feedback fault. Unless the
  arm is past its target there (by more than ``REST_COUNTS``) and the valve still pushes
  it on into the stop: that is the law holding it wrong (an integral wound up on the way),
  a ``Trip`` (not feedback) saying so.

Each joint is judged in actuator coordinates, where its own valve acts (the
Yaw reading includes Bend; Yaw's actuator does not). Each tick samples one joint
in turn (a joint every ``n`` ticks), so the cost per tick is one joint's
arithmetic. Inputs: believed actuator and joint positions,
desired positions and velocities, the controller output per joint (joint
sense, %), the mode. Outputs: a ``Trip`` (following error) or a ``Trip`` with
``feedback`` set.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from control.rt.jog import REST_COUNTS, rest_margin
from hw.machine import Machine
from hw.transmission import output_min_pwm

MS = 1_000_000
STILL_COUNTS = 1.0  # a reading within a count of where it was has not moved
MOVED_COUNTS = 10.0  # a valve that should have moved the joint this far, and did not
AGAINST_COUNTS = 5.0  # motion the wrong way beyond this (and a quarter of the expected)
CLOSING_FLOOR_COUNTS = 2.0


@dataclass(frozen=True)
class Trip:
    """A joint the supervisor gives up on: ``feedback`` faults latch the E-stop; a following
    error aborts a move into hold (or latches when the joint cannot even hold)."""

    joint: int
    message: str
    feedback: bool = False


class _Window:
    """One joint's samples, oldest overwritten: time, actuator, error (nan in open loop), and
    summed from the start the actuator travel its duty predicts and the duty itself."""

    __slots__ = ("a", "d", "e", "index", "t", "u")

    def __init__(self, size: int) -> None:
        self.t = [0] * size
        self.a = [0.0] * size
        self.e = [math.nan] * size
        self.d = [0.0] * size
        self.u = [0.0] * size
        self.index = 0


class Supervisor:
    def __init__(self, machine: Machine, period_ns: int) -> None:
        s = machine.supervision
        joints = self.joints = machine.joints
        n = self.n = machine.n_joints
        self.window_ns = round(s.window_s * 1e9)
        self.size = math.ceil(self.window_ns / (n * period_ns)) + 1
        self.closing = s.closing_fraction
        self.count = [abs(j.encoder.gradient) for j in joints]
        self.speed_per_ns = [j.max_speed * 1e-9 for j in joints]
        self.min_pwm = [output_min_pwm(j) for j in joints]
        self.stop_below = [j.lower + rest_margin(j) for j in joints]  # on a limit's stop
        self.stop_above = [j.upper - rest_margin(j) for j in joints]
        self.open_at = [(p + s.open_margin_pct, q + s.open_margin_pct) for p, q in self.min_pwm]
        self.min_ferror = [j.min_following_error for j in joints]
        self.ferror_per_speed = [j.following_error / j.max_speed for j in joints]
        self.windows = [_Window(self.size) for _ in range(n)]
        self.travel = [0.0] * n  # predicted actuator travel, integrated sample to sample
        self.effort = [0.0] * n  # |duty| integrated likewise (% ns)
        self.open_since = [0] * n  # when the valve last opened well, one way (0: not open)
        self.open_sign = [0.0] * n
        self.filled = [0] * n
        self.turn = 0

    def rearm(self) -> None:
        """Forget the windows: a new mode or move is judged afresh."""
        self.filled = [0] * self.n
        self.open_since = [0] * self.n

    def speed(self, j: int, u: float) -> float:
        """Signed actuator speed (units/ns) that output ``u`` (%) should at least give: the
        machine file's nominal line (nothing up to the minimum PWM, ``max_speed`` at 100 %)
        with the deadband widened by ``open_margin_pct``, since gravity and friction slow a
        joint most near its deadband."""
        up = u > 0.0
        over = abs(u) - self.open_at[j][0 if up else 1]
        if over <= 0.0:
            return 0.0
        p = self.min_pwm[j][0 if up else 1]
        return math.copysign(self.speed_per_ns[j] * over / (100.0 - p), u)

    def sample(self, now: int, actuator: list[float], position: list[float],
               desired: list[float], velocity: list[float], duty: list[float],
               closed_loop: bool) -> Trip | None:
        """Sample the joint whose turn it is; a Trip if it fails a check."""
        j = self.turn
        self.turn = j + 1 if j + 1 < self.n else 0
        w = self.windows[j]
        k = w.index
        last = k - 1 if k else self.size - 1
        u = duty[j]
        if self.filled[j]:
            self.travel[j] += self.speed(j, u) * (now - w.t[last])
            self.effort[j] += abs(u) * (now - w.t[last])
        self.track_opening(j, u, now)
        w.t[k] = now
        w.a[k] = actuator[j]
        error = desired[j] - position[j] if closed_loop else math.nan
        w.e[k] = error
        w.d[k] = self.travel[j]
        w.u[k] = self.effort[j]
        w.index = k + 1 if k + 1 < self.size else 0
        self.filled[j] += 1
        old = self.oldest(j, now)
        if old < 0:
            return None
        if self.open_since[j] and now - self.open_since[j] >= self.window_ns:
            trip = self.feedback(j, w, old, k, u)
            if trip is not None:
                return trip
        if closed_loop:
            return self.following(j, w, old, k, velocity[j])
        return None

    def track_opening(self, j: int, u: float, now: int) -> None:
        """Remember since when the valve has been well open in one direction."""
        p_up, p_down = self.open_at[j]
        sign = 1.0 if u >= p_up else -1.0 if u <= -p_down else 0.0
        if sign == 0.0:
            self.open_since[j] = 0
        elif sign != self.open_sign[j] or not self.open_since[j]:
            self.open_since[j] = now
        self.open_sign[j] = sign

    def oldest(self, j: int, now: int) -> int:
        """The index of the sample a window before ``now``, or -1 while the window fills."""
        if self.filled[j] < self.size:
            return -1
        w = self.windows[j]
        k = w.index  # the oldest sample, about size - 1 samples back
        return k if now - w.t[k] >= self.window_ns else -1

    def feedback(self, j: int, w: _Window, old: int, new: int, u: float) -> Trip | None:
        """A well-open valve and a reading that stays still, or moves the other way."""
        moved = w.a[new] - w.a[old]
        expected = w.d[new] - w.d[old]
        count = self.count[j]
        joint = self.joints[j]
        span = (w.t[new] - w.t[old]) / 1e9
        if abs(expected) < MOVED_COUNTS * count:
            return None
        where = (f"{joint.name}'s valve has been open at {u:+.0f} % (minimum PWM "
                 f"{self.min_pwm[j][0 if u > 0 else 1]:g} %) for {span:.2f} s")
        if abs(moved) <= STILL_COUNTS * count:
            if self.on_stop(j, w.a[new], expected):
                return self.pushed_past(j, w.e[new], expected, where, w.a[new])
            return Trip(j, f"feedback fault: {where} and its reading has not moved from "
                           f"{w.a[new]:.2f}{joint.symbol} (it should have moved about "
                           f"{abs(expected):.1f}{joint.symbol}): frozen encoder, cut cable, "
                           "seized joint or no hydraulic supply", feedback=True)
        if moved * expected < 0.0 and abs(moved) > max(AGAINST_COUNTS * count,
                                                        0.25 * abs(expected)):
            return Trip(j, f"feedback fault: {where} and its reading moved {moved:+.1f}"
                           f"{joint.symbol}, the other way: check the encoder and the valve's "
                           "wiring", feedback=True)
        return None

    def on_stop(self, j: int, actuator: float, expected: float) -> bool:
        """Whether joint ``j`` rests on a limit's stop with its valve pushing it there (the
        stops act on the actuator, at the joint's limits)."""
        if expected > 0.0:
            return actuator >= self.stop_above[j]
        return actuator <= self.stop_below[j]

    def pushed_past(self, j: int, error: float, expected: float, where: str, at: float
                    ) -> Trip | None:
        """On a limit's stop with the valve pushing into it: None while the target is there
        too (or open loop), a Trip when the arm is past its target and pushed on."""
        if not error * math.copysign(1.0, expected) < -REST_COUNTS * self.count[j]:
            return None  # NaN (open loop) fails the comparison too
        joint = self.joints[j]
        return Trip(j, f"{where}, pushing {joint.name} onto its limit stop at {at:.2f}"
                       f"{joint.symbol}, {abs(error):.2f}{joint.symbol} past its target: its "
                       "gains hold it there (an integral wound up on the way?) or its valve "
                       "is wrong: check them")

    def following(self, j: int, w: _Window, old: int, new: int, velocity: float) -> Trip | None:
        """Beyond the limit at both ends of the window: a fault if its duty was zero and the
        error did not close, or if its duty should have moved it and it moved less than
        ``closing_fraction`` of that."""
        e_new, e_old = w.e[new], w.e[old]
        limit = max(self.min_ferror[j], self.ferror_per_speed[j] * abs(velocity))
        if not (abs(e_new) > limit and abs(e_old) > limit):
            return None
        joint = self.joints[j]
        span = (w.t[new] - w.t[old]) / 1e9
        where = (f"following error: {joint.name} is {abs(e_new):.1f}{joint.symbol} from its "
                 f"target (limit {limit:.3g}{joint.symbol})")
        if w.u[new] == w.u[old]:
            if abs(e_old) - abs(e_new) >= CLOSING_FLOOR_COUNTS * self.count[j]:
                return None
            return Trip(j, f"{where} and not closing; its duty has been zero for {span:.2f} s: "
                           "check its gains")
        expected = w.d[new] - w.d[old]
        moved = w.a[new] - w.a[old]
        if expected < 0.0:
            moved = -moved  # along what the duty asks
        if abs(expected) < MOVED_COUNTS * self.count[j] or moved >= self.closing * abs(expected):
            return None  # moving as its duty says; a duty near the deadband is not judged
        return Trip(j, f"{where}; in {span:.2f} s its valve should have moved it "
                       f"{abs(expected):.2f}{joint.symbol} and it moved {moved:+.2f}"
                       f"{joint.symbol}: a jammed valve, a blocked joint or no supply")
