"""The control loop of the control subprocess (the thesis's ``RT.o``/``PDcontrol.o``).

Every tick, on an absolute deadline grid: ``read`` the encoders and turn them
into joint units through the glitch filter, ``poll`` the command channel,
``control`` (the mode machine and the eq. 5.1 law), ``guard`` (E-stop, limits,
following error), ``write`` the valves, ``publish`` the status and record the
move. On an overrun the loop skips to the next grid point; it never catches
up with a burst of ticks.
"""

from __future__ import annotations

import math
import select
import time
from dataclasses import dataclass
from multiprocessing.connection import Connection
from pathlib import Path

from control import shm
from control.law import DifferenceLaw, valve_duty
from control.layout import (
    HIST_BIN_NS,
    HIST_BINS,
    LINK_FIELDS,
    ControlLayout,
    Flag,
    Mode,
    MoveLayout,
)
from control.recorder import save_run
from control.runs import run_from_record
from control.seqlock import SeqlockReader, SeqlockWriter
from hw.backend import Backend
from hw.gray import gray_table, gray_to_binary
from hw.machine import Machine

MS = 1_000_000
INJECTABLE = ("press_estop",)
GRAY_TABLE_BITS = 16  # Gray encoders up to this wide decode by table lookup (64 k entries)
OUTBOX_LIMIT = 256
ESTOP_LATCHED, ESTOP_INPUT, HOMED, UI_LOST = (int(f) for f in (
    Flag.ESTOP_LATCHED, Flag.ESTOP_INPUT, Flag.HOMED, Flag.UI_LOST))
LINK_FAULT, REALTIME, MOVING, FAULT = (int(f) for f in (
    Flag.LINK_FAULT, Flag.REALTIME, Flag.MOVING, Flag.FAULT))


@dataclass(frozen=True)
class LoopConfig:
    period_ns: int
    heartbeat_timeout_ns: int = 250 * MS
    orphan_timeout_ns: int = 5_000 * MS
    glitch_margin: float = 1.5  # plausible jump = margin x max_speed x elapsed + 3 counts
    glitch_resync: int = 5  # consecutive rejections after which a reading is believed
    ferror_window_ns: int = 250 * MS
    initialise_duty: float = 20.0  # function.c Initialise(): -20 % with Max 20
    initialise_timeout_ns: int = 60_000 * MS
    data_dir: Path | None = None


