"""The simulator backend: hydraulic plant, UPP card PWM and encoders behind ``Backend``.

Like ros2_control's ``GenericSystem`` this is a real backend, not a test
double: the plant (:mod:`hw.sim.plant`) is advanced lazily to the clock's time on
every ``read``/``write``, in steps of at most 1 ms, and the encoders
(:mod:`hw.sim.encoders`) latch what they would have seen. With ``lockstep=True``
the clock is a ``StepClock``: time passes only when the control loop sleeps
until its next deadline, so a 10 s move simulates in a fraction of a second
and every run with the same seed gives the same raw words.

The read/write path allocates no lists; it is meant to be called from one thread.
"""

from __future__ import annotations

from collections.abc import Sequence

from hw.backend import LinkCounters, RealClock, StepClock
from hw.machine import Machine
from hw.sim.encoders import GrayEncoderBoard, QuadratureEncoder
from hw.sim.plant import STEP_S, Plant
from hw.sim.valve import next_period_ns, quantise_duty

MAX_CATCH_UP_NS = 1_000_000_000  # a plant left alone longer is simulated for the last second only


def check_plant(machine: Machine) -> None:
    """Raise MachineError, naming the file and the key, if the simulator cannot run the
    machine file's plant: what building a SimBackend refuses, asked before a controller
    starts (``servodesk machine``, the command line's sim backend)."""
    SimBackend(machine, lockstep=True)


