"""The controller of eq. 5.1: a generalised difference equation, one joint per call.

    u(k+1) = Σ w[i]·u(k−i) + Σ kp[i]·e(k−i) + kd·Σ f[i]·e(k−i) / (p·Δt) + Σ ki·e(k)·Δt

then saturation to ±100 %, minimum-PWM compensation (section 5.4.1, errata #5)
and the coefficient set's duty limit. The integral is clamped at ``integral_limit``
and, to prevent windup as section 3.6.1 intends, does not grow while the output is
saturated the way its error pushes (conditional integration, errata #31): the
listing's clamp alone lets a 400 mm rig step wind it to 13 % (slip ``windup``).
The set's ``deadband`` (per joint, joint units; LinuxCNC pid's, issue 24) stops the
limit cycle a P.I. with minimum-PWM compensation keeps at rest (the output crossing zero
steps the valve from one minimum PWM to the other, 2-11 times a second): with no desired
velocity a rest begins once |e| is within half the deadband and lasts until |e| is past it
on ``REST_EXIT_SAMPLES`` samples running (hysteresis: a reading flickering a count at the
edge, or a wrong reading of section 6.2, neither starts nor ends one); while
resting the law sees no error, the integral holds, and the output goes out without the
compensation, clipped to the minimum PWM, so the valve stays inside its overlap.
The set's ``integral_separation`` (%) stops the integral too while the feedback terms
(all but the feed-forward) ask for more than it and the step would add to that
(conditional integration, Åström and Hägglund); a step that unwinds it is always taken (held
whenever the feedback was large, an integral wound up on the way to a jog's goal stayed, and
held the arm past the goal, on the stop at a limit): a P.I.
designed for the small errors of a followed path otherwise winds up on the way to a step
(the rig's 100 mm step overshot 13.6 mm, 2.7 with 20 %).
Taps are newest first (errata #21). With ``w`` empty, ``kp = [Kp]`` and the
filter (11, −18, 9, −2)/6 it is the PID of eq. 3.3; with ``w`` non-empty, the
observer controller of section 3.6.2.

The sample time Δt is the machine file's ``sample_time_ms`` (0.5: 2 kHz): the integral
(ki·Δt) and the derivative (kd/(p·Δt)) are of seconds, so a P.I.D. set means the same at any
rate; the ``w`` taps and a ``kp`` of more than one tap (the observer controller) are a
discrete design for one Δt and must be designed again for another.

Inputs per tick: joint index and error e(k) = desired − actual in joint units
(mm, deg). Output: u(k+1) in percent, before down-scaling and polarity, which the
machine's transmission (``hw.transmission``) applies. The tick path uses plain
floats and fixed-length lists shifted in place: six joints at 1 kHz cost
microseconds (``benchmarks/law.py``).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace
from numbers import Real
from operator import mul

from hw.machine import Coefficients, Joint, Machine
from hw.transmission import output_min_pwm

EQ33_FILTER = (11.0, -18.0, 9.0, -2.0)  # eq. 3.3: 4-point backward difference of e
EQ33_DIVISOR = 6.0  # eq. 3.3: divided by 6·Δt (errata #1, #20)
INTEGRAL_LIMIT = 50.0  # section 3.6.1: Σ Ki·e·Δt limited to 50
SATURATION = 100.0  # u(k) ∈ [−100 %, 100 %], eq. 5.1
# A rest ends after this many samples running past the deadband: the simulator's wrong
# readings at rest (section 6.2) last 1-2 samples and the glitch filter can pass one on
# for 3, each kicking the valve from its overlap
REST_EXIT_SAMPLES = 5
_INF = math.inf
# The listings' slips (docs/errata.md), to run the thesis's law as printed (control/timing.py)
SLIPS = {
    "derivative": "errata #1: the derivative is divided by 6 and multiplied by Δt",
    "integral_oldest": "errata #2: the integral sums the oldest error of the history",
    "min_pwm": "errata #5: integer division makes the minimum-PWM factor 1: u + pmin",
    "windup": "errata #31: the integral grows while the valve is saturated (clamped at ±50 only)",
}


@dataclass(frozen=True, slots=True)
class _JointGains:
    """One joint's coefficients prepared for the tick; rebuilt only by ``set_coefficients``."""

    gain_unit: float  # joint units per unit of error the gains act on (errata #18)
    w: tuple[float, ...]  # weights on u(k), u(k−1), …
    b: tuple[float, ...]  # taps on e(k), e(k−1), …: kp[i] + kd·f[i] / (p·Δt), see _error_taps
    ki_dt: float  # ki·Δt
    oldest: bool  # integrate the oldest error (slip "integral_oldest")
    windup: bool  # integrate while saturated (slip "windup")
    integral_limit: float
    separation: float  # % of output above which the integral holds; 0: none
    pos_scale: float  # 1 − pmin/100
    pmin: float
    neg_scale: float  # 1 − nmin/100
    nmin: float
    duty_limit: float
    kv: float  # velocity feed-forward, % per joint unit/s
    deadband: float  # |e| (gain units) at which a rest ends; 0: none
    rest_band: float  # |e| within which a rest begins: half the deadband (hysteresis)


