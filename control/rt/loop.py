"""The control loop of the control subprocess (the thesis's ``RT.o``/``PDcontrol.o``).

Every tick, on an absolute deadline grid: ``read`` the encoders into joint
units through the glitch filter, ``poll`` the client (its E-stop and heartbeat
words, then the command channel), ``control`` (the mode machine and the eq. 5.1
law), ``guard`` (E-stop, feedback, limits, the supervisor), record the move,
``write`` the valves, ``publish`` the status. On an overrun the loop skips to
the next grid point; it never catches up with a burst of ticks, and it never
blocks: no file I/O (a run whose client is gone is kept, and handed over to a saver
after the loop, ``RunSaver``),
events wait in the ``Outbox``. In the last part of each period a shadow controller ticks,
a piece at a time while the next piece fits before the deadline (``WarmUp``,
control/rt/warmup.py), so the live tick runs on warm code. Each stage's state lives in its
component:
``EncoderInput``, ``ClientWatch``, ``ModeMachine``, ``Guards``, ``Supervisor``,
``LatencyStats``, ``Outbox``.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from control.rt import commands as cmd
from control.rt.channel import CommandChannel
from control.rt.encoder_input import EncoderInput
from control.rt.events import EStop, Fault, MoveDone, Notice, Refused
from control.rt.guards import Guards
from control.rt.heartbeat import ClientWatch
from control.rt.latency import LatencyStats
from control.rt.layout import HIST_BINS, ControlLayout, Mode
from control.rt.modes import ActiveMove, InitialiseConfig, ModeMachine
from control.rt.outbox import Outbox
from control.rt.publisher import Publisher
from control.rt.saver import RunSaver, release
from control.rt.sealed import open_sealed
from control.rt.seqlock import SeqlockReader
from control.rt.supervisor import Supervisor
from control.rt.wire import Wire
from hw.backend import Backend, StepClock
from hw.machine import Machine
from hw.transmission import Transmission

if TYPE_CHECKING:
    from control.rt.warmup import WarmUp

MS = 1_000_000
SETTLE_NS = 2_000 * MS  # after motion, a lockstep clock steps this long before pacing (idle)
OPEN_LOOP_REDUCED = ("reduced speed (T1): open-loop duty cannot be held to 250 mm/s; jog in "
                     "position or velocity, or switch to automatic (full speed) first")
NOT_HOMED = ("not initialised: the encoder is not zeroed: run Initialise first (drives the ram "
             "to the bottom and zeroes the encoder)")


@dataclass(frozen=True)
class LoopConfig:
    period_ns: int
    heartbeat_timeout_ns: int = 250 * MS
    orphan_timeout_ns: int = 5_000 * MS
    # plausible jump = margin x full_duty_speed x elapsed + 3 counts (control/rt/encoder_input.py)
    glitch_margin: float = 1.5
    initialise: InitialiseConfig = field(default_factory=InitialiseConfig)
    slots: int = 1  # ticks per sample: the thesis's timing (control/timing.py) serves n
    slips: frozenset[str] = frozenset()  # the listing's slips to run (control.rt.law.SLIPS)


class Controller:
    """Owns the backend while it runs; talks to the client through ``wire`` and shared memory."""

    def __init__(self, machine: Machine, backend: Backend, wire: Wire,
                 control_buf: memoryview, config: LoopConfig) -> None:
        self.machine = machine
        self.backend = backend
        self.wire = wire
        self.config = config
        self.clock = backend.clock
        n = self.n = machine.n_joints
        self.layout = ControlLayout(n)
        self.coefficient_readers = {
            which: SeqlockReader(control_buf, self.layout.coefficient_offset(which),
                                 self.layout.coefficients.struct)
            for which in ("hold", "track")}
        hist = control_buf[self.layout.hist_offset:
                           self.layout.hist_offset + 8 * (HIST_BINS + 5)].cast("q")
        self.transmission = Transmission(machine)
        self.outbox = Outbox(wire)
        self.latency = LatencyStats(hist, config.period_ns, machine.supervision.overrun_fraction)
        self.encoders = EncoderInput(machine, self.transmission, config.glitch_margin)
        self.guards = Guards(machine, self.outbox)
        self.supervisor = Supervisor(machine, config.period_ns)
        self.modes = ModeMachine(machine, self.transmission, self.encoders, self.guards,
                                 self.outbox, config.period_ns * config.slots / 1e9,
                                 config.initialise, slots=config.slots, slips=config.slips)
        self.saver = RunSaver()
        self.settle_band = [j.tolerance for j in machine.joints]
        self.moved_ns = 0  # when the robot was last in motion (``idle``)
        self.valve = [0.0] * n
        self.client = ClientWatch(self.layout.client_words(control_buf),
                                  config.heartbeat_timeout_ns, config.orphan_timeout_ns)
        self.running = True
        self.realtime = False
        self.tick_count = 0
        self.publisher = Publisher(control_buf, self.layout, self.clock.now_ns())
        self.deadline = 0
        self.warm_up: WarmUp | None = None  # a shadow ticked before each deadline (warmup.py)
        # the timed part of a tick, stage by stage, each given the tick's wake-up (``compute``);
        # a shadow runs them one at a time
        self.stages: tuple[Callable[[int], None], ...] = (
            self.begin, self.read, self.poll, self.watch, self.control, self.guard, self.finish)
        self.channel = CommandChannel(wire, self.outbox, self.client, n, {
            cmd.Shutdown: self.on_shutdown,
            cmd.Hold: self.on_hold, cmd.EmergencyStop: self.on_estop, cmd.Reset: self.on_reset,
            cmd.Initialise: self.on_initialise, cmd.Manual: self.on_manual,
            cmd.JogPosition: self.on_jog_position, cmd.JogVelocity: self.on_jog_velocity,
            cmd.SetCoefficients: self.on_coefficients,
            cmd.StartMove: self.on_move, cmd.Inject: self.on_inject,
            cmd.FeedOverride: self.on_feed, cmd.Pause: self.on_feed, cmd.Resume: self.on_feed,
            cmd.SetSpeedMode: self.on_speed_mode,
        })

    # -- the loop ---------------------------------------------------------------

    def start(self) -> None:
        """Read the joints, hold where they are and publish, so the first status is real."""
        self.encoders.resync(self.backend, self.config.period_ns)
        self.modes.hold_here()
        self.publish()
        self.outbox.flush()

    def run(self) -> None:
        """Run until told to stop or orphaned; the valves are closed on the way out."""
        self.deadline = self.clock.now_ns() + self.config.period_ns
        while self.running:
            self.cycle()
        self.zero_valves()
        self.publish()
        self.outbox.flush()

    def cycle(self) -> None:
        """Wait for the deadline (ticking the shadow, if any, in the window before it), tick,
        and set the next deadline."""
        clock = self.clock
        if isinstance(clock, StepClock):
            clock.idle = self.idle(clock.now_ns())
        if self.warm_up is not None:
            self.warm_before(self.warm_up)
        clock.sleep_until(self.deadline)
        woke = clock.now_ns()
        try:
            self.tick(woke)
        except Exception as exc:
            self.fail_safe(exc)
        self.deadline = self.latency.next_deadline(self.deadline, clock.now_ns())

    def warm_before(self, warm_up: WarmUp) -> None:
        """Tick the shadow in the window before the deadline; one that failed is dropped."""
        warm_up.before(self.deadline)
        if warm_up.error:
            self.warm_up = None
            self.outbox.put(Notice(f"warm-up tick off (the live loop is unaffected): "
                                   f"{warm_up.error}"))

    def in_motion(self) -> bool:
        """Something for the next tick to step: a move, an initialise, a position jog
        travelling, manual duty, or a joint outside its settle band (``tolerance``) of the
        hold target; nothing while the E-stop is latched (every valve closed)."""
        modes = self.modes
        if modes.move is not None:
            return True
        if self.guards.latched:
            return False
        if modes.mode == Mode.HOLD:
            return modes.jog.moving or any(
                abs(t - q) > band for t, q, band in
                zip(modes.hold_target, modes.position, self.settle_band, strict=True))
        return modes.mode != Mode.MANUAL_ACTUATE or any(modes.manual)

    def idle(self, now: int) -> bool:
        """Nothing stepped for ``SETTLE_NS``: a lockstep clock then paces at real time rather
        than spinning (``hw.backend.StepClock``); until then the arm settles as fast as the
        loop computes, as a move does."""
        if self.in_motion():
            self.moved_ns = now
        return now - self.moved_ns > SETTLE_NS

    def fail_safe(self, exc: Exception) -> None:
        """A bug in a tick closes the valves and latches the E-stop; a second one stops the loop."""
        if self.guards.latched and self.guards.reason.startswith("controller error"):
            self.running = False
            return
        self.latch_estop(f"controller error: {type(exc).__name__}: {exc}")
        self.zero_valves()

    def tick(self, woke: int) -> None:
        self.compute(woke)
        self.publish()
        self.outbox.flush()
        self.tick_count += 1

    def compute(self, woke: int) -> None:
        """The tick up to the valves written, the part it times (``LatencyStats.computed``)."""
        for stage in self.stages:
            stage(woke)

    def begin(self, woke: int) -> None:
        self.latency.woke(woke - self.deadline)
        self.modes.begin_tick(self.tick_count)

    def control(self, woke: int) -> None:
        self.modes.control(self.guards.latched, woke)

    def finish(self, woke: int) -> None:
        """Record the move's sample, write the valves, and time the tick."""
        if self.modes.move is not None and self.modes.sample_end:
            self.record(self.clock.now_ns())
        self.write()
        self.latency.computed(self.clock.now_ns() - woke)

    def read(self, _woke: int = 0) -> None:
        before = self.clock.now_ns()
        self.encoders.read(self.backend, self.modes.serviced)
        self.latency.io_total_ns += self.clock.now_ns() - before

    # -- poll: the client's E-stop word, then its commands (the FIFO analogue) -----

    def poll(self, _woke: int = 0) -> None:
        if self.client.estop_pressed() and not self.guards.latched:
            self.latch_estop("operator E-stop")
        self.channel.poll()

    def refused(self, command: cmd.Command, closed_loop: bool = False) -> bool:
        """Refuse ``command`` while the E-stop is latched, or a closed-loop one before the
        rig's encoder is zeroed (it would steer by unknown counts); True if refused."""
        if self.guards.latched:
            reason = f"E-stop latched ({self.guards.reason}); reset first"
        elif closed_loop and not self.encoders.homed:
            reason = NOT_HOMED
        else:
            return False
        if isinstance(command, cmd.StartMove):
            self.outbox.put(MoveDone(command.move_id, f"refused: {reason}", 0))
        else:
            self.outbox.put(Refused(command.NAME, reason))
        return True

    def on_shutdown(self, _: cmd.Shutdown) -> None:
        self.end_move("stopped: controller shut down")
        self.running = False

    def on_hold(self, command: cmd.Hold) -> None:
        self.end_move(command.reason or "aborted by operator")
        self.hold_here()

    def on_estop(self, _: cmd.EmergencyStop) -> None:
        self.latch_estop("operator E-stop")

    def on_reset(self, command: cmd.Reset) -> None:
        if not self.guards.latched:  # its hold would stop a move and leave it running
            self.outbox.put(Refused(command.NAME, "no E-stop is latched: nothing to release"))
            return
        if self.backend.estop:
            self.outbox.put(Refused(command.NAME,
                                    "E-stop input still pressed: release it, then reset"))
            return
        if self.backend.fault:
            try:  # blocks while the board answers: latched, with no link, nothing else to do
                self.backend.reconnect()
            except OSError as exc:
                self.outbox.put(Refused(command.NAME, f"reconnecting failed: {exc}"))
                return
            self.outbox.put(Notice("link re-established"))
        self.guards.release()
        self.modes.law.reset()
        self.encoders.resync(self.backend, self.config.period_ns)
        self.hold_here()
        self.outbox.put(EStop(False, "reset by operator"))

    def on_manual(self, command: cmd.Manual) -> None:
        if self.refused(command):
            return
        if self.modes.reduced and any(command.duty):
            self.outbox.put(Refused(command.NAME, OPEN_LOOP_REDUCED))
            return
        if self.modes.mode != Mode.MANUAL_ACTUATE:
            self.end_move("aborted: manual actuation")
            self.modes.start_manual()
            self.rearm()
        if not self.modes.set_manual(command.duty):
            self.outbox.put(Notice(f"manual duty limited to ±{self.config.initialise.duty:g} % "
                                   "until the encoder is zeroed: run Initialise"))

    def on_jog_position(self, command: cmd.JogPosition) -> None:
        if self.refused(command, closed_loop=True):
            return
        modes = self.modes
        self.end_move("aborted: position jog")  # a settling move too: its goal would move
        if modes.mode != Mode.HOLD:
            self.hold_here()
        modes.jog_by(command.joint, command.delta)

    def on_jog_velocity(self, command: cmd.JogVelocity) -> None:
        """Streamed jog (``control/rt/jog.py``): refused while a move follows its path (a
        settling one ends, as for a position jog); all zeros with no stream asks nothing."""
        modes = self.modes
        if not any(command.velocity) and not any(modes.jog.streamed):
            return
        if modes.move is not None and not modes.settling:
            self.outbox.put(Refused(command.NAME, "a move is running: hold it (or wait for it "
                                                  "to end) first"))
            return
        if self.refused(command, closed_loop=True):
            return
        self.end_move("aborted: velocity jog")
        if modes.mode != Mode.HOLD:
            self.hold_here()
        modes.jog.stream(command.velocity)

    def on_coefficients(self, command: cmd.SetCoefficients) -> None:
        values = self.coefficient_readers[command.which].read()
        coefficients = self.layout.coefficients.decode(values, command.which)
        cmd.check_coefficients(coefficients, self.n)
        self.modes.set_coefficients(command.which, coefficients)

    def on_initialise(self, command: cmd.Initialise) -> None:
        if self.refused(command):
            return
        if self.machine.encoder_kind == "gray":
            self.outbox.put(Refused(command.NAME, "absolute encoders need no initialise"))
            return
        self.end_move("aborted: initialise")
        self.modes.start_initialise(self.clock.now_ns())

    def on_move(self, command: cmd.StartMove, path_fd: int) -> None:
        """Follow the path sealed in ``path_fd`` (``control/rt/sealed.py``), recording into the
        move segment: a path that is not sealed is refused, so nobody can change it once sent."""
        if self.refused(command, closed_loop=not command.tracking):
            return
        if command.tracking and self.modes.reduced:
            self.outbox.put(MoveDone(command.move_id, f"refused: {OPEN_LOOP_REDUCED}", 0))
            return
        move = ActiveMove.attach(command, open_sealed(path_fd, 8 * command.samples * self.n),
                                 self.clock.now_ns())
        self.end_move("superseded by a new move")
        self.modes.start_move(move)
        self.rearm()

    def on_feed(self, command: cmd.FeedOverride | cmd.Pause | cmd.Resume) -> None:
        self.modes.feed_command(command, self.clock.now_ns())

    def on_speed_mode(self, command: cmd.SetSpeedMode) -> None:
        """Reduced speed (T1) or automatic: to reduced at once (a path slows to its cap along
        the path, a jog at the joints' acceleration; open-loop duty, which cannot be held to
        it, ends in a hold); to automatic only at rest, so no motion speeds up unasked."""
        modes, reduced = self.modes, command.mode == "reduced"
        if reduced == modes.reduced:
            return
        if not reduced and self.moving_by_command():
            self.outbox.put(Refused(command.NAME, "automatic (full speed) is set only at rest: "
                                                  "hold, or wait for the motion to end, first"))
            return
        if reduced and (modes.mode == Mode.MANUAL_ACTUATE
                        or (modes.move is not None and modes.move.tracking)):
            self.end_move("aborted: reduced speed set")
            self.hold_here()
        modes.set_reduced(reduced, self.clock.now_ns())
        self.outbox.put(Notice("speed: reduced (T1): the tool at most 250 mm/s, each joint at "
                               "most its jog speed" if reduced else
                               "speed: automatic (full speed)"))

    def moving_by_command(self) -> bool:
        """A move (or its settle), a jog travelling, manual duty or an initialise running."""
        modes = self.modes
        return (modes.move is not None or modes.jog.moving or modes.mode == Mode.INITIALISE
                or (modes.mode == Mode.MANUAL_ACTUATE and any(modes.manual)))

    def on_inject(self, command: cmd.Inject) -> None:
        """Drive a simulator-only input (``press_estop``) from a test; refused on real hardware."""
        inject = getattr(self.backend, command.method, None)
        if inject is None:
            self.outbox.put(Refused(command.NAME, f"{command.method} needs the simulator"))
            return
        inject(*command.args)

    # -- guard: E-stop, feedback, limits, the supervisor ----------------------------

    def guard(self, now: int) -> None:
        backend, guards, modes, encoders = self.backend, self.guards, self.modes, self.encoders
        if guards.latched:
            return
        if backend.estop:
            self.latch_estop("E-stop input pressed")
        elif backend.fault:
            self.latch_estop(f"link fault: {backend.fault}")
        elif encoders.fault:
            self.feedback_fault(encoders.fault_joint, encoders.fault)
        elif modes.fault:
            self.abort(Fault("path_row", modes.fault_joint, f"{modes.fault}; move aborted"))
            modes.fault = ""
        elif encoders.homed and modes.mode != Mode.INITIALISE:
            closed = modes.mode == Mode.HOLD or modes.mode == Mode.FOLLOW_TRACK
            guards.stop_at_limits(encoders.position, modes.duty, closed)
            trip = self.supervisor.sample(now, encoders.actuator, encoders.position,
                                          modes.desired, modes.velocity, modes.duty, closed)
            if trip is None:
                return
            if trip.feedback:
                self.feedback_fault(trip.joint, trip.message)
            elif modes.move is not None or modes.mode != Mode.HOLD:
                self.abort(Fault("following_error", trip.joint, trip.message + "; holding"))
            else:
                self.outbox.put(Fault("following_error", trip.joint,
                                      f"{trip.message} while holding; valves closed: check "
                                      "the joint, then reset"))
                self.latch_estop(f"{trip.message} while holding")

    def feedback_fault(self, joint: int, message: str) -> None:
        """Feedback that cannot be believed: every valve closed, the E-stop latched."""
        self.outbox.put(Fault("feedback", joint, f"{message}; valves closed: check it, then "
                                                 "reset"))
        self.latch_estop(message)

    def abort(self, fault: Fault, commanded: bool = False) -> None:
        """End the move (if any) and hold where the joints are, or (``commanded``: a stall,
        not the arm, is to blame) where they were last commanded; tell the client why."""
        self.end_move(f"fault: {fault.message}")
        if commanded:
            self.modes.hold_commanded()
            self.rearm()
        else:
            self.hold_here()
        self.outbox.put(fault)

    def latch_estop(self, reason: str) -> None:
        self.guards.latch(reason)
        self.end_move(f"estop: {reason}")
        self.modes.zero_duty()
        self.modes.mode = Mode.HOLD
        self.outbox.put(EStop(True, reason))

    def hold_here(self) -> None:
        self.modes.hold_here()
        self.rearm()

    def rearm(self) -> None:
        self.guards.rearm()
        self.supervisor.rearm()

    # -- write and publish ----------------------------------------------------------

    def write(self) -> None:
        if self.guards.latched:
            self.modes.zero_duty()
        self.transmission.valve_duties(self.modes.duty, self.valve)
        before = self.clock.now_ns()
        self.backend.write(self.valve)
        self.latency.io_total_ns += self.clock.now_ns() - before

    def zero_valves(self) -> None:
        self.modes.zero_duty()
        for j in range(self.n):
            self.valve[j] = 0.0
        self.backend.write(self.valve)

    def publish(self) -> None:
        self.publisher.publish(self.tick_count, self.clock.now_ns(), self.modes, self.guards,
                               self.encoders, self.backend, self.latency, self.valve,
                               bool(self.client.lost_since), self.realtime)

    def release(self) -> list[str]:
        """After the loop: end any move, hand over the runs the client left behind (each
        segment says how its move ended, and its timeline), drop every view into the
        segments; the segments handed over, for a saver to save (``control/rt/saver.py``)."""
        self.end_move("stopped: controller shut down")
        handed = self.saver.hand_over()
        self.outbox.flush()
        self.client.release()
        self.publisher.release()
        for reader in self.coefficient_readers.values():
            reader.release()
        self.latency.hist.release()
        return handed

    # -- watch: the client may vanish, the machine may be overloaded --------------------

    def watch(self, now: int) -> None:
        lost, back, orphaned = self.client.check()
        if lost:  # the stall holds (here and below) keep the target: docs/supervisor.md
            self.end_move("interrupted: client silent")
            self.modes.hold_commanded()
            self.rearm()
            self.outbox.put(Fault("ui_lost", -1, "client silent for 250 ms: holding position"))
        elif back:
            self.saver.drop()
            self.outbox.put(Notice("client is back; holding position"))
        elif orphaned:
            self.running = False
        if self.modes.held_too_long(now):
            self.abort(Fault("feed_hold", -1, self.modes.held_too_long_text), commanded=True)
        if overloaded := self.latency.overloaded(now):
            self.abort(Fault("overrun", -1, f"overrun: {overloaded:.0%} of the last second's "
                             "ticks were late (a flooded link or a starved CPU); holding the "
                             "commanded position"), commanded=True)

    @property
    def orphaned(self) -> bool:
        """True when the client is gone, so this process must clean up after it."""
        return not self.outbox.open or bool(self.client.lost_since)

    # -- moves ending ---------------------------------------------------------------

    def record(self, now: int) -> None:
        """A sample of the move into its record; after the path's last row a closed-loop move
        settles (``control/rt/settle.py``): it stays the move, holding the path's end, until
        in position (``complete``) or out of ``goal_time`` (``unsettled: …``, still holding)."""
        modes = self.modes
        move = modes.move
        if modes.record(now, self.backend.supply_mpa):
            if modes.mode == Mode.FOLLOW_TRACK:
                modes.start_settle(now)
                self.rearm()
            else:  # open loop: no goal, it holds where the duty left it
                self.end_move("complete")
                self.hold_here()
        elif move.settle is not None and (verdict := move.settle.sample(now, modes.position)):
            self.end_move(verdict)

    def end_move(self, status: str) -> None:
        """Finish the move (if any), tell the client; if it is gone, keep it for the saver."""
        move = self.modes.move
        if move is None:
            return
        self.modes.move = None
        if move.gaps:
            total = sum(length for _, length in move.gaps)
            status += f", with a {total:.1f} s controller stall"
        move.layout.write_status(move.segment.buf, status)  # for whoever saves the run
        self.modes.feed.end_move((self.clock.now_ns() - move.start_ns) / 1e9)
        self.outbox.put(MoveDone(move.move_id, status, move.index, **move.timeline()))
        if self.orphaned:
            self.saver.keep(move)
        else:
            release(move, unlink=False)
