"""The runner: a checked program played through a ``ControlClient`` one step at a time.

Lifecycle, in words (``RunnerState``): ``ready`` → ``running`` (``run``: every step to the
end; ``single_step``: one step, then ``held``) → ``done`` when every step came in position,
``failed`` when one did not (an E-stop, a fault, a move not in position within goal_time, a
step that could not be planned or sent: its result says why), ``stopped`` when the operator
stopped it (``stop``: the move in progress is held where it is, the program ends). ``pause``
is a feed hold (``ControlClient.pause``: the move decelerates on its path and stands; a
timed wait stops counting), ``resume`` goes on. ``proceed`` is the operator's key that ends a
``wait = "operator"``.

Each step is planned from where the joints are when it starts (the check planned it from
where the step before was to end; ``control.program.check``), sent, and waited for; its
``StepResult`` is kept in ``results`` and reported, as are the start of each step and the
end of the program, through ``on_report`` (called on the runner's thread: a TUI posts it to
its own loop), and ``MoveStarted`` once a step's move is under way. ``run`` and
``single_step`` start a thread; ``run_next`` runs the next step in the caller's thread
instead (a caller that drives the program itself).

Every move of a program run carries ``meta["program"]`` in its run's metadata: the
program's name and file, the program-run id (one per ``Runner``), the step's number and
title and its repeat passes, so the runs of one program run can be found together
(``servodesk runs list --program ID``). Waits count the controller's clock (in lockstep,
the simulator's time, as fast as it runs).
"""

from __future__ import annotations

import contextlib
import enum
import secrets
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from datetime import UTC, datetime
from typing import TYPE_CHECKING, Any

import numpy as np

from control.link import ControllerError
from control.motion.plan import result_records
from control.program import move_steps
from control.program.check import CheckedProgram
from control.program.model import Feed, Visit, Wait
from control.rt.layout import Mode

if TYPE_CHECKING:
    from control.client import ControlClient, MoveHandle, MoveResult

POLL_S = 0.01  # how often a wait or a move looks at the stop, the E-stop and the clock
INITIALISE_S = 120.0  # the rig's ram from its top to the bottom stop at 20 % takes ~30 s
START_WAIT_S = 10.0  # a move the controller took is running within a few ticks
STOPPED = "stopped by the operator"


class RunnerState(enum.Enum):
    READY = "ready"
    RUNNING = "running"
    PAUSED = "paused"
    HELD = "held"  # between single steps: the next one waits for run or single_step
    DONE = "done"
    FAILED = "failed"
    STOPPED = "stopped"

    @property
    def over(self) -> bool:
        return self in (RunnerState.DONE, RunnerState.FAILED, RunnerState.STOPPED)


@dataclass(frozen=True)
class StepResult:
    """How one visit of a step ended: ``status`` (a move's: ``complete``, ``unsettled: …``,
    ``estop: …``, ``aborted: …``; ``ok`` for a wait or a feed, ``there already`` for a go
    to where the joints are; ``error: …`` for a step that could not run), ``ok`` when it
    completed (in position, for a move), ``seconds`` on the controller's clock (a move's: its
    run's, approach, path and settle, stretched by a feed override or hold), and the move's
    result for a step that moved."""

    visit: Visit
    status: str
    ok: bool
    seconds: float = 0.0
    move: MoveResult | None = None

    def figures(self) -> dict[str, Any]:
        """The result as JSON-ready figures (``servodesk run --json``)."""
        step = self.visit.step
        out: dict[str, Any] = {"step": step.number, "title": step.title,
                               "passes": list(self.visit.passes), "status": self.status,
                               "ok": self.ok, "seconds": round(self.seconds, 4)}
        move = self.move
        if move is not None:
            out["kind"] = move.plan.kind if move.plan is not None else move.run.kind
            out["run"] = move.files.stem if move.files is not None else None
            out["save_error"] = move.save_error or None
            out["settle"] = move.settle or None
            out["metrics"] = result_records(move.summaries())
        return out


@dataclass(frozen=True)
class ProgramOutcome:
    """A program run as it ended: ``state`` (done, failed or stopped), why, its results."""

    run_id: str
    state: RunnerState
    reason: str
    results: tuple[StepResult, ...]

    @property
    def complete(self) -> bool:
        return self.state is RunnerState.DONE


@dataclass(frozen=True)
class StepStarted:
    visit: Visit


@dataclass(frozen=True)
class MoveStarted:
    """The step's move is under way on the controller (``handle``: its id, plan, samples)."""

    visit: Visit
    handle: MoveHandle


@dataclass(frozen=True)
class StepDone:
    result: StepResult


@dataclass(frozen=True)
class ProgramEnded:
    outcome: ProgramOutcome


Report = StepStarted | MoveStarted | StepDone | ProgramEnded


def new_run_id() -> str:
    """A program run's id: its UTC start and a few random letters (``20261127-051200-3fa9``)."""
    return f"{datetime.now(UTC):%Y%m%d-%H%M%S}-{secrets.token_hex(2)}"