@dataclass
class ActiveMove:
    """The move in progress and its segment views."""

    move_id: int
    kind: str
    meta: dict
    segment: object
    layout: MoveLayout
    cells: memoryview  # float64 view of the whole segment
    recorded: memoryview  # uint64 progress counter
    tracking: bool
    index: int = 0
    start_ns: int = 0


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
        self.hist = control_buf[self.layout.hist_offset:
                                self.layout.hist_offset + 8 * (HIST_BINS + 5)].cast("q")
        self.coefficients = {"hold": machine.hold, "track": machine.track}
        self.law = DifferenceLaw(machine, machine.hold, config.period_ns / 1e9)
        joints = machine.joints
        self.gray = machine.encoder_kind == "gray"
        self.gray_table = (gray_table(machine.encoder_bits)  # wider: decoded word by word
                           if self.gray and machine.encoder_bits <= GRAY_TABLE_BITS else [])
        self.gradient = [j.encoder.gradient for j in joints]
        self.constant = [j.encoder.constant for j in joints]
        self.coupled = [-1 if j.encoder.coupled_to is None else j.encoder.coupled_to
                        for j in joints]
        self.coupling = [j.encoder.coupling for j in joints]
        self.lower = [j.lower for j in joints]
        self.upper = [j.upper for j in joints]
        self.max_speed = [j.max_speed * 1e-9 * config.glitch_margin for j in joints]
        self.step_floor = [3 * abs(j.encoder.gradient) for j in joints]
        self.limit_margin = [2 * abs(j.encoder.gradient) for j in joints]  # two encoder counts
        self.ferror = [j.following_error for j in joints]
        self.raw = [0] * n
        self.offset = [0] * n
        self.position = [0.0] * n
        self.desired = [0.0] * n
        self.duty = [0.0] * n
        self.valve = [0.0] * n
        self.manual = [0.0] * n
        self.velocity = [0.0] * n
        self.dt = config.period_ns / 1e9
        self.hold_target = [0.0] * n
        self.glitches = [0] * n
        self.rejects = [config.glitch_resync] * n  # believe the first reading
        self.last_ok_ns = [0] * n
        self.ferror_snapshot = [math.inf] * n
        self.limit_reported = [False] * n
        self.homed = self.gray
        self.mode = Mode.HOLD
        self.move: ActiveMove | None = None
        self.estop_latched = False
        self.fault = ""
        self.ui_lost_since = 0
        self.conn_open = True
        self.running = True
        self.realtime = False
        self.tick_count = 0
        self.started_ns = self.clock.now_ns()
        self.deadline = 0
        self.late_ns = 0
        self.late_max_ns = 0
        self.late_min_ns = -1  # none yet
        self.late_sum_ns = 0
        self.late_count = 0
        self.overruns = 0
        self.compute_ns = 0
        self.compute_max_ns = 0
        self.compute_total_ns = 0
        self.io_total_ns = 0  # time inside backend.read/write, part of compute
        self.next_ferror_ns = 0
        self.init_started_ns = 0
        self.init_reference = (0.0, 0)
        self.last_rx_wall = time.monotonic_ns()
        self.outbox: list[tuple[str, dict]] = []
        self.poller = select.poll()
        self.poller.register(conn.fileno(), select.POLLIN)
        self.writable = select.poll()  # a unix socket polls writable with 3/4 of its buffer free
        self.writable.register(conn.fileno(), select.POLLOUT)

    # -- the loop ---------------------------------------------------------------

    def start(self) -> None:
        """Read the joints, hold where they are and publish, so the first status is real."""
        self.read()
        self.hold_here()
        self.publish()
        self.flush_events()

    def run(self) -> None:
        """Run until told to stop or orphaned; the valves are closed on the way out."""
        self.deadline = self.clock.now_ns() + self.config.period_ns
        while self.running:
            self.clock.sleep_until(self.deadline)
            woke = self.clock.now_ns()
            try:
                self.tick(woke)
            except Exception as exc:
                self.fail_safe(exc)
            self.next_deadline()
        self.zero_valves()
        self.publish()
        self.flush_events()

    def fail_safe(self, exc: Exception) -> None:
        """A bug in a tick closes the valves and latches the E-stop; a second one stops the loop."""
        if self.estop_latched and self.fault.startswith("controller error"):
            self.running = False
            return
        self.latch_estop(f"controller error: {type(exc).__name__}: {exc}")
        self.zero_valves()

    def tick(self, woke: int) -> None:
        self.measure_lateness(woke)
        self.read()
        self.poll()
        self.watch_heartbeat()
        self.control()
        self.guard()
        if self.move is not None:
            self.record()  # after guard: the run holds the duty the valves really get
        self.write()
        self.compute_ns = self.clock.now_ns() - woke
        self.compute_max_ns = max(self.compute_max_ns, self.compute_ns)
        self.compute_total_ns += self.compute_ns
        self.publish()
        self.flush_events()
        self.tick_count += 1

    def next_deadline(self) -> None:
        period = self.config.period_ns
        self.deadline += period
        behind = self.clock.now_ns() - self.deadline
        if behind > 0:
            missed = behind // period + 1
            self.overruns += missed
            self.deadline += missed * period

    def measure_lateness(self, woke: int) -> None:
        late = max(0, woke - self.deadline)
        self.late_ns = late
        hist = self.hist  # shared memory: each access costs, so the loop keeps its own tallies
        hist[min(late // HIST_BIN_NS, HIST_BINS)] += 1
        base = HIST_BINS + 1
        if late < self.late_min_ns or self.late_min_ns < 0:
            self.late_min_ns = hist[base] = late
        if late > self.late_max_ns:
            self.late_max_ns = hist[base + 1] = late
        self.late_sum_ns += late
        self.late_count += 1
        hist[base + 2] = self.late_sum_ns
        hist[base + 3] = self.late_count

    # -- read: encoders to joint units, with the glitch filter (section 6.2) ----

    def read(self) -> None:
        before = self.clock.now_ns()
        self.backend.read(self.raw)
        self.io_total_ns += self.clock.now_ns() - before
        now = self.backend.sample_ns  # a late serial reply re-reads old words: time them so
        raw, table, position = self.raw, self.gray_table, self.position
        size = len(table)
        for j in range(self.n):
            word = raw[j]
            if not self.gray:
                count = word - self.offset[j]
            else:  # a word wider than the encoder's is decoded too: the glitch filter judges it
                count = table[word] if 0 <= word < size else gray_to_binary(word)
            q = self.gradient[j] * count + self.constant[j]
            coupled = self.coupled[j]
            if coupled >= 0:
                q += self.coupling[j] * position[coupled]  # rtshare.h joint_dep
            self.accept(j, q, now)

    def accept(self, j: int, q: float, now: int) -> None:
        """Take a reading unless it jumps further than the joint can move since the last one."""
        bound = self.max_speed[j] * (now - self.last_ok_ns[j]) + self.step_floor[j]
        if abs(q - self.position[j]) <= bound or self.rejects[j] >= self.config.glitch_resync:
            self.position[j] = q
            self.last_ok_ns[j] = now
            self.rejects[j] = 0
        else:
            self.rejects[j] += 1
            self.glitches[j] += 1

    # -- poll: commands from the client (the FIFO analogue) ----------------------

    def poll(self) -> None:
        if not self.conn_open:
            return
        try:
            for _ in range(16):
                if not self.poller.poll(0):  # one syscall; Connection.poll builds a selector
                    return
                message = self.conn.recv()
                self.last_rx_wall = time.monotonic_ns()
                if self.ui_lost_since:
                    self.ui_lost_since = 0
                    self.event("notice", message="client is back; holding position")
                self.handle(*message)
        except (EOFError, OSError):
            self.conn_open = False
            self.last_rx_wall = 0

    def handle(self, op: str, *args: object) -> None:
        if op == "hb":
            return
        handler = getattr(self, f"cmd_{op}", None)
        if handler is None:
            self.event("notice", message=f"unknown command {op!r} ignored")
            return
        handler(*args)

    def cmd_stop(self) -> None:
        self.end_move("stopped: controller shut down")
        self.running = False

    def cmd_hold(self) -> None:
        self.end_move("aborted by operator")
        self.hold_here()

    def cmd_estop(self) -> None:
        self.latch_estop("operator E-stop")

    def cmd_reset(self) -> None:
        if self.backend.estop:
            self.event("notice", message="E-stop input still pressed: release it, then reset")
            return
        if self.backend.fault and not self.reconnect():
            return
        self.estop_latched = False
        self.fault = ""
        self.law.reset()
        self.resync()
        self.hold_here()
        self.event("estop", latched=False, reason="reset by operator")

    def resync(self) -> None:
        """Believe the next reading outright: the joints may have moved while nobody watched."""
        self.rejects = [self.config.glitch_resync] * self.n
        self.read()

    def reconnect(self) -> bool:
        """Reopen a faulted link on the operator's reset; the valves stay closed meanwhile.

        This blocks the loop while the board answers (ticks overrun and are counted);
        with the E-stop latched and the link down there is nothing else to do.
        """
        try:
            self.backend.reconnect()
        except OSError as exc:
            self.event("notice", message=f"cannot reset: reconnecting failed: {exc}")
            return False
        if self.backend.fault:
            self.event("notice", message=f"cannot reset: {self.backend.fault}")
            return False
        self.event("notice", message="link re-established")
        return True

    def cmd_manual(self, duty: list[float]) -> None:
        if self.refuse_when_stopped("manual actuation"):
            return
        if self.mode != Mode.MANUAL_ACTUATE:
            self.end_move("aborted: manual actuation")
            self.mode = Mode.MANUAL_ACTUATE
            self.limit_reported = [False] * self.n
        self.manual[:] = [max(-100.0, min(100.0, float(d))) for d in duty]

    def cmd_jog_position(self, joint: int, delta: float) -> None:
        if self.refuse_when_stopped("position jog"):
            return
        if self.mode != Mode.HOLD:
            self.end_move("aborted: position jog")
            self.hold_here()
        self.hold_target[joint] = self.clamp(joint, self.hold_target[joint] + float(delta))

    def cmd_coefficients(self, which: str) -> None:
        values = self.coefficient_readers[which].read()
        self.coefficients[which] = self.layout.coefficients.decode(values, which)
        if (which == "hold") == (self.mode == Mode.HOLD):
            self.law.set_coefficients(self.coefficients[which])

    def cmd_initialise(self) -> None:
        if self.refuse_when_stopped("initialise"):
            return
        if self.gray:
            self.event("notice", message="absolute encoders need no initialise")
            return
        self.end_move("aborted: initialise")
        self.mode = Mode.INITIALISE
        self.init_started_ns = self.clock.now_ns()
        self.init_reference = (self.position[0], self.init_started_ns)

    def cmd_move(self, move_id: int, segment: str, kind: str, tracking: bool, meta: dict) -> None:
        if self.refuse_when_stopped(f"move {move_id}", move_id):
            return
        if not tracking and not self.homed:
            self.event("move_done", move_id=move_id, status="refused: not initialised",
                       recorded=0)
            self.event("fault", kind="not_initialised", joint=-1,
                       message="the encoder is not zeroed: run Initialise first (drives the ram "
                               "to the bottom and zeroes the encoder)")
            return
        self.end_move("superseded by a new move")
        seg = shm.attach(segment)
        layout = MoveLayout.read_header(seg.buf)
        self.move = ActiveMove(
            move_id=move_id, kind=kind, meta=meta, segment=seg, layout=layout,
            cells=seg.buf.cast("d"), recorded=seg.buf[MoveLayout.RECORDED_OFFSET:
                                                      MoveLayout.RECORDED_OFFSET + 8].cast("Q"),
            tracking=tracking, start_ns=self.clock.now_ns())
        self.mode = Mode.TRACKING_ACTUATE if tracking else Mode.FOLLOW_TRACK
        self.law.set_coefficients(self.coefficients["track"])
        self.ferror_snapshot = [math.inf] * self.n
        self.limit_reported = [False] * self.n

    def cmd_inject(self, method: str, *args: object) -> None:
        """Drive a simulator-only input (``press_estop``) from a test; refused on real hardware."""
        if method not in INJECTABLE or not hasattr(self.backend, method):
            self.event("notice", message=f"{method} cannot be injected into this backend")
            return
        getattr(self.backend, method)(*args)

    def refuse_when_stopped(self, what: str, move_id: int | None = None) -> bool:
        if not self.estop_latched:
            return False
        reason = f"refused: E-stop latched ({self.fault}); reset first"
        if move_id is not None:
            self.event("move_done", move_id=move_id, status=reason, recorded=0)
        else:
            self.event("notice", message=f"{what} {reason}")
        return True

    # -- control: the mode machine (section 5.1.1) --------------------------------

    def control(self) -> None:
        mode = self.mode
        if self.estop_latched:
            self.zero_duty()
        elif mode == Mode.HOLD:
            self.closed_loop(self.hold_target)
        elif mode == Mode.FOLLOW_TRACK:
            self.follow_track()
        elif mode == Mode.MANUAL_ACTUATE:
            self.open_loop(self.manual)
        elif mode == Mode.TRACKING_ACTUATE:
            self.tracking_actuate()
        else:
            self.initialise()

    def closed_loop(self, target: list[float], velocity: list[float] | None = None) -> None:
        law = self.law
        for j in range(self.n):
            self.desired[j] = target[j]
            v = velocity[j] if velocity is not None else 0.0
            self.duty[j] = law.update(j, target[j] - self.position[j], v)

    def open_loop(self, duty: list[float]) -> None:
        for j in range(self.n):
            self.desired[j] = math.nan
            self.duty[j] = duty[j]

    def follow_track(self) -> None:
        move = self.move
        n, k, last = self.n, move.index, move.layout.samples - 1
        row = move.layout.desired_offset // 8 + k * n
        before = row - n if k > 0 else row  # central difference, one-sided at the ends
        after = row + n if k < last else row
        span = max((after - before) // n, 1) * self.dt
        for j in range(n):
            self.desired[j] = self.clamp(j, move.cells[row + j])
            self.velocity[j] = (move.cells[after + j] - move.cells[before + j]) / span
        for j in range(n):  # feed-forward drives the actuator: the Yaw reading includes Bend
            if self.coupled[j] >= 0:
                self.velocity[j] -= self.coupling[j] * self.velocity[self.coupled[j]]
        self.closed_loop(self.desired, self.velocity)

    def tracking_actuate(self) -> None:
        move = self.move
        row = move.layout.profile_offset // 8 + move.index * self.n
        for j in range(self.n):
            self.desired[j] = math.nan
            self.duty[j] = move.cells[row + j]

    def record(self) -> None:
        """Append this tick to the move's record; finish the move after its last sample."""
        move = self.move
        t = (self.clock.now_ns() - move.start_ns) / 1e9
        move.layout.row.pack_into(move.segment.buf,
                                  move.layout.record_offset + move.index * move.layout.row.size,
                                  t, *self.desired, *self.position, *self.duty)
        move.index += 1
        move.recorded[0] = move.index
        if move.index >= move.layout.samples:
            self.end_move("complete")
            if self.mode == Mode.FOLLOW_TRACK:
                self.hold_at(self.desired)
            else:
                self.hold_here()

    def initialise(self) -> None:
        """Drive the rig's ram down until it rests on the bottom stop, then zero (section 3.5)."""
        for j in range(self.n):
            self.desired[j] = math.nan
            self.duty[j] = -self.config.initialise_duty
        now = self.clock.now_ns()
        start_q, start_ns = self.init_reference
        if now - start_ns < 200 * MS:
            return
        if abs(self.position[0] - start_q) < 0.5 and now - self.init_started_ns > 500 * MS:
            for j in range(self.n):
                self.offset[j] += round((self.position[j] - self.constant[j]) / self.gradient[j])
                self.position[j] = self.constant[j]
            self.homed = True
            self.hold_here()
            self.event("move_done", move_id=0, status="complete: initialised at the bottom",
                       recorded=0)
        elif now - self.init_started_ns > self.config.initialise_timeout_ns:
            self.hold_here()
            self.event("fault", kind="initialise", joint=0,
                       message="initialise did not reach the bottom stop in time; holding")
        else:
            self.init_reference = (self.position[0], now)

    # -- guard: E-stop, limits, following error -----------------------------------

    def guard(self) -> None:
        if self.backend.estop and not self.estop_latched:
            self.latch_estop("E-stop input pressed")
        fault = self.backend.fault
        if fault and not self.estop_latched:
            self.latch_estop(f"link fault: {fault}")
        if self.estop_latched:
            return
        if self.mode in (Mode.MANUAL_ACTUATE, Mode.TRACKING_ACTUATE) and self.homed:
            self.stop_at_limits()
        elif self.mode in (Mode.HOLD, Mode.FOLLOW_TRACK) and self.homed:
            self.check_following_error()

    def stop_at_limits(self) -> None:
        for j in range(self.n):
            q, u = self.position[j], self.duty[j]
            margin = self.limit_margin[j]
            if (q >= self.upper[j] - margin and u > 0) or (q <= self.lower[j] + margin and u < 0):
                self.duty[j] = 0.0
                if not self.limit_reported[j]:
                    self.limit_reported[j] = True
                    joint = self.machine.joints[j]
                    self.event("fault", kind="limit", joint=j,
                               message=f"{joint.name} at {q:.1f}{joint.symbol} reached its limit "
                                       f"{joint.limit_text()}: motion stopped on that joint")

    def check_following_error(self) -> None:
        now = self.clock.now_ns()
        if now < self.next_ferror_ns:
            return
        self.next_ferror_ns = now + self.config.ferror_window_ns
        for j in range(self.n):
            error = abs(self.desired[j] - self.position[j])
            if error > self.ferror[j] and error > 0.9 * self.ferror_snapshot[j]:
                self.following_error(j, error)
                return
            self.ferror_snapshot[j] = error

    def following_error(self, j: int, error: float) -> None:
        """FERROR: abort a move into hold; a joint that cannot even hold gets its valves closed."""
        joint = self.machine.joints[j]
        where = (f"following error: {joint.name} is {error:.1f}{joint.symbol} from its target "
                 f"(limit {self.ferror[j]:g}{joint.symbol}) and not closing")
        if self.move is not None:
            message = f"{where}; move aborted, holding"
            self.end_move(f"fault: {message}")
            self.hold_here()
            self.event("fault", kind="following_error", joint=j, message=message)
        else:
            self.event("fault", kind="following_error", joint=j,
                       message=f"{where} while holding; valves closed: check the joint, then reset")
            self.latch_estop(f"{where} while holding")

    def latch_estop(self, reason: str) -> None:
        self.estop_latched = True
        self.fault = reason
        self.end_move(f"estop: {reason}")
        self.zero_duty()
        self.mode = Mode.HOLD
        self.event("estop", latched=True, reason=reason)

    # -- write and publish ----------------------------------------------------------

    def write(self) -> None:
        joints = self.machine.joints
        for j in range(self.n):
            self.valve[j] = 0.0 if self.estop_latched else valve_duty(joints[j], self.duty[j])
        before = self.clock.now_ns()
        self.backend.write(self.valve)
        self.io_total_ns += self.clock.now_ns() - before

    def zero_duty(self) -> None:
        for j in range(self.n):
            self.duty[j] = 0.0

    def zero_valves(self) -> None:
        self.zero_duty()
        for j in range(self.n):
            self.valve[j] = 0.0
        self.backend.write(self.valve)

    def publish(self) -> None:
        move = self.move
        flags = ((ESTOP_LATCHED if self.estop_latched else 0)  # plain ints: enum ORs cost µs
                 | (ESTOP_INPUT if self.backend.estop else 0)
                 | (HOMED if self.homed else 0)
                 | (UI_LOST if self.ui_lost_since else 0)
                 | (LINK_FAULT if self.backend.fault else 0)
                 | (REALTIME if self.realtime else 0)
                 | (MOVING if move is not None else 0)
                 | (FAULT if self.fault else 0))
        counters = self.backend.counters
        self.status_writer.write(
            self.tick_count, self.clock.now_ns() - self.started_ns, time.monotonic_ns(),
            int(self.mode), flags,
            move.move_id if move else 0, move.index if move else 0,
            move.layout.samples if move else 0,
            self.late_ns, self.late_max_ns, self.overruns, self.compute_ns, self.compute_max_ns,
            self.compute_total_ns, self.io_total_ns,
            *self.position, *self.desired, *self.duty, *self.valve, *self.raw, *self.glitches,
            *[getattr(counters, name) for name in LINK_FIELDS], self.fault.encode()[:160])

    def release(self) -> None:
        """Let go of the shared memory: end any move, drop every view into the segments."""
        self.end_move("stopped: controller shut down")
        self.flush_events()
        self.status_writer.release()
        for reader in self.coefficient_readers.values():
            reader.release()
        self.hist.release()

    # -- heartbeats: the client may vanish -------------------------------------------

    def watch_heartbeat(self) -> None:
        wall = time.monotonic_ns()
        if not self.ui_lost_since and wall - self.last_rx_wall > self.config.heartbeat_timeout_ns:
            self.ui_lost_since = wall
            self.end_move("interrupted: client silent")
            self.hold_here()
            self.event("fault", kind="ui_lost", joint=-1,
                       message="client silent for 250 ms: holding position")
        elif self.ui_lost_since and wall - self.ui_lost_since > self.config.orphan_timeout_ns:
            self.running = False

    @property
    def orphaned(self) -> bool:
        """True when the client is gone, so this process must clean up after it."""
        return not self.conn_open or bool(self.ui_lost_since)

    # -- helpers ------------------------------------------------------------------

    def clamp(self, j: int, q: float) -> float:
        """Soft limits: no desired position ever leaves the joint's range."""
        if not self.homed:
            return q
        return min(self.upper[j], max(self.lower[j], q))

    def hold_here(self) -> None:
        self.hold_at(self.position)

    def hold_at(self, target: list[float]) -> None:
        self.hold_target[:] = [self.clamp(j, target[j]) for j in range(self.n)]
        self.mode = Mode.HOLD
        self.law.set_coefficients(self.coefficients["hold"])

    def end_move(self, status: str) -> None:
        """Finish the move in progress (if any): tell the client, or save it if orphaned."""
        move = self.move
        if move is None:
            return
        self.move = None
        saved = self.save_orphaned(move, status) if self.orphaned else ""
        self.event("move_done", move_id=move.move_id, status=status, recorded=move.index,
                   saved=saved)
        move.cells.release()
        move.recorded.release()
        shm.release(move.segment, unlink=self.orphaned)

    def save_orphaned(self, move: ActiveMove, status: str) -> str:
        """Save a move whose client is gone; return where (empty if it could not be saved)."""
        if self.config.data_dir is None:
            return ""
        record = move.layout.record(move.segment.buf)[:move.index].copy()
        run = run_from_record(self.machine, move.kind, status, move.meta, record,
                              self.config.period_ns / 1e9)
        try:
            return str(save_run(run, self.config.data_dir).json)
        except OSError:
            return ""

    def event(self, name: str, **payload: object) -> None:
        """Queue an event; it is sent after this tick's status is published."""
        self.outbox.append((name, payload))

    def flush_events(self) -> None:
        """Send queued events, so a client that receives one already sees its status.

        Never blocks: a frozen client stops reading, and the loop must go on, so
        events wait while the channel is full and the oldest are dropped past
        ``OUTBOX_LIMIT``.
        """
        if not self.conn_open:
            self.outbox.clear()
            return
        while self.outbox and self.writable.poll(0):
            try:
                self.conn.send(self.outbox.pop(0))
            except (BrokenPipeError, OSError):
                self.conn_open = False
                self.outbox.clear()
                return
        del self.outbox[:-OUTBOX_LIMIT]
