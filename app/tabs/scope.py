"""Scope: live desired vs actual (or error) and duty of every joint, the plots the thesis
drew offline with plotsix.m, drawn here at 25 frames per second with the braille raster.

A move's settle (its path over, the arm coming in position: ``docs/motion.md``) is marked
on each joint's plot by its goal band, the end ± the joint's goal tolerance, from when the
settle began to when it ended, and the bar says ``SETTLING`` while it lasts.

Only the visible tab draws. Data comes from the app's ``History``, filled by a
sampler thread at 200 Hz, so a frame copies at most a window of samples and
rasterises it in a few milliseconds (``benchmarks/ui.py``).
"""

from __future__ import annotations

import math
import time
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass
from typing import ClassVar

import numpy as np
from rich.style import Style
from rich.text import Text
from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import Grid, Vertical
from textual.reactive import reactive

from app.desk import Desk
from app.history import Window
from app.plotting.braille import Trace
from app.tabs.tab import TabPage
from app.widgets.live_text import LiveText
from app.widgets.scope import ScopePlot, draw_plots
from hw.machine import Joint

WINDOWS_S = (1.0, 2.0, 5.0, 10.0, 20.0, 60.0, 120.0)
DESIRED = Style(color="red")
ACTUAL = Style(color="bright_cyan")
DUTY = Style(color="yellow")
ERROR = Style(color="magenta")
SETTLE = Style(color="green", dim=True)
NICE_DUTY = (5.0, 10.0, 25.0, 50.0, 100.0)
SETTLES_KEPT = 8  # the settles the scope can mark, newest last
BAR_HZ = 4.0  # the bar's sample count and frame time, at a rate they can be read (its state
# at once): redrawn with every frame, the bar widened each frame's update to the plots under it


@dataclass
class Settle:
    """A move's settle seen on the status: controller time it began and ended (None while it
    lasts), and the end it held."""

    start_s: float
    goal: tuple[float, ...]
    end_s: float | None = None


def position_ranges(window: Window, joints: Sequence[Joint], fixed: bool
                    ) -> list[tuple[float, float]]:
    """Each joint's y range: auto-scaled around desired and actual (at least 4 tolerance
    bands), or the joint limits (fixed, or no value in the window); the window's extremes
    found for all joints at once."""
    if not len(window) or fixed:
        return [(joint.lower, joint.upper) for joint in joints]
    values = np.concatenate([window.position, window.desired])
    if np.isfinite(values.sum()):  # every value finite (a live window): their extremes
        los, his = values.min(axis=0).tolist(), values.max(axis=0).tolist()
        seen = [True] * len(joints)
    else:  # a joint without desired (NaN between moves): its finite values only
        finite = np.isfinite(values)
        seen = finite.any(axis=0).tolist()
        los = np.where(finite, values, np.inf).min(axis=0).tolist()
        his = np.where(finite, values, -np.inf).max(axis=0).tolist()
    out = []
    for joint, lo, hi, any_value in zip(joints, los, his, seen, strict=True):
        if not any_value:
            out.append((joint.lower, joint.upper))
            continue
        half = max((hi - lo) / 2 * 1.1, 2 * joint.tolerance)
        mid = (hi + lo) / 2
        out.append((mid - half, mid + half))
    return out


def symmetric_range(values: np.ndarray, floor: float) -> tuple[float, float]:
    finite = np.abs(values[np.isfinite(values)])
    top = max(float(finite.max()) * 1.1 if len(finite) else 0.0, floor)
    return -top, top


def duty_range(values: np.ndarray) -> tuple[float, float]:
    finite = np.abs(values[np.isfinite(values)])
    peak = float(finite.max()) if len(finite) else 0.0
    top = next((n for n in NICE_DUTY if peak <= n), 100.0)
    return -top, top


class JointScope(Vertical):
    """One joint: position (or error) over duty."""

    def __init__(self, index: int, *, id: str | None = None) -> None:
        super().__init__(id=id)
        self.index = index

    def compose(self) -> ComposeResult:
        yield ScopePlot(classes="scope-position")
        yield ScopePlot(classes="scope-duty")


