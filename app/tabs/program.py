"""Program: open a program file (``docs/programs.md``), check it whole, see its steps with the
current one marked and each done step's result, run it, step it, hold it, stop it, start it
from a chosen step, and edit its order (a step up or down, delete, insert a go to the
position selected in Positions, save).

Nothing runs until the program checks clean from where the joints are; every edit is checked
again. The runner (``control.program.Runner``) plays it on its own thread; its reports come
back as ``Reported`` messages, so the UI never waits for a move. In reduced speed (T1) a
program runs only while the enabling key (space) is held: a terminal sends no key-up, so
"held" is its auto-repeat arriving within a timeout (the Jog tab's ``KeyRepeat``), and
silence is a release: a feed hold; pressing again goes on. In automatic, ``r`` runs it with
no key held. A single step (``n``) needs no held key in either mode: the controller holds
its speed to T1's, as for any move started by hand.
"""

from __future__ import annotations

import contextlib
import math
import os
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import ClassVar

import numpy as np
from rich.text import Text
from textual import work
from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import Horizontal
from textual.message import Message
from textual.suggester import SuggestFromList
from textual.timer import Timer
from textual.widgets import DataTable, Input

from app.desk import Desk
from app.messages import RunsChanged
from app.tabs.jog import (
    RELEASE_CHECK_S,
    STALL_S,
    TOOL_RELEASE,
    KeyRepeat,
    behind_queued_keys,
)
from app.tabs.program_edit import delete_step, insert_go_to, move_step
from app.tabs.tab import TabPage
from app.widgets.dialogs import ConfirmScreen
from app.widgets.live_text import LiveText
from control.client import ControllerError
from control.motion.positions import PositionsError, load_positions, positions_file
from control.program import (
    CheckedProgram,
    Problem,
    Program,
    ProgramError,
    Runner,
    RunnerState,
    StepResult,
    check,
    dump_program,
    move_steps,
    read_program,
    visits,
)
from control.program.model import Step, Wait
from control.program.runner import MoveStarted, ProgramEnded, Report, StepDone, StepStarted
from control.rt.layout import Mode
from hw.machine import Machine

EXAMPLES = Path(__file__).resolve().parents[2] / "programs"  # the repository's, when there
ENABLE_KEY = 0  # the enabling key's id in its KeyRepeat
WATCH_HZ = 10.0  # while a program runs: T1 without the enabling key held is a feed hold
RESULT_CHARS = 32
COLUMNS = (("at", ""), ("n", "#"), ("step", "step"), ("line", "line"), ("result", "result"),
           ("settle", "settle"), ("time", "time"), ("run", "run"))
RUNNING = (RunnerState.RUNNING, RunnerState.PAUSED)
T1_RUN = ("reduced speed (T1): hold space to run the program (release: feed hold); n, then "
          "space held, runs one step; ^Y switches to automatic")