class _JointState:
    """Histories (newest first) and integrator of one joint; mutated in place every tick."""

    __slots__ = ("e", "integral", "outside", "resting", "u")

    def __init__(self, n_errors: int, n_outputs: int) -> None:
        self.e = [0.0] * n_errors
        self.u = [0.0] * n_outputs
        self.integral = 0.0
        self.resting = False  # inside the deadband at rest (``DifferenceLaw.update``)
        self.outside = 0  # resting, samples running with the error past the deadband


@dataclass(frozen=True)
class LawState:
    """A snapshot of one joint's state: errors in gain units, outputs in %, newest first."""

    errors: tuple[float, ...]
    outputs: tuple[float, ...]
    integral: float


class DifferenceLaw:
    """Eq. 5.1 for every joint of a machine, with state kept across coefficient changes.

    ``dt`` is the sample time Δt in seconds. ``set_coefficients`` may be called
    at any time, even mid-move (section 6.3): histories and integrators are
    kept, so the change is bumpless.
    """

    def __init__(self, machine: Machine, coefficients: Coefficients, dt: float,
                 slips: frozenset[str] = frozenset()) -> None:
        if not (math.isfinite(dt) and dt > 0):
            raise ValueError(f"sample time must be a positive number of seconds, got {dt}")
        if not slips <= SLIPS.keys():
            raise ValueError(f"unknown slips {sorted(slips - SLIPS.keys())}")
        self.machine = machine
        self.dt = dt
        self.slips = slips
        self._states = [_JointState(1, 1) for _ in machine.joints]
        self.set_coefficients(coefficients)

    @property
    def coefficients(self) -> Coefficients:
        return self._coefficients

    def set_coefficients(self, c: Coefficients) -> None:
        """Swap the gains; histories grow to the new tap lengths, integrators are kept
        (bumpless) inside the new set's limit, but not by a set with no integral action
        (``ki`` 0): nothing would ever unwind it, a frozen offset that minimum PWM opens the
        valve on (a zeroed hold crept Rotate 13° in a suite run)."""
        _check_shape(c, self.machine)
        gains = tuple(_prepare(joint, c, j, self.dt, self.slips)
                      for j, joint in enumerate(self.machine.joints))
        for state, g in zip(self._states, gains, strict=True):
            _grow(state.e, max(len(g.b), len(c.filter)))
            _grow(state.u, max(len(g.w), 1))
            limit = g.integral_limit if g.ki_dt else 0.0
            state.integral = max(-limit, min(limit, state.integral))
        self._gains = gains
        self._coefficients = c

    def reset(self) -> None:
        """Clear every history and integrator (after an E-stop, before a fresh start)."""
        for s in self._states:
            s.e[:] = [0.0] * len(s.e)
            s.u[:] = [0.0] * len(s.u)
            s.integral = 0.0
            s.resting = False
            s.outside = 0

    def state(self, j: int) -> LawState:
        """A copy of joint ``j``'s histories and integrator (for display and tests)."""
        s = self._states[j]
        return LawState(tuple(s.e), tuple(s.u), s.integral)

    def update(self, j: int, error: float, velocity: float = 0.0,
               feed_forward: bool = True) -> float:
        """u(k+1) in % for joint ``j`` from e(k) = desired − actual in mm or degrees.

        ``velocity`` is the desired velocity (units/s) for the feed-forward ``kv``; with
        ``feed_forward`` false it only says the target moves (a jog's), so no rest begins.
        """
        g = self._gains[j]
        s = self._states[j]
        e = error / g.gain_unit  # error in gain units, errata #18
        if not -_INF < e < _INF:  # a NaN would poison the integrator for good
            raise ValueError(f"{self.machine.joints[j].name}: error {error} is not a number")
        if not (g.deadband and velocity == 0.0):
            rest = s.resting = False
        elif s.resting:  # it ends past the deadband REST_EXIT_SAMPLES running, not on a glitch
            s.outside = 0 if -g.deadband <= e <= g.deadband else s.outside + 1
            rest = s.resting = s.outside < REST_EXIT_SAMPLES
            if not rest:
                s.outside = 0
        else:  # it begins within half the deadband
            rest = s.resting = -g.rest_band <= e <= g.rest_band
        if rest:
            e = 0.0  # inside the deadband at rest: no error (LinuxCNC pid's deadband)
        errors = s.e
        errors.pop()
        errors.insert(0, e)  # e(k), e(k−1), … newest first
        u = sum(map(mul, g.w, s.u))  # Σ w[i]·u(k−i)
        u += sum(map(mul, g.b, errors))  # Σ kp[i]·e(k−i) + kd·Σ f[i]·e(k−i) / (p·Δt)
        step = g.ki_dt * (errors[-1] if g.oldest else e)  # errata #2, #3
        if g.separation and ((step > 0.0 and u + s.integral > g.separation)
                             or (step < 0.0 and u + s.integral < -g.separation)):
            step = 0.0  # conditional integration: the feedback asks for much, this way already
        if feed_forward:
            u += g.kv * velocity  # velocity feed-forward (chapter 6)
        integral = s.integral + step
        if integral > g.integral_limit:
            integral = g.integral_limit
        elif integral < -g.integral_limit:
            integral = -g.integral_limit
        if not g.windup and ((step > 0.0 and u + integral > SATURATION)
                             or (step < 0.0 and u + integral < -SATURATION)):
            integral = s.integral  # section 3.6.1: no windup while saturated (errata #31)
        s.integral = integral
        u += integral
        if u > SATURATION:
            u = SATURATION
        elif u < -SATURATION:
            u = -SATURATION
        if rest:  # the valve stays inside its overlap: no minimum-PWM step to chatter across
            if u > g.pmin:
                u = g.pmin
            elif u < -g.nmin:
                u = -g.nmin
        elif u > 0.0:  # minimum PWM maps (0, 100] onto (pmin, 100], errata #5
            u = g.pos_scale * u + g.pmin
        elif u < 0.0:
            u = g.neg_scale * u - g.nmin
        if u > g.duty_limit:
            u = g.duty_limit
        elif u < -g.duty_limit:
            u = -g.duty_limit
        outputs = s.u
        outputs.pop()
        outputs.insert(0, u)  # u(k+1) becomes u(k) of the next tick
        return u


