"""Jog: the thesis's manual control (option.c Manual()), plus hold-to-move and position jog.

Three modes, cycled with ``m``:

- **duty** — as option.c: a/z s/x d/c f/v g/b h/n add or take the increment
  (1–9 %) from the duty of In/Out, Rotate, Up/Down, Bend, Yaw, Swivel; the
  joint keeps moving until its duty is changed back or space zeroes all. On
  the rig, as function.c Manual(): Up/Down arrows ±10 %, space closes the valve.
- **hold-to-move** — a joint moves at 10 × increment % (at most
  ``HOLD_DUTY_MAX``, 50 %) only while its key is held. Terminals send no key-up
  event, so a held key is recognised by its auto-repeat and a release by the
  silence after it (``KeyRepeat``), the way keyboard teleop tools do it. When
  the last held key is let go the joints hold where they stopped (closed loop),
  rather than sag at zero duty in manual actuation.
- **position** — closed loop: each press moves the joint's hold target by the
  step chosen with 1–9, from its unit's table (``POSITION_STEPS``: 0.05 … 20 mm,
  0.01 … 5°).

Cartesian jog (``w`` cycles the frame joint → world → tool; the Unimate only, the
rig is a single axis): the same six key pairs move the tool along x, y, z or
turn it about x, y, z (γ, β, α) of the world or the tool frame, on a straight
line, on the branch the arm is on (``control.motion.cartesian_jog``).

- **position** — each press jogs the tool by the step (mm or °, as above) at
  the machine's Cartesian jog speed; a step the arm cannot make (a joint
  limit, out of reach, the wrist singularity) moves nothing and says why.
- **hold-to-move** — while a key is held the tool moves along the axis at the
  chosen fraction of the Cartesian jog speed (``CARTESIAN_SPEEDS``, keys 1–9),
  one continuous motion streamed by a client-side servo (``control.servo``:
  joint velocities through the inverse Jacobian, drift pulled back onto the
  line); on release (no repeat within ``KeyRepeat``'s gap) it brakes along its
  line at the Cartesian jog acceleration and the arm holds there. It slows in
  the singularity zone and stops before a joint limit or where a joint would
  need more than its max_speed, saying which. A held jog leaves no run: each
  press-and-hold is one entry in the event log (Log tab), how far and why it
  stopped.

Duty mode has no Cartesian meaning: the Cartesian frames cycle position and
hold-to-move. The live pose (x, y, z, γ, β, α) is shown under the pad.

The keys belong to ``JogPad``, which posts what they ask for (``DutyChanged``,
``TargetStepped``, ``CartesianJogged``, ``Stopped``); ``JogTab`` sends it to the
controller.
"""

from __future__ import annotations

import contextlib
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np
from rich.table import Table
from rich.text import Text
from textual.app import ComposeResult
from textual.binding import Binding
from textual.message import Message
from textual.reactive import reactive
from textual.widget import Widget
from textual.widgets import Static

from app.event_log import LogEntry
from app.tabs.tab import TabPage
from app.widgets.limit_bar import LimitBar
from app.widgets.live_text import LiveText
from control.client import ControlClient, ControllerError, MoveHandle
from control.motion.cartesian_jog import AXES, Step, StepQueue, zone
from control.rt.layout import Mode, Status
from control.servo import CartesianServo, ServoReport
from hw.machine import Joint
from hw.transmission import output_min_pwm

JOG_KEYS = (("a", "z"), ("s", "x"), ("d", "c"), ("f", "v"), ("g", "b"), ("h", "n"))
MODES = ("duty", "hold-to-move", "position")
FRAMES = ("joint", "world", "tool")  # w cycles them; world and tool are Cartesian jogs
CARTESIAN_MODES = ("hold-to-move", "position")
REDUCED_JOINT_MODES = ("reduced speed (T1): joints jog by position steps; the duty modes need "
                       "automatic (^Y)")
# Hold-to-move Cartesian speed, keys 1-9: a fraction of the machine's cartesian_jog_speed.
CARTESIAN_SPEEDS = (0.05, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.8, 1.0)
ZONE_WARNING = 0.9  # the pose line warns once a Cartesian jog would run below this speed
WRIST_WARNING_DEG = 30.0  # a slowed jog with Yaw this close to 0° is the wrist's doing
# A held Cartesian jog's servo stops by itself this long after the last key event it saw: a
# UI that stopped delivering keys (the terminal's first repeat comes within 0.25-0.6 s).
SERVO_KEEPALIVE_S = 1.0
QUIET_STOPS = ("released", "the key stopped repeating", "another key", "the Jog tab was left",
               "E-stop")  # the operator's doing, or said elsewhere: no warning
NO_CARTESIAN = ("no Cartesian jog on this machine: {name} has no closed-form kinematics "
                "(a single axis), only joint jog")
RIG_ARROW_STEP = 10.0  # function.c Manual(): each arrow press changes the duty by 10 %
HOLD_DUTY_PER_STEP = 10.0  # hold-to-move duty is 10 × increment %,
HOLD_DUTY_MAX = 50.0  # at most this: a held key is for placing a joint, not for speed
HEADERS = ("keys", "joint", "command %", "min PWM +/−", "controller %", "valve %", "position",
           "target")
