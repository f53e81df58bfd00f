"""Controller tuning from identified joint models (thesis sections 5.4, 6.3) and feed-forward.

Loop model. The eq. 5.1 law (``control.rt.law``) turns error e (gain units) into
output u; min-PWM compensation maps u onto the valve beyond ``pmin`` (section
5.4.1); the valve and joint are the identified ``sysid.DeadbandModel``. With
compensation matching the deadband, the joint sees u through the slope
``K± = k±·(1 − p±/100)``, so for design the plant from u to position is::

    P(s) = K · ωn² / (s·(s² + 2ζωn·s + ωn²)) · e^(−s·delay),   K = max(K₊, K₋)

discretised with a zero-order hold at the loop's sample time, plus
``LOOP_DELAY_SAMPLES`` (an encoder word up to one scan old and the PWM
written at the next valve period). The larger slope is the stability worst
case. ``p±`` are the minimums **the law adds** (``hw.transmission.output_min_pwm``), whichever
they are.

PI design (``design_pi``): maximise the integral gain ki subject to the
closed loop being stable and its peak sensitivity ``max|1/(1 + C·P)|`` ≤ ``ms``
(the MIGO design of Åström and Hägglund, *Advanced PID Control*, ch. 7): for
every kp on a grid the largest admissible ki is found by bisection. For a
loop that already integrates (the joint), the integral of the error after a
ramp starts is ``v/(K·ki)``, so the largest ki is the best ramp tracker the
robustness bound allows; ``ms`` = 2 is the textbook's aggressive end (1.4 for
a hold set that must never ring). The result is an eq. 5.1 set (``kp`` one
tap, ``ki``, no derivative, no ``w``) that the operator applies to the hold or
the track set with ``ControlClient.set_coefficients``. Its integrator clamp is
the duty limit, not the thesis's 50 (section 3.6.1): at a steady speed the
error of a P.I. loop around an integrating joint goes to zero, so the
integrator alone holds the duty that speed needs, and a clamp at 50 % leaves
a following error wherever the path asks for more (the Unimate's In/Out at
200 mm/s needs about 60 %).

A proposal also stops the hold's limit cycle (issue 24): a P.I. whose output crosses
zero at rest steps the valve between its minimum PWMs, so each identified joint with a
minimum PWM gets a ``REST_COUNTS``-count ``deadband`` (``control.rt.law``).

Prediction (``simulate``): the law itself (``DifferenceLaw``, so saturation,
the integrator clamp, min-PWM compensation, the deadband and the velocity
feed-forward of the desired path are all there) closed around the identified
models, with the valve's duty quantisation. ``predict_move`` runs issue 24's
check on it: a minimum-jerk move of one joint at full speed, its overshoot and
the time after the path arrives until the joint stays within its
``goal_tolerance`` (``move_figures``, which judges a recorded move the same way, its
wrong encoder readings taken out with hindsight: ``without_wrong_readings``).

Feed-forward (``feed_forward``): the duty that gives the desired velocity on
the identified line, expressed as an addition to the law's output u *before*
min-PWM compensation: ``u_ff = kv±·v + offset±`` with ``kv± = 1/K±`` %/(unit/s)
and ``offset± = (d± − p±)/(1 − p±/100)`` %, the deadband the compensation
leaves (negative when it over-compensates; then speeds below ``k±·(p± − d±)``
cannot be reached with that sign of u and ``u_ff`` is held at 0).
``with_feed_forward`` puts the mean of kv± into a coefficient set's ``kv``:
the loop adds ``kv·v`` with ``v`` the desired velocity of the joint's actuator
(for Yaw, the reading's velocity less Bend's, rtshare.h ``joint_dep``). Since
min-PWM compensation takes the valve side the output opens (errata #27), the
identified offsets are near zero and one gain per joint suffices.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np
import scipy  # its signal loads on first use: 0.7 s no importer need pay
from numpy.typing import ArrayLike

from control.identify.sysid import DeadbandModel
from control.rt.law import DifferenceLaw
from hw.machine import Coefficients, Joint, Machine
from hw.transmission import Transmission, output_min_pwm, output_of, valve_duty

DEFAULT_MS = 2.0
LOOP_DELAY_SAMPLES = 1
FREQUENCIES = 1500  # log-spaced points from 0.01 Hz to Nyquist for the sensitivity peak
KP_GRID = 150  # loop gains K·kp tried, log-spaced from 0.5 rad/s to a quarter of Nyquist
BISECTIONS = 40
REST_SPEED = 1e-9  # units/s below which a desired velocity counts as standing still
REST_COUNTS = 2.0  # a proposal's deadband, encoder counts (the default sets', measured)
MOVE_FRACTION = 0.05  # predict_move: this share of the joint's range, towards its middle
MOVE_DWELL_S = 1.0  # and the end held this long after the path arrives


@dataclass(frozen=True)
class Margins:
    """Robustness of one joint's loop: peak sensitivity, gain crossover, phase margin."""

    stable: bool
    ms: float
    crossover_hz: float
    phase_margin_deg: float


