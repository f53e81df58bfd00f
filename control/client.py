"""``ControlClient``: the only handle the TUI, the CLI, scripts and tests use.

A client is made of a link to its controller (``control/link.py``: the control
subprocess it starts, ``control/embedded.py``, or a controller service it attaches to,
``control/attached.py``), the command API here, and a run keeper that saves the runs of
its moves on its own thread (``control/run_keeper.py``). It sends heartbeats, turns the
controller's events into saved runs, and notices within 250 ms when the controller
dies::

    with ControlClient("unimate2000b") as robot:
        move = robot.move(moves.step(robot.status().position, joint=2, target=10.0,
                                     duration=3.0, dt=robot.dt), kind="step")
        result = robot.wait(move)           # the run is already saved on disk
"""

from __future__ import annotations

import contextlib
import itertools
import math
import os
import queue
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from control.embedded import EmbeddedLink
from control.link import ANSWER_S, OUTGOING, ControllerError, Link, NotCommanding, Setting
from control.motion.acceptance import accept
from control.motion.plan import MovePlan, Summary, moving_joints, result_records, summaries
from control.recorder import Run, RunFiles, coefficients_record, default_data_dir
from control.rt import sealed, shm
from control.rt.commands import (
    Command,
    EmergencyStop,
    FeedOverride,
    Hold,
    Initialise,
    Inject,
    JogPosition,
    JogVelocity,
    Manual,
    Pause,
    Reset,
    Resume,
    SetCoefficients,
    SetSpeedMode,
    StartMove,
    finite,
    joint_index,
)
from control.rt.events import (
    CoefficientsApplied,
    ControllerEvent,
    Crash,
    Died,
    EStop,
    Fault,
    MoveDone,
    MoveStarted,
    Notice,
)
from control.rt.law import start_sets
from control.rt.layout import ESTOP_WORD, HEARTBEAT_WORD, LatencyHistogram, Mode, MoveLayout, Status
from control.rt.seqlock import SeqlockReader
from control.rt.speed_cap import MODES
from control.rt.wire import Broken, Message, Unreadable
from control.run_keeper import FinishedMove, RunKeeper, RunKept
from control.runs import encode_meta, segment_meta
from control.timing import Timing
from hw.machine import Coefficients, Machine, load_machine
from hw.sim import check_plant

if TYPE_CHECKING:
    from control.identify.gains import GainCheck
    from control.identify.sysid import DeadbandModel

__all__ = ["ControlClient", "ControllerError", "Event", "MoveHandle", "MoveResult",
           "NotCommanding"]

HEARTBEAT_S = 0.05
KEEP_WAIT_S = 30.0  # close(): how long the runs in hand may take to be saved (600 s: under 5)
CLOSED = "this client is closed: start a new ControlClient to read or command the controller"
DEATH_S = 0.25
# the event thread's wait for the channel: an event, or the controller's end of it closing,
# wakes it at once; the wait only bounds how soon a controller gone without closing it is seen
# (well inside the 250 ms promised) and how long close() waits for the thread. At 10 ms it
# woke 100 times a second for nothing, half a percent of a core on every tab
EVENT_WAIT_S = 0.1
MONITOR_JOIN_S = 2.0  # close(): how long the event thread may take to deliver what came before
_MOVES = itertools.count(1)  # a move's segment is named apart (it may outlive its client)
SPIN_US = 150.0  # spin before each deadline: keeps the core and its caches (benchmarks/loop.py)


@dataclass(frozen=True)
class Event:
    """Something the controller (or the client's watchdog) reported: a typed record from
    ``control.rt.events`` and when it arrived. ``kind`` and ``payload`` are the record's."""

    record: ControllerEvent
    wall: float = field(default_factory=time.monotonic)

    @property
    def kind(self) -> str:
        return self.record.KIND

    @property
    def payload(self) -> dict[str, object]:
        return self.record.payload

    @property
    def message(self) -> str:
        return str(self.record.message)


@dataclass(frozen=True)
class MoveResult:
    """A finished move: its status, its run, where the run was saved, the plan it ran, and
    how it went (``results``, computed once when it ended; saved in the run's metadata)."""

    move_id: int
    status: str
    run: Run
    files: RunFiles | None
    save_error: str = ""
    plan: MovePlan | None = None
    machine: Machine | None = None
    results: tuple[tuple[str, Summary], ...] = ()

    @property
    def complete(self) -> bool:
        """Every row was followed and then every joint came within its goal tolerance of the
        end, stopped, within the machine's goal_time (``docs/motion.md``); a stall in it is
        listed in the run and its status."""
        return self.status == "complete" or self.status.startswith("complete, ")

    @property
    def unsettled(self) -> bool:
        """Every row was followed, but a joint was not in position within goal_time (the
        status names it); the controller holds the path's end."""
        return self.status.startswith("unsettled")

    @property
    def settle(self) -> dict:
        """The settle after the path (``control/rt/settle.py``): ``path_end_s``,
        ``goal_time_s``, ``settle_s`` (per joint, s after the path's end; None: never in
        position) and ``goal_error`` (per joint, at the end); empty for an open-loop move or
        one that ended on its path."""
        return dict(self.run.meta.get("settle") or {})

    def summaries(self) -> list[tuple[str, Summary]]:
        """``(label, summary)`` per joint that moved, the approach left out, by the move's
        kind (``control.motion.plan.summaries``)."""
        return list(self.results)