NARROW_HEADERS = ("keys", "joint", "cmd", "min ±", "ctrl", "valve", "pos", "target")
JUSTIFY = ("center", "left", "right", "right", "right", "right", "right", "right")
NARROW = 100  # the table's width (columns) below which it takes NARROW_HEADERS
# Position-jog steps, keys 1-9, per unit: the same 1-2-5 ladder, up to 20 mm or 5° a press
# (a Unimate joint's range is 57° to 1,065 mm). The first steps are finer than one encoder
# count on some joints (In/Out 0.26 mm, Bend 0.06°): the hold target adds them up.
POSITION_STEPS = {
    "mm": (0.05, 0.1, 0.2, 0.5, 1.0, 2.0, 5.0, 10.0, 20.0),
    "deg": (0.01, 0.02, 0.05, 0.1, 0.2, 0.5, 1.0, 2.0, 5.0),
}
SYMBOLS = {"mm": " mm", "deg": "°"}  # after a number
RELEASE_CHECK_S = 0.01
JOINT_RELEASE = (0.11, 2.5)  # KeyRepeat's most (s) and factor in the joint frame
TOOL_RELEASE = (0.15, 4.0)  # and in a Cartesian frame: 4 repeats of 33 ms missed is a release
STEP_WAIT_S = 0.01  # how often a step waiting for another's move looks at it
STEP_WAITS = "the step waits: "
STALL_S = 0.03  # a release check this late follows a stall of the UI: its silence is excused
LATCHED_NOTICE_S = 3.0  # while latched, a jog key says why at most this often
LATCHED = ("E-stop latched: the jog keys do nothing until you release it (^R); the joints "
           "then hold where they are")
MODE_HELP = {
    "duty": "each press adds ± increment % to the joint's duty; space zeroes all (option.c)",
    "hold-to-move": f"a joint moves at 10 × increment % (≤ {HOLD_DUTY_MAX:g} %) only while "
                    "its key is held, then holds where it stopped",
    "position": "closed loop: each press moves the joint's hold target by the step",
}
CARTESIAN_HELP = {
    "hold-to-move": "the tool moves along the axis while the key is held, then holds",
    "position": "each press moves the tool by the step along the axis, on a straight line",
}


def _shown(displacement: tuple[float, ...]) -> str:
    """A Cartesian displacement as the axes it moves: 'x +2 mm, γ −0.5°'."""
    return ", ".join(f"{axis} {v:+g}{' mm' if k < 3 else '°'}"
                     for k, (axis, v) in enumerate(zip(AXES, displacement, strict=True)) if v)


def below_min_pwm(joint: Joint, duty: float) -> float | None:
    """The minimum PWM (%) of ``joint`` in the sense of ``duty`` (the controller output's,
    ``hw.transmission.output_min_pwm``) if a non-zero open-loop ``duty`` is below it: the
    valve will not open enough to move the joint (section 5.4.1). Else None."""
    if duty == 0.0:
        return None
    least = output_min_pwm(joint)[0 if duty > 0 else 1]
    return least if abs(duty) < least else None


def behind_queued_keys(widget: Widget, check: Callable[[], None]) -> Callable[[], None]:
    """``check`` sent through the app's message queue, behind every key the terminal sent
    before it. Run by the widget's own timer, a release check went ahead of repeats still
    waiting in a busy app's queue and took their silence for a release (a held Cartesian
    jog braked mid-line); behind them, the repeats are heard first, and the check's own
    lateness shows the stall (``STALL_S``)."""
    return lambda: widget.app.call_later(check)


@dataclass
class KeyRepeat:
    """Key-up events from auto-repeat: a key is held while it repeats; silence is a release.

    The first repeat comes after the terminal's initial delay (250–600 ms
    typically), the next ones every 30–50 ms. A key is taken as released when
    no repeat arrived within ``first_timeout`` of the first press or
    ``repeat_timeout`` of the last repeat; both adapt to the delays observed,
    so a release after a hold is seen within ``repeat_timeout`` (≤ ``most``: 110 ms
    for a joint, ``TOOL_RELEASE``'s 150 ms for a Cartesian hold, whose false release
    would brake and restart the tool mid-line, while a late one costs it 1 mm).
    A short tap moves for up to the initial delay: use position mode to nudge.
    """

    first_timeout: float = 0.55
    repeat_timeout: float = 0.11
    most: float = 0.11  # the longest repeat_timeout learned (s)
    factor: float = 2.5  # repeat_timeout is this many repeat intervals (within 0.06-most s)
    _pressed_at: dict[int, float] = field(default_factory=dict)
    _last: dict[int, float] = field(default_factory=dict)
    _repeats: dict[int, int] = field(default_factory=dict)
    interval: float = 0.04

    def press(self, key: int, now: float) -> bool:
        """Record a key event; True if it starts a hold (not a repeat of one)."""
        last = self._last.get(key)
        if last is None or now - last > self.timeout(key):
            self._pressed_at[key] = self._last[key] = now
            self._repeats[key] = 0
            return True
        gap = now - last
        if self._repeats[key] == 0:
            self.first_timeout = min(0.8, max(0.15, gap + 0.08))  # learn the initial delay
        else:
            self.interval = 0.8 * self.interval + 0.2 * gap
            self.repeat_timeout = min(self.most, max(0.06, self.factor * self.interval))
        self._repeats[key] += 1
        self._last[key] = now
        return False

    def excuse(self, seconds: float) -> None:
        """The UI could not hear keys for ``seconds`` (a stall): that silence is no release."""
        for k in self._last:
            self._last[k] += seconds

    def timeout(self, key: int) -> float:
        return self.first_timeout if self._repeats.get(key, 0) == 0 else self.repeat_timeout

    def released(self, now: float) -> list[int]:
        """Keys whose repeats stopped; they are forgotten."""
        gone = [k for k, last in self._last.items() if now - last > self.timeout(k)]
        for k in gone:
            self.forget(k)
        return gone

    def forget(self, key: int | None = None) -> None:
        keys = list(self._last) if key is None else [key]
        for k in keys:
            self._last.pop(k, None)
            self._pressed_at.pop(k, None)
            self._repeats.pop(k, None)

    @property
    def held(self) -> bool:
        return bool(self._last)