class Runner:
    """Runs ``checked`` through ``client`` (module docstring)."""

    def __init__(self, client: ControlClient, checked: CheckedProgram, *,
                 on_report: Callable[[Report], None] | None = None,
                 run_id: str | None = None) -> None:
        self.client = client
        self.checked = checked
        self.on_report = on_report
        self.run_id = run_id or new_run_id()
        self.results: list[StepResult] = []
        self.next = 0  # the index of the next visit to run
        self.state = RunnerState.READY
        self.reason = ""
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._go_on = threading.Event()  # the operator's key, for a wait
        self._paused = threading.Event()
        self._thread: threading.Thread | None = None
        self._ended = threading.Event()
        self._moving: MoveHandle | None = None

    # -- the operator's controls --------------------------------------------------------

    def run(self) -> None:
        """Run from the next step to the end, on the runner's thread."""
        self._start(single=False)

    def single_step(self) -> None:
        """Run the next step, then hold (``held``)."""
        self._start(single=True)

    def pause(self) -> None:
        """Feed hold: the move stands on its path; a timed wait stops counting."""
        with self._lock:
            if self.state is not RunnerState.RUNNING:
                return
            self.state = RunnerState.PAUSED
            self._paused.set()
        self.client.pause()

    def resume(self) -> None:
        with self._lock:
            if self.state is not RunnerState.PAUSED:
                return
            self.state = RunnerState.RUNNING
            self._paused.clear()
        self.client.resume()

    def stop(self) -> None:
        """Hold where the joints are and end the program (after its current step's result)."""
        with self._lock:
            if self.state.over:
                return
            self._stop.set()
            running = self._thread is not None and self._thread.is_alive()
            self._paused.clear()
        if self._moving is not None:
            self.client.hold(f"program {STOPPED}")
        if not running:
            self._end(RunnerState.STOPPED, STOPPED)

    def proceed(self) -> None:
        """The operator's go-on for a ``wait = "operator"`` step."""
        self._go_on.set()

    def wait(self, timeout: float | None = None) -> ProgramOutcome | None:
        """The outcome once the program has ended (None if it has not within ``timeout``)."""
        if not self._ended.wait(timeout):
            return None
        return self.outcome()

    def wait_idle(self, timeout: float | None = None) -> bool:
        """Whether the runner's thread is idle (held, or ended) within ``timeout``."""
        thread = self._thread
        if thread is not None:
            thread.join(timeout)
            return not thread.is_alive()
        return True

    def outcome(self) -> ProgramOutcome:
        return ProgramOutcome(self.run_id, self.state, self.reason, tuple(self.results))

    @property
    def current(self) -> Visit | None:
        """The visit running or to run next (None once past the last)."""
        visits = self.checked.visits
        return visits[self.next] if self.next < len(visits) else None

    # -- running ------------------------------------------------------------------------

    def _start(self, single: bool) -> None:
        with self._lock:
            if self.state not in (RunnerState.READY, RunnerState.HELD):
                raise RuntimeError(f"the program is {self.state.value}: it runs from ready or "
                                   "held only")
            self.state = RunnerState.RUNNING
            self._thread = threading.Thread(target=self._loop, args=(single,),
                                            name=f"program {self.run_id}", daemon=True)
            self._thread.start()

    def _loop(self, single: bool) -> None:
        try:
            self._steps(single)
        except Exception as exc:  # a bug here, or in on_report: hold, and end the program
            with contextlib.suppress(ControllerError):
                self.client.hold("program failed")
            self._end(RunnerState.FAILED, f"the runner failed: {exc!r}")

    def _steps(self, single: bool) -> None:
        while True:
            while self._paused.is_set() and not self._stop.is_set():
                time.sleep(POLL_S)  # a feed hold lasts until resume: no new step starts in one
            result = self.run_next()
            if result is None or self.state.over:
                return
            if single:
                with self._lock:
                    paused = self._paused.is_set()
                    self._paused.clear()  # held between steps: the next one starts unpaused
                    if self.state in (RunnerState.RUNNING, RunnerState.PAUSED):
                        self.state = RunnerState.HELD
                if paused:
                    self.client.resume()
                return

    def run_next(self) -> StepResult | None:
        """Run the next step in this thread; its result (None when none is left). Ends the
        program (``done``, ``failed``, ``stopped``) after its last step or a step that did not
        complete."""
        visit = self.current
        if visit is None and not self.state.over:  # nothing to run (comments only)
            self._end(RunnerState.DONE, "every step completed")
        if visit is None or self.state.over:
            return None
        if self.state in (RunnerState.READY, RunnerState.HELD):
            self.state = RunnerState.RUNNING
        self._go_on.clear()  # a key before the prompt is not its answer; one after it is
        self._report(StepStarted(visit))
        result = self._visit(visit)
        self.results.append(result)
        self.next += 1
        self._report(StepDone(result))
        if self._stop.is_set():
            self._end(RunnerState.STOPPED, STOPPED)
        elif not result.ok:
            self._end(RunnerState.FAILED, f"{visit.where} ({visit.step.title}): {result.status}")
        elif self.current is None:
            self._end(RunnerState.DONE, "every step completed")
        return result

    def _end(self, state: RunnerState, reason: str) -> None:
        with self._lock:
            if self.state.over:
                return
            self.state, self.reason = state, reason
        self._ended.set()
        self._report(ProgramEnded(self.outcome()))

    def _report(self, report: Report) -> None:
        if self.on_report is not None:
            self.on_report(report)

    def _visit(self, visit: Visit) -> StepResult:
        step = visit.step
        try:
            if self._stop.is_set():
                return StepResult(visit, STOPPED, False)
            if self.client.latched:
                return StepResult(visit, "estop: the E-stop is latched: release it first",
                                  False)
            if isinstance(step, Wait):
                return self._wait(visit)
            if isinstance(step, Feed):
                self.client.feed_override(step.percent / 100.0)
                return StepResult(visit, "ok", True)
            if move_steps.initialises(step, self.checked.machine):
                return self._initialise(visit)
            return self._move(visit)
        except move_steps.StepProblem as exc:
            return StepResult(visit, f"error: {exc}", False)
        except (ControllerError, ValueError, TimeoutError) as exc:
            return StepResult(visit, f"error: {exc}", False)

    def _move(self, visit: Visit) -> StepResult:
        checked, client = self.checked, self.client
        here = np.array(client.status().position)
        plan = move_steps.plan(visit.step, checked.machine, here, client.dt,
                               checked.position, checked.program.source.parent)
        if plan is None:
            return StepResult(visit, "there already", True)
        plan = replace(plan, meta={**plan.meta, "program": self._meta(visit)})
        handle = client.run(plan)
        self._moving = handle
        try:
            if self._stop.is_set():  # stopped while it was being sent
                client.hold(f"program {STOPPED}")
            self._started(visit, handle)
            while not handle.done.wait(POLL_S):
                client.check()
        finally:
            self._moving = None
        result = handle.result
        assert result is not None
        run = result.run  # its time column: the move's, stretched by a feed override or hold
        seconds = float(run.t[-1] - run.t[0]) if run.samples else 0.0
        return StepResult(visit, result.status, result.complete and not self._stop.is_set(),
                          seconds, result)

    def _started(self, visit: Visit, handle: MoveHandle) -> None:
        """Report the move once the controller follows it (or has: a short one in lockstep
        may be over before the first look)."""
        deadline = time.monotonic() + START_WAIT_S
        while (not handle.done.is_set() and time.monotonic() < deadline
               and self.client.status().move_id != handle.move_id):
            time.sleep(POLL_S / 4)
        self._report(MoveStarted(visit, handle))

    def _meta(self, visit: Visit) -> dict[str, Any]:
        program = self.checked.program
        return {"name": program.name, "file": str(program.source), "run_id": self.run_id,
                "step": visit.step.number, "title": visit.step.title,
                "passes": list(visit.passes), "visit": visit.index}

    def _wait(self, visit: Visit) -> StepResult:
        step = visit.step
        assert isinstance(step, Wait)
        waited, last = 0.0, self.client.status().time_s
        while True:
            if self._stop.is_set():
                return StepResult(visit, STOPPED, False, waited)
            status = self.client.status()
            if status.estop:
                return StepResult(visit, "estop: the E-stop latched during the wait", False,
                                  waited)
            self.client.check()
            if not self._paused.is_set():
                waited += max(0.0, status.time_s - last)
            last = status.time_s
            if step.operator and self._go_on.is_set():
                return StepResult(visit, "ok", True, waited)
            if not step.operator and waited >= step.seconds:
                return StepResult(visit, "ok", True, waited)
            if step.operator:
                self._go_on.wait(POLL_S)
            else:
                time.sleep(POLL_S)

    def _initialise(self, visit: Visit) -> StepResult:
        started = self.client.status().time_s
        ok, status = initialise_rig(self.client, self._stop.is_set)
        return StepResult(visit, status, ok, self.client.status().time_s - started)


def initialise_rig(client: ControlClient, stopped: Callable[[], bool] = lambda: False
                   ) -> tuple[bool, str]:
    """The rig's initialise (section 3.5), waited for: whether it completed, and its status
    (the ``initialised`` event's, a fault's, the E-stop's, ``stopped``'s). It reads the
    client's event queue (``poll_events``), as ``servodesk move --initialise`` does."""
    client.poll_events()  # what came before is not this initialise's
    client.initialise()
    deadline = time.monotonic() + INITIALISE_S
    while time.monotonic() < deadline:
        if stopped():
            client.hold(f"program {STOPPED}")
            return False, STOPPED
        for event in client.poll_events():
            if event.kind == "initialised":
                status = str(event.payload["status"])
                return status.startswith("complete"), status
            if event.kind == "fault" and client.status().mode != Mode.INITIALISE:
                return False, f"fault: {event.message}"
        if client.status().estop:
            return False, "estop: the E-stop latched during the initialise"
        client.check()
        time.sleep(POLL_S)
    return False, f"initialise not finished within {INITIALISE_S:g} s"