class ScopeTab(TabPage, can_focus=True):
    """Live plots; keys choose joints, window, view; pause freezes the picture."""

    REFRESH_HZ = 25.0
    TITLE = "Scope"
    LATER = ("#scope-joint-2, #scope-joint-3", "#scope-joint-4, #scope-joint-5")
    BINDINGS: ClassVar = [
        *[Binding(str(k), f"toggle({k - 1})", "joints", show=k == 1,
                  key_display="1-6" if k == 1 else None) for k in range(1, 7)],
        Binding("0", "all_joints", "all", show=False),
        Binding("p,space", "pause", "pause", key_display="p"),
        Binding("plus,equals_sign", "zoom(-1)", "zoom in", key_display="+"),
        Binding("minus", "zoom(1)", "zoom out", key_display="-"),
        Binding("left", "pan(1)", "back", key_display="←"),
        Binding("right", "pan(-1)", "forward", key_display="→"),
        Binding("e", "error_view", "error view"),
        Binding("u", "duty_view", "duty"),
        Binding("l", "limits", "y: limits/auto"),
    ]

    window_s: reactive[float] = reactive(10.0)
    paused: reactive[bool] = reactive(False)
    error_view: reactive[bool] = reactive(False)
    show_duty: reactive[bool] = reactive(True)
    fixed_y: reactive[bool] = reactive(False)

    def __init__(self, desk: Desk, *, id: str | None = None) -> None:
        super().__init__(desk, id=id)
        self.selected = [True] * 6
        self.paused_at = 0.0
        self.pan_s = 0.0
        self.frame_s = 0.0  # time the last frame took to compute, for the status line
        self.settles: deque[Settle] = deque(maxlen=SETTLES_KEPT)
        self._bar_shown: tuple[object, ...] = ()  # the bar's state as last shown, and when
        self._bar_at = 0.0
        self._plots: list[tuple[JointScope, ScopePlot, ScopePlot]] | None = None

    def compose(self) -> ComposeResult:
        yield LiveText(id="scope-bar")
        with Grid(id="scope-grid"):
            for j in range(self.machine.n_joints):
                yield JointScope(j, id=f"scope-joint-{j}")

    def on_mount(self) -> None:
        self.selected = [True] * self.machine.n_joints
        self._layout()

    def focus_main(self) -> None:
        self.focus()

    def check_action(self, action: str, parameters: tuple[object, ...]) -> bool | None:
        if action == "toggle":
            return int(parameters[0]) < self.machine.n_joints  # type: ignore[arg-type]
        if action == "pan":
            return self.paused or None
        return True

    # -- keys ---------------------------------------------------------------------------

    def action_toggle(self, j: int) -> None:
        if j < len(self.selected):
            self.selected[j] = not self.selected[j]
            if not any(self.selected):
                self.selected[j] = True
            self._layout()
            self.refresh_live()

    def action_all_joints(self) -> None:
        self.selected = [True] * self.machine.n_joints
        self._layout()
        self.refresh_live()

    def action_pause(self) -> None:
        self.paused = not self.paused
        self.pan_s = 0.0
        self.paused_at = self.desk.history.latest_time
        self.refresh_bindings()
        self.refresh_live(force=True)

    def action_zoom(self, direction: int) -> None:
        i = WINDOWS_S.index(self.window_s) if self.window_s in WINDOWS_S else 3
        self.window_s = WINDOWS_S[max(0, min(len(WINDOWS_S) - 1, i + direction))]
        self.refresh_live(force=True)

    def action_pan(self, direction: int) -> None:
        if self.paused:
            self.pan_s = max(0.0, self.pan_s + direction * self.window_s / 4)
            self.refresh_live(force=True)

    def action_error_view(self) -> None:
        self.error_view = not self.error_view
        self.refresh_live(force=True)

    def action_duty_view(self) -> None:
        self.show_duty = not self.show_duty
        self._layout()
        self.refresh_live(force=True)

    def action_limits(self) -> None:
        self.fixed_y = not self.fixed_y
        self.refresh_live(force=True)

    # -- drawing ------------------------------------------------------------------------

    def _layout(self) -> None:
        shown = 0
        for scope in self.query(JointScope):
            scope.display = self.selected[scope.index]
            shown += scope.display
            scope.query_one(".scope-duty").display = self.show_duty
        grid = self.query_one("#scope-grid", Grid)
        grid.styles.grid_size_columns = 2 if shown >= 3 else 1
        grid.styles.grid_size_rows = max(1, math.ceil(shown / (2 if shown >= 3 else 1)))

    def watch_settle(self) -> bool:
        """Note a settle beginning or ending (the status's SETTLING flag); True while one
        lasts."""
        status = self.status()
        if status is None:
            return False
        last = self.settles[-1] if self.settles else None
        if status.settling and (last is None or last.end_s is not None):
            self.settles.append(Settle(status.time_s, tuple(status.desired)))
        elif not status.settling and last is not None and last.end_s is None:
            last.end_s = status.time_s
        return status.settling

    def refresh_live(self, force: bool = False) -> None:
        settling = self.watch_settle()
        if self.paused and not force:
            return
        started = time.perf_counter()
        history = self.desk.history
        end = self.paused_at - self.pan_s if self.paused else None
        window = history.window(self.window_s, end)
        t_end = (end if end is not None else
                 float(window.t[-1]) if len(window) else 0.0)
        x = window.t - t_end
        x_range = (-self.window_s, 0.0)
        labels = (f"−{self.window_s:g} s", "", "now" if not self.paused
                  else f"t = {t_end:.2f} s")
        shown = [joint for joint in self._joint_plots() if joint[0].display]
        ranges = (None if self.error_view
                  else position_ranges(window, self.machine.joints, self.fixed_y))
        plots: list[ScopePlot] = []
        for scope, position, duty in shown:
            plots += self._set_joint(scope.index, position, duty, window, x, x_range, labels,
                                     None if ranges is None else ranges[scope.index])
        draw_plots(plots)  # the twelve plots' traces rastered together
        self.frame_s = time.perf_counter() - started
        self._bar(len(window), settling)

    def _joint_plots(self) -> list[tuple[JointScope, ScopePlot, ScopePlot]]:
        """Each joint's scope and its position and duty plots (found once: a query a frame
        cost a tenth of the frame)."""
        if self._plots is None:
            self._plots = [(scope, *scope.query(ScopePlot)) for scope in self.query(JointScope)]
        return self._plots

    def _set_joint(self, j: int, position: ScopePlot, duty: ScopePlot, window: Window,
                   x: np.ndarray, x_range: tuple[float, float], labels: tuple[str, str, str],
                   y_range: tuple[float, float] | None) -> list[ScopePlot]:
        """Set joint ``j``'s plots to this frame (``y_range``: the position plot's, None in the
        error view); the plots to draw."""
        joint = self.machine.joints[j]
        q, d, u = window.position[:, j], window.desired[:, j], window.duty[:, j]
        last = len(x) - 1
        if y_range is None:
            e = d - q
            title = Text.assemble((f"{joint.name} error [{joint.symbol}] ", "bold"),
                                  ("━ desired − actual ", ERROR),
                                  f"{e[last]:+.3f}" if last >= 0 and e[last] == e[last] else "")
            position.set([Trace(x, e, ERROR)], x_range,
                         symmetric_range(e, joint.tolerance), title, zero_line=True,
                         x_labels=labels)
        else:
            title = Text.assemble((f"{joint.name} [{joint.symbol}] ", "bold"),
                                  ("━ desired ", DESIRED),
                                  _value(d, last), ("  ━ actual ", ACTUAL), _value(q, last))
            position.set([*self._settle_band(j, joint, x, window),
                          Trace(x, d, DESIRED), Trace(x, q, ACTUAL)], x_range, y_range, title,
                         x_labels=labels)
        if not self.show_duty:
            return [position]
        title = Text.assemble(("duty [%] ", "bold"), ("━ controller ", DUTY), _value(u, last))
        duty.set([Trace(x, u, DUTY)], x_range, duty_range(u), title, zero_line=True,
                 x_labels=labels)
        return [position, duty]

    def _settle_band(self, j: int, joint: Joint, x: np.ndarray, window: Window) -> list[Trace]:
        """Each settle in the window as its goal band, goal ± goal_tolerance, drawn over the
        time it lasted."""
        if not len(window):
            return []
        t_end = float(window.t[-1]) - float(x[-1])  # x = t − t_end
        traces = []
        for settle in self.settles:
            ends = np.array([settle.start_s, settle.end_s if settle.end_s is not None
                             else float(window.t[-1])]) - t_end
            for side in (-1.0, 1.0):
                band = settle.goal[j] + side * joint.goal_tolerance
                traces.append(Trace(ends, np.array([band, band]), SETTLE))
        return traces

    def _bar(self, samples: int, settling: bool = False) -> None:
        shown = (self.paused, settling, self.window_s, tuple(self.selected), self.error_view,
                 self.fixed_y)
        now = time.monotonic()
        if shown == self._bar_shown and now - self._bar_at < 1.0 / BAR_HZ:
            return
        self._bar_shown, self._bar_at = shown, now
        state = Text("PAUSED", "bold yellow") if self.paused else Text("LIVE", "bold green")
        if settling:
            state.append("  SETTLING", "bold yellow")
        joints = " ".join(f"{j + 1}" if on else "·" for j, on in enumerate(self.selected))
        view = "error" if self.error_view else "desired vs actual"
        self.query_one("#scope-bar", LiveText).show(Text.assemble(
            state, ("  window ", "dim"), f"{self.window_s:g} s", ("  joints ", "dim"), joints,
            ("  view ", "dim"), view, ("  y ", "dim"), "limits" if self.fixed_y else "auto",
            ("  samples ", "dim"), str(samples),
            ("  frame ", "dim"), f"{self.frame_s * 1e3:.1f} ms"))


def _value(values: np.ndarray, last: int) -> str:
    if last < 0 or not math.isfinite(values[last]):
        return "–"
    return f"{values[last]:.2f}"
