"""Moves: the thesis's movement menus (option.c, function.c; sections 3.5 and 5.2) as forms.

Unimate 2000B: single step, multi-step (all six joints), ramp, sine, end point
and orientation (through the closed-form inverse, every solution shown), path
from a file, via points (joint space, or Cartesian x y z with γ and β held,
section 6.4). Rig: step, multi-step (the sequence of positions and dwell times
of function.c MultiStep), ramp, sine, set pulse (open loop), initialise, path
from a file, via points. The forms are in ``move_forms``, ``end_point_form`` and
``path_forms``; the tab hands each one where the joints are (``MoveForm.here``).

Each field is validated as it is typed; the desired path is previewed before
Run (ctrl+s). A move that starts elsewhere than where the joints are gets an
approach ramp first (the thesis's move() to the start position), left out of
the result summary. The wait for the end runs in a worker; the summary
(overshoot, settling time, steady-state error per joint) appears when it ends.
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
from textual_plotext import PlotextPlot

from app.desk import Desk
from app.messages import RunsChanged
from app.plotting.run_plot import draw_path
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
from app.widgets.live_text import LiveText
from control.client import ControlClient, MoveHandle, MoveResult
from control.layout import Status
from control.motion import moves
from control.motion.plan import MovePlan
from control.motion.robot_model import has_unimate_model
from control.recorder import Run
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


class MovesTab(TabPage):
    """Choose a move, fill it in, preview it, run it, read its result."""

    REFRESH_HZ = 10.0
    TITLE = "Moves"

    class HoldRequested(Message):
        """Abort was pressed: abort the move and hold every joint where it is."""

    @dataclass
    class RunUnsaved(Message):
        """A move's run could not be saved: keep it, so it can be saved elsewhere."""

        run: Run

    @dataclass
    class MoveFinished(Message, bubble=False):
        """The move ended (from the waiting worker): its result and summary rows."""

        result: MoveResult
        plan: MovePlan
        summaries: list[tuple[str, moves.StepSummary]]

    def __init__(self, desk: Desk, *, id: str | None = None) -> None:
        super().__init__(desk, id=id)
        self.handle: MoveHandle | None = None
        self.plan_running: MovePlan | None = None
        self.initialising = False
        self.last_result: MoveResult | None = None
        self._preview_timer: Timer | None = None
        self._filled = False
        self.forms: list[MoveForm] = []

    def compose(self) -> ComposeResult:
        kinds = forms_for(self.machine)
        with Horizontal():
            with Vertical(id="moves-left"):
                yield OptionList(*[Option(k.LABEL, id=k.__name__) for k in kinds],
                                 id="move-kinds")
                yield Static(id="move-error")
                with Horizontal(id="move-buttons"):
                    yield Button("Run ^S", id="move-run", variant="success")
                    yield Button("Abort ^G", id="move-abort", variant="error")
            with ContentSwitcher(id="move-forms", initial=f"form-{kinds[0].KIND}"):
                for kind in kinds:
                    yield kind(self.machine, self.model)
            with Vertical(id="moves-right"):
                yield Static(id="move-preview-title")
                yield PlotextPlot(id="move-preview")
                yield ProgressBar(total=100, show_eta=False, id="move-progress")
                yield LiveText(id="move-state")
                yield DataTable(id="move-result", cursor_type="none", zebra_stripes=True)

    def on_mount(self) -> None:
        self.forms = list(self.query(MoveForm))
        self.query_one("#move-result", DataTable).add_columns(*moves.SUMMARY_COLUMNS)
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
        super().shown()
        self._fill_forms()
        self.schedule_preview()

    def client_ready(self, client: ControlClient) -> None:
        super().client_ready(client)
        if self.visible_now:
            self._fill_forms()

    def _fill_forms(self) -> None:
        if self._filled or self.status() is None:
            return
        self._filled = True
        current = self.current()
        for form in self.forms:
            form.fill(current)

    def on_option_list_option_highlighted(self, event: OptionList.OptionHighlighted) -> None:
        event.stop()
        kind = next(k for k in forms_for(self.machine) if k.__name__ == event.option.id)
        self.query_one("#move-forms", ContentSwitcher).current = f"form-{kind.KIND}"
        self.query_one("#move-error", Static).update("")
        self.form.fill(self.current())
        self.schedule_preview()

    def on_option_list_option_selected(self, event: OptionList.OptionSelected) -> None:
        event.stop()
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
        plot = self.query_one("#move-preview", PlotextPlot)
        try:
            plan = self.make_plan()
        except (FieldError, ValueError) as exc:
            title.update(Text(str(exc), "yellow"))
            plot.plt.clear_figure()
            plot.refresh()
            return
        dt = self.desk.dt
        if plan.path is not None:
            t = np.arange(plan.samples) * dt
            names = [j.name for j in self.machine.joints]
            units = [j.symbol for j in self.machine.joints]
            draw_path(plot.plt, t, plan.path, names, units, plan.moving,
                      max(20, plot.size.width), plan.title)
            summary = f"{plan.title}: {plan.samples} samples, {t[-1]:.2f} s"
        elif plan.profile is not None:
            t = np.arange(plan.samples) * dt
            draw_path(plot.plt, t, plan.profile, ["duty"], ["%"], [0],
                      max(20, plot.size.width), plan.title)
            summary = f"{plan.title}: open loop, {plan.samples} samples"
        else:
            plot.plt.clear_figure()
            summary = "initialise: drives down to the bottom stop, then zeroes the encoder"
        plot.refresh()
        note = f" · {plan.note}" if plan.note else ""
        approach = (f" · includes a {plan.approach * dt:.2f} s approach to the start"
                    if plan.approach else "")
        title.update(Text.assemble(("preview  ", "bold"), summary, approach, note))

    # -- running ----------------------------------------------------------------------------

    def on_button_pressed(self, event: Button.Pressed) -> None:
        if event.button.id == "move-run":
            event.stop()
            self.action_run()
        elif event.button.id == "move-abort":
            event.stop()
            self.post_message(self.HoldRequested())

    def action_run(self) -> None:
        error = self.query_one("#move-error", Static)
        if self.handle is not None or self.initialising:
            error.update(Text("a move is running: wait for it, or abort it with ^G", "yellow"))
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
        style = "green" if result.complete else "bold yellow"
        self._state(Text(f"{plan.title}: {result.status} · {saved}", style))
        bar = self.query_one("#move-progress", ProgressBar)
        if result.complete:
            bar.update(progress=bar.total)
        self._result_table(message.summaries)
        if result.files is None and result.run.samples:
            self.post_message(self.RunUnsaved(result.run))
        self.form.fill(self.current())  # "here" has moved
        self.schedule_preview()
        self.post_message(RunsChanged())
        severity = "information" if result.complete else "warning"
        self.notify(f"{plan.title}: {result.status}", severity=severity)

    def initialised(self, status: str) -> None:
        self.initialising = False
        self._state(Text(f"initialise: {status}", "green" if "complete" in status else "yellow"))

    def _result_table(self, summaries: list[tuple[str, moves.StepSummary]]) -> None:
        table = self.query_one("#move-result", DataTable)
        table.clear()
        for label, s in summaries:
            table.add_row(*moves.summary_cells(label, s))

    def _state(self, text: Text) -> None:
        self.query_one("#move-state", LiveText).show(text)

    def refresh_live(self) -> None:
        status = self.status()
        here = self._position(status)
        for form in self.forms:
            form.here = here
        handle = self.handle
        if status is None or handle is None:
            return
        if status.move_id == handle.move_id and status.move_total:
            bar = self.query_one("#move-progress", ProgressBar)
            bar.update(total=status.move_total, progress=status.move_done)
            dt = self.desk.dt
            self._state(Text(f"running {handle.kind}: {status.move_done * dt:.2f} / "
                             f"{status.move_total * dt:.2f} s", "cyan"))