def _jog_bindings() -> list[Binding]:
    out = []
    for j, (plus, minus) in enumerate(JOG_KEYS):
        first = j == 0
        out.append(Binding(plus, f"jog({j}, 1)", "jog joint + / −" if first else f"joint {j} +",
                           show=first, key_display="a/z…h/n" if first else None))
        out.append(Binding(minus, f"jog({j}, -1)", f"joint {j} −", show=False))
    for k in range(1, 10):
        out.append(Binding(str(k), f"increment({k})", "increment / step" if k == 1
                           else f"increment {k}",
                           show=k == 1, key_display="1-9" if k == 1 else None))
    return out


class JogPad(Widget, can_focus=True):
    """The focusable part of the Jog tab: its keys set the duties and steps it posts up.

    ``armed`` is set by the tab: True only while the tab is the visible one. ``latched``
    too: while the E-stop is latched a jog key changes nothing and says why.
    """

    BINDINGS: ClassVar = [
        *_jog_bindings(),
        Binding("up", "arrow(1)", "rig +10 %", key_display="↑"),
        Binding("down", "arrow(-1)", "rig −10 %", key_display="↓"),
        Binding("space", "stop_all", "all duties 0", key_display="space"),
        Binding("m", "mode", "mode"),
        Binding("w", "frame", "frame joint/world/tool"),
        Binding("enter", "hold_here", "hold here"),
        Binding("p", "arm_view", "arm view"),
    ]

    mode: reactive[str] = reactive("duty")
    increment: reactive[int] = reactive(5)
    frame: reactive[str] = reactive("joint")
    reduced: reactive[bool] = reactive(False)  # the controller's reduced speed (T1)

    @dataclass
    class DutyChanged(Message):
        """Send these manual duties (%, one per joint) to the controller."""

        duty: tuple[float, ...]

    @dataclass
    class TargetStepped(Message):
        """Move ``joint``'s hold target by ``step`` (mm or °): the closed-loop position jog."""

        joint: int
        step: float

    @dataclass
    class CartesianJogged(Message):
        """Jog the tool by ``displacement`` [dx, dy, dz (mm), dγ, dβ, dα (°)] in ``frame``
        at ``speed`` of the Cartesian jog speed: a step."""

        displacement: tuple[float, ...]
        frame: str
        speed: float

    @dataclass
    class CartesianHeld(Message):
        """A Cartesian hold-to-move key: move the tool at ``velocity`` [vx, vy, vz (mm/s),
        ωγ, ωβ, ωα (°/s)] in ``frame`` while held; ``repeat``: the key's auto-repeat (still
        held), not a new hold."""

        velocity: tuple[float, ...]
        frame: str
        repeat: bool

    class ArmViewToggled(Message):
        """Show the arm's view in place of the table and help, or hide it again."""

    @dataclass
    class Stopped(Message):
        """Every duty is zero: leave manual actuation for closed-loop hold (the thesis's
        default mode); ``hold`` asks for the hold even when not in manual; ``tool``: a held
        Cartesian jog was let go, to be stopped along its line first."""

        hold: bool
        tool: bool = False

    def __init__(self, units: tuple[str, ...], *,
                 cartesian_speed: tuple[float, float] | None = None, machine_name: str = "",
                 id: str | None = None) -> None:
        super().__init__(id=id)
        # the machine's cartesian_jog_speed (mm/s, °/s) if it has kinematics (world and tool
        # frames), else None
        self.cartesian_speeds = cartesian_speed
        self.machine_name = machine_name
        self.units = units  # each joint's unit, "mm" or "deg": its position steps
        self.n = len(units)
        self.duty = [0.0] * self.n
        self.repeat = KeyRepeat()
        self._mode_in_automatic: str | None = None  # the mode reduced speed put aside
        self.armed = False
        self.latched = False
        self._told_latched = -math.inf
        self._checked = -math.inf  # when the release was last checked

    def on_mount(self) -> None:
        self._release_timer = self.set_interval(
            RELEASE_CHECK_S, behind_queued_keys(self, self._check_release), pause=True)

    def render(self) -> Text:
        if self.latched:
            return Text.assemble(("E-STOP latched", "bold red"), ("  ·  ", "dim"),
                                 "jog keys do nothing until ^R releases it")
        units = POSITION_STEPS if self.frame != "joint" else [
            unit for unit in POSITION_STEPS if unit in self.units]
        steps = " · ".join(f"{self.step(unit):g}{SYMBOLS[unit]}" for unit in units)
        held = (f"{self.cartesian_speed:.0%} of the jog speed while held"
                if self.frame != "joint" else f"duty {self.hold_duty:g} % while held")
        amount = {"duty": f"increment {self.increment} %", "hold-to-move": held,
                  "position": f"step {steps} a press"}[self.mode]
        helps = MODE_HELP if self.frame == "joint" else CARTESIAN_HELP
        return Text.assemble(("frame ", "dim"), (self.frame, "bold"), ("  ·  mode ", "dim"),
                             (self.mode, "bold"), ("  ·  ", "dim"), (amount, "bold"),
                             ("  ·  ", "dim"), helps[self.mode])

    def check_action(self, action: str, parameters: tuple[object, ...]) -> bool | None:
        if not self.armed:
            return False  # a key must never move a joint the operator cannot see
        if action == "jog":
            return int(parameters[0]) < self.n  # type: ignore[arg-type]
        if action == "arrow":
            return self.n == 1
        return True

    def step(self, unit: str) -> float:
        """The position-jog step of the chosen increment in ``unit`` (mm or deg)."""
        return POSITION_STEPS[unit][self.increment - 1]

    @property
    def cartesian_speed(self) -> float:
        """The hold-to-move Cartesian speed of the chosen increment, a fraction of the
        machine's cartesian_jog_speed."""
        return CARTESIAN_SPEEDS[self.increment - 1]

    @property
    def hold_duty(self) -> float:
        """The hold-to-move duty of the chosen increment (%), capped at HOLD_DUTY_MAX."""
        return min(HOLD_DUTY_MAX, HOLD_DUTY_PER_STEP * self.increment)

    def action_arm_view(self) -> None:
        self.post_message(self.ArmViewToggled())

    def action_increment(self, k: int) -> None:
        self.increment = k

    def action_mode(self) -> None:
        if self.reduced and self.frame == "joint":
            self.notify(REDUCED_JOINT_MODES, severity="warning")
            return
        self.stop(hold=False)
        modes = MODES if self.frame == "joint" else CARTESIAN_MODES
        self.mode = modes[(modes.index(self.mode) + 1) % len(modes)]

    def watch_reduced(self, reduced: bool) -> None:
        """In reduced speed a joint is jogged by position steps only: the duty modes' open-loop
        duty is refused there (the controller cannot hold it to 250 mm/s). Back in automatic
        the pad takes the mode it had again."""
        if reduced and self.frame == "joint" and self.mode != "position":
            self.stop(hold=False)
            self._mode_in_automatic = self.mode
            self.mode = "position"
        elif not reduced and self._mode_in_automatic is not None:
            if self.frame == "joint":
                self.mode = self._mode_in_automatic
            self._mode_in_automatic = None

    def watch_frame(self, frame: str) -> None:
        self.repeat.most, self.repeat.factor = JOINT_RELEASE if frame == "joint" else TOOL_RELEASE

    def action_frame(self) -> None:
        """Cycle joint → world → tool jog; a machine without kinematics says it has none."""
        if self.cartesian_speeds is None:
            self.notify(NO_CARTESIAN.format(name=self.machine_name), severity="warning")
            return
        self.stop(hold=False)
        self.frame = FRAMES[(FRAMES.index(self.frame) + 1) % len(FRAMES)]
        if self.frame != "joint" and self.mode == "duty":
            self.mode = "position"  # a duty has no Cartesian meaning
        self.watch_reduced(self.reduced)

    def refused_while_latched(self) -> bool:
        """True while the E-stop is latched; then say why (not at every key of a burst)."""
        if not self.latched:
            return False
        now = time.monotonic()
        if now - self._told_latched > LATCHED_NOTICE_S:
            self._told_latched = now
            self.notify(LATCHED, severity="warning")
        return True

    def action_jog(self, joint: int, sign: int) -> None:
        if self.frame != "joint":
            self.jog_tool(joint, sign)
            return
        if joint >= self.n or self.refused_while_latched():
            return
        if self.mode == "duty":
            self.duty[joint] = max(-100.0, min(100.0, self.duty[joint] + sign * self.increment))
            self.send()
        elif self.mode == "hold-to-move":
            self.hold_key(joint, sign * self.hold_duty)
        else:
            self.post_message(self.TargetStepped(joint, sign * self.step(self.units[joint])))

    def jog_tool(self, axis: int, sign: int) -> None:
        """A Cartesian jog key: ``axis`` 0-5 is x, y, z, γ, β, α of the frame."""
        if self.refused_while_latched():
            return
        unit = "mm" if axis < 3 else "deg"
        d = [0.0] * 6
        if self.mode == "position":
            d[axis] = sign * self.step(unit)
            self.post_message(self.CartesianJogged(tuple(d), self.frame, 1.0))
            return
        key = axis * 2 + (sign < 0)  # the other key of the pair is another hold
        new = self.repeat.press(key, time.monotonic())
        if new:  # one Cartesian axis at a time: a new key ends the hold before it
            self.repeat.forget()
            self.repeat.press(key, time.monotonic())
        assert self.cartesian_speeds is not None  # the frame is joint without them
        d[axis] = sign * self.cartesian_speed * self.cartesian_speeds[0 if unit == "mm" else 1]
        self.post_message(self.CartesianHeld(tuple(d), self.frame, repeat=not new))
        self._listen()

    def action_arrow(self, sign: int) -> None:
        if self.refused_while_latched():
            return
        if self.mode == "duty":
            self.duty[0] = max(-100.0, min(100.0, self.duty[0] + sign * RIG_ARROW_STEP))
            self.send()
        else:
            self.action_jog(0, sign)

    def action_stop_all(self) -> None:
        """Space: every duty to 0 in duty mode (option.c); in the other modes a stop that
        holds where the joints are, as a release does (a held Cartesian jog brakes along its
        line first): zero duty there would drop the closed-loop hold."""
        if self.refused_while_latched():
            return
        if self.mode != "duty":
            self.stop(hold=True)
            return
        self.repeat.forget()
        self.duty = [0.0] * self.n
        self.send()

    def action_hold_here(self) -> None:
        if self.refused_while_latched():
            return
        self.stop(hold=True)

    def hold_key(self, joint: int, duty: float) -> None:
        if self.repeat.press(joint, time.monotonic()) or self.duty[joint] != duty:
            self.duty[joint] = duty
            self.send()
        self._listen()

    def _listen(self) -> None:
        """Check for releases from now on (every RELEASE_CHECK_S while a key is held)."""
        if self._checked == -math.inf:  # paused: its first check is on time, not late
            self._checked = time.monotonic()
        self._release_timer.resume()

    def _deafen(self) -> None:
        """No key held: stop checking (the next hold starts afresh)."""
        self._release_timer.pause()
        self._checked = -math.inf

    def _check_release(self) -> None:
        """Every RELEASE_CHECK_S while a key is held: stop the joints let go; when the last
        is let go, hold every joint where it stopped (at zero duty a joint would sag)."""
        if self._checked == -math.inf:  # queued before the pad stopped listening
            return
        now = time.monotonic()
        late, self._checked = now - self._checked - RELEASE_CHECK_S, now
        if late > STALL_S:  # the UI was not listening: repeats may be waiting behind this
            self.repeat.excuse(late)
            return
        gone = self.repeat.released(now)
        if self.frame != "joint":  # one Cartesian axis at a time: its release stops the jog
            if gone and not self.repeat.held:
                self.let_go()
                self.post_message(self.Stopped(True, tool=True))
            return
        if not self.repeat.held:
            self._deafen()
            if gone:
                self.stop(hold=True)
        elif gone:
            for j in gone:
                self.duty[j] = 0.0
            self.send()

    def send(self) -> None:
        self.post_message(self.DutyChanged(tuple(self.duty)))

    def stop(self, hold: bool) -> None:
        """Let go and ask for closed-loop hold (see ``Stopped``); always when a Cartesian key
        was held: its jog is running, and letting go must end it."""
        tool = self.moving_tool
        self.let_go()
        self.post_message(self.Stopped(hold or tool, tool))

    @property
    def moving_tool(self) -> bool:
        """A Cartesian hold-to-move key is held: its jog runs until it is let go."""
        return self.frame != "joint" and self.repeat.held

    def let_go(self) -> None:
        """Forget every held key and zero every duty; the tab decides about the hold."""
        self.repeat.forget()
        self._deafen()
        self.duty = [0.0] * self.n

    def forget_duties(self) -> None:
        """The controller left manual mode (a move, hold): start again from zero."""
        if any(self.duty):
            self.repeat.forget()
            self.duty = [0.0] * self.n

    def estop(self, latched: bool) -> None:
        """The E-stop latched (every duty and held key forgotten) or was released (the pad
        starts from zero: a release never starts motion by itself)."""
        self.let_go()
        self.latched = latched
        self.refresh()


