"""Identify: system identification and tuning from ``tracking_actuate`` (thesis section 6.3).

Choose a joint and an excitation (steps, PRBS, chirp; ``control.identify.excitation``),
sized from where the joint is now and refused, with the excitation module's
message, if it could reach an end stop. Run plays it open loop, fits the
joint's models to the recorded run (``control.identify.sysid``), proposes P.I. gains
(``control.identify.tuning.propose`` on the current track and hold sets) and predicts
issue 24's check of the current and the proposed track set on the identified models
(``tuning.predict_move``): a minimum-jerk move of the joint at full speed, plotted, with
its overshoot and the time after the path arrives until the joint stays within its
goal_tolerance. Then a fresh PRBS the fit never saw is played from
where the joint stopped, and both models' fit on it is shown: the held-out
figure to judge a model by (the fit on its own run flatters it). "Apply to
track" / "Apply to hold" send the proposal to the controller, with velocity
feed-forward (``with_feed_forward``) while the switch is on (the default: without it
the rig's P.I. overshoots a fast move by 11 mm), and only from a TUI
that commands (``Desk.refusal``); "Check move" then runs the predicted move on the
robot with the track set in use and shows the measured figures beside the predicted.
Joints identified earlier in the session keep their models, so the proposal covers every
joint identified so far.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

import numpy as np
from rich.text import Text
from textual import work
from textual.app import ComposeResult
from textual.containers import Horizontal, VerticalScroll
from textual.message import Message
from textual.widgets import Button, DataTable, Label, Select, Static, Switch

from app.desk import Desk
from app.messages import RunsChanged
from app.plotting.figure import ACTUAL, DESIRED, PROPOSED, Figure, Line, Panel
from app.tabs.tab import TabPage
from app.widgets.fields import FieldError, JointField, NumberCheck, NumberField, seconds_check
from app.widgets.figure_plot import FigurePlot
from app.widgets.live_text import LiveText
from control.client import ControlClient, MoveHandle
from control.recorder import Run
from hw.machine import Coefficients, Joint, Machine

if TYPE_CHECKING:  # the numerics pull in scipy (≈0.9 s): imported when first used
    from control.identify import excitation, tuning
    from control.identify.sysid import DeadbandModel, Fit, Identification

PROFILES = (("Steps (Figure 3.2 staircase)", "steps"), ("PRBS", "prbs"), ("Chirp", "chirp"))
STEP_LEVELS = 6  # excitation.steps' default
HELD_OUT_S = 2.0
HELD_OUT_SEED = 97  # a PRBS none of the tab's excitations uses (prbs' default seed is 1)


@dataclass(frozen=True)
class Outcome:
    """What one identification produced: the fit, both proposals and the predicted moves
    (``desired``, ``current``, ``proposed``, ``proposed_ff`` position ``(N,)`` of the joint;
    ``figures`` their overshoot and settle, by the same three names)."""

    identification: Identification
    models: tuple[DeadbandModel | None, ...]
    track: Coefficients
    hold: Coefficients
    designs: tuple[tuning.Design | None, ...]
    feed_forward: tuple[tuning.FeedForward | None, ...]
    t: np.ndarray
    desired: np.ndarray
    current: np.ndarray
    proposed: np.ndarray
    proposed_ff: np.ndarray
    figures: dict[str, tuning.MoveFigures]


def build(machine: Machine, kind: str, joint: int, start: np.ndarray,
          amplitude: float | None, duration: float | None) -> excitation.Excitation:
    """The chosen excitation from ``start (J,)``, ``duration`` s long (None: the module's
    default); ValueError (the module's) if it could hit a stop."""
    from control.identify import excitation

    if kind == "steps":
        options = {} if duration is None else {"hold_s": duration / (2 * STEP_LEVELS)}
        return excitation.steps(machine, joint, start, amplitude=amplitude,
                                levels=STEP_LEVELS, **options)
    profile = {"prbs": excitation.prbs, "chirp": excitation.chirp}[kind]
    options = {} if duration is None else {"duration": duration}
    return profile(machine, joint, start, amplitude=amplitude, **options)


def figures_text(figures: tuning.MoveFigures, joint: Joint) -> str:
    """``over 0.12°, settled 0.00 s``: a move's overshoot and settle after arrival."""
    settle = "not settled" if np.isinf(figures.settle_s) else f"settled {figures.settle_s:.2f} s"
    return f"over {figures.overshoot:.2f}{joint.symbol}, {settle}"


def with_kv(coefficients: Coefficients, base: Coefficients,
            ffs: tuple[tuning.FeedForward | None, ...]) -> Coefficients:
    """``coefficients`` with the identified joints' feed-forward; the others keep ``base``'s."""
    from control.identify import tuning

    added = tuning.with_feed_forward(coefficients, ffs)
    kv = tuple(new if ff is not None else (base.kv[j] if base.kv else 0.0)
               for j, (new, ff) in enumerate(zip(added.kv, ffs, strict=True)))
    return replace(added, kv=kv)


class IdentifyTab(TabPage):
    """Excite one joint, fit its model, propose and apply gains."""

    TITLE = "Identify"
    LATER = ("#identify-amplitude, #identify-duration, #identify-run",
             "#identify-error, #identify-ff-row, #identify-apply", "#identify-right")

    class Fitting(Message, bubble=False):
        """The excitation ran to its end; the fit has started (from the worker)."""

    @dataclass
    class Identified(Message, bubble=False):
        """The fit, the proposals and the predicted steps (from the worker)."""

        outcome: Outcome

    @dataclass
    class Failed(Message, bubble=False):
        """The run or the fit failed; ``reason`` says why (from the worker)."""

        reason: str

    @dataclass
    class Checked(Message, bubble=False):
        """Both models' fit on the fresh held-out PRBS (from the worker)."""

        joint: int
        fits: tuple[Fit, Fit]

    @dataclass
    class Unchecked(Message, bubble=False):
        """The held-out run did not complete; ``reason`` says why (from the worker)."""

        reason: str

    @dataclass
    class Moved(Message, bubble=False):
        """The check move ran: its measured and predicted figures, or why not (from the
        worker)."""

        joint: int
        measured: tuning.MoveFigures | None
        predicted: tuning.MoveFigures | None
        reason: str = ""

    def __init__(self, desk: Desk, *, id: str | None = None) -> None:
        super().__init__(desk, id=id)
        self.models: list[DeadbandModel | None] = []
        self.handle: MoveHandle | None = None
        self.outcome: Outcome | None = None
        self.held_out: dict[int, tuple[Fit, Fit]] = {}

    def compose(self) -> ComposeResult:
        self.models = [None] * self.machine.n_joints
        with Horizontal():
            with VerticalScroll(id="identify-left"):
                yield Static("Open loop (tracking_actuate): the joint moves by itself about "
                             "where it is now, twice (the profile, then a fresh PRBS to check "
                             "the fit on); both are sized to keep off the stops.",
                             classes="form-help")
                yield JointField("joint", self.machine.joints, id="identify-joint")
                with Horizontal(classes="field"):
                    yield Label("profile", classes="field-label")
                    yield Select(PROFILES, value="prbs", allow_blank=False, compact=True,
                                 id="identify-profile", classes="field-select")
                yield NumberField("amplitude",
                                  NumberCheck("amplitude", " %", 0.0, 100.0, strict_low=True,
                                              optional=True), placeholder="auto",
                                  id="identify-amplitude")
                yield NumberField("duration", seconds_check("duration", optional=True),
                                  placeholder="auto", id="identify-duration")
                yield Button("Run identification", id="identify-run", variant="success")
                yield Static(id="identify-error")
                with Horizontal(classes="field", id="identify-ff-row"):
                    yield Label("feed-forward", classes="field-label")
                    yield Switch(value=True, id="identify-ff")
                with Horizontal(id="identify-apply"):
                    yield Button("Apply to track", id="identify-apply-track", variant="warning",
                                 disabled=True)
                    yield Button("Apply to hold", id="identify-apply-hold", variant="warning",
                                 disabled=True)
                yield Button("Check move", id="identify-check", disabled=True)
            with VerticalScroll(id="identify-right"):
                yield LiveText(id="identify-state")
                yield LiveText(id="identify-settle")
                yield DataTable(id="identify-model", cursor_type="none", zebra_stripes=True)
                yield Static("fit %: own = on the run it was fitted to, new = on a fresh PRBS "
                             "it never saw; v velocity, q position. Kp / Ki, Ms, PM: the "
                             "proposed P.I. set and its margins.", classes="form-help")
                yield FigurePlot(id="identify-plot")

    def on_mount(self) -> None:
        self.query_one("#identify-model", DataTable).add_columns(
            "joint", "k+", "d+ %", "k−", "d− %", "fn Hz", "ζ", "own v%", "new v%", "new q%",
            "ARX new v%", "Kp / Ki", "Ms, PM")
        self._state(Text("no identification yet", "dim"))

    def focus_main(self) -> None:
        self.query_one("#identify-joint Select", Select).focus()

    # -- running ----------------------------------------------------------------------------

    def on_button_pressed(self, event: Button.Pressed) -> None:
        event.stop()
        if event.button.id == "identify-run":
            self.action_run()
        elif event.button.id == "identify-apply-track":
            self.apply("track")
        elif event.button.id == "identify-apply-hold":
            self.apply("hold")
        elif event.button.id == "identify-check":
            self.check_move()

    def on_switch_changed(self, event: Switch.Changed) -> None:
        event.stop()
        if self.outcome is not None:
            self._plot(self.outcome)
            self._settle(self.outcome)

    def joint(self) -> int:
        return self.query_one(JointField).index

    def action_run(self) -> None:
        error = self.query_one("#identify-error", Static)
        if self.handle is not None:
            error.update(Text("an identification is running: wait for it, or abort it with ^G",
                              "yellow"))
            return
        if busy := self.move_in_progress():
            error.update(Text(busy, "bold red"))
            self.notify(f"not run: {busy}", severity="error")
            return
        client, status = self.client, self.status()
        if client is None or status is None:
            self.command("identify", ControlClient.check)
            return
        j = self.joint()
        kind = str(self.query_one("#identify-profile", Select).value)
        try:
            amplitude = self.query_one("#identify-amplitude", NumberField).value()
            duration = self.query_one("#identify-duration", NumberField).value()
            profile = build(self.machine, kind, j, np.array(status.position), amplitude,
                            duration)
            meta = {**profile.meta, "joint": self.machine.joints[j].name, "profile": kind}
            handle = client.actuate(profile.duty, "tracking_actuate", meta)
        except (FieldError, ValueError) as exc:
            error.update(Text(str(exc), "bold red"))
            self.notify(f"not run: {exc}", severity="error")
            return
        except Exception as exc:  # ControllerError: the controller refused to start it
            error.update(Text(str(exc), "bold red"))
            return
        error.update("")
        self.handle = handle
        self._state(Text(f"playing {kind} on {self.machine.joints[j].name} "
                         f"({profile.duration:.1f} s)…", "cyan"))
        self._identify(client, handle, j)

    @work(thread=True, group="identify")
    def _identify(self, client: ControlClient, handle: MoveHandle, j: int) -> None:
        try:
            result = client.wait(handle)
            if not result.complete:
                raise ValueError(f"the run ended {result.status}: nothing to fit; run it again")
            self.post_message(self.Fitting())
            outcome = self._fit(client, result.run, j)
        except Exception as exc:  # a refusal of sysid/tuning or a closed controller
            self.post_message(self.Failed(f"{exc}"))
            return
        self.post_message(self.Identified(outcome))

    def on_identify_tab_fitting(self, message: Fitting) -> None:
        self._state(Text("fitting the model and designing gains…", "cyan"))

    def _fit(self, client: ControlClient, run: Run, j: int) -> Outcome:
        """Identify, propose and predict (worker thread)."""
        from control.identify import sysid, tuning

        m = self.machine
        identification = sysid.identify(run, m, j)
        models = list(self.models)
        models[j] = identification.deadband
        track, hold = client.coefficients["track"], client.coefficients["hold"]
        proposal = tuning.propose(models, m, track)
        hold_proposal = tuning.propose(models, m, hold)
        ffs = tuple(None if model is None else tuning.feed_forward(model, spec)
                    for model, spec in zip(models, m.joints, strict=True))
        sets = {"current": track, "proposed": proposal.coefficients,
                "proposed_ff": with_kv(proposal.coefficients, track, ffs)}
        moves = {name: tuning.predict_move(models, m, c, j, run.actual[-1])
                 for name, c in sets.items()}
        first = moves["current"]
        return Outcome(identification, tuple(models), proposal.coefficients,
                       hold_proposal.coefficients, proposal.designs, ffs, first.loop.t,
                       first.desired[:, j],
                       *(moves[name].loop.position[:, j] for name in sets),
                       {name: move.figures for name, move in moves.items()})

    def on_identify_tab_failed(self, message: Failed) -> None:
        self.handle = None
        self.query_one("#identify-error", Static).update(Text(message.reason, "bold red"))
        self._state(Text("identification failed", "bold yellow"))
        self.notify(f"identify: {message.reason}", severity="error")

    def on_identify_tab_identified(self, message: Identified) -> None:
        outcome = message.outcome
        self.handle = None
        self.outcome = outcome
        self.models = list(outcome.models)
        self.held_out.pop(outcome.identification.joint, None)
        self._table()
        self._plot(outcome)
        self._settle(outcome)
        for which in ("track", "hold"):
            self.query_one(f"#identify-apply-{which}", Button).disabled = False
        self.post_message(RunsChanged())
        self._hold_out(outcome)

    # -- the held-out check -----------------------------------------------------------------

    def _hold_out(self, outcome: Outcome) -> None:
        """Play a fresh PRBS from where the joint is, sized with the identified model."""
        from control.identify import excitation

        ident = outcome.identification
        client, status = self.client, self.status()
        name = self.machine.joints[ident.joint].name
        own = f"{name}: fit {ident.deadband_fit.velocity_pct:.1f} % in velocity on its own run"
        try:
            if client is None or status is None:
                raise ValueError("the controller is not running")
            profile = excitation.prbs(self.machine, ident.joint, np.array(status.position),
                                      duration=HELD_OUT_S, seed=HELD_OUT_SEED,
                                      model=ident.deadband)
            meta = {**profile.meta, "joint": name, "profile": "prbs", "purpose": "held-out"}
            handle = client.actuate(profile.duty, "tracking_actuate", meta)
        except Exception as exc:  # sizing refused, or the controller refused to start it
            self._state(Text(f"{own}; held-out check not played: {exc}", "yellow"))
            return
        self.handle = handle
        self._state(Text(f"{own}; checking it on a fresh {HELD_OUT_S:g} s PRBS…", "cyan"))
        self._check(client, handle, ident)

    @work(thread=True, group="identify")
    def _check(self, client: ControlClient, handle: MoveHandle, ident: Identification) -> None:
        from control.identify import sysid

        try:
            result = client.wait(handle)
            if not result.complete:
                raise ValueError(f"the held-out run ended {result.status}")
            data = sysid.joint_series(result.run, self.machine, ident.joint)
            fits = (sysid.validate(ident.deadband, data), sysid.validate(ident.arx, data))
        except Exception as exc:  # a stopped run or a closed controller
            self.post_message(self.Unchecked(f"{exc}: the fit shown is on the model's own run; "
                                             "run the identification again to check it"))
            return
        self.post_message(self.Checked(ident.joint, fits))

    def on_identify_tab_unchecked(self, message: Unchecked) -> None:
        self.handle = None
        self._state(Text(message.reason, "yellow"))

    def on_identify_tab_checked(self, message: Checked) -> None:
        joint, fits = message.joint, message.fits
        self.handle = None
        self.held_out[joint] = fits
        line, arx = fits
        self._state(Text.assemble(
            (f"{self.machine.joints[joint].name}: ", "bold"),
            (f"held-out fit {line.velocity_pct:.1f} %", "bold green"),
            f" in velocity, {line.position_pct:.1f} % in position, ARX "
            f"{arx.velocity_pct:.1f} % (a fresh {HELD_OUT_S:g} s PRBS the fit never saw)"))
        self._table()
        self.post_message(RunsChanged())

    def _table(self) -> None:
        """One row per joint identified so far, the proposal's design beside its model."""
        table = self.query_one("#identify-model", DataTable)
        table.clear()
        outcome = self.outcome
        if outcome is None:
            return
        for j, model in enumerate(self.models):
            if model is None:
                continue
            design = outcome.designs[j]
            own = outcome.identification.deadband_fit if j == outcome.identification.joint \
                else None
            held = self.held_out.get(j)
            table.add_row(
                model.name, f"{model.k_pos:.4g}", f"{model.d_pos:.1f}", f"{model.k_neg:.4g}",
                f"{model.d_neg:.1f}", f"{model.wn / (2 * np.pi):.1f}", f"{model.zeta:.2f}",
                f"{own.velocity_pct:.1f}" if own else "earlier",
                f"{held[0].velocity_pct:.1f}" if held else "…",
                f"{held[0].position_pct:.1f}" if held else "",
                f"{held[1].velocity_pct:.1f}" if held else "",
                "–" if design is None else f"{design.kp:.3g} / {design.ki:.4g}",
                "–" if design is None else
                f"{design.margins.ms:.2f}, {design.margins.phase_margin_deg:.0f}°")

    def _plot(self, outcome: Outcome) -> None:
        spec = self.machine.joints[outcome.identification.joint]
        ff = self.query_one("#identify-ff", Switch).value
        proposed = outcome.proposed_ff if ff else outcome.proposed
        lines = (Line(outcome.t, outcome.desired, DESIRED, "desired"),
                 Line(outcome.t, outcome.current, ACTUAL, "current track set"),
                 Line(outcome.t, proposed, PROPOSED,
                      "proposed" + (" + feed-forward" if ff else "")))
        title = f"predicted full-speed move · {spec.name}"
        panel = Panel(title, lines, spec.symbol)
        self.query_one("#identify-plot", FigurePlot).show(Figure(title, (panel,)))

    def _settle(self, outcome: Outcome, measured: tuning.MoveFigures | None = None) -> None:
        """The predicted figures of the current and the proposed track set (and, after a
        check move, the measured ones)."""
        spec = self.machine.joints[outcome.identification.joint]
        ff = self.query_one("#identify-ff", Switch).value
        proposed = outcome.figures["proposed_ff" if ff else "proposed"]
        parts: list[str | tuple[str, str]] = [
            ("fast move predicted: ", "bold"),
            f"current {figures_text(outcome.figures['current'], spec)}; ",
            (f"proposed {figures_text(proposed, spec)}", "bold green")]
        if measured is not None:
            parts += [("; measured ", "bold"), figures_text(measured, spec)]
        self.query_one("#identify-settle", LiveText).show(Text.assemble(*parts))

    def apply(self, which: str) -> None:
        refusal = self.desk.refusal(f"apply to {which}")
        if refusal:
            self._state(Text(refusal, "bold red"))
            self.notify(refusal, severity="error", timeout=8)
            return
        outcome = self.outcome
        client = self.client
        if outcome is None:
            self.notify("run an identification first", severity="warning")
            return
        if client is None:
            self.command(f"apply to {which}", ControlClient.check)
            return
        proposed = outcome.track if which == "track" else outcome.hold
        if self.query_one("#identify-ff", Switch).value:
            proposed = with_kv(proposed, client.coefficients[which], outcome.feed_forward)
        if self.command(f"apply to {which}",  # the gain check judges them on the models fitted
                        lambda client: client.set_coefficients(which, proposed, outcome.models)):
            self.notify(f"proposed gains applied to the {which} set")
            self._state(Text(f"applied to the {which} set: {proposed.note}", "green"))
            self.query_one("#identify-check", Button).disabled = False

    def check_move(self) -> None:
        """Run the predicted move from where the joint is now with the track set in use, and
        show what it measured beside what the models predict for that set."""
        from control.identify import tuning

        refusal = self.desk.refusal("check move") or self.move_in_progress()
        outcome, client, status = self.outcome, self.client, self.status()
        if refusal or outcome is None or self.handle is not None:
            self._state(Text(refusal or "wait for the identification to finish", "bold red"))
            return
        if client is None or status is None:
            self.command("check move", ControlClient.check)
            return
        j = outcome.identification.joint
        try:
            prediction = tuning.predict_move(list(self.models), self.machine,
                                             client.coefficients["track"], j, status.position)
            handle = client.move(prediction.desired)
        except Exception as exc:  # the acceptance rules or the controller refused it
            self._state(Text(f"check move not run: {exc}", "bold red"))
            return
        self.handle = handle
        self._state(Text(f"check move: {self.machine.joints[j].name} at full speed…", "cyan"))
        self._measure(client, handle, prediction)

    @work(thread=True, group="identify")
    def _measure(self, client: ControlClient, handle: MoveHandle,
                 prediction: tuning.MovePrediction) -> None:
        from control.identify import tuning

        j = prediction.joint
        try:
            run = client.wait(handle).run
            if run is None or len(run.t) <= prediction.arrives:
                raise ValueError("the move ended before its path did")
            measured = tuning.move_figures(run.t, run.desired[:, j], run.actual[:, j],
                                           prediction.arrives, self.machine.joints[j])
        except Exception as exc:  # a stopped move or a closed controller
            self.post_message(self.Moved(j, None, None, f"check move: {exc}"))
            return
        self.post_message(self.Moved(j, measured, prediction.figures))

    def on_identify_tab_moved(self, message: Moved) -> None:
        self.handle = None
        if message.measured is None or self.outcome is None:
            self._state(Text(message.reason or "check move not measured", "yellow"))
            return
        spec = self.machine.joints[message.joint]
        self._settle(self.outcome, message.measured)
        self._state(Text(f"check move of {spec.name}: measured "
                         f"{figures_text(message.measured, spec)}, predicted "
                         f"{figures_text(message.predicted, spec)} for the track set in use",
                         "green"))
        self.post_message(RunsChanged())

    def _state(self, text: Text) -> None:
        self.query_one("#identify-state", LiveText).show(text)
