"""The control loop of the control subprocess (the thesis's ``RT.o``/``PDcontrol.o``).

Every tick, on an absolute deadline grid: ``read`` the encoders into joint
units through the glitch filter, ``poll`` the command channel, ``control``
(the mode machine and the eq. 5.1 law), ``guard`` (E-stop, limits, following
error), ``write`` the valves, ``publish`` the status and record the move. On
an overrun the loop skips to the next grid point; it never catches up with a
burst of ticks. Each stage's state lives in its component: ``EncoderInput``,
``ModeMachine``, ``Guards``, ``LatencyStats``, ``Outbox``.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from multiprocessing.connection import Connection
from pathlib import Path

from control import commands as cmd
from control import shm
from control.channel import CommandChannel, command_name
from control.encoder_input import EncoderInput
from control.events import EStop, Fault, MoveDone, Notice, Refused
from control.guards import Guards, Trip
from control.heartbeat import ClientWatch
from control.latency import LatencyStats
from control.layout import HIST_BINS, ControlLayout, Flag, Mode
from control.modes import ActiveMove, InitialiseConfig, ModeMachine
from control.outbox import Outbox
from control.saver import RunSaver
from control.seqlock import SeqlockReader, SeqlockWriter
from hw.backend import Backend
from hw.machine import Machine
from hw.transmission import Transmission

MS = 1_000_000
ESTOP_LATCHED, ESTOP_INPUT, HOMED, UI_LOST, LINK_FAULT, REALTIME, MOVING, FAULT = (
    int(f) for f in Flag)  # in Flag's order; plain ints, as enum ORs cost µs


@dataclass(frozen=True)
class LoopConfig:
    period_ns: int
    heartbeat_timeout_ns: int = 250 * MS
    orphan_timeout_ns: int = 5_000 * MS
    glitch_margin: float = 1.5  # plausible jump = margin x max_speed x elapsed + 3 counts
    glitch_resync: int = 5  # consecutive rejections after which a reading is believed
    ferror_window_ns: int = 250 * MS
    initialise: InitialiseConfig = field(default_factory=InitialiseConfig)
    data_dir: Path | None = None


class Controller:
    """Owns the backend while it runs; talks to the client through ``conn`` and shared memory."""

    def __init__(self, machine: Machine, backend: Backend, conn: Connection,
                 control_buf: memoryview, config: LoopConfig) -> None:
        self.machine = machine
        self.backend = backend
        self.conn = conn
        self.config = config
        self.clock = backend.clock
        n = self.n = machine.n_joints
        self.layout = ControlLayout(n)
        self.status_writer = SeqlockWriter(control_buf, self.layout.status_offset,
                                           self.layout.status.struct)
        self.coefficient_readers = {
            which: SeqlockReader(control_buf, self.layout.coefficient_offset(which),
                                 self.layout.coefficients.struct)
            for which in ("hold", "track")}
        hist = control_buf[self.layout.hist_offset:
                           self.layout.hist_offset + 8 * (HIST_BINS + 5)].cast("q")
        self.transmission = Transmission(machine)
        self.outbox = Outbox(conn)
        self.latency = LatencyStats(hist, config.period_ns)
        self.encoders = EncoderInput(machine, self.transmission, config.glitch_margin,
                                     config.glitch_resync)
        self.guards = Guards(machine, self.outbox, config.ferror_window_ns)
        self.modes = ModeMachine(machine, self.transmission, self.encoders, self.guards,
                                 self.outbox, config.period_ns / 1e9, config.initialise)
        self.saver = RunSaver(machine, config.data_dir, config.period_ns / 1e9)
        self.valve = [0.0] * n
        self.client = ClientWatch(config.heartbeat_timeout_ns, config.orphan_timeout_ns)
        self.running = True
        self.realtime = False
        self.tick_count = 0
        self.started_ns = self.clock.now_ns()
        self.deadline = 0
        self.channel = CommandChannel(conn, self.outbox, self.client)
        self.handlers: dict[type[cmd.Command], Callable] = {
            cmd.Heartbeat: lambda _: None, cmd.Shutdown: self.on_shutdown,
            cmd.Hold: self.on_hold, cmd.EmergencyStop: self.on_estop, cmd.Reset: self.on_reset,
            cmd.Initialise: self.on_initialise, cmd.Manual: self.on_manual,
            cmd.JogPosition: self.on_jog_position, cmd.SetCoefficients: self.on_coefficients,
            cmd.StartMove: self.on_move, cmd.Inject: self.on_inject,
        }

    # -- the loop ---------------------------------------------------------------

    def start(self) -> None:
        """Read the joints, hold where they are and publish, so the first status is real."""
        self.encoders.read(self.backend)
        self.modes.hold_here()
        self.publish()
        self.outbox.flush()

    def run(self) -> None:
        """Run until told to stop or orphaned; the valves are closed on the way out."""
        clock, latency = self.clock, self.latency
        self.deadline = clock.now_ns() + self.config.period_ns
        while self.running:
            clock.sleep_until(self.deadline)
            woke = clock.now_ns()
            try:
                self.tick(woke)
            except Exception as exc:
                self.fail_safe(exc)
            self.deadline = latency.next_deadline(self.deadline, clock.now_ns())
        self.zero_valves()
        self.publish()
        self.outbox.flush()

    def fail_safe(self, exc: Exception) -> None:
        """A bug in a tick closes the valves and latches the E-stop; a second one stops the loop."""
        if self.guards.latched and self.guards.reason.startswith("controller error"):
            self.running = False
            return
        self.latch_estop(f"controller error: {type(exc).__name__}: {exc}")
        self.zero_valves()

    def tick(self, woke: int) -> None:
        self.latency.woke(woke - self.deadline)
        self.read()
        self.poll()
        self.watch_heartbeat()
        self.modes.control(self.guards.latched, woke)
        self.guard(woke)
        if self.modes.move is not None and self.modes.record(self.clock.now_ns()):
            self.finish_move()
        self.write()
        self.latency.computed(self.clock.now_ns() - woke)
        self.publish()
        self.outbox.flush()
        self.tick_count += 1

    def read(self) -> None:
        before = self.clock.now_ns()
        self.encoders.read(self.backend)
        self.latency.io_total_ns += self.clock.now_ns() - before

    # -- poll: typed commands from the client (the FIFO analogue) -----------------

    def poll(self) -> None:
        for command in self.channel.receive():
            self.handle(command)

    def handle(self, command: object) -> None:
        """Check what arrived and carry it out by its type; what fails is refused, never
        raised, and latches nothing."""
        handler = self.handlers.get(type(command))
        if handler is None:
            self.outbox.put(Refused(command_name(command), "not a command this controller knows"))
            return
        try:
            command.check(self.n)
            handler(command)
        except Exception as exc:  # a record that bypassed its builder, or a value that broke
            self.outbox.put(Refused(command_name(command), f"{type(exc).__name__}: {exc}"))
            if isinstance(command, cmd.StartMove):
                self.outbox.put(MoveDone(command.move_id, f"refused: {exc}", 0))

    def refuse_when_stopped(self, command: cmd.Command) -> bool:
        if not self.guards.latched:
            return False
        reason = f"E-stop latched ({self.guards.reason}); reset first"
        if isinstance(command, cmd.StartMove):
            self.outbox.put(MoveDone(command.move_id, f"refused: {reason}", 0))
        else:
            self.outbox.put(Refused(command.NAME, reason))
        return True

    def on_shutdown(self, _: cmd.Shutdown) -> None:
        self.end_move("stopped: controller shut down")
        self.running = False

    def on_hold(self, _: cmd.Hold) -> None:
        self.end_move("aborted by operator")
        self.modes.hold_here()

    def on_estop(self, _: cmd.EmergencyStop) -> None:
        self.latch_estop("operator E-stop")

    def on_reset(self, command: cmd.Reset) -> None:
        if self.backend.estop:
            self.outbox.put(Refused(command.NAME,
                                    "E-stop input still pressed: release it, then reset"))
            return
        if self.backend.fault and not self.reconnect():
            return
        self.guards.release()
        self.modes.law.reset()
        self.encoders.resync(self.backend)
        self.modes.hold_here()
        self.outbox.put(EStop(False, "reset by operator"))

    def reconnect(self) -> bool:
        """Reopen a faulted link on the operator's reset, valves closed. This blocks while the
        board answers (ticks overrun, counted): latched, with no link, there is nothing to do."""
        try:
            self.backend.reconnect()
        except OSError as exc:
            self.outbox.put(Refused("reset", f"reconnecting failed: {exc}"))
            return False
        if self.backend.fault:
            self.outbox.put(Refused("reset", self.backend.fault))
            return False
        self.outbox.put(Notice("link re-established"))
        return True

    def on_manual(self, command: cmd.Manual) -> None:
        if self.refuse_when_stopped(command):
            return
        if self.modes.mode != Mode.MANUAL_ACTUATE:
            self.end_move("aborted: manual actuation")
            self.modes.start_manual()
            self.guards.rearm()
        self.modes.manual[:] = command.duty

    def on_jog_position(self, command: cmd.JogPosition) -> None:
        if self.refuse_when_stopped(command):
            return
        modes = self.modes
        if modes.mode != Mode.HOLD:
            self.end_move("aborted: position jog")
            modes.hold_here()
        j = command.joint
        modes.hold_target[j] = self.guards.clamp(j, modes.hold_target[j] + command.delta,
                                                 self.encoders.homed)

    def on_coefficients(self, command: cmd.SetCoefficients) -> None:
        values = self.coefficient_readers[command.which].read()
        coefficients = self.layout.coefficients.decode(values, command.which)
        cmd.check_coefficients(coefficients, self.n)
        self.modes.set_coefficients(command.which, coefficients)

    def on_initialise(self, command: cmd.Initialise) -> None:
        if self.refuse_when_stopped(command):
            return
        if self.machine.encoder_kind == "gray":
            self.outbox.put(Refused(command.NAME, "absolute encoders need no initialise"))
            return
        self.end_move("aborted: initialise")
        self.modes.start_initialise(self.clock.now_ns())

    def on_move(self, command: cmd.StartMove) -> None:
        if self.refuse_when_stopped(command):
            return
        if not command.tracking and not self.encoders.homed:
            self.outbox.put(MoveDone(command.move_id, "refused: not initialised", 0))
            self.outbox.put(Fault("not_initialised", -1,
                             "the encoder is not zeroed: run Initialise first (drives the ram to "
                             "the bottom and zeroes the encoder)"))
            return
        self.end_move("superseded by a new move")
        self.modes.start_move(ActiveMove.attach(command, self.clock.now_ns()))
        self.guards.rearm()

    def on_inject(self, command: cmd.Inject) -> None:
        """Drive a simulator-only input (``press_estop``) from a test; refused on real hardware."""
        inject = getattr(self.backend, command.method, None)
        if inject is None:
            self.outbox.put(Refused(command.NAME, f"{command.method} cannot be injected into this "
                                             "backend"))
            return
        inject(*command.args)

    # -- guard: E-stop, limits, following error -----------------------------------

    def guard(self, now: int) -> None:
        backend, guards, modes = self.backend, self.guards, self.modes
        if backend.estop and not guards.latched:
            self.latch_estop("E-stop input pressed")
        if backend.fault and not guards.latched:
            self.latch_estop(f"link fault: {backend.fault}")
        if guards.latched or not self.encoders.homed:
            return
        mode = modes.mode
        if mode == Mode.MANUAL_ACTUATE or mode == Mode.TRACKING_ACTUATE:
            guards.stop_at_limits(modes.position, modes.duty)
        elif mode == Mode.HOLD or mode == Mode.FOLLOW_TRACK:
            trip = guards.following_error(modes.desired, modes.position, now)
            if trip is not None:
                self.following_error(trip)

    def following_error(self, trip: Trip) -> None:
        """FERROR: abort a move into hold; a joint that cannot even hold gets its valves closed."""
        if self.modes.move is not None:
            message = f"{trip.message}; move aborted, holding"
            self.end_move(f"fault: {message}")
            self.modes.hold_here()
            self.outbox.put(Fault("following_error", trip.joint, message))
        else:
            self.outbox.put(Fault("following_error", trip.joint,
                             f"{trip.message} while holding; valves closed: check the joint, "
                             "then reset"))
            self.latch_estop(f"{trip.message} while holding")

    def latch_estop(self, reason: str) -> None:
        self.guards.latch(reason)
        self.end_move(f"estop: {reason}")
        self.modes.zero_duty()
        self.modes.mode = Mode.HOLD
        self.outbox.put(EStop(True, reason))

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
        modes, guards, backend, latency = self.modes, self.guards, self.backend, self.latency
        move = modes.move
        flags = ((ESTOP_LATCHED if guards.latched else 0)
                 | (ESTOP_INPUT if backend.estop else 0)
                 | (HOMED if self.encoders.homed else 0)
                 | (UI_LOST if self.client.lost_since else 0)
                 | (LINK_FAULT if backend.fault else 0)
                 | (REALTIME if self.realtime else 0)
                 | (MOVING if move is not None else 0)
                 | (FAULT if guards.reason else 0))
        self.status_writer.write(*self.layout.status.encode(
            self.tick_count, self.clock.now_ns() - self.started_ns, time.monotonic_ns(),
            modes.mode, flags, move.move_id if move else 0, move.index if move else 0,
            move.layout.samples if move else 0, latency, modes.position, modes.desired,
            modes.duty, self.valve, self.encoders.raw, self.encoders.glitches,
            backend.counters, guards.reason))

    def release(self) -> None:
        """Let go of the shared memory: end any move, drop every view into the segments."""
        self.end_move("stopped: controller shut down")
        self.outbox.flush()
        self.status_writer.release()
        for reader in self.coefficient_readers.values():
            reader.release()
        self.latency.hist.release()

    # -- heartbeats: the client may vanish -------------------------------------------

    def watch_heartbeat(self) -> None:
        lost, orphaned = self.client.check()
        if lost:
            self.end_move("interrupted: client silent")
            self.modes.hold_here()
            self.outbox.put(Fault("ui_lost", -1, "client silent for 250 ms: holding position"))
        elif orphaned:
            self.running = False

    @property
    def orphaned(self) -> bool:
        """True when the client is gone, so this process must clean up after it."""
        return not self.outbox.open or bool(self.client.lost_since)

    # -- moves ending ---------------------------------------------------------------

    def finish_move(self) -> None:
        """The last sample is recorded: hold at the path's end (or where an open-loop move left
        the joints)."""
        following = self.modes.mode == Mode.FOLLOW_TRACK
        self.end_move("complete")
        if following:
            self.modes.hold_at(self.modes.desired)
        else:
            self.modes.hold_here()

    def end_move(self, status: str) -> None:
        """Finish the move in progress (if any): tell the client, or save it if orphaned."""
        move = self.modes.move
        if move is None:
            return
        self.modes.move = None
        saved = self.saver.save(move, status) if self.orphaned else ""
        self.outbox.put(MoveDone(move.move_id, status, move.index, saved))
        move.cells.release()
        move.recorded.release()
        shm.release(move.segment, unlink=self.orphaned)