@dataclass(frozen=True)
class Design:
    """A P.I. design for one joint: ``kp`` %/unit, ``ki`` %/(unit·s) (gain units), its margins."""

    joint: str
    kp: float
    ki: float
    margins: Margins


@dataclass(frozen=True)
class Proposal:
    """Proposed coefficients and the design of each joint (None: kept from ``base``)."""

    coefficients: Coefficients
    designs: tuple[Design | None, ...]


@dataclass(frozen=True)
class FeedForward:
    """Velocity feed-forward of one joint (module docstring): ``kv_pos``, ``kv_neg`` in
    %/(unit/s) and ``offset_pos``, ``offset_neg`` in % (signed), to add to the law's output
    before min-PWM compensation; ``gain_pos``, ``gain_neg`` = 1/k± %/(unit/s) and
    ``deadband_pos``, ``deadband_neg`` = d± % are the same line for adding to the valve duty
    after it."""

    joint: str
    unit: str
    kv_pos: float
    kv_neg: float
    offset_pos: float
    offset_neg: float
    gain_pos: float
    gain_neg: float
    deadband_pos: float
    deadband_neg: float

    def duty(self, velocity: ArrayLike) -> np.ndarray:
        """``u_ff`` (%) for desired velocities (units/s), never against their sign."""
        v = np.asarray(velocity, dtype=float)
        up = np.maximum(self.kv_pos * v + self.offset_pos, 0.0)
        down = np.minimum(self.kv_neg * v - self.offset_neg, 0.0)
        return np.where(v > REST_SPEED, up, np.where(v < -REST_SPEED, down, 0.0))


@dataclass(frozen=True)
class ClosedLoop:
    """A predicted (or recorded) closed-loop response: ``t (N,)`` s, ``desired``,
    ``position`` ``(N, J)`` mm/deg, ``duty (N, J)`` % controller output."""

    t: np.ndarray
    desired: np.ndarray
    position: np.ndarray
    duty: np.ndarray

    def rms_error(self) -> np.ndarray:
        """RMS of desired − position per joint ``(J,)``."""
        return np.sqrt(np.mean((self.desired - self.position) ** 2, axis=0))


@dataclass(frozen=True)
class MoveFigures:
    """How one joint ended a move: ``overshoot`` past the path's end (units, ≥ 0) and
    ``settle_s`` from the path's arrival until it stays within its ``goal_tolerance``
    (``math.inf``: still outside when the record ends)."""

    overshoot: float
    settle_s: float


@dataclass(frozen=True)
class MovePrediction:
    """``predict_move``: the move's ``desired (N, J)`` path (its end held), the row its
    path ``arrives`` at, and the predicted ``loop`` and ``figures`` of the joint."""

    joint: int
    desired: np.ndarray
    arrives: int
    loop: ClosedLoop
    figures: MoveFigures


def slopes(model: DeadbandModel, joint: Joint) -> tuple[float, float]:
    """``K₊, K₋``: joint units/s per % of law output u, through the law's compensation."""
    p_pos, p_neg = output_min_pwm(joint)
    return model.k_pos * (1.0 - p_pos / 100.0), model.k_neg * (1.0 - p_neg / 100.0)


