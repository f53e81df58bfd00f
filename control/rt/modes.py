"""The mode machine (section 5.1.1): hold, follow_track, manual_actuate, tracking_actuate, and
the rig's initialise (section 3.4.1), each turning positions into controller output.

Inputs: the encoder input's believed positions, the active move's sealed path, the
operator's manual duty and hold target. Outputs: ``desired`` (nan when open
loop) and ``duty`` per joint, each tick's row in the move's record, and
``fault`` when a row of the path cannot be trusted.

Nothing read from a move's path is trusted (sealed, it is what the commanding client sent,
and that client may be wrong): a desired row must be finite,
inside the limits and, for a smooth kind, no farther from the previous one
than the joint can move in a tick (step kinds jump, as the thesis's did); a
duty row must be finite and within ±100 %. Until the rig's encoder is zeroed
open-loop duty is limited to the initialise duty (section 3.5). In reduced speed
(``control/rt/speed_cap.py``) a path advances no faster than the reduced limits allow
(``feed.py``) and a jog no faster either (``jog.py``).
"""

from __future__ import annotations

import math
import mmap
from collections.abc import Sequence
from dataclasses import dataclass, field

from control.rt import shm
from control.rt.commands import STEP_KINDS, FeedOverride, Pause, Resume, StartMove
from control.rt.encoder_input import EncoderInput
from control.rt.events import Fault, Initialised, Notice, Refused
from control.rt.feed import FeedRate
from control.rt.guards import Guards
from control.rt.jog import PositionJog
from control.rt.law import DifferenceLaw, start_sets
from control.rt.layout import Mode, MoveLayout
from control.rt.outbox import Outbox
from control.rt.settle import GoalCheck
from control.rt.speed_cap import SpeedCap
from hw.machine import Coefficients, Machine
from hw.transmission import Transmission

MS = 1_000_000
SUPPLY_EVERY_S = 0.1  # the run lists the supply pressure this often (meta "supply")
TIMELINE_ENTRIES = 2_000  # a move's stalls or supply readings kept at most: MoveDone's bound


@dataclass
class ActiveMove:
    """The move in progress: its sealed path, and its segment's views."""

    move_id: int
    kind: str
    segment: object
    layout: MoveLayout
    path_map: mmap.mmap  # the sealed path, read-only (control/rt/sealed.py)
    path: memoryview  # float64 view of it: samples rows of n joints
    recorded: memoryview  # uint64 progress counter
    tracking: bool
    smooth: bool  # its rows may not jump (commands.STEP_KINDS may)
    index: int = 0  # rows recorded: the next row of the path to record
    phase: float = 0.0  # where on the path it is, in rows (feed override: control/rt/feed.py)
    start_ns: int = 0
    last_tick_ns: int = 0
    gaps: list[tuple[float, float]] = field(default_factory=list)  # (t s, length s) stalls
    feed: list[tuple[float, float]] = field(default_factory=list)  # (t s, override) as set
    pauses: list[tuple[float, float]] = field(default_factory=list)  # (t s, length s) holds
    supply: list[tuple[float, float]] = field(default_factory=list)  # (t s, MPa) every 0.1 s
    supply_every: float = SUPPLY_EVERY_S  # doubled, the list thinned, when it is full
    speed_mode: list[tuple[float, str]] = field(default_factory=list)  # (t s, mode): start, change
    settle: GoalCheck | None = None  # after the path's last row: holding its end (settle.py)

    @classmethod
    def attach(cls, command: StartMove, path_map: mmap.mmap, now: int) -> ActiveMove:
        """Open the move segment the client made for the run (``docs/shared_memory.md``), to
        follow ``path_map``; ValueError if the segment is not the move's."""
        seg = shm.attach(command.segment)
        try:
            layout = MoveLayout.read_header(seg.buf)
            if layout.samples != command.samples or 8 * layout.samples * layout.n != len(path_map):
                raise ValueError(f"move segment {command.segment} is for {layout.samples} rows "
                                 f"of {layout.n} joints, the move {command.samples} rows")
        except BaseException:
            shm.release(seg, unlink=False)
            path_map.close()
            raise
        recorded = seg.buf[MoveLayout.RECORDED_OFFSET:MoveLayout.RECORDED_OFFSET + 8].cast("Q")
        return cls(move_id=command.move_id, kind=command.kind, segment=seg, layout=layout,
                   path_map=path_map, path=memoryview(path_map).cast("d"),
                   recorded=recorded, tracking=command.tracking,
                   smooth=command.kind not in STEP_KINDS, start_ns=now, last_tick_ns=now)

    def timeline(self) -> dict[str, object]:
        """Its stalls, feed changes and supply, and its settle, as the run lists them."""
        settle = {}
        if self.settle is not None:
            settle = {"path_end_s": round((self.settle.start_ns - self.start_ns) / 1e9, 4),
                      **self.settle.record()}
        return {"gaps": tuple(self.gaps), "feed": tuple(self.feed), "pauses": tuple(self.pauses),
                "supply": tuple(self.supply), "settle": settle,
                "speed_mode": tuple(self.speed_mode)}


