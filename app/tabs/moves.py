"""Moves: the thesis's movement menus (option.c, function.c; sections 3.5 and 5.2) as forms.

Unimate 2000B: single step, multi-step (all six joints), ramp, sine, end point
and orientation (through the closed-form inverse, every solution shown), path
from a file, via points (joint space, or Cartesian x y z with γ and β held,
section 6.4). Rig: step, multi-step (the sequence of positions and dwell times
of function.c MultiStep), ramp, sine, set pulse (open loop), initialise, path
from a file, via points. The forms are in ``move_forms``, ``end_point_form`` and
``path_forms``; the tab hands each one where the joints are (``MoveForm.here``).

Each field is validated as it is typed; the desired path is previewed before
Run (ctrl+s), with the start the move will use and the approach ramp in front of it
when it starts elsewhere than where the joints are (the thesis's move() to the start
position; grey in the plot, left out of the result). The forms take where the joints
are from the controller's status when they are shown and as it changes (``MoveForm``:
nothing they show is stale). The wait for the end runs in a worker; the result appears when
it ends, by the move's kind (``control.motion.moves.summary_cells``): a step's response, a
smooth path's tracking error, a sine's amplitude ratio and phase lag, for each joint that
moved; a move that stopped early shows where.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from rich.text import Text
from textual import work
from textual.app import ComposeResult
from textual.containers import Horizontal, Vertical
from textual.message import Message
from textual.timer import Timer
from textual.widgets import (
    Button,
    ContentSwitcher,
    DataTable,
    Input,
    OptionList,
    ProgressBar,
    Select,
    Static,
)
from textual.widgets.option_list import Option

from app.desk import Desk
from app.messages import RunsChanged
from app.plotting.run_plot import path_compact, path_figure
from app.tabs.end_point_form import EndPointForm
from app.tabs.move_forms import (
    InitialiseForm,
    MoveForm,
    MultiStepForm,
    PulseForm,
    RampForm,
    SequenceForm,
    SineForm,
    StepForm,
    mid_range,
)
from app.tabs.path_forms import PathFileForm, ViaPointsForm
from app.tabs.tab import TabPage
from app.widgets.fields import FieldError, NumberField
from app.widgets.figure_plot import FigurePlot
from app.widgets.live_text import LiveText
from control.client import ControlClient, MoveHandle, MoveResult
from control.motion.moves import summary_cells, summary_columns
from control.motion.plan import SETTLE_COLUMNS, MovePlan, Summary, moving_joints, settle_cell
from control.motion.robot_model import has_unimate_model
from control.recorder import Run
from control.rt.layout import Status
from hw.machine import Machine

PREVIEW_DELAY_S = 0.25


def forms_for(machine: Machine) -> list[type[MoveForm]]:
    """The forms the menu offers for ``machine``, in menu order."""
    if machine.n_joints == 1:
        return [StepForm, SequenceForm, RampForm, SineForm, PulseForm, InitialiseForm,
                PathFileForm, ViaPointsForm]
    kinds: list[type[MoveForm]] = [StepForm, MultiStepForm, RampForm, SineForm]
    if has_unimate_model(machine):
        kinds.append(EndPointForm)
    return [*kinds, PathFileForm, ViaPointsForm]


FEED_BUTTONS = {"feed-down": -1, "feed-hold": 0, "feed-up": 1}


class MovesTab(TabPage):
    """Choose a move, fill it in, preview it, run it, read its result."""

    REFRESH_HZ = 10.0
    TITLE = "Moves"
    LATER = ("#move-forms", "#moves-right", "#moves-bottom")

    class HoldRequested(Message):
        """Abort was pressed: abort the move and hold every joint where it is."""

    @dataclass
    class FeedRequested(Message):
        """A feed button: the override down or up a tenth (``steps``), or (0) feed hold or
        resume: the same as ctrl+↓, ctrl+↑ and ctrl+f on every tab."""

        steps: int

    @dataclass
    class RunUnsaved(Message):
        """A move's run could not be saved: keep it, so it can be saved elsewhere."""

        run: Run

    @dataclass
    class MoveFinished(Message, bubble=False):
        """The move ended (from the waiting worker): its result and summary rows."""

        result: MoveResult
        plan: MovePlan
        summaries: list[tuple[str, Summary]]

    def __init__(self, desk: Desk, *, id: str | None = None) -> None:
        super().__init__(desk, id=id)
        self.handle: MoveHandle | None = None
        self.plan_running: MovePlan | None = None
        self.initialising = False
        self.last_result: MoveResult | None = None
        self._preview_timer: Timer | None = None
        self.forms: list[MoveForm] = []
        self.previewed: MovePlan | None = None  # the plan previewed: ^A shows it on the arm

    def compose(self) -> ComposeResult:
        kinds = forms_for(self.machine)
        with Horizontal(id="moves-top"):
            with Vertical(id="moves-left"):
                yield OptionList(*[Option(k.LABEL, id=k.__name__) for k in kinds],
                                 id="move-kinds")
                with Horizontal(id="move-buttons"):
                    yield Button("Run ^S", id="move-run", variant="success", compact=True)
                    yield Button("Abort ^G", id="move-abort", variant="error", compact=True)
                with Horizontal(id="move-feed"):
                    yield Button("−", id="feed-down", compact=True, tooltip="feed −10 % (^↓)")
                    yield Button("hold", id="feed-hold", compact=True,
                                 tooltip="feed hold, or resume (^F)")
                    yield Button("+", id="feed-up", compact=True, tooltip="feed +10 % (^↑)")
            with ContentSwitcher(id="move-forms", initial=f"form-{kinds[0].KIND}"):
                for kind in kinds:
                    yield kind(self.machine, self.model)
            with Vertical(id="moves-right"):
                yield Static(id="move-preview-title")
                yield FigurePlot(id="move-preview")
        with Vertical(id="moves-bottom"):
            yield Static(id="move-error")
            with Horizontal(id="move-run-state"):
                yield ProgressBar(total=100, show_eta=False, id="move-progress")
                yield LiveText(id="move-state")
            yield DataTable(id="move-result", cursor_type="none", zebra_stripes=True)

    def on_mount(self) -> None:
        self.forms = list(self.query(MoveForm))
        for form in self.query(PathFileForm):
            form.typed_path = self.desk.typed_path
        self._result_table([])
        self._state(Text("no move yet", "dim"))

    # -- plumbing ---------------------------------------------------------------------------

    @property
    def form(self) -> MoveForm:
        switcher = self.query_one("#move-forms", ContentSwitcher)
        return self.query_one(f"#{switcher.current}", MoveForm)

    def current(self) -> np.ndarray:
        """``(J,)``: where the joints are (the middle of their ranges before the controller
        reports)."""
        return self._position(self.status())

    def _position(self, status: Status | None) -> np.ndarray:
        return mid_range(self.machine) if status is None else np.array(status.position)

    def focus_main(self) -> None:
        self.query_one("#move-kinds", OptionList).focus()

    def shown(self) -> None:
        super().shown()  # refresh_live: the forms' ``here``
        self._fill_form()
        self.schedule_preview()

    def client_ready(self, client: ControlClient) -> None:
        super().client_ready(client)
        if self.visible_now:
            self.refresh_live()
            self._fill_form()

    def _fill_form(self) -> None:
        """The form shown takes where the joints are now, and what it fills in from it."""
        status = self.status()
        if status is not None:
            self.form.here = tuple(status.position)
            self.form.fill(np.array(status.position))

    def on_option_list_option_highlighted(self, event: OptionList.OptionHighlighted) -> None:
        event.stop()
        kind = next(k for k in forms_for(self.machine) if k.__name__ == event.option.id)
        self.query_one("#move-forms", ContentSwitcher).current = f"form-{kind.KIND}"
        self.form.reveal_later()
        self.query_one("#move-error", Static).update("")
        self._fill_form()
        self.schedule_preview()

    def on_option_list_option_selected(self, event: OptionList.OptionSelected) -> None:
        """The form's first field takes the keys, if they are still the menu's: on a loaded
        machine a click on the menu is selected late, after the operator clicked a field and
        typed, and focusing the first field then sent the next keys there (issue 26)."""
        event.stop()
        if self.app.focused is not event.option_list:
            return
        inputs = [w for w in self.form.query("Input, Select") if w.focusable]
        if inputs:
            inputs[0].focus()

    def on_input_changed(self, event: Input.Changed) -> None:
        self.schedule_preview()

    def on_select_changed(self, event: Select.Changed) -> None:
        self.schedule_preview()

    def on_data_table_row_highlighted(self, event: DataTable.RowHighlighted) -> None:
        if event.data_table.id == "ik-solutions":
            self.schedule_preview()

    def on_move_form_preview_wanted(self, message: MoveForm.PreviewWanted) -> None:
        message.stop()
        self.schedule_preview()

    def schedule_preview(self) -> None:
        if self._preview_timer is not None:
            self._preview_timer.stop()
        self._preview_timer = self.set_timer(PREVIEW_DELAY_S, self.preview)

    # -- preview ----------------------------------------------------------------------------

    def make_plan(self) -> MovePlan:
        form = self.form
        current = self.current()
        if isinstance(form, EndPointForm):
            form.solve(current)
        dt = self.desk.dt
        return form.plan(current, dt).approached(current, self.machine, dt)

    def preview(self) -> None:
        title = self.query_one("#move-preview-title", Static)
        plot = self.query_one("#move-preview", FigurePlot)
        current = self.current()
        try:
            plan = self.make_plan()
        except (FieldError, ValueError) as exc:
            title.update(Text(str(exc), "yellow"))
            plot.show(None)
            self.previewed = None
            return
        self.previewed = plan
        dt = self.desk.dt
        names = [j.name for j in self.machine.joints]
        if plan.path is not None:
            t = np.arange(plan.samples) * dt
            units = [j.symbol for j in self.machine.joints]
            shown = [*plan.moving, *(j for j in moving_joints(plan.path)
                                     if j not in plan.moving)]
            plot.show(path_figure(t, plan.path, names, units, shown, plan.approach, plan.title),
                      path_compact(t, plan.path, names, shown, plan.approach, plan.title))
            summary = f"{plan.title}: {t[-1]:.2f} s"
        elif plan.profile is not None:
            t = np.arange(plan.samples) * dt
            plot.show(path_figure(t, plan.profile, names, ["%"] * len(names), list(plan.moving),
                                  0, plan.title))
            summary = f"{plan.title}: open loop, {t[-1]:.2f} s"
        else:
            plot.show(None)
            summary = "initialise: drives down to the bottom stop, then zeroes the encoder"
        note = f" · {plan.note}" if plan.note else ""
        title.update(Text.assemble(("preview  ", "bold"), summary, note, "\n",
                                   start_text(plan, current, self.machine, dt)))

    # -- running ----------------------------------------------------------------------------

    def on_button_pressed(self, event: Button.Pressed) -> None:
        if event.button.id == "move-run":
            event.stop()
            self.action_run()
        elif event.button.id == "move-abort":
            event.stop()
            self.post_message(self.HoldRequested())
        elif event.button.id in FEED_BUTTONS:
            event.stop()
            self.post_message(self.FeedRequested(FEED_BUTTONS[event.button.id]))

    def action_run(self) -> None:
        error = self.query_one("#move-error", Static)
        if self.handle is not None or self.initialising:
            error.update(Text("a move is running: wait for it, or abort it with ^G", "yellow"))
            return
        if busy := self.move_in_progress():
            error.update(Text(busy, "bold red"))
            self.notify(f"not run: {busy}", severity="error")
            return
        for f in self.form.query(NumberField):
            if f.display and (f.parent is None or f.parent.display):
                f.check_now()
        try:
            plan = self.make_plan()
        except (FieldError, ValueError) as exc:
            error.update(Text(f"{exc}", "bold red"))
            self.notify(f"not run: {exc}", severity="error")
            return
        error.update("")
        client = self.client
        if client is None:
            self.command("run", ControlClient.check)
            return
        if plan.kind == "initialise":
            if self.command("initialise", ControlClient.initialise):
                self.initialising = True
                self._result_table([])  # a step's columns say nothing of an initialise
                # no steps to count: the bar pulses until the controller says it is done
                self.query_one("#move-progress", ProgressBar).update(total=None, progress=0)
                self._state(Text("initialising: driving down to the bottom stop…", "cyan"))
            return
        try:
            handle = client.run(plan)
        except Exception as exc:  # ControllerError, ValueError from the client's checks
            error.update(Text(f"{exc}", "bold red"))
            self.notify(f"not run: {exc}", severity="error")
            return
        self.handle, self.plan_running = handle, plan
        self.query_one("#move-result", DataTable).clear()
        self._state(Text(f"running {plan.title}…", "cyan"))
        self._wait(client, handle, plan)

    @work(thread=True, group="move-wait")
    def _wait(self, client: ControlClient, handle: MoveHandle, plan: MovePlan) -> None:
        result = client.wait(handle)
        self.post_message(self.MoveFinished(result, plan, result.summaries()))

    def on_moves_tab_move_finished(self, message: MoveFinished) -> None:
        result, plan = message.result, message.plan
        self.handle = None
        self.plan_running = None
        self.last_result = result
        saved = (f"saved as {result.files.stem}" if result.files else
                 result.save_error or "nothing recorded")
        bar = self.query_one("#move-progress", ProgressBar)
        bar.update(total=max(1, plan.samples),  # where it stopped: the settle is past the path
                   progress=min(result.run.samples, plan.samples))
        if result.complete:
            self._state(Text(f"{plan.title}: {result.status} · {saved}", "green"))
        elif result.unsettled:
            self._state(Text(f"{plan.title}: {result.status}; holding the path's end · {saved}",
                             "bold yellow"))
        else:
            dt = self.desk.dt
            self._state(Text(
                f"{plan.title}: {result.status} at {result.run.samples * dt:.2f} of "
                f"{plan.samples * dt:.2f} s ({100 * result.run.samples / max(1, plan.samples):.0f}"
                f" %) · {saved}", "bold yellow"))
        self._result_table(message.summaries, result.settle)
        if result.files is None and result.run.samples:
            self.post_message(self.RunUnsaved(result.run))
        self.form.fill(self.current())  # "here" has moved
        self.schedule_preview()
        self.post_message(RunsChanged())
        severity = "information" if result.complete else "warning"
        self.notify(f"{plan.title}: {result.status}", severity=severity)

    def initialised(self, status: str) -> None:
        self.initialising = False
        done = 100 if "complete" in status else 0
        self.query_one("#move-progress", ProgressBar).update(total=100, progress=done)
        self._state(Text(f"initialise: {status}", "green" if "complete" in status else "yellow"))

    def _result_table(self, summaries: list[tuple[str, Summary]],
                      settle: dict | None = None) -> None:
        """The move's results, and when each joint came in position after the path."""
        table = self.query_one("#move-result", DataTable)
        table.clear(columns=True)
        table.add_columns(*summary_columns(summaries), SETTLE_COLUMNS[1])
        table.show_header = bool(summaries)  # no move's columns over no rows
        for label, s in summaries:
            table.add_row(*summary_cells(label, s),
                          settle_cell(label, settle or {}, self.machine))

    def _feed_label(self, paused: bool, override: float) -> None:
        """The feed button says what it will do and, off 100 %, the override."""
        label = "resume" if paused else ("hold" if override == 1.0 else f"{override:.0%}")
        button = self.query_one("#feed-hold", Button)
        if str(button.label) != label:
            button.label = label

    def _state(self, text: Text) -> None:
        self.query_one("#move-state", LiveText).show(text)

    def refresh_live(self) -> None:
        status = self.status()
        if status is not None:
            self.form.here = tuple(status.position)  # the others get it when shown
            self._feed_label(status.paused, status.feed_override)
        handle = self.handle
        if status is None or handle is None:
            return
        if status.move_id == handle.move_id and status.move_total:
            bar = self.query_one("#move-progress", ProgressBar)
            bar.update(total=status.move_total, progress=status.move_done)
            dt = self.desk.dt
            if status.settling:
                self._state(settling_text(handle.kind, status, self.machine))
                return
            self._state(Text(f"running {handle.kind}: {status.move_done * dt:.2f} / "
                             f"{status.move_total * dt:.2f} s", "cyan"))