def loop_plant(model: DeadbandModel, joint: Joint, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """The design plant from law output u to the error's units, discrete at ``dt``:
    ``(num, den)`` polynomials in z (highest power first)."""
    gain = max(slopes(model, joint)) / joint.gain_unit  # the law sees error / gain_unit
    wn, zeta = model.wn, model.zeta
    num, den, _ = scipy.signal.cont2discrete(
        ([gain * wn * wn], [1.0, 2.0 * zeta * wn, wn * wn, 0.0]), dt, "zoh")
    num = np.trim_zeros(np.ravel(num), "f")
    lag = round(model.delay_s / dt) + LOOP_DELAY_SAMPLES
    return num, np.concatenate([np.ravel(den), np.zeros(lag)])


def controller(coefficients: Coefficients, j: int, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """Joint ``j``'s eq. 5.1 law as ``(num, den)`` polynomials in z, linear part only:
    ``(Σ b_i z⁻ⁱ + ki·Δt / (1 − z⁻¹)) / (1 − Σ w_i z^−(i+1))``."""
    b = np.array(error_taps(coefficients, j, dt))
    w = np.array(coefficients.w[j], dtype=float)
    ki_dt = coefficients.ki[j] * dt
    # coefficients of z⁰, z⁻¹, …: numerator B·(1 − z⁻¹) + ki·Δt, denominator
    # (1 − z⁻¹)·(1 − Σ w_i z^−(i+1)); padded to one length they read as polynomials in z,
    # highest power first, with the same ratio
    num = np.convolve(b, [1.0, -1.0])
    num[0] += ki_dt
    den = np.convolve([1.0, -1.0], np.concatenate([[1.0], -w]))
    size = max(len(num), len(den))
    return np.pad(num, (0, size - len(num))), np.pad(den, (0, size - len(den)))


def error_taps(coefficients: Coefficients, j: int, dt: float) -> tuple[float, ...]:
    """The taps on e(k), e(k−1), … of eq. 5.1: ``kp[i] + kd·filter[i] / (divisor·Δt)``."""
    kp = list(coefficients.kp[j])
    kd = coefficients.kd[j]
    d = [kd * f / (coefficients.filter_divisor * dt) for f in coefficients.filter] if kd else []
    n = max(len(kp), len(d), 1)
    kp += [0.0] * (n - len(kp))
    d += [0.0] * (n - len(d))
    return tuple(p + q for p, q in zip(kp, d, strict=True))


def margins(plant: tuple[np.ndarray, np.ndarray], ctrl: tuple[np.ndarray, np.ndarray],
            dt: float) -> Margins:
    """Stability (closed-loop poles), peak sensitivity, crossover and phase margin."""
    pn, pd = plant
    cn, cd = ctrl
    char = np.polyadd(np.polymul(cd, pd), np.polymul(cn, pn))
    stable = bool(np.all(np.abs(np.roots(char)) < 1.0))
    w, loop = _loop_response(plant, ctrl, dt)
    ms = float(np.max(np.abs(1.0 / (1.0 + loop))))
    above = np.abs(loop) >= 1.0
    cross = int(np.flatnonzero(above)[-1]) if above.any() else 0
    pm = float(180.0 + np.degrees(np.angle(loop[cross])))
    return Margins(stable, ms if stable else math.inf, float(w[cross] / (2 * math.pi)), pm)


def design_pi(model: DeadbandModel, joint: Joint, dt: float, ms: float = DEFAULT_MS) -> Design:
    """The P.I. gains with the largest ki whose loop is stable with peak sensitivity ≤ ``ms``."""
    if ms <= 1.0:
        raise ValueError(f"the peak sensitivity bound must exceed 1, got {ms:g}")
    plant = loop_plant(model, joint, dt)
    w, response = _plant_response(plant, dt)
    z = np.exp(1j * w * dt)  # once, not at each of the search's 6,000 steps
    gain = max(slopes(model, joint)) / joint.gain_unit
    best: tuple[float, float] | None = None
    for kp in np.geomspace(0.5, 0.25 * math.pi / dt, KP_GRID) / gain:
        if not _admissible(plant, response, z, dt, kp, 0.0, ms):
            continue
        lo, hi = 0.0, 1e3 * kp / dt
        for _ in range(BISECTIONS):
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if _admissible(plant, response, z, dt, kp, mid, ms) else (lo, mid)
        if best is None or lo > best[1]:
            best = (float(kp), lo)
    if best is None:
        raise ValueError(f"{joint.name}: no P.I. gains keep the peak sensitivity under {ms:g} "
                         "on the identified model; allow a larger ms or check the model")
    kp, ki = best
    return Design(joint.name, kp, ki, margins(plant, _pi(kp, ki, dt), dt))


def propose(models: Sequence[DeadbandModel | None], machine: Machine, base: Coefficients, *,
            ms: float = DEFAULT_MS, name: str = "proposed", dt: float | None = None) -> Proposal:
    """A P.I. set from the identified ``models`` (one per joint; None keeps ``base``'s gains),
    with ``base``'s filter and duty limit, and the integrator clamped at the duty limit."""
    if len(models) != machine.n_joints:
        raise ValueError(f"need one model (or None) per joint, {machine.n_joints}, got "
                         f"{len(models)}")
    step = machine.sample_time_s if dt is None else dt
    designs = tuple(None if m is None else design_pi(m, joint, step, ms)
                    for m, joint in zip(models, machine.joints, strict=True))
    kp = tuple(base.kp[j] if d is None else (d.kp,) for j, d in enumerate(designs))
    ki = tuple(base.ki[j] if d is None else d.ki for j, d in enumerate(designs))
    kd = tuple(base.kd[j] if d is None else 0.0 for j, d in enumerate(designs))
    w = tuple(base.w[j] if d is None else () for j, d in enumerate(designs))
    deadband = tuple((rest_band(joint) if d is not None else
                      (base.deadband[j] if base.deadband else 0.0))
                     for j, (d, joint) in enumerate(zip(designs, machine.joints, strict=True)))
    shown = ", ".join(f"{d.joint} {d.kp:.3g}/{d.ki:.3g}" for d in designs if d is not None)
    note = f"P.I. (Kp/Ki) by max ki with Ms ≤ {ms:g} on identified models: {shown}"
    coefficients = replace(base, name=name, note=note, kp=kp, ki=ki, kd=kd, w=w,
                           integral_limit=base.duty_limit,
                           deadband=deadband if any(deadband) else ())
    return Proposal(coefficients, designs)


def rest_band(joint: Joint) -> float:
    """A proposal's deadband for ``joint``: ``REST_COUNTS`` encoder counts where min-PWM
    compensation makes a P.I. chatter at rest, none on a valve without (the rig's servo
    valve holds on its pressure gain only with the integrator live, docs/identification.md)."""
    if not any(output_min_pwm(joint)):
        return 0.0
    return REST_COUNTS * abs(joint.encoder.gradient)


def feed_forward(model: DeadbandModel, joint: Joint) -> FeedForward:
    """The joint's velocity feed-forward from its identified line (module docstring)."""
    p_pos, p_neg = output_min_pwm(joint)
    k_pos, k_neg = slopes(model, joint)
    return FeedForward(
        joint=joint.name, unit=joint.unit,
        kv_pos=float(1.0 / k_pos), kv_neg=float(1.0 / k_neg),
        offset_pos=float((model.d_pos - p_pos) / (1.0 - p_pos / 100.0)),
        offset_neg=float((model.d_neg - p_neg) / (1.0 - p_neg / 100.0)),
        gain_pos=float(1.0 / model.k_pos), gain_neg=float(1.0 / model.k_neg),
        deadband_pos=float(model.d_pos), deadband_neg=float(model.d_neg),
    )


def with_feed_forward(coefficients: Coefficients,
                      ffs: Sequence[FeedForward | None]) -> Coefficients:
    """``coefficients`` with velocity feed-forward ``kv`` = mean of kv± per joint (0 for None)."""
    kv = tuple(0.0 if ff is None else (ff.kv_pos + ff.kv_neg) / 2 for ff in ffs)
    return replace(coefficients, kv=kv)


def simulate(models: Sequence[DeadbandModel | None], machine: Machine,
             coefficients: Coefficients, desired: ArrayLike, *,
             initial: ArrayLike | None = None, dt: float | None = None) -> ClosedLoop:
    """The eq. 5.1 law (``DifferenceLaw``) closed around the identified models, following
    ``desired (N, J)`` from rest at the readings ``initial (J,)`` (default: its first row);
    joints without a model follow exactly. The models move actuators; the law sees
    readings, a coupled one including its partner (the Yaw reading includes Bend, rtshare.h
    ``joint_dep``), and the desired velocity of each actuator for ``kv``, the path's central
    difference as the controller's follow_track takes it."""
    d = np.asarray(desired, dtype=float)
    q0 = d[0] if initial is None else np.asarray(initial, dtype=float)
    step = machine.sample_time_s if dt is None else dt
    law = DifferenceLaw(machine, coefficients, step)
    transmission = Transmission(machine)
    follows = transmission.actuators_of(d)  # joints without a model: their actuators follow
    velocity = np.gradient(follows, step, axis=0) if len(d) > 1 else np.zeros_like(d)
    start = transmission.actuators_of(q0)
    plants = [None if m is None else _Plant(m, joint, step, machine.valve_resolution_pct, a)
              for m, joint, a in zip(models, machine.joints, start, strict=True)]
    actuator = [0.0] * machine.n_joints
    reading = [0.0] * machine.n_joints
    position = d.copy()
    duty = np.zeros_like(d)
    for k in range(len(d)):
        for j, plant in enumerate(plants):
            actuator[j] = follows[k, j] if plant is None else plant.position
        transmission.joints_from_actuators(actuator, reading)
        position[k] = reading
        for j, plant in enumerate(plants):
            if plant is not None:
                duty[k, j] = law.update(j, d[k, j] - reading[j], float(velocity[k, j]))
                plant.step(duty[k, j])
    return ClosedLoop(np.arange(len(d)) * step, d, position, duty)


def move_figures(t: np.ndarray, desired: np.ndarray, actual: np.ndarray, arrives: int,
                 joint: Joint) -> MoveFigures:
    """Overshoot and settle of one joint's move: ``t``, ``desired``, ``actual`` ``(N,)``,
    the path's end reached at row ``arrives`` and held after it."""
    actual = without_wrong_readings(t, actual, joint.full_duty_speed)
    target, travel = desired[-1], desired[-1] - desired[0]
    overshoot = max(0.0, float(np.max(np.sign(travel) * (actual - target))))
    outside = np.flatnonzero(np.abs(actual[arrives:] - target) > joint.goal_tolerance)
    if len(outside) == 0:
        return MoveFigures(overshoot, 0.0)
    last = arrives + int(outside[-1]) + 1
    return MoveFigures(overshoot, float(t[last] - t[arrives]) if last < len(t) else math.inf)


def without_wrong_readings(t: np.ndarray, reading: np.ndarray, speed: float) -> np.ndarray:
    """``reading (N,)`` at ``t`` with each wrong reading (section 6.2) taken out, with
    hindsight: a value the reading jumps to and back from, each way further than the joint
    moves at ``speed`` (its full-duty speed) while the value is held, is not the joint's. The
    loop cannot tell such a word from motion when it comes (``control.rt.encoder_input``
    believes a wrong word within reach), but the next one shows it; it is replaced by the
    value before it. Motion, an overshoot or a hunt of a few counts, is kept as read."""
    starts = np.concatenate(([0], np.flatnonzero(np.diff(reading)) + 1))
    values = reading[starts].copy()
    ends = np.append(starts[1:], len(reading))
    out = reading.copy()
    for i in range(1, len(starts) - 1):
        reach = speed * float(t[ends[i]] - t[starts[i]])
        away, back = values[i] - values[i - 1], values[i + 1] - values[i]
        if away * back < 0 and min(abs(away), abs(back)) > reach:
            values[i] = values[i - 1]
            out[starts[i]:ends[i]] = values[i]
    return out


def move_path(machine: Machine, joint: int, start: ArrayLike, speed: float = 1.0, *,
              dt: float | None = None) -> tuple[np.ndarray, int]:
    """``predict_move``'s path from ``start (J,)``: joint ``joint`` by ``MOVE_FRACTION`` of
    its range towards its middle, a minimum-jerk go_to at ``speed`` of its max_speed and
    max_accel, its end held ``MOVE_DWELL_S``; and the row the path arrives at."""
    from control.motion.trajectory import via_path

    step = machine.sample_time_s if dt is None else dt
    q0 = np.asarray(start, dtype=float)
    spec = machine.joints[joint]
    goal = q0.copy()
    sign = 1.0 if q0[joint] <= (spec.upper + spec.lower) / 2 else -1.0
    goal[joint] += sign * MOVE_FRACTION * (spec.upper - spec.lower)
    path = via_path(np.vstack([q0, goal]), machine, dt=step, speed_fraction=speed).q
    held = np.repeat(path[-1:], round(MOVE_DWELL_S / step), axis=0)
    return np.vstack([path, held]), len(path) - 1


def predict_move(models: Sequence[DeadbandModel | None], machine: Machine,
                 coefficients: Coefficients, joint: int, start: ArrayLike,
                 speed: float = 1.0) -> MovePrediction:
    """Issue 24's check of ``coefficients`` on the identified ``models``: ``move_path``'s
    move of ``joint`` simulated (``simulate``), its overshoot and settle time."""
    desired, arrives = move_path(machine, joint, start, speed)
    loop = simulate(models, machine, coefficients, desired)
    figures = move_figures(loop.t, desired[:, joint], loop.position[:, joint], arrives,
                           machine.joints[joint])
    return MovePrediction(joint, desired, arrives, loop, figures)


class _Plant:
    """One identified joint advanced tick by tick: quantised valve, line, dynamics, integral."""

    def __init__(self, model: DeadbandModel, joint: Joint, dt: float, resolution: float,
                 start: float) -> None:
        self.model = model
        self.joint = joint
        self.dt = dt
        self.resolution = resolution
        num, den = _second_order(model, dt)
        self.b1, self.b2 = float(num[1]), float(num[2])
        self.a1, self.a2 = float(den[1]), float(den[2])
        self.lag = [0.0] * (round(model.delay_s / dt) + 2)  # w(k−delay−1), w(k−delay−2)
        self.v = [0.0, 0.0]
        self.position = start

    def step(self, u: float) -> None:
        """Apply law output ``u`` (%) for one tick."""
        valve = valve_duty(self.joint, u)
        applied = math.trunc(valve / self.resolution) * self.resolution  # UPP truncation
        u_applied = output_of(self.joint, applied)
        self.lag.insert(0, float(self.model.steady(u_applied)))
        self.lag.pop()
        w1, w2 = self.lag[-2], self.lag[-1]
        v = self.b1 * w1 + self.b2 * w2 - self.a1 * self.v[0] - self.a2 * self.v[1]
        self.position += 0.5 * (v + self.v[0]) * self.dt
        self.v = [v, self.v[0]]


def _second_order(model: DeadbandModel, dt: float) -> tuple[np.ndarray, np.ndarray]:
    wn, zeta = model.wn, model.zeta
    num, den, _ = scipy.signal.cont2discrete(([wn * wn], [1.0, 2.0 * zeta * wn, wn * wn]), dt,
                                             "zoh")
    return np.ravel(num), np.ravel(den)


def _pi(kp: float, ki: float, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """A P.I. law ``kp + ki·Δt·z/(z − 1)`` as (num, den) in z."""
    return np.array([kp + ki * dt, -kp]), np.array([1.0, -1.0])


def _frequencies(dt: float) -> np.ndarray:
    return 2 * math.pi * np.geomspace(0.01, 0.5 / dt, FREQUENCIES)


def _plant_response(plant: tuple[np.ndarray, np.ndarray],
                    dt: float) -> tuple[np.ndarray, np.ndarray]:
    w = _frequencies(dt)
    z = np.exp(1j * w * dt)
    return w, np.polyval(plant[0], z) / np.polyval(plant[1], z)


def _loop_response(plant: tuple[np.ndarray, np.ndarray], ctrl: tuple[np.ndarray, np.ndarray],
                   dt: float) -> tuple[np.ndarray, np.ndarray]:
    w, p = _plant_response(plant, dt)
    z = np.exp(1j * w * dt)
    return w, p * np.polyval(ctrl[0], z) / np.polyval(ctrl[1], z)


def _admissible(plant: tuple[np.ndarray, np.ndarray], response: np.ndarray, z: np.ndarray,
                dt: float, kp: float, ki: float, ms: float) -> bool:
    """Whether P.I. (kp, ki) gives a stable loop with peak sensitivity ≤ ms (``response`` the
    plant's at the points ``z`` of the unit circle)."""
    cn, cd = _pi(kp, ki, dt)
    # np.polymul's own product, without its 50 µs of argument handling (a tenth of the step)
    char = np.polyadd(np.convolve(cd, plant[1]), np.convolve(cn, plant[0]))
    if np.any(np.abs(np.roots(char)) >= 1.0):
        return False
    loop = response * np.polyval(cn, z) / np.polyval(cd, z)
    return bool(np.max(np.abs(1.0 / (1.0 + loop))) <= ms)