class SimBackend:
    """Simulated machine: plant, PWM output and encoders, with an E-stop input.

    Options (all keyword):
      initial: joint positions at power-up, joint units (default: mid-range of each joint).
      load_kg: load on a prismatic joint, e.g. the rig's weights, 50…300 kg (default: machine file).
      supply_mpa: supply pressure (default: machine file; the rig's Figure 3.2 used 13.3 MPa).
      glitch_scale: multiplies the encoders' wrong-reading rate; 0 turns wrong readings off.
      scan_period_s: time the I/O board takes to scan all Gray-code encoders once
        (default: the sample time, a full six-joint sample per tick).
      select_to_latch_s: time from selecting an encoder (lighting its lamp) to latching its
        word, at most its slot of ``scan_period_s / n`` (default: the whole slot). The
        thesis's RT.o read one joint per interrupt: 1 ms per joint is ``scan_period_s=6e-3,
        select_to_latch_s=1e-3``; 6 ms per joint is ``36e-3, 6e-3`` (section 6.2).
      scan_lead_s: the scan began this long before the backend started. RT.o selected the
        next joint's encoder at the end of each interrupt and read it at the start of the
        next: with a lead of one slot, the word latched at each tick is the joint the thesis
        timing's controller serves at that tick (``control/timing.py``).
    """

    def __init__(self, machine: Machine, seed: int = 0, lockstep: bool = False, *,
                 initial: Sequence[float] | None = None, load_kg: float | None = None,
                 supply_mpa: float | None = None, glitch_scale: float = 1.0,
                 scan_period_s: float | None = None,
                 select_to_latch_s: float | None = None, scan_lead_s: float = 0.0) -> None:
        self.machine = machine
        self.clock: StepClock | RealClock = StepClock() if lockstep else RealClock()
        self.counters = LinkCounters()
        self.plant = Plant(machine, initial=initial, load_kg=load_kg, supply_mpa=supply_mpa)
        n = machine.n_joints
        self._n = n
        self._step_ns = round(STEP_S * 1e9)
        self._period_ns = round(machine.valve_period_us * 1e3)
        self._resolution = machine.valve_resolution_pct
        self._t_ns = self.clock.now_ns()
        self.sample_ns = self._t_ns
        self._a_prev = [0.0] * n
        self._a_now = [0.0] * n
        self.plant.actuator_positions(self._a_now)
        self._duty = [0.0] * n
        self._switch_ns = 0  # when the last written duty reaches the valves
        self._estop = False
        self._open = [1.0] * n  # how much of its duty each valve opens to (jam_valve)
        self._lies: dict[int, tuple[int | None, int, int]] = {}  # joint: (frozen word, stuck)
        self._board: GrayEncoderBoard | None = None
        self._quadrature: tuple[QuadratureEncoder, ...] = ()
        if machine.encoder_kind == "gray":
            self._board = GrayEncoderBoard(machine, self._a_now, seed=seed,
                                           glitch_scale=glitch_scale,
                                           scan_period_s=scan_period_s,
                                           select_to_latch_s=select_to_latch_s,
                                           start_ns=self._t_ns - round(scan_lead_s * 1e9))
        else:
            self._quadrature = tuple(QuadratureEncoder(j.encoder.gradient, a)
                                     for j, a in zip(machine.joints, self._a_now, strict=True))

    # -- Backend ---------------------------------------------------------------------------

    def open(self) -> None:
        """Bring every valve to closed (0 % duty)."""
        self._close_valves()

    def close(self) -> None:
        """Close every valve; safe to call twice."""
        self._close_valves()

    def reconnect(self) -> None:
        """A simulator has no link to lose."""

    def read(self, raw: list[int]) -> None:
        """Fill ``raw`` with the encoder words: Gray words (Unimate) or signed counts (rig).

        ``sample_ns`` is the plant's time: a new sample whenever the clock has moved since
        the last read (the encoders latched on the way), the same one when it has not (a
        lockstep clock read twice between two sleeps)."""
        self._advance()
        self.sample_ns = self._t_ns
        if self._board is not None:
            words = self._board.words
            for i in range(self._n):
                raw[i] = words[i]
        else:
            a = self._a_now
            for i, encoder in enumerate(self._quadrature):
                raw[i] = encoder.count(a[i])
        if self._lies:
            for i, (frozen, stuck_mask, stuck_value) in self._lies.items():
                raw[i] = frozen if frozen is not None else (raw[i] & ~stuck_mask) | stuck_value

    def advance(self) -> None:
        """What ``read`` does first: integrate the plant, and latch the encoders, up to the
        clock's time (the loop's warm-up steps its shadow's plant as a piece of its own)."""
        self._advance()

    def write(self, duty_pct: Sequence[float]) -> None:
        """Command signed valve duty per joint, percent; clipped to ±100 and quantised.

        A new duty reaches the valve at the start of the next PWM period. While the
        E-stop is pressed it is remembered but the valves stay closed.

        The plant is not integrated up to now first unless the last duty is due by then:
        the new one is scheduled from the plant's own time, exactly where it would apply,
        so a read and a write a few µs apart cost one plant step, not two.
        """
        now = self.clock.now_ns()
        if self._t_ns < self._switch_ns <= now or now - self._t_ns > self._step_ns:
            self._advance()  # the last duty is due by now, or the plant is far behind
        self._switch_ns = next_period_ns(now, self._period_ns)
        delay_s = (self._switch_ns - self._t_ns) * 1e-9
        resolution, duties, opened, estop = self._resolution, self._duty, self._open, self._estop
        for i, actuator in enumerate(self.plant.actuators):
            duty = quantise_duty(duty_pct[i], resolution)
            duties[i] = duty
            if not estop:
                actuator.command(opened[i] * duty, delay_s)

    @property
    def estop(self) -> bool:
        """True while the E-stop is pressed; the valves are then closed whatever is commanded."""
        return self._estop

    @property
    def fault(self) -> str:
        """Always healthy: the simulated link cannot fail."""
        return ""

    @property
    def supply_mpa(self) -> float:
        """The supply pressure now, MPa: the pump and accumulator's (``hw.sim.supply``)."""
        return self.plant.supply.pressure / 1e6

    # -- simulator inputs and probes ---------------------------------------------------------

    def press_estop(self, pressed: bool) -> None:
        """Press (True) or release the E-stop; releasing lets the last written duty through."""
        self._advance()
        self._estop = pressed
        if pressed:
            for actuator in self.plant.actuators:
                actuator.command(0.0, 0.0)
        else:
            self._switch_ns = next_period_ns(self._t_ns, self._period_ns)
            delay_s = (self._switch_ns - self._t_ns) * 1e-9
            for actuator, duty in zip(self.plant.actuators, self._duty, strict=True):
                actuator.command(duty, delay_s)

    def jam_valve(self, joint: int, shut: float) -> None:
        """Jam joint ``joint``'s valve: ``shut`` is the fraction of every duty it loses (1: it
        stays shut whatever it is sent; 0: free again)."""
        self._advance()
        self._open[joint] = 1.0 - min(max(float(shut), 0.0), 1.0)
        if not self._estop:
            self.plant.actuators[joint].command(self._open[joint] * self._duty[joint], 0.0)

    def freeze_encoder(self, joint: int, frozen: bool) -> None:
        """Freeze (True) joint ``joint``'s encoder word at its present value, as a stalled
        multiplexer or a cut cable reading a constant would; False frees it."""
        if not frozen:
            self._lies.pop(joint, None)
            return
        raw = [0] * self._n
        self.read(raw)
        self._lies[joint] = (raw[joint], 0, 0)

    def stick_bit(self, joint: int, bit: int, value: int | None) -> None:
        """Stick bit ``bit`` of joint ``joint``'s word at ``value`` (0 or 1); None frees it."""
        if value is None:
            self._lies.pop(joint, None)
        else:
            self._lies[joint] = (None, 1 << bit, (1 << bit) if value else 0)

    def joint_positions(self) -> list[float]:
        """True joint positions now, joint units (mm, degrees), couplings included."""
        self._advance()
        out = [0.0] * self._n
        self.plant.joint_positions(out)
        return out

    def joint_velocities(self) -> list[float]:
        """True joint velocities now, joint units per second."""
        self._advance()
        out = [0.0] * self._n
        self.plant.joint_velocities(out)
        return out

    def applied_duty(self) -> list[float]:
        """Duty the valves receive now, percent: quantised, this PWM period's, 0 under E-stop."""
        self._advance()
        return [a.target for a in self.plant.actuators]

    def chamber_pressures(self) -> list[tuple[float, float]]:
        """(p_a, p_b) per joint, Pa: chamber a drives towards larger readings."""
        self._advance()
        return [(a.pa, a.pb) for a in self.plant.actuators]

    def wrong_readings(self) -> list[int]:
        """Encoder words latched wrong since power-up, per joint (quadrature encoders: none)."""
        return [0] * self._n if self._board is None else list(self._board.wrong_readings)

    # -- internals ---------------------------------------------------------------------------

    def _close_valves(self) -> None:
        self._advance()
        for i, actuator in enumerate(self.plant.actuators):
            self._duty[i] = 0.0
            actuator.command(0.0, 0.0)

    def _advance(self) -> None:
        """Integrate the plant, and latch the encoders, up to the clock's time."""
        now = self.clock.now_ns()
        if now <= self._t_ns:
            return
        if now - self._t_ns > MAX_CATCH_UP_NS:
            self._t_ns = now - MAX_CATCH_UP_NS
        t0 = self._t_ns
        # whole steps of 0.5…1.5 nominal: a real-time tick a few µs over 1 ms is one step
        steps = max(1, (now - t0 + self._step_ns // 2) // self._step_ns)
        for k in range(1, steps + 1):
            self._step_to(t0 + (now - t0) * k // steps)

    def _step_to(self, t1: int) -> None:
        t0 = self._t_ns
        self._a_prev, self._a_now = self._a_now, self._a_prev
        self.plant.step((t1 - t0) * 1e-9)
        self.plant.actuator_positions(self._a_now)
        if self._board is not None:
            self._board.update(t0, t1, self._a_prev, self._a_now)
        self._t_ns = t1