def settling_text(kind: str, status: Status, machine: Machine) -> Text:
    """A move whose path is over, coming in position: the joints not in it yet."""
    out = [j.name for j, s in zip(machine.joints, status.settle_s, strict=True) if s != s]
    waiting = f"waiting for {', '.join(out)}" if out else "every joint in position"
    return Text.assemble(("settling ", "bold yellow"), f"{kind}: the path is over, holding its "
                         f"end until in position (at most {machine.goal_time_s:g} s); {waiting}")


def start_text(plan: MovePlan, current: np.ndarray, machine: Machine, dt: float,
               most: int = 3) -> Text:
    """Where the move starts, from where the joints are now: "starts here" with the moving
    joints' positions, or the approach ramp in front and the joints it moves (``most`` of
    them named)."""
    if plan.path is None:
        return Text("starts where the joints are", "dim")
    start = plan.path[plan.approach]
    joints = machine.joints
    if not plan.approach:
        named = [f"{joints[j].name} {current[j]:.2f}{joints[j].symbol}"
                 for j in plan.moving[:most]]
        return Text.assemble(("start ", "bold"), "here" + (f": {', '.join(named)}" if named
                                                          else ""), ("  · no approach", "dim"))
    away = [j for j in range(machine.n_joints)
            if abs(start[j] - current[j]) > joints[j].tolerance]
    named = [f"{joints[j].name} {current[j]:.2f}→{start[j]:.2f}{joints[j].symbol}"
             for j in away[:most]]
    more = f" and {len(away) - most} more" if len(away) > most else ""
    return Text.assemble(("approach ", "bold yellow"), f"{plan.approach * dt:.2f} s first: ",
                         ", ".join(named) + more)