def pid(machine: Machine, kp: float | Sequence[float], ki: float | Sequence[float],
        kd: float | Sequence[float], *, integral_limit: float = INTEGRAL_LIMIT,
        duty_limit: float = SATURATION, name: str = "pid", note: str = "") -> Coefficients:
    """A PID coefficient set of eq. 3.3; each gain is one number for all joints or one per joint."""
    n = machine.n_joints
    kps, kis, kds = (_per_joint(g, n, label) for g, label in ((kp, "kp"), (ki, "ki"), (kd, "kd")))
    return Coefficients(
        name=name,
        note=note or f"PID of eq. 3.3: Kp {_gains_text(kps)}, Ki {_gains_text(kis)}, "
                     f"Kd {_gains_text(kds)}",
        kp=tuple((k,) for k in kps),
        ki=kis,
        kd=kds,
        w=tuple(() for _ in range(n)),
        filter=EQ33_FILTER,
        filter_divisor=EQ33_DIVISOR,
        integral_limit=integral_limit,
        duty_limit=duty_limit,
    )


def pi(machine: Machine, kp: float | Sequence[float], ki: float | Sequence[float], *,
       integral_limit: float = INTEGRAL_LIMIT, duty_limit: float = SATURATION,
       name: str = "pi", note: str = "") -> Coefficients:
    """A P.I. set (section 5.4.2): ``pid`` with Kd = 0."""
    c = pid(machine, kp, ki, 0.0, integral_limit=integral_limit, duty_limit=duty_limit,
            name=name, note=note)
    if note:
        return c
    return replace(c, note=f"P.I. of section 5.4.2: Kp {_gains_text(tuple(k[0] for k in c.kp))}, "
                           f"Ki {_gains_text(c.ki)}")