class ProgramTab(TabPage):
    """Open, check, run and edit a program."""

    REFRESH_HZ = 5.0
    TITLE = "Program"
    LATER = ("#program-lower",)
    BINDINGS: ClassVar = [
        Binding("r", "run", "run"),
        Binding("space", "enable", "hold: run (T1)", key_display="space"),
        Binding("n", "single_step", "one step"),
        Binding("p", "pause", "hold/resume"),
        Binding("s", "stop", "stop"),
        Binding("f", "run_from", "from step…"),
        Binding("g", "go_on", "go on (wait)"),
        Binding("l", "load", "open"),
        Binding("c", "check", "check"),
        Binding("u", "move(-1)", "step up"),
        Binding("d", "move(1)", "step down"),
        Binding("delete", "delete", "delete", key_display="Del"),
        Binding("i", "insert", "insert go to"),
        Binding("w", "save", "save"),
    ]

    @dataclass
    class Loaded(Message, bubble=False):
        """A file was read (from the file worker): its program, or the problems of its form;
        ``missing``: there is no file at ``path`` (a new program may start there)."""

        path: Path
        program: Program | None
        problems: list[Problem]
        missing: bool = False

    @dataclass
    class Checked(Message, bubble=False):
        """A program was checked from where the joints were (from the check worker):
        ``checked`` if clean, else its problems; ``then`` what was asked (run, step, from,
        enable) once it checks clean; ``generation`` tells a stale check."""

        program: Program
        checked: CheckedProgram | None
        problems: list[Problem]
        then: str
        generation: int

    @dataclass
    class Reported(Message, bubble=False):
        """A report of the runner (from its thread)."""

        report: Report

    @dataclass
    class Saved(Message, bubble=False):
        """The program was written to ``path`` and read back (``program``), or ``error``."""

        path: Path
        program: Program | None
        error: str = ""

    @dataclass
    class Examples(Message, bubble=False):
        """The program files found (``paths``), this machine's repository example first."""

        paths: list[str]
        example: str

    def __init__(self, desk: Desk, *, id: str | None = None) -> None:
        super().__init__(desk, id=id)
        self.program: Program | None = None
        self.checked: CheckedProgram | None = None
        self.problems: list[Problem] = []
        self.dirty = False  # edited since it was read or saved
        self.checking = False
        self.runner: Runner | None = None
        self.results: dict[int, StepResult] = {}  # each step's latest result, by number
        self.at: int | None = None  # the step running, or to run next
        self.moving = ""  # what the step's move is doing, while it moves
        self.enabling = KeyRepeat(most=TOOL_RELEASE[0], factor=TOOL_RELEASE[1])
        self._generation = 0
        self._single_armed = False  # T1: n pressed, the enabling key will run one step
        self._release_seen = -math.inf  # the release check's last look (-inf: not looking)
        self._paused_seen = False  # the controller's feed hold as last seen (^F's edges)

    def compose(self) -> ComposeResult:
        with Horizontal(id="program-top"):
            yield Input(placeholder="program file (TOML): Enter or l opens it",
                        id="program-path", compact=True)
        yield DataTable(id="program-table", cursor_type="row", zebra_stripes=True)
        with Horizontal(id="program-lower"):
            yield LiveText(id="program-state")
            yield LiveText(id="program-problems")

    def on_mount(self) -> None:
        super().on_mount()
        table = self.query_one("#program-table", DataTable)
        for key, label in COLUMNS:
            table.add_column(label, key=key)
        self._release_timer: Timer = self.set_interval(
            RELEASE_CHECK_S, behind_queued_keys(self, self._check_release), pause=True)
        self._watch_timer: Timer = self.set_interval(1.0 / WATCH_HZ, self._watch, pause=True)
        self._problems_text()
        self._find_examples()

    def focus_main(self) -> None:
        self.query_one("#program-table", DataTable).focus()

    # -- files ---------------------------------------------------------------------------------

    @work(thread=True, group="program-file")
    def _find_examples(self) -> None:
        """Program files in the data directory's ``programs`` folder and the repository's."""
        found: list[str] = []
        example = ""
        for folder in (self.desk.data_dir / "programs", EXAMPLES):
            with contextlib.suppress(OSError):
                for path in sorted(folder.glob("*.toml")):
                    found.append(str(path))
                    if not example and folder == EXAMPLES:
                        with contextlib.suppress(ProgramError):
                            if read_program(path).machine == self.machine.name:
                                example = str(path)
        self.post_message(self.Examples(found, example))

    def on_program_tab_examples(self, message: Examples) -> None:
        field = self.query_one("#program-path", Input)
        field.suggester = SuggestFromList(message.paths, case_sensitive=True)
        if not field.value and message.example:
            field.value = message.example

    def on_input_submitted(self, event: Input.Submitted) -> None:
        if event.input.id == "program-path":
            event.stop()
            self.action_load()
            self.focus_main()

    def action_load(self) -> None:
        """Read the file named in the path field, then check it."""
        if refusal := self._running_refusal("open another program"):
            self._say(refusal, "bold red")
            return
        text = self.query_one("#program-path", Input).value.strip()
        if not text:
            self._say("type a program file's path first (suggestions as you type)", "yellow")
            return
        try:
            path = self.desk.typed_path(text, "open a program")
        except ValueError as exc:
            self._say(str(exc), "bold red")
            return
        self._read(path)

    @work(thread=True, group="program-file")
    def _read(self, path: Path) -> None:
        if not path.exists():
            self.post_message(self.Loaded(path, None, [], missing=True))
            return
        try:
            program = read_program(path)
        except ProgramError as exc:
            self.post_message(self.Loaded(path, None, list(exc.problems)))
            return
        self.post_message(self.Loaded(path, program, []))

    def on_program_tab_loaded(self, message: Loaded) -> None:
        if message.missing:
            self._offer_new(message.path)
            return
        self.runner, self.results, self.at = None, {}, None
        if message.program is None:
            self.program, self.checked, self.problems = None, None, message.problems
            self._show_steps()
            self._say(f"{message.path}: {len(message.problems)} problem(s): it cannot run "
                      "until they are fixed (fix the file, then l)", "bold red")
            return
        self._use(message.program, dirty=False)
        self._say(f"opened {message.path}", "green")

    def _offer_new(self, path: Path) -> None:
        def answer(yes: bool | None) -> None:
            if yes:
                self.runner, self.results, self.at = None, {}, None
                self._use(Program(path.stem, self.machine.name, path, ()), dirty=True)
                self._say(f"new program {path.name}: select a position in Positions (F9), "
                          "then i here inserts a go to it; w saves", "green")

        self.app.push_screen(ConfirmScreen(
            f"Start a new program {path.name}?",
            f"There is no file at {path}. A new program for {self.machine.title} starts "
            "empty; w writes it there.", "New program"), answer)

    def _use(self, program: Program, *, dirty: bool, select: int | None = None) -> None:
        """Show ``program`` and check it from where the joints are."""
        self.program, self.dirty = program, dirty
        self.checked = None
        self._show_steps(select)
        self._check()

    def action_save(self) -> None:
        """Write the program to the path in the field (asks before replacing a file)."""
        program = self.program
        if program is None:
            self._say("nothing to save: open or start a program first (l)", "yellow")
            return
        if refusal := self.desk.refusal("save a program"):
            self._say(refusal, "bold red")
            return
        text = self.query_one("#program-path", Input).value.strip() or str(program.source)
        try:
            path = self.desk.typed_path(text, "save a program")
        except ValueError as exc:
            self._say(str(exc), "bold red")
            return
        if not program.steps:
            self._say("no steps to save: insert one first (i)", "yellow")
            return

        def answer(yes: bool | None) -> None:
            if yes:
                self._write(program, path)

        if not path.exists():
            self._write(program, path)
            return
        self.app.push_screen(ConfirmScreen(
            f"Replace {path.name}?",
            f"{path} is written with the {program.count} steps listed here, in this order. "
            "Its # comments are not kept (a step's label is).", "Save"), answer)

    @work(thread=True, group="program-file")
    def _write(self, program: Program, path: Path) -> None:
        """Written whole beside the file, then renamed over it: never half a program."""
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            fd, temporary = tempfile.mkstemp(prefix=f".{path.name}.", dir=path.parent)
            try:
                with os.fdopen(fd, "w", encoding="utf-8") as out:
                    out.write(dump_program(program))
                os.replace(temporary, path)
            except BaseException:
                with contextlib.suppress(OSError):
                    os.unlink(temporary)
                raise
            saved = read_program(path)
        except (OSError, ValueError) as exc:
            self.post_message(self.Saved(path, None, f"cannot save {path}: {exc}; choose "
                                         "another path in the field and press w again"))
            return
        self.post_message(self.Saved(path, saved))

    def on_program_tab_saved(self, message: Saved) -> None:
        if message.program is None:
            self._say(message.error, "bold red")
            self.notify(message.error, severity="error", timeout=8)
            return
        select = self._selected()
        self._use(message.program, dirty=False, select=select)
        self._say(f"saved {message.path}", "green")
        self.notify(f"saved {message.path}")

    # -- the check -----------------------------------------------------------------------------

    def action_check(self) -> None:
        if self.program is None:
            self._say("open a program first (l)", "yellow")
            return
        self._check()

    def _check(self, start: int = 1, then: str = "") -> None:
        program = self.program
        if program is None:
            return
        self._generation += 1
        self.checking = True
        self.problems = []
        self._problems_text()
        status = self.status()
        here = (np.array(status.position) if status is not None
                else _resting(self.machine))
        self._check_worker(program, here, start, then, self._generation)

    @work(thread=True, group="program-check")
    def _check_worker(self, program: Program, here: np.ndarray, start: int, then: str,
                      generation: int) -> None:
        source = str(program.source)
        if not program.steps:
            problems = [Problem(source, 0, "no steps yet: select a position in Positions (F9), "
                                           "then press i here to insert a go to it")]
            self.post_message(self.Checked(program, None, problems, then, generation))
            return
        try:
            book = load_positions(positions_file(self.desk.data_dir, self.machine), self.machine)
            checked = check(program, self.machine, book, here, start=start, dt=self.desk.dt)
        except PositionsError as exc:
            problem = Problem(source, 0, f"the positions file: {exc}")
            self.post_message(self.Checked(program, None, [problem], then, generation))
            return
        except ProgramError as exc:
            self.post_message(self.Checked(program, None, list(exc.problems), then, generation))
            return
        self.post_message(self.Checked(program, checked, [], then, generation))

    def on_program_tab_checked(self, message: Checked) -> None:
        if message.generation != self._generation or message.program is not self.program:
            return  # an edit or another check came since
        self.checking = False
        self.checked, self.problems = message.checked, message.problems
        self._problems_text()
        self._mark_problems()
        if message.checked is None:
            if message.then:
                self._say(f"not run: the program has {len(message.problems)} problem(s) "
                          "(listed): fix them first", "bold red")
            return
        if message.then:
            self._go(message.then, message.checked)

    def _problems_text(self) -> None:
        widget = self.query_one("#program-problems", LiveText)
        if self.program is None and not self.problems:
            widget.show(Text("no program open: type its path above (or a new one) and press "
                             "Enter", "dim"))
            return
        if not self.problems:
            text = ("checking…" if self.checking else
                    "checks clean from where the joints are" if self.checked is not None
                    else "")
            widget.show(Text(text, "green"))
            return
        lines = [Text(f"{len(self.problems)} problem(s): nothing runs until they are fixed",
                      "bold red")]
        for p in self.problems:
            where = (f"line {p.line}" if p.line else "") + (
                f"{', ' if p.line else ''}step {p.step.number}" if p.step is not None else "")
            lines.append(Text.assemble((where + ": " if where else "", "bold"), p.text))
        widget.show(Text("\n").join(lines))

    def _mark_problems(self) -> None:
        """The steps with a problem: their result cell says so."""
        wrong = {p.step.number: p.text for p in self.problems if p.step is not None}
        table = self.query_one("#program-table", DataTable)
        for number, text in wrong.items():
            with contextlib.suppress(Exception):
                table.update_cell(str(number), "result",
                                  Text(f"✗ {text}"[:RESULT_CHARS], "bold red"), update_width=True)

    # -- the listing ---------------------------------------------------------------------------

    def _show_steps(self, select: int | None = None) -> None:
        table = self.query_one("#program-table", DataTable)
        keep = select if select is not None else self._selected()
        table.clear()
        program = self.program
        if program is None:
            return
        for step, depth in program.listing():
            table.add_row(*self._cells(step.number, "  " * depth + step.title, step.line),
                          key=str(step.number))
        if keep is not None and table.row_count:
            table.move_cursor(row=min(keep, table.row_count) - 1)

    def _cells(self, number: int, title: str, line: int) -> list[str | Text]:
        result = self.results.get(number)
        mark = Text("▶", "bold cyan") if number == self.at else ""
        name = Text(title, "bold cyan") if number == self.at else title
        return [mark, str(number), name, str(line or ""), *_result_cells(result)]

    def _row(self, number: int) -> None:
        """Redraw step ``number``'s row (its mark and result)."""
        program = self.program
        if program is None:
            return
        with contextlib.suppress(ValueError):
            step = program.step(number)
            depth = next(d for s, d in program.listing() if s.number == number)
            cells = self._cells(number, "  " * depth + step.title, step.line)
            table = self.query_one("#program-table", DataTable)
            for (key, _), cell in zip(COLUMNS, cells, strict=True):
                with contextlib.suppress(Exception):
                    table.update_cell(str(number), key, cell, update_width=True)

    def _mark(self, number: int | None) -> None:
        before, self.at = self.at, number
        for n in {before, number} - {None}:
            self._row(n)  # type: ignore[arg-type]

    def _selected(self) -> int | None:
        table = self.query_one("#program-table", DataTable)
        if not table.row_count:
            return None
        row_key, _ = table.coordinate_to_cell_key(table.cursor_coordinate)
        return int(row_key.value) if row_key.value is not None else None

    # -- running -------------------------------------------------------------------------------

    def action_run(self) -> None:
        """Run to the end (automatic); in T1 the enabling key runs it."""
        if self._reduced():
            self._refuse(T1_RUN)
            return
        self._start("run")

    def action_single_step(self) -> None:
        """One step; in T1 it runs while the enabling key is held, as a run does (ISO
        10218-1: no motion in T1 without it), so n only makes space's next hold one step."""
        if not self._reduced():
            self._start("step")
            return
        runner = self.runner
        first = self._first(1)
        if runner is not None and runner.state in (RunnerState.READY, RunnerState.HELD):
            first = runner.current.step if runner.current else None
        if refusal := self._refusal(first):
            self._refuse(refusal)
            return
        self._single_armed = True
        self._say("reduced speed (T1): hold space to run one step (release: feed hold)", "cyan")

    def _start(self, then: str, start: int = 1) -> None:
        """Run (``run``), one step (``step``), or from ``start`` (``from``) once it checks
        clean from where the joints are now; a held or ready program goes on as it is."""
        runner = self.runner
        if runner is not None and runner.state in (RunnerState.READY, RunnerState.HELD) \
                and then in ("run", "step", "enable"):
            if refusal := self._refusal(runner.current.step if runner.current else None):
                self._refuse(refusal)
                return
            self._go(then, runner.checked, runner)
            return
        if runner is not None and not runner.state.over:
            self._refuse(f"the program is {runner.state.value}: "
                         + ("p resumes it, s stops it" if runner.state is RunnerState.PAUSED
                            else "wait for the step, p holds it, s stops it"))
            return
        if self.program is None:
            self._refuse("open a program first: its path above, then Enter (or l)")
            return
        if refusal := self._refusal(self._first(start)):
            self._refuse(refusal)
            return
        self._check(start, then)

    def _first(self, start: int) -> Step | None:
        """The first step that will run from ``start`` (for the unzeroed rig's refusal)."""
        program = self.program
        if program is None or not program.steps:
            return None
        with contextlib.suppress(ValueError):
            first = next(iter(visits(program, start)), None)
            return None if first is None else first.step
        return None

    def _go(self, then: str, checked: CheckedProgram, runner: Runner | None = None) -> None:
        """Start what was asked, now that ``checked`` is clean (a new program run unless
        ``runner`` goes on); a new one is refused if the state changed during its check."""
        if runner is None and (refusal := self._refusal(
                checked.visits[0].step if checked.visits else None)):
            self._refuse(refusal)
            return
        needs_key = then == "enable" or (then == "step" and self._reduced())
        if needs_key and not self.enabling.held:
            self._say("the enabling key was let go before the check ended: hold space to run",
                      "yellow")
            return
        if runner is None:
            if self.runner is not None and not self.runner.state.over:
                self.runner.stop()
            runner = self.runner = Runner(self.connection, checked,  # type: ignore[arg-type]
                                          on_report=self._from_runner)
            self.results = {}
            self._show_steps()
            self._mark(runner.current.step.number if runner.current else None)
        self._single_armed = False
        try:
            if then == "step":
                runner.single_step()
            elif then == "from" and self._reduced():
                self._say(f"ready from step {checked.start}: {T1_RUN}", "cyan")
                return
            else:
                runner.run()
        except RuntimeError as exc:
            self._refuse(str(exc))
            return
        self._watch_timer.resume()
        self._state_text()

    def _from_runner(self, report: Report) -> None:
        """On the runner's thread: to the UI's."""
        with contextlib.suppress(RuntimeError):  # the app has closed
            self.post_message(self.Reported(report))

    def on_program_tab_reported(self, message: Reported) -> None:
        report = message.report
        if isinstance(report, StepStarted):
            self.moving = ""
            self._mark(report.visit.step.number)
        elif isinstance(report, MoveStarted):
            handle = report.handle
            self.moving = f"moving: {handle.plan.title}, {handle.samples * self.desk.dt:.2f} s"
        elif isinstance(report, StepDone):
            result = report.result
            self.moving = ""
            self.results[result.visit.step.number] = result
            self._row(result.visit.step.number)
            move = result.move
            if move is not None:
                if move.files is None and move.run.samples:
                    from app.tabs.moves import MovesTab  # its message: the Runs tab keeps it

                    self.post_message(MovesTab.RunUnsaved(move.run))
                self.post_message(RunsChanged())
            runner = self.runner
            following = runner.current if runner is not None else None
            self._mark(following.step.number if following is not None else None)
        elif isinstance(report, ProgramEnded):
            outcome = report.outcome
            self._mark(None)
            style = "green" if outcome.complete else "bold yellow"
            self._say(f"program {outcome.state.value}: {outcome.reason} · run {outcome.run_id}",
                      style)
            self.notify(f"program {outcome.state.value}: {outcome.reason}",
                        severity="information" if outcome.complete else "warning")
        self._state_text()

    def action_pause(self) -> None:
        """Feed hold of the running program, or resume (in T1 only the enabling key goes on)."""
        runner = self.runner
        if runner is None or runner.state not in RUNNING:
            self._refuse("no program is running: r runs it (T1: hold space)")
            return
        if runner.state is RunnerState.RUNNING:
            self._command(runner.pause)
        elif self._reduced():
            self._refuse("reduced speed (T1): hold space to go on")
        else:
            self._command(runner.resume)
        self._state_text()

    def action_stop(self) -> None:
        """Hold where the joints are and end the program run."""
        runner = self.runner
        if runner is None or runner.state.over:
            self._refuse("no program run to stop")
            return
        self._command(runner.stop)
        self._state_text()

    def action_go_on(self) -> None:
        """The operator's go-on for a ``wait = "operator"`` step."""
        runner = self.runner
        visit = runner.current if runner is not None else None
        if runner is None or visit is None or not (isinstance(visit.step, Wait)
                                                    and visit.step.operator):
            self._refuse("no step waits for the operator now")
            return
        runner.proceed()

    def action_run_from(self) -> None:
        """Start from the selected step, after asking."""
        number = self._selected()
        program = self.program
        if number is None or program is None:
            self._refuse("open a program and select the step to start from")
            return
        if self.runner is not None and self.runner.state in RUNNING:
            self._refuse("the program is running: stop it (s) first")
            return
        step = program.step(number)
        if refusal := self._refusal(self._first(number)):
            self._refuse(refusal)
            return

        def answer(yes: bool | None) -> None:
            if yes:
                self._start("from", number)
            else:
                self._say(f"not started: the start from step {number} was cancelled", "yellow")

        skipped = f"Steps 1…{number - 1} are skipped; " if number > 1 else ""
        self.app.push_screen(ConfirmScreen(
            f"Start from step {number} ({step.title})?",
            f"{skipped}step {number} is planned from where the joints are now (inside a "
            "repeat, that repeat's first pass starts there; its later passes run whole). "
            + ("In T1 it then runs while space is held." if self._reduced()
               else "It runs at once, to the end.") + " Esc is the E-stop.",
            f"Start at {number}"), answer)

    # -- the enabling key (T1) -----------------------------------------------------------------

    def action_enable(self) -> None:
        """Space: held, the program runs in T1; its first press starts or resumes it. A hold
        that goes on through the program's end, a stop or an E-stop starts nothing again:
        its repeats stay a hold (they used to be forgotten there, and the next repeat, taken
        for a new press, ran the program again); only a new press does."""
        if not self._reduced():
            self._say("automatic: r runs the program (space is T1's enabling key)", "dim")
            return
        new = self.enabling.press(ENABLE_KEY, time.monotonic())
        self._listen()
        if not new:
            return
        runner = self.runner
        if runner is not None and runner.state is RunnerState.PAUSED:
            if refusal := self._refusal(None, running=True):
                self._refuse(refusal)
                return
            self._command(runner.resume)
            self._state_text()
        elif runner is None or runner.state is not RunnerState.RUNNING:
            self._start("step" if self._single_armed else "enable")

    def _listen(self) -> None:
        """Look for the enabling key's release from now on (every RELEASE_CHECK_S)."""
        if self._release_seen == -math.inf:  # not listening: its first look is on time
            self._release_seen = time.monotonic()
        self._release_timer.resume()

    def _check_release(self) -> None:
        """Every RELEASE_CHECK_S while the enabling key is held: its release is a feed hold."""
        if self._release_seen == -math.inf:  # queued before the tab stopped listening
            return
        now = time.monotonic()
        late, self._release_seen = now - self._release_seen - RELEASE_CHECK_S, now
        if late > STALL_S:  # the UI was not listening: repeats may be waiting behind this
            self.enabling.excuse(late)
            return
        self.enabling.released(now)
        if self.enabling.held:
            return
        self._release_timer.pause()
        self._release_seen = -math.inf
        self._hold_released("the enabling key was let go")

    def _hold_released(self, why: str) -> None:
        """In T1 a program runs (a single step too) only while the enabling key is held."""
        runner = self.runner
        if runner is not None and runner.state is RunnerState.RUNNING and self._reduced():
            self._command(runner.pause)
            self._say(f"{why}: feed hold · press and hold space to go on", "bold yellow")
            self._state_text()

    def _watch(self) -> None:
        """While a program run lasts: T1 with no enabling key is a feed hold (^Y to T1
        mid-run, the tab left); the app's ^F hold and resume are the program's too."""
        runner = self.runner
        if runner is None or runner.state.over:
            self._watch_timer.pause()
            return
        status = self.status()
        if status is None:
            return
        if not self.enabling.held:
            self._hold_released("T1 needs the enabling key held")
        paused, before = status.paused, self._paused_seen
        self._paused_seen = paused
        if paused and not before and runner.state is RunnerState.RUNNING:
            self._command(runner.pause)  # ^F: its waits stop counting, no step starts
        elif before and not paused and runner.state is RunnerState.PAUSED:
            if self._reduced():  # ^F resumed the move, but only the enabling key may
                self._command(self.connection.pause)  # type: ignore[union-attr]
                self._say("reduced speed (T1): hold space to go on", "bold yellow")
            else:
                self._command(runner.resume)
        self._state_text()

    # -- editing -------------------------------------------------------------------------------

    def action_move(self, delta: int) -> None:
        number = self._editable("move a step")
        if number is None:
            return
        self._edit(lambda program: move_step(program, number, delta))

    def action_delete(self) -> None:
        number = self._editable("delete a step")
        if number is None:
            return
        self._edit(lambda program: delete_step(program, number))

    def action_insert(self) -> None:
        """A go to the position selected in Positions, after the selected step."""
        if self.program is None:
            self._refuse("open or start a program first: its path above, then Enter")
            return
        if refusal := self._editing_refusal("insert a step"):
            self._refuse(refusal)
            return
        positions = self.app.tabs.made_tab("positions")  # type: ignore[attr-defined]
        chosen = positions.selected() if positions is not None and positions.is_mounted else None
        if chosen is None:
            self._refuse("select a position in Positions (F9) first: i inserts a go to it")
            return
        speed = positions.go_speed()
        after = self._selected() if self.program.steps else None
        joints = chosen.joints if chosen.taught else None
        self._edit(lambda program: insert_go_to(program, after, chosen.name, speed, joints))

    def _editable(self, what: str) -> int | None:
        refusal = self._editing_refusal(what)
        number = self._selected()
        if not refusal and number is None:
            refusal = f"{what}: select a step first"
        if refusal:
            self._refuse(refusal)
            return None
        return number

    def _editing_refusal(self, what: str) -> str:
        if self.program is None:
            return f"{what}: open a program first"
        return self._running_refusal(what)

    def _running_refusal(self, what: str) -> str:
        runner = self.runner
        if runner is not None and not runner.state.over:
            return f"{what}: the program run is {runner.state.value}; stop it (s) first"
        return ""

    def _edit(self, change: Callable[[Program], tuple[Program, int | None]]) -> None:
        program = self.program
        assert program is not None
        try:
            edited, select = change(program)
        except ValueError as exc:  # a block's end, a repeat left empty (ProgramError)
            self._refuse(str(exc).splitlines()[0])
            return
        self.runner, self.results, self.at = None, {}, None
        self._use(edited, dirty=True, select=select)
        self._say("edited: checking again · w saves", "cyan")

    # -- refusals ------------------------------------------------------------------------------

    def _refusal(self, first: Step | None, *, running: bool = False) -> str:
        """Why a program cannot run now ("" if it can); ``first`` the step it starts with."""
        if self.connection is None or self.client is None:
            return "the controller is not running — " + (self.client_problem
                                                         or "wait for it to start")
        if refusal := self.desk.refusal("run a program"):
            return refusal
        status = self.status()
        if status is None:
            return "the controller is not running — the link is lost"
        if status.estop:
            return "the E-stop is latched: release it (^R) when it is safe, then run again"
        ours = self.runner is not None and self.runner.state in RUNNING  # held: not its move
        if (status.moving or status.mode == Mode.INITIALISE) and not (ours or running):
            return "a move is running (Moves or Positions tab): wait for it, or hold (^G)"
        if self.checking:
            return "the program is being checked: a moment"
        if not status.homed:
            with contextlib.suppress(move_steps.StepProblem):
                if first is not None and move_steps.initialises(first, self.machine):
                    return ""
            return ("the encoders are not zeroed: run Initialise (Moves tab) first, or begin "
                    'the program with move = "initialise"')
        return ""

    def _refuse(self, text: str) -> None:
        self._say(text, "bold red")
        self.notify(text, severity="error", timeout=6)

    def _reduced(self) -> bool:
        status = self.status()
        return status is not None and status.speed_mode == "reduced"

    def _command(self, call: Callable[[], None]) -> None:
        try:
            call()
        except (ControllerError, ValueError, OSError) as exc:
            self._refuse(str(exc))

    # -- the screen ----------------------------------------------------------------------------

    def _say(self, text: str, style: str) -> None:
        self._said = Text(text, style)
        self._state_text()

    def _state_text(self) -> None:
        program = self.program
        lines: list[Text] = []
        if program is not None:
            mode = "T1: hold space to run" if self._reduced() else "automatic: r runs"
            edited = " · edited, not saved (w)" if self.dirty else ""
            lines.append(Text.assemble((program.name, "bold"), f" · {program.count} steps · "
                                       f"{program.source}{edited} · {mode}"))
        runner = self.runner
        if runner is not None:
            state = runner.state.value
            visit = runner.current
            at = (f" · {visit.where}: {visit.step.title}" if visit is not None
                  and not runner.state.over else "")
            wait = (" · g goes on" if visit is not None and isinstance(visit.step, Wait)
                    and visit.step.operator and runner.state is RunnerState.RUNNING else "")
            lines.append(Text.assemble((state, _STATE_STYLE.get(runner.state, "")), at, wait,
                                       f" · run {runner.run_id}",
                                       f" · {self.moving}" if self.moving else ""))
        said = getattr(self, "_said", None)
        if said is not None:
            lines.append(said)
        self.query_one("#program-state", LiveText).show(Text("\n").join(lines))

    def refresh_live(self) -> None:
        self._state_text()

    def hidden(self) -> None:
        super().hidden()
        self.enabling.forget()  # its repeats no longer come here: in T1, a release

    def client_down(self, problem: str) -> None:
        super().client_down(problem)
        self.enabling.forget()