@dataclass(frozen=True)
class InitialiseConfig:
    duty: float = 20.0  # function.c Initialise(): -20 % with Max 20
    timeout_ns: int = 60_000 * MS


@dataclass
class InitialiseRun:
    started_ns: int
    reference_q: float
    reference_ns: int


@dataclass
class ModeMachine:
    machine: Machine
    transmission: Transmission
    encoders: EncoderInput
    guards: Guards
    outbox: Outbox
    dt: float
    initialise_config: InitialiseConfig
    mode: Mode = Mode.HOLD
    move: ActiveMove | None = None
    init_run: InitialiseRun | None = None
    coefficients: dict[str, Coefficients] = field(default_factory=dict)
    slots: int = 1  # ticks per sample: the thesis's timing serves one joint a tick
    slips: frozenset[str] = frozenset()  # the listing's slips (control.rt.law.SLIPS)

    def __post_init__(self) -> None:
        n = self.n = self.machine.n_joints
        hold, track = start_sets(self.machine, thesis_timing=self.slots > 1)
        self.coefficients = {"hold": hold, "track": track}
        self.law = DifferenceLaw(self.machine, hold, self.dt, self.slips)
        self.serviced: range = range(n)  # the joints this tick runs eq. 5.1 for
        self.slot_joints = [range(j, j + 1) for j in range(n)]
        self.sample_start = self.sample_end = True  # this tick begins / ends a sample
        self.speed = SpeedCap(self.machine)  # reduced speed (T1): control/rt/speed_cap.py
        self.jog = PositionJog(self.machine, self.dt, self.speed)
        self.feed = FeedRate(self.machine, self.dt)
        self.path_velocity = [0.0] * self.machine.n_joints
        self.peak_velocity = [0.0] * self.machine.n_joints  # reduced speed's (reduced_cap)
        self.position = self.encoders.position  # the same list: read once a tick, shared
        self.desired = [0.0] * n
        self.duty = [0.0] * n
        self.velocity = [0.0] * n
        self.actuator_velocity = [0.0] * n
        self.manual = [0.0] * n
        self.hold_target = [0.0] * n
        self.initialise_duty = [-self.initialise_config.duty] * n
        joints = self.machine.joints
        self.lower = [j.lower for j in joints]
        self.upper = [j.upper for j in joints]
        counts = [abs(j.encoder.gradient) for j in joints]
        row_speed = [1.5 * j.max_speed * self.dt for j in joints]  # per row, with slack
        self.row_step = [v + 2 * c for v, c in zip(row_speed, counts, strict=True)]
        self.first_row_step = [v + 2 * j.tolerance for v, j in zip(self.row_step, joints,
                                                                   strict=True)]
        self.stall_ns = round(self.machine.supervision.stall_s * 1e9)
        self.max_pause_s = self.machine.supervision.max_pause_s
        self.fault = ""  # a row that cannot be trusted: the controller aborts into hold
        self.fault_joint = -1

    def begin_tick(self, tick: int) -> None:
        """The thesis's timing (``control/timing.py``): tick ``tick`` serves joint
        ``tick mod n``; a sample's path row, jog and feed step at its first tick, its record at
        its last. servodesk's timing serves every joint every tick."""
        if self.slots > 1:
            slot = tick % self.slots
            self.serviced = self.slot_joints[slot]
            self.sample_start, self.sample_end = slot == 0, slot == self.slots - 1

    # -- entering modes ------------------------------------------------------------------

    def hold_at(self, target: list[float]) -> None:
        homed, clamp = self.encoders.homed, self.guards.clamp
        self.hold_target[:] = [clamp(j, target[j], homed) for j in range(self.n)]
        self.desired[:] = self.hold_target  # published before the next tick's law sets it
        self.jog.stop_at(self.hold_target)
        for j in range(self.n):
            self.velocity[j] = 0.0
        self.mode = Mode.HOLD
        self.law.set_coefficients(self.coefficients["hold"])

    def jog_by(self, j: int, delta: float) -> None:
        """Position jog (in hold): joint ``j``'s goal moves by ``delta``, inside its limits;
        the hold target follows at the joint's jog speed (``control/rt/jog.py``)."""
        self.jog.move_goal(j, self.guards.clamp(j, self.jog.goal[j] + delta, self.encoders.homed))

    def hold_here(self) -> None:
        self.hold_at(self.position)

    def hold_commanded(self) -> None:
        """Hold where the joints were last commanded (the move's desired, the hold target
        while holding), so a stall never moves the target to where the arm drifted; a joint
        with no such position (open loop) or one outside its limits holds where it is."""
        commanded = self.desired if self.mode == Mode.FOLLOW_TRACK else self.hold_target
        if self.mode not in (Mode.FOLLOW_TRACK, Mode.HOLD):
            commanded = self.position
        lower, upper, position = self.lower, self.upper, self.position
        self.hold_at([c if lower[j] <= c <= upper[j] else position[j]  # NaN fails both
                      for j, c in enumerate(commanded)])

    @property
    def settling(self) -> bool:
        """The move's path is over; it holds the end until in position (``settle.py``)."""
        return self.move is not None and self.move.settle is not None

    def start_settle(self, now: int) -> None:
        """After the path's last row: hold its end, judged each sample until in position."""
        self.hold_at(self.desired)
        self.move.settle = GoalCheck(self.machine, self.hold_target, now, self.dt)

    def feed_command(self, command: FeedOverride | Pause | Resume, now: int) -> None:
        """The operator's feed override, feed hold or resume (``control/rt/feed.py``); a hold
        with no move is refused."""
        if isinstance(command, Pause) and self.move is None:
            self.outbox.put(Refused(command.NAME, "no move is running"))
            return
        t = (now - self.move.start_ns) / 1e9 if self.move is not None else 0.0
        match command:
            case FeedOverride(value=value):
                self.feed.set_override(value, t)
            case Pause():
                self.feed.pause(t)
            case Resume():
                self.feed.resume(t)

    @property
    def held_too_long_text(self) -> str:
        return (f"{self.feed.held_by}: the move was held longer than {self.max_pause_s:g} s; "
                "ended, holding")

    def held_too_long(self, now: int) -> bool:
        """The move held, by a feed hold or the feed override at 0, for longer than
        ``max_pause_s``."""
        move, since = self.move, self.feed.held_since
        return (move is not None and since is not None
                and (now - move.start_ns) / 1e9 - since > self.max_pause_s)

    @property
    def reduced(self) -> bool:
        return self.speed.reduced

    def set_reduced(self, on: bool, now: int) -> None:
        """Reduced speed on or off: a running path comes down to its cap along the path, a
        jog slows at the joints' acceleration (``feed.py``, ``jog.py``); the move's run lists
        the change."""
        self.speed.reduced = on
        self.feed.reduce(on)
        if self.move is not None:
            self.move.speed_mode.append((round((now - self.move.start_ns) / 1e9, 4),
                                         self.speed.mode))

    def start_manual(self) -> None:
        self.mode = Mode.MANUAL_ACTUATE

    def set_manual(self, duty: tuple[float, ...]) -> bool:
        """The operator's open-loop duty; False if it had to be limited (rig not zeroed)."""
        limit = 100.0 if self.encoders.homed else self.initialise_config.duty
        self.manual[:] = [max(-limit, min(limit, d)) for d in duty]
        return all(abs(d) <= limit for d in duty)

    def start_move(self, move: ActiveMove) -> None:
        self.move = move
        move.speed_mode.append((0.0, self.speed.mode))
        self.feed.start_move(move.feed, move.pauses)
        self.mode = Mode.TRACKING_ACTUATE if move.tracking else Mode.FOLLOW_TRACK
        self.law.set_coefficients(self.coefficients["track"])

    def start_initialise(self, now: int) -> None:
        self.mode = Mode.INITIALISE
        self.init_run = InitialiseRun(now, self.position[0], now)

    def set_coefficients(self, which: str, coefficients: Coefficients) -> None:
        """Replace a set; the law takes it at once if it is the set in use (section 6.3)."""
        self.coefficients[which] = coefficients
        if (which == "hold") == (self.mode == Mode.HOLD):
            self.law.set_coefficients(coefficients)

    # -- each tick ---------------------------------------------------------------------

    def control(self, latched: bool, now: int) -> None:
        mode = self.mode
        if latched:
            self.zero_duty()
        elif mode == Mode.HOLD:
            if not self.jog.moving:
                self.closed_loop(self.hold_target, None)
                return
            if self.sample_start:
                self.jog.advance(self.hold_target)
                self.velocity[:] = self.jog.velocity
            self.jogging()
        elif mode == Mode.FOLLOW_TRACK:
            self.follow_track()
        elif mode == Mode.MANUAL_ACTUATE:
            self.open_loop(self.manual)
        elif mode == Mode.TRACKING_ACTUATE:
            self.tracking_actuate()
        else:
            self.initialise(now)

    def closed_loop(self, target: list[float], velocity: list[float] | None) -> None:
        update, position, desired, duty = self.law.update, self.position, self.desired, self.duty
        if self.slots > 1:
            desired[:] = target
        for j in self.serviced:
            desired[j] = target[j]
            duty[j] = update(j, target[j] - position[j], velocity[j] if velocity else 0.0)

    def jogging(self) -> None:
        """The hold law on a jog's moving target: no rest in the deadband for a joint whose
        target moves (resting while it crept away, the joint moved in stick-slip jerks), and
        no feed-forward (a jog is the hold law's, as before)."""
        update, position, target, duty = (self.law.update, self.position, self.hold_target,
                                          self.duty)
        velocity, desired = self.velocity, self.desired
        if self.slots > 1:
            desired[:] = target
        for j in self.serviced:
            desired[j] = target[j]
            duty[j] = update(j, target[j] - position[j], velocity[j], False)

    def open_loop(self, source: list[float]) -> None:
        desired, duty = self.desired, self.duty
        for j in self.serviced:
            desired[j] = math.nan
            duty[j] = source[j]

    def follow_track(self) -> None:
        move = self.move
        if not (self.feed.steady and move.phase == move.index):
            self.follow_scaled(move)
            return
        n, k, last, cells = self.n, move.index, move.layout.samples - 1, move.path
        row = k * n  # a row a tick, as the thesis's
        if not self.row_trusted(move, cells, row):
            return
        before = row - n if k > 0 else row  # central difference, one-sided at the ends
        after = row + n if k < last else row
        span = max((after - before) // n, 1) * self.dt
        desired, velocity = self.desired, self.velocity
        for j in range(n):
            desired[j] = cells[row + j]
            velocity[j] = (cells[after + j] - cells[before + j]) / span
        self.transmission.actuators_from_joints(velocity, self.actuator_velocity)
        self.closed_loop(desired, self.actuator_velocity)

    def follow_scaled(self, move: ActiveMove) -> None:
        """The path at the feed's rate: the desired position interpolated at the move's
        phase, the desired velocity the path's times the rate (control/rt/feed.py)."""
        n, last, cells = self.n, move.layout.samples - 1, move.path
        k = min(int(move.phase), last)
        frac = move.phase - k if k < last else 0.0
        row = k * n
        ahead = row + n if k < last else row
        if not (self.row_trusted(move, cells, row)
                and self.row_trusted(move, cells, ahead, cells[row:row + n])):
            return
        path_velocity, desired, velocity = self.path_velocity, self.desired, self.velocity
        for j in range(n):
            a, b = cells[row + j], cells[ahead + j]
            path_velocity[j] = (b - a) / self.dt
            desired[j] = a + frac * (b - a)
        if self.sample_start:
            self.feed.advance(path_velocity, self.reduced_cap(cells, k, ahead)
                              if self.speed.reduced else 1.0)
        rate = self.feed.rate
        for j in range(n):
            velocity[j] = rate * path_velocity[j]
        self.transmission.actuators_from_joints(velocity, self.actuator_velocity)
        self.closed_loop(desired, self.actuator_velocity)

    def reduced_cap(self, cells: memoryview, k: int, ahead: int) -> float:
        """The fraction of the path's speed reduced speed allows here: from the faster of this
        segment and the next (this tick's advance may reach into it), per joint."""
        n, path_velocity, peak = self.n, self.path_velocity, self.peak_velocity
        beyond = ahead + n if k + 1 < self.move.layout.samples - 1 else ahead
        for j in range(n):
            later = abs(cells[beyond + j] - cells[ahead + j]) / self.dt
            peak[j] = max(abs(path_velocity[j]), later)
        return self.speed.fraction(peak, self.desired)

    def row_trusted(self, move: ActiveMove, cells: memoryview, row: int,
                    previous: Sequence[float] | None = None) -> bool:
        """Whether a desired row is finite, in the limits and (smooth kinds) no jump from
        ``previous`` (the last tick's desired); if not, ``fault`` says why and nothing moves."""
        lower, upper = self.lower, self.upper
        first = previous is None and move.index == 0
        if previous is None:
            previous = self.position if first else self.desired
        allowed = self.first_row_step if first else self.row_step
        for j in range(self.n):
            x = cells[row + j]
            if lower[j] <= x <= upper[j] and not (move.smooth
                                                  and abs(x - previous[j]) > allowed[j]):
                continue
            joint = self.machine.joints[j]
            why = (f"{x:g}{joint.symbol} is outside {joint.limit_text()}"
                   if not lower[j] <= x <= upper[j] else
                   f"jumps {x - previous[j]:+.3g}{joint.symbol} from "
                   f"{previous[j]:.2f}{joint.symbol}, more than a {move.kind} may in a tick")
            self.reject_row(move, j, f"{joint.name} {why}")
            return False
        return True

    def reject_row(self, move: ActiveMove, j: int, why: str) -> None:
        self.fault_joint = j
        self.fault = f"move {move.move_id} row {move.index}: {why}"
        self.zero_duty()

    def tracking_actuate(self) -> None:
        move = self.move
        row = move.index * self.n
        desired, duty, cells = self.desired, self.duty, move.path
        limit = 100.0 if self.encoders.homed else self.initialise_config.duty
        for j in self.serviced:
            u = cells[row + j]
            if not -100.0 <= u <= 100.0:
                self.reject_row(move, j, f"{self.machine.joints[j].name} duty {u:g} % is not "
                                         "in -100…100 %")
                return
            desired[j] = math.nan
            duty[j] = u if -limit <= u <= limit else math.copysign(limit, u)

    def initialise(self, now: int) -> None:
        """Drive the rig's ram down until it rests on the bottom stop, then zero (section 3.5)."""
        self.open_loop(self.initialise_duty)
        run = self.init_run
        if now - run.reference_ns < 200 * MS:
            return
        if abs(self.position[0] - run.reference_q) < 0.5 and now - run.started_ns > 500 * MS:
            self.encoders.zero()
            self.law.reset()  # resting on the stop: nothing of the law before the zero holds
            self.hold_here()
            self.outbox.put(Initialised("complete: initialised at the bottom"))
        elif now - run.started_ns > self.initialise_config.timeout_ns:
            self.hold_here()
            self.outbox.put(Fault("initialise", 0, "initialise did not reach the bottom stop in "
                                                   "time; holding"))
        else:
            run.reference_q, run.reference_ns = self.position[0], now

    def record(self, now: int, supply_mpa: float) -> bool:
        """Append a row to the move's record once the move reaches the next row of its path
        (every tick at full feed; the duty is what the valves get, after the guards), then
        advance the phase by the feed's rate; True after the path's last row. While the move
        settles, a row a sample of the hold of its end, as long as the segment has room. A gap
        longer than ``stall_s`` between two ticks of the move is a controller stall, listed in
        ``gaps``.
        Every ``SUPPLY_EVERY_S`` the supply pressure (when the backend knows it) goes into
        ``supply``. Both lists are bounded (``TIMELINE_ENTRIES``), as a slow feed can make a
        move long: past it the supply's interval doubles and every other reading goes, and
        later stalls are added to the last one listed."""
        move = self.move
        layout = move.layout
        rate = 1.0 if move.tracking else self.feed.rate
        t = (now - move.start_ns) / 1e9
        if now - move.last_tick_ns > self.stall_ns and move.index:
            gap = (now - move.last_tick_ns) / 1e9
            if len(move.gaps) < TIMELINE_ENTRIES:
                move.gaps.append((round(t - gap, 4), round(gap, 4)))
            else:
                start, length = move.gaps[-1]
                move.gaps[-1] = (start, round(length + gap, 4))
            self.outbox.put(Notice(f"controller stalled {gap:.3f} s during move "
                                   f"{move.move_id} at t = {t - gap:.2f} s: the run lists the "
                                   "gap"))
        move.last_tick_ns = now
        if supply_mpa == supply_mpa and t >= move.supply_every * len(move.supply):
            move.supply.append((round(t, 4), round(supply_mpa, 4)))
            if len(move.supply) >= TIMELINE_ENTRIES:
                move.supply_every *= 2
                del move.supply[1::2]
        settling = move.settle is not None
        if (move.phase >= move.index or settling) and move.index < layout.rows:
            layout.row.pack_into(move.segment.buf,
                                 layout.record_offset + move.index * layout.row.size,
                                 t, *self.desired, *self.position, *self.duty)
            move.index += 1
            move.recorded[0] = move.index
        if settling:
            return False
        move.phase = min(move.phase + rate, layout.samples - 1.0) if move.index < \
            layout.samples else move.phase
        return move.index >= layout.samples

    def zero_duty(self) -> None:
        duty = self.duty
        for j in range(self.n):
            duty[j] = 0.0