def preset(name: str, machine: Machine) -> Coefficients:
    """A coefficient set of the machine file by name: ``hold``, ``track``, the Unimate's
    ``thesis_pi`` (section 5.4.2), the rig's ``observer`` (section 3.6.2, as printed, errata
    #12)."""
    try:
        return machine.coefficients[name]
    except KeyError:
        have = ", ".join(machine.coefficients)
        raise KeyError(f"machine {machine.name} has no coefficient set {name!r} "
                       f"(it has: {have})") from None


def start_sets(machine: Machine, thesis_timing: bool = False
               ) -> tuple[Coefficients, Coefficients]:
    """The hold and track sets a controller starts with: the machine file's ``hold`` and
    ``track``, or in the thesis's timing (control/timing.py: a sample of 6-36 ms, where gains
    designed at 1 ms go unstable) the sets the thesis ran, ``thesis_hold`` and
    ``thesis_track``, when the file has them."""
    c = machine.coefficients
    if not thesis_timing:
        return machine.hold, machine.track
    return c.get("thesis_hold", machine.hold), c.get("thesis_track", machine.track)


def _prepare(joint: Joint, c: Coefficients, j: int, dt: float,
             slips: frozenset[str]) -> _JointGains:
    up, down = output_min_pwm(joint)
    unscaled = "min_pwm" in slips
    return _JointGains(
        gain_unit=joint.gain_unit,
        w=tuple(c.w[j]),
        b=_error_taps(c.kp[j], c.kd[j], c.filter, c.filter_divisor, dt,
                      "derivative" in slips),
        ki_dt=c.ki[j] * dt,
        oldest="integral_oldest" in slips,
        windup="windup" in slips,
        integral_limit=c.integral_limit,
        separation=c.integral_separation,
        pos_scale=1.0 if unscaled else 1.0 - up / 100.0,
        pmin=up,
        neg_scale=1.0 if unscaled else 1.0 - down / 100.0,
        nmin=down,
        duty_limit=c.duty_limit,
        kv=c.kv[j] if c.kv else 0.0,
        deadband=c.deadband[j] / joint.gain_unit if c.deadband else 0.0,
        rest_band=c.deadband[j] / joint.gain_unit / 2 if c.deadband else 0.0,
    )


def _error_taps(kp: Sequence[float], kd: float, f: Sequence[float], divisor: float,
                dt: float, as_printed: bool = False) -> tuple[float, ...]:
    """The proportional and derivative terms of eq. 5.1 both weigh e(k−i), so they are one
    tap vector: b[i] = kp[i] + kd·f[i] / (p·Δt). Summing once per tick instead of twice
    saves a quarter of a PID tick (benchmarks/law.py); the arithmetic is the equation's.
    ``as_printed``: PDcontrol.c's ``/6*SampleTime``, kd·f[i]·Δt / p (errata #1)."""
    scale = dt / divisor if as_printed else 1.0 / (divisor * dt)
    d = [kd * fi * scale for fi in f] if kd else []
    n = max(len(kp), len(d))
    kp = [*kp, *[0.0] * (n - len(kp))]
    d = [*d, *[0.0] * (n - len(d))]
    return tuple(p + q for p, q in zip(kp, d, strict=True))


def _check_shape(c: Coefficients, machine: Machine) -> None:
    n = machine.n_joints
    for label, value in (("kp", c.kp), ("ki", c.ki), ("kd", c.kd), ("w", c.w)):
        if len(value) != n:
            raise ValueError(f"coefficient set {c.name!r}: {label} has {len(value)} entries, "
                             f"machine {machine.name} has {n} joints")
    if c.filter_divisor <= 0:
        raise ValueError(f"coefficient set {c.name!r}: filter_divisor must be positive, "
                         f"got {c.filter_divisor:g}")


def _grow(history: list[float], length: int) -> None:
    """Extend a history with zeros (oldest end) so ``length`` taps can read it; never shrink."""
    if len(history) < length:
        history.extend([0.0] * (length - len(history)))


def _per_joint(gain: float | Sequence[float], n: int, label: str) -> tuple[float, ...]:
    values = (float(gain),) * n if isinstance(gain, Real) else tuple(map(float, gain))
    if len(values) != n:
        raise ValueError(f"{label}: expected one gain or {n}, got {len(values)}")
    bad = [v for v in values if not math.isfinite(v)]
    if bad:
        raise ValueError(f"{label}: gains must be finite numbers, got {bad[0]}")
    return values


def _gains_text(values: tuple[float, ...]) -> str:
    return f"{values[0]:g}" if len(set(values)) == 1 else "/".join(f"{v:g}" for v in values)