_STATE_STYLE = {RunnerState.RUNNING: "bold cyan", RunnerState.PAUSED: "bold yellow",
                RunnerState.HELD: "yellow", RunnerState.DONE: "bold green",
                RunnerState.FAILED: "bold red", RunnerState.STOPPED: "bold yellow"}


def _result_cells(result: StepResult | None) -> list[str | Text]:
    """A done step's status, how long its joints took to come in position after the path,
    its time on the controller's clock, and its run."""
    if result is None:
        return ["", "", "", ""]
    passes = "/".join(str(p) for p in result.visit.passes)
    status = (f"pass {passes}: " if passes else "") + result.status
    style = "green" if result.ok else "bold red" if result.status.startswith(
        ("error", "estop", "aborted")) else "bold yellow"
    move = result.move
    settle = ""
    if move is not None and move.settle:
        times = move.settle.get("settle_s") or []
        settle = ("not in position" if any(t is None for t in times)
                  else f"{max(times, default=0.0):.2f} s")
    run = move.files.stem if move is not None and move.files is not None else ""
    return [Text(status[:RESULT_CHARS], style), settle, f"{result.seconds:.2f} s", run]


def _resting(machine: Machine) -> np.ndarray:
    """Where a check with no controller starts: the machine's home, else mid-range."""
    if machine.home is not None:
        return np.array(machine.home, dtype=float)
    return np.array([(j.lower + j.upper) / 2 for j in machine.joints])