@dataclass
class MoveHandle:
    """A move sent to the controller; ``ControlClient.wait`` returns its result."""

    move_id: int
    kind: str
    samples: int
    meta: dict
    plan: MovePlan
    segment: object
    layout: MoveLayout
    done: threading.Event = field(default_factory=threading.Event)
    result: MoveResult | None = None


class ControlClient:
    """Start and talk to the control subprocess of one machine.

    ``machine`` is a built-in name, a TOML path or a loaded ``Machine``;
    ``backend`` is ``sim`` or ``serial`` (with ``port``). ``lockstep`` runs the
    simulator as fast as it computes (tests). ``speed_mode`` is the controller's speed at
    the start: ``automatic`` (full speed) or ``reduced`` (ISO 10218-1's T1: the tool at most
    250 mm/s, each joint at most its jog_speed; ``set_speed_mode``). ``on_event`` is called
    from the client's monitor thread for every event (a TUI marshals it to its loop).
    ``ControlClient.attach`` gives a client of a controller run apart, with this API.

    A client is made of parts: its ``link`` to the controller (``control/link.py``: one it
    started, ``EmbeddedLink``, or a service's, ``ServiceLink``), the command API below, and
    its run ``keeper`` (``control/run_keeper.py``).
    """

    def __init__(self, machine: str | Path | Machine = "unimate2000b", backend: str = "sim", *,
                 port: str | None = None, seed: int = 0, lockstep: bool = False,
                 data_dir: str | Path | None = None, period_s: float | None = None,
                 realtime: bool = True, spin_us: float = SPIN_US,
                 heartbeat_timeout_s: float = DEATH_S, orphan_timeout_s: float = 5.0,
                 start_timeout_s: float = 30.0, sim_options: dict | None = None,
                 on_event: Callable[[Event], None] | None = None,
                 timing: Timing | None = None, speed_mode: str = "automatic") -> None:
        _check_speed_mode(speed_mode)
        machine = machine if isinstance(machine, Machine) else load_machine(machine)
        if backend == "sim":
            check_plant(machine)  # a MachineError naming the key, before anything starts
        timing = timing or Timing()
        setting = Setting(
            machine=machine, backend=backend, port=port, timing=timing,
            dt=period_s or timing.sample_time_s(machine),
            data_dir=Path(data_dir) if data_dir is not None else default_data_dir(),
            lockstep=lockstep)
        early: list[ControllerEvent] = []
        link, notices = EmbeddedLink.launch(
            setting, start_sets(machine, timing.name == "thesis"), seed=seed, realtime=realtime,
            spin_us=spin_us, heartbeat_timeout_s=heartbeat_timeout_s,
            orphan_timeout_s=orphan_timeout_s, start_timeout_s=start_timeout_s,
            sim_options=sim_options or {}, early=early.append)
        self._join(link, on_event, [*map(Notice, notices), *early])
        if speed_mode != self.speed_mode:
            try:
                self.set_speed_mode(speed_mode)
            except BaseException:
                self.close()
                raise

    @classmethod
    def attach(cls, path: str | Path | None = None, *, name: str = "",
               on_event: Callable[[Event], None] | None = None,
               timeout_s: float = 5.0) -> ControlClient:
        """A client of the controller that ``servodesk controller`` runs (``path``: its socket,
        by default the one in the user's runtime directory), with this class's API
        (``control/attached.py``). It observes until ``take_command``; ``close`` detaches and
        leaves the controller running."""
        # here, not at the top: a client that starts its controller never needs it
        from control.attached import ServiceLink

        client = cls.__new__(cls)
        client._join(ServiceLink.connect(path, name, timeout_s), on_event, [])
        return client

    def _join(self, link: Link, on_event: Callable[[Event], None] | None,
              early: Sequence[ControllerEvent]) -> None:
        """Work through ``link``: the client's own state, its views of the control segment,
        the sets the controller has, and its threads; ``early`` events go out first."""
        setting = self.setting = link.setting
        self.link = link
        self.machine = setting.machine
        self.on_event = on_event
        self.events: queue.Queue[Event] = queue.Queue()
        self.dead = ""
        self.heartbeat_on = True  # a controller service turns its own off while another commands
        self.layout = link.layout
        self._words = self.layout.client_words(link.segment.buf)
        self._status = SeqlockReader(link.segment.buf, self.layout.status_offset,
                                     self.layout.status.struct)
        self._moves: dict[int, MoveHandle] = {}
        self.keeper = RunKeeper()  # saves finished moves' runs off the monitor thread
        self._kept: dict[str, str] = {}  # run id: segment of a run not saved, for the next start
        self._ids = itertools.count(setting.first_move_id)
        self._closing = threading.Event()
        self._stopping = False
        self._manual = [0.0] * self.machine.n_joints  # the duties jog_joint keeps for the others
        self._latched = False  # an E-stop sent or reported, until the controller releases it
        started = start_sets(self.machine, setting.timing.name == "thesis")
        self.coefficients = {which: self._coefficients_in_use(which, c) for which, c in
                             zip(("hold", "track"), started, strict=True)}
        # what the gain check said of each set in use, saved with every run (control.identify.gains)
        self.coefficient_checks: dict[str, dict[str, object]] = {
            which: {"passed": None, "summary": "the machine file's set, applied at start"}
            for which in self.coefficients}
        self._models: tuple[DeadbandModel | None, ...] = (None,) * self.machine.n_joints
        self._monitor = threading.Thread(target=self._watch, name="servodesk-events",
                                         daemon=True)
        self._heart = threading.Thread(target=self._beat, name="servodesk-heartbeat",
                                       daemon=True)
        link.start()
        for thread in (self._monitor, self._heart):
            thread.start()
        for record in early:
            self._dispatch(Event(record))

    def _coefficients_in_use(self, which: str, given: Coefficients) -> Coefficients:
        """The set the controller has: the machine file's (by its name) or one a client set."""
        values = self.link.read_coefficients(which)
        if values == self.layout.coefficients.encode(given):
            return given
        return self.layout.coefficients.decode(values, f"{which} (set by a client)")

    # -- what the link says ------------------------------------------------------------

    @property
    def backend(self) -> str:
        return self.setting.backend

    @property
    def port(self) -> str | None:
        return self.setting.port

    @property
    def timing(self) -> Timing:
        return self.setting.timing

    @property
    def dt(self) -> float:
        """Between path rows, s."""
        return self.setting.dt

    @property
    def data_dir(self) -> Path:
        return self.setting.data_dir

    @property
    def lockstep(self) -> bool:
        return self.setting.lockstep

    @property
    def notice(self) -> str:
        """How the controller is scheduled, when it is not as asked."""
        return self.setting.notice

    @property
    def realtime(self) -> bool:
        return self.setting.realtime

    @property
    def name(self) -> str:
        """The name a controller service gave this client ("" for one's own controller)."""
        return self.setting.name

    @property
    def service_pid(self) -> int:
        return self.setting.service_pid

    @property
    def pid(self) -> int:
        """The control process's id."""
        return self.link.pid

    @property
    def alive(self) -> bool:
        return not self.dead and not self.link.exited()

    @property
    def commanding(self) -> bool:
        return self.link.commanding

    @property
    def role(self) -> str:
        """In a sentence: whether this client commands, and who does if not ("" when it
        started its controller)."""
        return self.link.role

    @property
    def holder(self) -> str:
        """Who holds command of a controller service ("" nobody)."""
        return self.link.holder

    def take_command(self, timeout_s: float = ANSWER_S) -> None:
        """Become the commanding client of a controller service; ``NotCommanding`` with the
        reason if another holds command."""
        self.check()
        self.link.take_command(timeout_s)

    def release_command(self, timeout_s: float = ANSWER_S) -> None:
        """Give command of a controller service back: the controller holds every joint;
        another client may take it."""
        self.check()
        self.link.release_command(timeout_s)

    def controller_log(self) -> str:
        """Everything the control process has written to its stderr so far (when this client
        started it)."""
        return self.link.log()

    # -- lifecycle -------------------------------------------------------------------

    def __enter__(self) -> ControlClient:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        """Let go of the controller (one this client started is stopped, valves closed; a
        service's runs on), save what it finished, let go of every segment (unlinking this
        client's own). A controller that does not stop in time (frozen, flooded) is killed;
        the runs in hand get ``KEEP_WAIT_S`` to be saved (one not saved by then stays in its
        segment for the next start)."""
        if self._closing.is_set():
            return
        self._stopping = True
        if not self.dead:
            self.link.stop(self._moves_end)
        self._closing.set()
        self.link.close()
        self._heart.join(timeout=0.2)
        # the monitor reads what came before the close itself, on its way out: read here too
        # while it still dispatched, the channel was polled by two threads ("concurrent poll()
        # invocation") and a listener called from both at once
        self._monitor.join(timeout=MONITOR_JOIN_S)
        for handle in list(self._moves.values()):
            self._finish(handle, "interrupted: client closed", None)
        self.keeper.wait(KEEP_WAIT_S)
        self._words.release()
        self._status.release()
        self.link.release()

    def _moves_end(self, timeout_s: float) -> None:
        """Wait at most ``timeout_s`` for this client's moves to end."""
        deadline = time.monotonic() + timeout_s
        for handle in list(self._moves.values()):
            handle.done.wait(max(deadline - time.monotonic(), 0.0))

    # -- the monitor thread: heartbeats out, events in, death noticed -------------------

    def _beat(self) -> None:
        """Heartbeats on their own thread, so saving a run or a busy UI never silences them."""
        while not (self.dead or self._stopping):
            if self.heartbeat_on:
                self.beat()
            if self._closing.wait(HEARTBEAT_S):
                return

    def beat(self) -> None:
        """One heartbeat, the way this client's link carries it (``Link.beat``). A controller
        service calls it for the client that commands, each time that client's reaches it."""
        self.link.beat(self._words)

    def _watch(self) -> None:
        """Dispatch the controller's events and report its death."""
        wire = self.link.wire
        while not self._closing.is_set():
            try:
                if wire.poll(EVENT_WAIT_S):
                    self._dispatch(Event(wire.recv().record))
            except Unreadable:
                pass  # a message of a newer servodesk, say: nothing to act on
            except Broken:
                self._died(self.link.closed)
            # ask on every pass, after the death too: it reaps an exited controller at once
            # rather than leaving a zombie until close()
            exited = self.link.exited()
            if exited and not self.dead:
                self._died(exited)
            if self.dead:
                self._closing.wait(0.05)
        self._drain()

    def _drain(self) -> None:
        with contextlib.suppress(Broken, Unreadable):
            while self.link.wire.poll():
                self._dispatch(Event(self.link.wire.recv().record))

    def _died(self, why: str) -> None:
        if self.dead or self._stopping:
            return
        self.dead = (f"controller died: {why}. The valves are closed by the I/O board's "
                     f"watchdog; {self.link.restart}")
        for handle in list(self._moves.values()):
            self._finish(handle, "interrupted: controller died", None)
        self._dispatch(Event(Died(self.dead)))

    def _dispatch(self, event: Event) -> None:
        record = event.record
        self.link.observe(record)
        if isinstance(record, EStop):
            self._latched = record.latched
            self._forget_manual()
        elif isinstance(record, MoveDone):
            handle = self._moves.get(record.move_id)
            if handle is not None:
                self._finish(handle, record.status, record.saved, record.timeline)
        elif isinstance(record, Crash):
            event = Event(Fault("crash", -1, f"controller crashed: {record.message}"))
        self.events.put(event)
        if self.on_event is not None:
            self.on_event(event)

    def _finish(self, handle: MoveHandle, status: str, saved: str | None,
                timeline: dict[str, tuple[tuple[float, float], ...]] | None = None) -> None:
        """Hand a finished move to the run keeper (``control/run_keeper.py``) and return at
        once: on its own thread it saves the run (its metrics, and its stalls and feed changes,
        ``timeline``, in its metadata), unlinks the segment once the run is saved (a run that
        cannot be saved now stays whole there for the next start to recover) and completes
        the handle. The monitor thread, which hears E-stops and faults, never waits on a disk."""
        if self._moves.pop(handle.move_id, None) is None:
            return
        move = FinishedMove(handle.segment, handle.layout, handle.meta, status, timeline,
                            saved or "")
        self.keeper.hand(move, lambda kept: self._kept_run(handle, status, kept),
                         measure=lambda run: self._results(handle.plan, run), save_empty=False)

    def _kept_run(self, handle: MoveHandle, status: str, kept: RunKept) -> None:
        """On the keeper's thread, the run saved (or kept): the handle's result."""
        run = kept.run if kept.run is not None else self._unread(handle, status)
        error = ""
        if kept.kept:
            error = (f"run not saved ({kept.problem}); it is kept in memory (save it elsewhere "
                     "from the Runs tab) and in shared memory, where the next start saves it")
            self._kept[str(handle.meta["run_id"])] = handle.segment.name
        handle.result = MoveResult(handle.move_id, status, run, kept.files, error, handle.plan,
                                   self.machine, tuple(kept.results))
        handle.done.set()

    def _unread(self, handle: MoveHandle, status: str) -> Run:
        """An empty run in place of one its segment would not give (it stays there)."""
        empty = np.empty((0, self.machine.n_joints))
        return Run.from_machine(self.machine, handle.kind, status, {}, np.empty(0), empty,
                                empty, empty, meta={"run_id": handle.meta.get("run_id")})

    def _results(self, plan: MovePlan, run: Run) -> tuple[list[tuple[str, Summary]], dict]:
        """The move's metrics (``control.motion.plan.summaries``) and what goes into its run's
        metadata with them, with what went wrong if they could not be computed: a run is
        saved whatever its metrics do."""
        try:
            results = summaries(plan, run, self.machine)
        except Exception as exc:  # never lose a run over its summary
            return [], {"results_error": f"{type(exc).__name__}: {exc}",
                        "results": result_records([])}
        return results, {"results": result_records(results)}

    def release_kept(self, run: Run) -> None:
        """``run``, which could not be saved, has been saved elsewhere: let go of the copy
        kept in shared memory for the next start to recover."""
        name = self._kept.pop(str(run.meta.get("run_id")), None)
        if name is not None:
            with contextlib.suppress(FileNotFoundError):
                shm.release(shm.attach(name), unlink=True)

    # -- commands ------------------------------------------------------------------------

    def _send(self, command: Command, fds: tuple[int, ...] = ()) -> None:
        """Send ``command`` (and descriptors to send with it, closed once sent) on the
        channel from this thread, or queue it behind those still waiting (``control/outgoing.py``);
        never waits. ControllerError if the controller is dead or has not taken the last
        ``OUTGOING`` commands (frozen or flooded)."""
        if self.dead:
            raise ControllerError(self.dead)
        self.link.may_send(command)
        try:
            self.link.put(Message(command, fds))
        except queue.Full:
            raise ControllerError(f"the controller has not taken the last {OUTGOING} commands "
                                  "(frozen or overloaded): E-stop still works") from None

    def _forget_manual(self) -> None:
        """The controller left manual actuation (E-stop, hold, a move): a later ``jog_joint``
        starts from zero duty on every other joint, never from duties set before."""
        self._manual = [0.0] * self.machine.n_joints

    def send(self, command: Command, fds: tuple[int, ...] = ()) -> None:
        """Send a typed command (``control.rt.commands``) as it is, with the descriptors that
        came with it (a move's sealed path), which are closed once sent: the controller checks
        it (a controller service relays its clients' commands this way)."""
        self._send(command, fds)

    def hold(self, reason: str = "") -> None:
        """Abort any move and hold every joint where it is (the thesis's default mode);
        ``reason``: how a running move ends, if not "aborted by operator"."""
        self._send(Hold(reason))
        self._forget_manual()

    def estop(self) -> None:
        """Latch every valve closed until ``reset``. Never waits: the E-stop count in shared
        memory reaches the controller on its next tick whatever the channel holds; the message
        behind it is best effort."""
        self._words[ESTOP_WORD] += 1
        self._latched = True
        self._forget_manual()
        with contextlib.suppress(ControllerError):
            self._send(EmergencyStop())

    @property
    def latched(self) -> bool:
        """The E-stop is latched, or was sent and the controller has not released it since."""
        if self._latched:
            return True
        try:
            return self.status().estop
        except (ControllerError, TimeoutError, ValueError):
            return False

    def reset(self) -> None:
        """Release a latched E-stop (refused while the E-stop input is pressed); every joint
        then holds where it is: nothing moves until a new command."""
        self._send(Reset())

    def initialise(self) -> None:
        """Rig: drive the ram to the bottom and zero the encoder (section 3.5)."""
        self._send(Initialise())

    def inject(self, method: str, *args: object) -> None:
        """Simulator only: drive a simulated input, e.g. ``inject("press_estop", True)``."""
        self._send(Inject(method, args))

    def jog(self, duty: Sequence[float]) -> None:
        """Manual actuation: open-loop duty per joint in %, in each joint's positive sense.

        Raises ValueError (nothing sent) unless there is one finite duty per joint. While the
        E-stop is latched the controller refuses it (a ``refused`` event) and the duty is not
        remembered: nothing set then moves a joint after the release."""
        command = Manual.of(self.machine, duty)
        self._send(command)
        if not self.latched:
            self._manual = list(command.duty)

    def jog_joint(self, joint: int | str, duty: float) -> None:
        """Set one joint's manual duty (joint by index or name), keeping the others'."""
        manual = list(self._manual)
        manual[joint_index(self.machine, joint)] = finite("jog duty", duty)
        self.jog(manual)

    def jog_position(self, joint: int | str, delta: float) -> None:
        """Closed-loop jog: move the hold target of one joint by ``delta`` (mm or deg)."""
        self._send(JogPosition.of(self.machine, joint, delta))

    def jog_velocity(self, velocities: Sequence[float]) -> None:
        """Streamed jog: each joint's hold target moves at its velocity (mm/s or deg/s, one a
        joint, capped at its jog_speed) until the next call; send again within 150 ms to keep
        moving, or it brakes to a stop (the deadman). Refused while a move runs; all zeros
        stops. ValueError (nothing sent) for a wrong count or a number that is not finite."""
        self._send(JogVelocity.of(self.machine, velocities))

    def feed_override(self, value: float) -> None:
        """The path being followed advances at ``value`` (0…1) of its speed, now and for the
        moves after (LinuxCNC's feed override; the controller ramps to it within the joints'
        acceleration). ValueError (nothing sent) outside 0…1 or not finite."""
        self._send(FeedOverride(value))

    def pause(self) -> None:
        """Feed hold: the move decelerates along its path to a stop and holds there."""
        self._send(Pause())

    def resume(self) -> None:
        """End a feed hold: the move goes on from where it stopped, with no jump."""
        self._send(Resume())

    @property
    def speed_mode(self) -> str:
        """The controller's speed mode, from its status: ``reduced`` (T1) or ``automatic``."""
        return self.status().speed_mode

    def set_speed_mode(self, mode: str, timeout_s: float = 2.0) -> None:
        """Reduced speed (ISO 10218-1's T1: every motion the controller makes keeps the tool at
        most 250 mm/s and each joint at most its jog_speed; open-loop duty is refused) or
        automatic (full speed). To reduced takes effect at once: a running path slows to it
        along its path, a jog at the joints' acceleration, open-loop duty ends in a hold. To
        automatic only at rest: ValueError (nothing sent) while a motion runs. Returns once
        the status shows the mode; ``NotCommanding`` for an observer, ``ControllerError`` if
        the controller did not switch within ``timeout_s``."""
        _check_speed_mode(mode)
        command = SetSpeedMode(mode)
        self.link.may_send(command)
        status = self.status()
        if mode == "automatic" and status.speed_mode != mode and status.moving:
            raise ValueError("automatic (full speed) is set only at rest: hold, or wait for "
                             "the motion to end, first")
        self._send(command)
        deadline = time.monotonic() + timeout_s
        while self.status().speed_mode != mode:
            self.check()
            if time.monotonic() > deadline:
                raise ControllerError(f"the controller did not switch to {mode} speed within "
                                      f"{timeout_s:g} s (refused: see the events)")
            time.sleep(0.002)

    def set_coefficients(self, which: str, coefficients: Coefficients,
                         models: Sequence[DeadbandModel | None] | None = None, *,
                         override: str | None = None) -> GainCheck:
        """Replace the hold or track set; applied at once, even during a move (section 6.3).

        The set is checked first (``control.identify.gains``): every number finite, and every
        joint's loop stable with margin on its model: ``models`` (one per joint, None for the
        machine file's nominal model), and for a joint without one here the identified model
        given earlier in this session (``models``), else the nominal one. Refused: ValueError
        naming each joint and why, nothing applied. ``override="reason"`` applies a set the
        stability check refuses (never one with a number that is not finite): the reason and
        the refusal go into the metadata of every run made with the set
        (``coefficients.<which>.check``) and out as a notice event. Returns the check."""
        from control.identify import gains  # scipy: loaded on first use, never by the controller

        command = SetCoefficients(which)
        self.link.may_send(command)  # before the set is written where the controller reads it
        if override is not None and (not isinstance(override, str) or not override.strip()):
            raise ValueError(f"override needs the reason as a non-empty string, got {override!r}")
        known = self._known_models(models)
        check = (gains.assess if override is not None else gains.check)(
            coefficients, self.machine, known, self.dt)
        self.link.write_coefficients(which, coefficients)
        self.coefficients[which] = coefficients
        self.coefficient_checks[which] = check.record(override)
        self._models = known
        self._send(command)
        overridden = override if override is not None and not check.ok else ""
        self._dispatch(Event(CoefficientsApplied(which, coefficients.name, check.summary(),
                                                 overridden)))
        if not check.ok:
            self._dispatch(Event(Notice(
                f"gain check overridden for the {which} set {coefficients.name!r} ({override}): "
                f"{check.summary()}; recorded with every run made with it")))
        return check

    @property
    def models(self) -> tuple[DeadbandModel | None, ...]:
        """The identified model of each joint given to ``set_coefficients`` in this session
        (None: the machine file's nominal model), which later gain checks use."""
        return self._models

    def _known_models(self, models: Sequence[DeadbandModel | None] | None
                      ) -> tuple[DeadbandModel | None, ...]:
        if models is None:
            return self._models
        if len(models) != self.machine.n_joints:
            raise ValueError(f"models: need one model (or None) per joint, "
                             f"{self.machine.n_joints}, got {len(models)}")
        return tuple(m if m is not None else known
                     for m, known in zip(models, self._models, strict=True))

    def move(self, desired: np.ndarray, kind: str = "path", meta: dict | None = None) -> MoveHandle:
        """follow_track: track ``desired (N, J)`` (mm, deg) each tick, then hold at its end.

        ``kind`` says what the path may do (``control.motion.acceptance``): a smooth kind
        (the default ``path``, ramp, sine, …) keeps every joint's max_speed and max_accel; a
        step kind (``step``, ``multi_step``) may jump. A path that starts away from the joints
        gets an approach ramp first (``run``). Raises ValueError, nothing sent, if the rules
        refuse it."""
        return self.run(MovePlan.of_path(np.asarray(desired, dtype=np.float64), kind, meta))

    def go_to(self, q: Sequence[float], speed: float = 0.5, meta: dict | None = None
              ) -> MoveHandle:
        """A joint-space move from where the joints are to ``q`` (mm, deg): a quintic
        trajectory at ``speed`` of each joint's max_speed and max_accel (0 < speed ≤ 1); like
        every closed-loop move it is complete only once in position (``wait``).
        ValueError (nothing sent) for a target outside the limits or a bad speed."""
        from control.motion import form_plans  # its paths and kinematics: not at the start

        plan = form_plans.go_to(self.machine, np.array(self.status().position), q, speed,
                                dt=self.dt)
        return self.run(replace(plan, meta={**plan.meta, **(meta or {})}))

    def jog_cartesian(self, displacement: Sequence[float], frame: str = "world",
                      speed: float = 1.0, *, stop_short: bool = False) -> MoveHandle:
        """Move the tool by ``displacement`` ``[dx, dy, dz (mm), dγ, dβ, dα (deg)]`` along a
        straight line in ``frame`` (``world`` or ``tool``) at ``speed`` (0 < speed ≤ 1) of
        the machine's Cartesian jog speed, on the branch the arm is on; returns the move's
        handle as soon as it is sent (``control.motion.cartesian_jog``). A step waits first for
        a move in progress to end (its path and its settle: at most their time; not one in a
        feed hold, nor for a ``stop_short`` jog, which supersedes it); the line then starts
        where the joints were last commanded (the hold target, the end a move settled at, a
        running move's desired), never at a swinging pose, so steps add up exactly; an arm
        farther than its goal tolerance from there gets an approach in front of the line.

        ``Unreachable`` (a ValueError), nothing sent, when the line leaves the workspace,
        needs a joint past its limit or comes near a singularity: the reason names which.
        ``stop_short`` instead jogs as far as the line allows and says why in the handle's
        ``meta["stopped"]``. ValueError for bad input or a machine without kinematics."""
        from control.motion.cartesian_jog import plan_jog  # its kinematics: not at the start

        status = self.status() if stop_short else self._after_move()
        here = start = np.array(status.position)
        target = np.array(status.desired)
        if status.mode in (Mode.HOLD, Mode.FOLLOW_TRACK) and np.isfinite(target).all():
            start = target
            goal = np.array([j.goal_tolerance for j in self.machine.joints])
            if np.all(np.abs(here - target) <= goal):
                here = target  # in position: no approach
        jog = plan_jog(start, displacement, self.machine, frame=frame, dt=self.dt, speed=speed,
                       stop_short=stop_short)
        meta = {"displacement": jog.displacement.tolist(), "frame": frame, "speed": speed,
                "asked": [float(v) for v in displacement], "stopped": jog.stopped,
                "start_pose": jog.poses[0].tolist(), "end_pose": jog.poses[-1].tolist()}
        plan = MovePlan("cartesian_jog", f"Cartesian jog ({frame})", jog.q, meta=meta,
                        moving=moving_joints(jog.q))
        # judged from the snapshot it was planned from, not a second look (run) at the joints
        return self._start(accept(plan, here, self.machine, self.dt))

    def _after_move(self) -> Status:
        """The status once the move in progress has ended (in position, or not within
        goal_time), waiting at most its path's time left and goal_time (and a second); at
        once if none runs, or it stands in a feed hold (it stands on its path)."""
        status = self.status()
        left_s = ((status.move_total - status.move_done) * self.dt
                  / max(status.feed_override, 0.05) + self.machine.goal_time_s + 1.0)
        deadline = time.monotonic() + left_s
        while status.moving and not status.paused and time.monotonic() < deadline:
            self.check()
            time.sleep(0.002)
            status = self.status()
        return status

    def run(self, plan: MovePlan) -> MoveHandle:
        """Run a planned move (``control.motion.plan``): its path, with an approach from where
        the joints are now when it starts elsewhere, or its duty profile. The acceptance rules
        (``control.motion.acceptance.accept``) decide; ValueError, nothing sent, if they
        refuse."""
        here = np.array(self.status().position) if plan.path is not None else None
        return self._start(accept(plan, here, self.machine, self.dt))

    def actuate(self, profile: np.ndarray, kind: str = "tracking_actuate",
                meta: dict | None = None) -> MoveHandle:
        """tracking_actuate: play ``profile (N, J)`` duty in % open loop and record the response.

        Raises ValueError (nothing sent) unless every duty is finite and in -100…100 %."""
        duty = np.asarray(profile, dtype=np.float64)
        moving = (tuple(int(j) for j in np.flatnonzero(np.any(duty != 0, axis=0)))
                  if duty.ndim == 2 else ())
        return self.run(MovePlan(kind, kind, profile=duty, meta=dict(meta or {}), moving=moving))

    def _start(self, plan: MovePlan) -> MoveHandle:
        """Send an accepted plan: its path or profile sealed (``control/rt/sealed.py``) with the
        StartMove, and all its run needs to be saved by whoever outlives the move in a new
        move segment, where the controller records it."""
        kind, path, profile = plan.kind, plan.path, plan.profile
        samples = len(path if path is not None else profile)
        meta = segment_meta(self.machine, kind, self.dt, self.data_dir, self.pid, {
            "backend": self.backend, "timing": self.timing.describe(self.machine),
            "coefficients": {k: {**coefficients_record(c), "check": self.coefficient_checks[k]}
                             for k, c in self.coefficients.items()},
            # what a saved run's summary needs of its plan (control.motion.plan.run_summaries)
            "approach_samples": plan.approach,
            "moving": list(plan.moving),
            "open_loop": path is None,
            **plan.meta,
        })
        encoded = encode_meta(meta)
        layout = MoveLayout(samples, self.machine.n_joints, len(encoded),
                            self.settle_rows if path is not None else 0)
        move_id = next(self._ids)
        segment = shm.create(f"mv{next(_MOVES)}", layout.size,
                             f"a {kind} move of {samples * self.dt:.1f} s")
        layout.write_header(segment.buf)
        layout.write_meta(segment.buf, encoded)
        handle = MoveHandle(move_id, kind, samples, meta, plan, segment, layout)
        self._moves[move_id] = handle
        path_fd = -1
        try:
            path_fd = sealed.seal(path if path is not None else profile)
            self._send(StartMove(move_id, segment.name, kind, path is None, samples), (path_fd,))
        except BaseException:
            if path_fd >= 0:
                os.close(path_fd)
            self._moves.pop(move_id, None)
            shm.release(segment, unlink=True)
            raise
        self._forget_manual()  # the move ends manual actuation
        self._dispatch(Event(MoveStarted(move_id, kind, samples * self.dt)))
        return handle

    @property
    def settle_rows(self) -> int:
        """Rows a closed-loop move's segment has after its path for its settle: goal_time's,
        and two to spare (the controller records no more than there is room for)."""
        return math.ceil(self.machine.goal_time_s / self.dt) + 2

    def wait(self, handle: MoveHandle, timeout: float | None = None) -> MoveResult:
        """Block until the move ends and return its result: ``complete`` once in position
        after its path (``MoveResult.complete``), ``unsettled`` if not within goal_time, or
        aborted, E-stop or fault."""
        if not handle.done.wait(timeout):
            raise TimeoutError(f"move {handle.move_id} ({handle.kind}) still running after "
                               f"{timeout:g} s")
        assert handle.result is not None
        return handle.result

    # -- observation -----------------------------------------------------------------------

    def status(self) -> Status:
        """The controller's newest status snapshot (consistent: read under the seqlock);
        ControllerError once the client is closed (its shared memory is let go)."""
        try:
            return self.layout.status.decode(self._status.read())
        except TimeoutError:  # the writer died mid-record: the last status is torn
            if self.dead or not self.alive:
                raise ControllerError(self.dead or "the control process has exited") from None
            raise
        except ValueError:  # a released segment: closed, maybe by another thread meanwhile
            if self._closing.is_set():
                raise ControllerError(CLOSED) from None
            raise

    @property
    def heartbeat_ns(self) -> int:
        """The heartbeat word as last written (monotonic ns), by whichever client beats."""
        return self._words[HEARTBEAT_WORD]

    @property
    def segment_name(self) -> str:
        """The control segment's name in /dev/shm."""
        return self.link.segment.name

    def histogram(self) -> LatencyHistogram:
        """The loop's wake-up lateness histogram in 5 µs bins, as Table 2.1."""
        if self._closing.is_set():  # its shared memory is let go, as ``status`` says
            raise ControllerError(CLOSED)
        return LatencyHistogram.from_counters(
            self.layout.histogram(self.link.segment.buf).copy(), self.status().overruns)

    def poll_events(self) -> list[Event]:
        """Every event since the last call, oldest first."""
        out = []
        with contextlib.suppress(queue.Empty):
            while True:
                out.append(self.events.get_nowait())
        return out

    def wait_event(self, kind: str, timeout: float = 5.0,
                   match: Callable[[Event], bool] | None = None) -> Event:
        """Wait for the next event of ``kind`` (others are dropped)."""
        deadline = time.monotonic() + timeout
        while (left := deadline - time.monotonic()) > 0:
            try:
                event = self.events.get(timeout=left)
            except queue.Empty:
                break
            if event.kind == kind and (match is None or match(event)):
                return event
        raise TimeoutError(f"no {kind!r} event within {timeout:g} s")

    def check(self) -> None:
        """Raise ``ControllerError`` if the controller has died."""
        if self.dead:
            raise ControllerError(self.dead)


def _check_speed_mode(mode: object) -> None:
    if mode not in MODES:
        raise ValueError(f"speed mode {mode!r} is not one of {', '.join(MODES)}")