class JogTab(TabPage):
    """Manual control of every joint, and of the tool in a Cartesian frame, from the keyboard."""

    REFRESH_HZ = 10.0
    TITLE = "Jog"
    _was_manual = False
    cartesian_note = Text("")  # why the last Cartesian jog was refused or ends early
    zone_note = ""  # the singularity zone's warning in full, when the arm is near one
    _jog: MoveHandle | None = None  # the last Cartesian jog sent
    _sending: tuple[JogPad.CartesianJogged, ...] | None = None  # while a step is being sent
    # (it waits for a move in progress, in a worker), the steps pressed meanwhile
    _steps: StepQueue | None = None  # steps pressed while it ran (made with the client)
    _dropping: list[str] | None = None  # the step waiting for another's move: why to drop it
    _refused = 0  # queued steps refused since the queue began: the reason is told once
    _servo: CartesianServo | None = None  # the held Cartesian jog, while it runs or brakes
    _unlogged: tuple[tuple[CartesianServo, JogPad.CartesianHeld], ...] = ()  # held jogs whose
    # ends are not in the event log yet, with what each was started with
    _zone_asked: tuple[object, ...] = ()  # the last joints, frame and speed the zone was found for
    _zone_said: tuple[str, ...] = ()  # and what was said of it
    _pose_at: tuple[float, ...] = ()  # the joints the tool's pose was last found for
    _pose_was: tuple[float, ...] = ()  # and that pose

    def compose(self) -> ComposeResult:
        speed = self.machine.cartesian_jog_speed if self.model is not None else None
        yield JogPad(tuple(j.unit for j in self.machine.joints), cartesian_speed=speed,
                     machine_name=self.machine.name, id="jog-pad")
        yield LiveText(id="jog-pose")
        yield LiveText(id="jog-cartesian-note")
        yield LiveText(id="jog-table")
        yield LiveText(id="jog-dead-band")
        yield Static(self._keys_help(), id="jog-help")

    def on_mount(self) -> None:
        self.query_one("#jog-table").styles.height = self.machine.n_joints + 1

    @property
    def pad(self) -> JogPad:
        return self.query_one(JogPad)

    def focus_main(self) -> None:
        self.pad.focus()

    def shown(self) -> None:
        self.pad.armed = True
        super().shown()

    def hidden(self) -> None:
        super().hidden()
        self.pad.armed = False
        self.pad.let_go()  # leaving the tab must not leave a joint moving: decided now
        self._forget_steps()
        self._drop_waiting("the Jog tab was left")
        self._release_servo("the Jog tab was left")
        self._leave_manual(hold=False)

    def estop(self, latched: bool) -> None:
        self.pad.estop(latched)
        self._forget_steps()
        if latched:
            self._drop_waiting("the E-stop latched")
        self._release_servo("E-stop")
        self.refresh_live()

    def on_jog_pad_arm_view_toggled(self) -> None:
        from app.widgets.arm_view import ArmView, named_positions  # loaded when first shown

        views = self.query(ArmView)
        if views:
            view = views.first()
            shown = view.display = not view.display
        else:
            view = ArmView(self.machine, self.model, self.status, id="jog-arm")
            self.mount(view)
            shown = True
        if shown:  # as taught now: positions taught since it was last shown are marked too
            view.show_positions(named_positions(self.desk.data_dir, self.machine))
        short = self.screen.has_class("-short")  # 80 × 24: in place of the table too
        for part, hide in (("#jog-help", True), ("#jog-dead-band", True), ("#jog-table", short)):
            self.query_one(part).display = not (shown and hide)

    def on_jog_pad_duty_changed(self, message: JogPad.DutyChanged) -> None:
        # A duty the pad has moved on from (a later key, or let go since: the tab was left,
        # the E-stop) is not sent: a later message carries the pad's duties, or none should.
        if not self.visible_now or self.pad.latched or message.duty != tuple(self.pad.duty):
            return
        status = self.status()
        if not any(message.duty) and status is not None and status.mode != Mode.MANUAL_ACTUATE:
            # no duty to zero: manual actuation at 0 % would let go of the held joints (and
            # abort a move into it), so space holds instead, as in the other modes
            self.command("hold", ControlClient.hold)
            return
        self.command("jog", lambda client: client.jog(list(message.duty)))
        self.refresh_live()

    def on_jog_pad_target_stepped(self, message: JogPad.TargetStepped) -> None:
        if not self.visible_now or self.pad.latched:  # pressed just before the tab was left
            return
        self.command("position jog",
                     lambda client: client.jog_position(message.joint, message.step))
        self.refresh_live()

    def on_jog_pad_cartesian_jogged(self, message: JogPad.CartesianJogged) -> None:
        if not self.visible_now or self.pad.latched:
            return
        if self._sending is not None:  # queued once the step being sent has its path
            self._sending += (message,)
            return
        running = self._jog is not None and not self._jog.done.is_set()
        if running or (self._steps is not None and self._steps.steps):
            self._queue(message)  # a new move now would start from rest while the arm moves
        else:
            self._forget_steps()
            self._send_jog(message)
        self.refresh_live()

    def _queue(self, message: JogPad.CartesianJogged) -> None:
        """Queue a step pressed while a step runs, if the arm can make it after the ones
        before it; the first one refused says why, the ones after only count."""
        client, running = self.client, self._jog
        if client is None or running is None or running.plan.path is None:
            return
        if self._steps is None:
            self._steps = StepQueue(self.machine, client.dt)
        steps = self._steps
        reason = steps.add(running.plan.path[-1], Step(message.displacement, message.frame,
                                                       message.speed))
        if reason:
            self._refused += 1
            if self._refused == 1:
                self._first_refusal = reason
                self.notify(reason, severity="warning")
        self.cartesian_note = self._queue_note()

    _first_refusal = ""  # why the first queued step was refused, shown while the queue runs

    def _queue_note(self) -> Text:
        """The steps waiting for the running one, and how many were refused and why."""
        parts: list[str | tuple[str, str]] = []
        steps = self._steps
        if steps is not None and steps.steps:
            parts += [("next: ", "dim"), _shown(steps.total),
                      (f" ({steps.steps[0].frame} frame), when this step ends", "dim")]
        if self._refused:
            many = f"{self._refused} steps" if self._refused > 1 else "a step"
            parts += [("; " if parts else "", "dim"), (f"{many} refused: ", "bold yellow"),
                      self._first_refusal]
        return Text.assemble(*parts)

    def _forget_steps(self) -> None:
        if self._steps is not None:
            self._steps.clear()
        self._refused = 0
        self._first_refusal = ""

    def on_jog_pad_cartesian_held(self, message: JogPad.CartesianHeld) -> None:
        """A held Cartesian key: start its servo, or keep it going on a repeat."""
        servo = self._servo
        if servo is not None and servo.running and message.repeat:
            servo.renew()
            return
        if not self.visible_now or self.pad.latched:
            return
        self._release_servo("another key")
        if self._sending is not None or (self._jog is not None and not self._jog.done.is_set()):
            self.cartesian_note = Text.assemble(("hold-to-move waits: ", "bold yellow"),
                                                "a step is running; press again when it ends")
            return
        self._forget_steps()
        self.cartesian_note = Text("")
        self.command("Cartesian jog", lambda client: self._start_servo(client, message))
        self.refresh_live()

    def _start_servo(self, client: ControlClient, message: JogPad.CartesianHeld) -> None:
        servo = CartesianServo(client, message.velocity, message.frame,
                               keepalive_s=SERVO_KEEPALIVE_S)
        servo.start(after=self._servo)  # the one let go may still be braking
        self._servo = servo
        self._unlogged += ((servo, message),)

    def _release_servo(self, why: str = "released") -> None:
        if self._servo is not None:
            self._servo.release(why)

    def _servo_ended(self) -> None:
        """Each held jog that has stopped: one log entry for the press-and-hold, and a note
        and a notification when something other than the release stopped it."""
        while self._unlogged and self._unlogged[0][0].done.is_set():
            (servo, asked), *rest = self._unlogged
            self._unlogged = tuple(rest)
            self._log_held(servo.wait(0), asked)

    def _log_held(self, report: ServoReport, asked: JogPad.CartesianHeld) -> None:
        axis = int(np.flatnonzero(asked.velocity)[0])
        unit = " mm" if axis < 3 else "°"
        moved = math.copysign(report.distance, asked.velocity[axis])  # along the axis's sign
        what = (f"held Cartesian jog {AXES[axis]} {moved:+.1f}{unit} ({asked.frame} "
                f"frame) in {report.duration:.1f} s, {report.drift:.2f} mm off its line: "
                f"{report.stopped}")
        self.desk.events.add(LogEntry(time.time(), "jog", what, data={
            "velocity": list(asked.velocity), "frame": asked.frame,
            "distance": report.distance, "drift_mm": report.drift, "braked": report.braked,
            "duration_s": report.duration, "stopped": report.stopped}))
        if report.stopped not in QUIET_STOPS:
            self.cartesian_note = Text.assemble(("the jog stopped: ", "bold yellow"),
                                                report.stopped)
            self.notify(f"Cartesian jog stopped: {report.stopped}", severity="warning")

    def _send_jog(self, message: JogPad.CartesianJogged) -> None:
        """Send the step from a worker: it waits for a move in progress (another tab's, the
        API's) to end and settle, seconds in which the keys must still work; the note says
        so, and leaving the tab or the E-stop drops it: no step starts unseen, or late."""
        self.cartesian_note = Text("")
        client = self.client
        if client is None:
            self.command("Cartesian jog", lambda client: None)  # says why it cannot
            return
        self._sending = ()
        status = self.status()
        if status is not None and status.moving and not status.paused:
            self.cartesian_note = Text.assemble(
                (STEP_WAITS, "bold yellow"), f"move {status.move_id} is in progress; "
                "the step runs once it ends and settles (leaving the tab or Esc drops it)")
        dropping = self._dropping = []
        self.run_worker(lambda: self._jog_tool(client, message, dropping), thread=True,
                        group="cartesian-step")

    def _drop_waiting(self, why: str) -> None:
        if self._dropping is not None:
            self._dropping.append(why)

    def _jog_tool(self, client: ControlClient, message: JogPad.CartesianJogged,
                  dropping: list[str]) -> None:
        """The worker: wait for a move in progress (not one in a feed hold, which the step
        supersedes) unless the step is dropped meanwhile, then send the jog; hand its handle,
        or why it was refused or dropped, to the tab."""
        try:
            while not dropping and (status := client.status()).moving and not status.paused:
                client.check()
                time.sleep(STEP_WAIT_S)
            if dropping:
                raise ValueError(f"the Cartesian step was dropped: {dropping[0]} before the "
                                 "move in progress ended")
            handle = client.jog_cartesian(message.displacement, message.frame, message.speed)
        except (ValueError, ControllerError, OSError) as exc:
            self._from_worker(self._step_refused, exc)
        else:
            self._from_worker(self._step_sent, handle)

    def _from_worker(self, call: Callable[[object], None], arg: object) -> None:
        with contextlib.suppress(RuntimeError):  # the app closed while the step waited
            self.app.call_from_thread(call, arg)

    def _step_sent(self, handle: MoveHandle) -> None:
        self._jog = handle
        if self.cartesian_note.plain.startswith(STEP_WAITS):  # it waits no more
            self.cartesian_note = Text("")
        pressed, self._sending = self._sending or (), None
        for message in pressed:
            self._queue(message)
        self.refresh_live()

    def _step_refused(self, exc: Exception) -> None:
        """A jog the arm cannot make says why under the pad and in a notification (its
        message names the jog: no prefix); the steps pressed to follow it are dropped."""
        self._sending = None
        text = str(exc) if isinstance(exc, ValueError) else f"Cartesian jog: {exc}"
        self.cartesian_note = Text.assemble(("jog refused: ", "bold yellow"), text)
        self.notify(text, severity="error")
        self._forget_steps()
        self.refresh_live()

    def on_jog_pad_stopped(self, message: JogPad.Stopped) -> None:
        if message.tool:  # the servo brakes along its line; the arm then holds there
            self._release_servo()
            return
        self._leave_manual(message.hold)

    def _leave_manual(self, hold: bool) -> None:
        """Hold, the thesis's default mode, if asked to or if the controller is in manual."""
        status = self.status()
        if hold or (status is not None and status.mode == Mode.MANUAL_ACTUATE):
            self.command("hold", ControlClient.hold)

    def refresh_live(self) -> None:
        self._servo_ended()
        steps = self._steps
        if (steps is not None and steps.steps and self._sending is None
                and (self._jog is None or self._jog.done.is_set())):
            step = steps.next()
            if step is not None and self.visible_now and not self.pad.latched:
                self._send_jog(JogPad.CartesianJogged(step.displacement, step.frame, step.speed))
                if not self.cartesian_note.plain:  # sent: what is still to come, or refused
                    self.cartesian_note = self._queue_note()
        status = self.status()
        if status is not None:
            if status.estop and not self.pad.latched:  # latched before its event arrived
                self.pad.estop(True)
            manual = status.mode == Mode.MANUAL_ACTUATE
            if self._was_manual and not manual:  # E-stop, hold or a move ended manual mode
                self.pad.forget_duties()
            self._was_manual = manual
            self.pad.reduced = status.speed_mode == "reduced"
        self.query_one("#jog-pose", LiveText).show(self._pose(status))
        note = self.cartesian_note
        if not note.plain and self.zone_note:  # nothing else to say: the whole warning
            note = Text.assemble(("⚠ ", "bold yellow"), (self.zone_note, "yellow"))
        self.query_one("#jog-cartesian-note", LiveText).show(note)
        self.query_one("#jog-table", LiveText).show(self._table(status))
        self.query_one("#jog-dead-band", LiveText).show(self._dead_band_note())

    def _pose(self, status: Status | None) -> Text:
        """The tool's live pose and, in a Cartesian frame, which keys move it along what."""
        if self.model is None:
            return Text("no tool pose: a single axis (Cartesian jog needs the Unimate's "
                        "kinematics)", "dim")
        if status is None:
            return Text("tool pose  –", "dim")
        at = tuple(status.position)
        if at != self._pose_at:  # at rest: the same pose, ten times a second
            self._pose_at, self._pose_was = at, tuple(self.model.pose(status.position))
        x, y, z, g, b, a = self._pose_was
        if self.size.width < NARROW:  # every number whole at 80 columns
            position = f"x {x:.1f}  y {y:.1f}  z {z:.1f} mm  "
            angles = f"γ {g:.2f}°  β {b:.2f}°  α {a:.2f}°"
        else:
            position, angles = (f"x {x:8.1f}  y {y:8.1f}  z {z:8.1f} mm   ",
                                f"γ {g:7.2f}°  β {b:7.2f}°  α {a:7.2f}°")
        parts: list[str | tuple[str, str]] = [("tool  ", "dim"), position, angles]
        warnings = self._zone_warnings(status)
        self.zone_note = warnings[0] if warnings else ""
        if warnings:
            room = self.query_one("#jog-pose").size.width - len(Text.assemble(*parts)) - 5
            fits = [w for w in warnings if len(w) <= room]
            parts += [("   ⚠ ", "bold yellow"), (fits[0] if fits else "", "yellow")]
        elif self.pad.frame != "joint":
            keys = "  ".join(f"{p}/{m} {axis}" for (p, m), axis in zip(JOG_KEYS, AXES,
                                                                     strict=True))
            parts += [("   keys (", "dim"), (self.pad.frame, "bold"), (" frame) ", "dim"), keys]
        return Text.assemble(*parts)

    def _zone_warnings(self, status: Status) -> list[str]:
        """What the singularity zone does to a Cartesian jog from the commanded joints, in the
        pad's frame (world in the joint frame) at its speed, said at three lengths (the pose
        line takes the longest that fits): none when every axis runs as asked."""
        q = np.array(status.desired)
        if not np.isfinite(q).all():
            q = np.array(status.position)
        frame = "world" if self.pad.frame == "joint" else self.pad.frame
        speed = self.pad.cartesian_speed if self.pad.mode == "hold-to-move" else 1.0
        asked = (tuple(q), frame, speed)
        if asked != self._zone_asked:  # the joints at rest: the same answer, ten times a second
            self._zone_asked, self._zone_said = asked, tuple(self._zone_words(q, frame, speed))
        return list(self._zone_said)

    def _zone_words(self, q: np.ndarray, frame: str, speed: float) -> list[str]:
        near = zone(q, self.machine, frame, speed)
        slowed = np.flatnonzero(near.scale < ZONE_WARNING)
        if not len(slowed):
            return []
        joints = self.machine.joints
        axes = ", ".join(f"{AXES[k]} stops ({joints[near.joint[k]].name})"
                         if near.scale[k] == 0.0 else f"{AXES[k]} {near.scale[k]:.0%}"
                         for k in slowed)
        short = ", ".join(f"{AXES[k]} {'stops' if near.scale[k] == 0.0 else 'slow'}"
                          for k in slowed)
        if abs(near.yaw) >= WRIST_WARNING_DEG:
            return [f"near a singularity; {frame} jog {axes}", short]
        return [f"wrist singularity near: Yaw {near.yaw:.1f}° from 0°; {frame} jog {axes}",
                f"Yaw {near.yaw:.1f}° from 0°: {short}", f"Yaw {near.yaw:.1f}°"]

    def _command(self, j: int) -> Text:
        """Joint ``j``'s commanded duty, marked when its valve will not open at it."""
        command = self.pad.duty[j]
        if below_min_pwm(self.machine.joints[j], command) is not None:
            return Text(f"{command:+.0f} ⚠", "bold yellow")
        return Text(f"{command:+.0f}", "bold" if command else "dim")

    def _dead_band_note(self) -> Text:
        """What a marked duty means, naming each joint it marks."""
        parts = []
        for j, joint in enumerate(self.machine.joints):
            least = below_min_pwm(joint, self.pad.duty[j])
            if least is not None:
                parts.append(f"{joint.name} {self.pad.duty[j]:+.0f} % (needs {least:g} %)")
        if not parts:
            return Text("min PWM: the least duty that moves the joint, each way (section "
                        "5.4.1); a command below it is marked ⚠", "dim")
        return Text.assemble(("⚠ below the minimum PWM, will not move: ", "bold yellow"),
                             ", ".join(parts))

    def _table(self, status: Status | None) -> Table:
        """Keys, joint, command, min PWM, controller and valve duty, position, target and a
        limit bar; under ``NARROW`` columns (80×24) the headers are short and the values
        carry no unit, so that every number is whole."""
        narrow = self.size.width < NARROW
        table = Table(expand=True, box=None, padding=(0, 1), header_style="bold")
        for name, justify in zip(NARROW_HEADERS if narrow else HEADERS, JUSTIFY, strict=True):
            table.add_column(name, justify=justify, no_wrap=True)
        table.add_column("limits" if narrow else "within limits", ratio=1, no_wrap=True)
        rig = self.machine.n_joints == 1
        for j, joint in enumerate(self.machine.joints):
            keys = "↑/↓  a/z" if rig else "/".join(JOG_KEYS[j])
            up, down = output_min_pwm(joint)
            least = Text(f"{up:g} / {down:g}", "dim")
            if status is None:
                table.add_row(keys, joint.name, self._command(j), least, "–", "–", "–", "–", "")
                continue
            q, d = status.position[j], status.desired[j]
            unit = "" if narrow else f" {joint.symbol}"
            table.add_row(
                keys, joint.name, self._command(j), least, f"{status.duty[j]:+6.1f}",
                f"{status.valve[j] + 0.0:+6.1f}",  # a closed valve is +0.0, never -0.0
                f"{q:.2f}{unit}", "–" if d != d else f"{d:.2f}{unit}",
                LimitBar(q, joint.lower, joint.upper, d))
        return table

    def _keys_help(self) -> Text:
        if self.machine.n_joints == 1:
            pairs = "↑/↓ (or a/z) Ram ±"
        else:
            pairs = "  ".join(f"{p}/{m} {j.name}" for (p, m), j in
                              zip(JOG_KEYS, self.machine.joints, strict=False))
        units = {j.unit for j in self.machine.joints}
        steps = "  ".join(" ".join(f"{v:g}" for v in table) + SYMBOLS[unit]
                          for unit, table in POSITION_STEPS.items() if unit in units)
        frames = " · w frame joint/world/tool" if self.model is not None else ""
        return Text.assemble(
            ("keys  ", "dim"), pairs,
            (f"   1–9 increment · space all stop · m mode · enter hold here{frames}", "dim"),
            ("\n1–9   ", "dim"), f"duty ±1…9 % a press · hold-to-move 10…{HOLD_DUTY_MAX:g} % · "
            f"position steps {steps}", self._cartesian_help())

    def _cartesian_help(self) -> Text:
        if self.model is None:
            return Text("")
        keys = "  ".join(f"{p}/{m} {axis}" for (p, m), axis in zip(JOG_KEYS, AXES, strict=True))
        mm, deg = self.machine.cartesian_jog_speed
        speeds = f"{CARTESIAN_SPEEDS[0]:.0%}…{CARTESIAN_SPEEDS[-1]:.0%}"
        return Text.assemble(
            ("\nworld/tool  ", "dim"), keys,
            ("   position: the step a press, on a straight line · hold-to-move: ", "dim"),
            f"{speeds} of {mm:g} mm/s, {deg:g}°/s", (" · stops before a limit or a singularity",
                                                    "dim"))
