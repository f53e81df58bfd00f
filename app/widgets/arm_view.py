"""The arm's live view: the Unimate 2000B in 3D (or the rig's ram) drawn in braille from the
controller's status, the planned motion beside it (``app.plotting.arm_scene``).

It reads its ``source`` (the newest status) ``POLL_HZ`` times a second while it is on
screen, and draws only when what it shows changed: the joints, the desired pose, the view,
its size, the plan or the positions; a view at rest costs one comparison a poll. A drawn
frame repaints only the rows that changed. Keys (when it has the focus): ←/→ orbit, ↑/↓
tilt, +/− zoom, f s t i the front, side, top and isometric views, 0 the view's default.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path
from typing import ClassVar

import numpy as np
from rich.style import Style
from rich.text import Text
from textual.binding import Binding
from textual.geometry import Region, Size
from textual.reactive import reactive
from textual.strip import Strip
from textual.widget import Widget

from app.plotting.arm_scene import (
    JOINT_LEVELS,
    WRIST_NEAR_DEG,
    YAW,
    ArmScene,
    Marker,
    Plan,
    RigScene,
    limit_levels,
    tool_trace,
)
from app.plotting.dot_canvas import DotCanvas, Drawn
from app.plotting.projection import VIEWS, Projection, View
from control.motion.positions import (
    Position,
    PositionBook,
    PositionsError,
    load_positions,
    positions_file,
)
from control.rt.layout import Status
from hw.machine import Machine
from kinematics.unimate import Unimate2000B

POLL_HZ = 25.0  # above the 20 frames a second a jog needs, below the UI's frame rate
ORBIT_DEG = 15.0
ZOOM_STEP = 1.25
REDUCED = (60, 16)  # below this many columns or rows: no floor grid, no labels
KEYS_HELP = "←→↑↓ orbit  +/− zoom  f s t i view  0 reset"


def named_positions(data_dir: Path, machine: Machine) -> tuple[Position, ...]:
    """Home, park and the taught positions in the data directory's file (none taught when it
    cannot be read: the Positions tab says why)."""
    try:
        return load_positions(positions_file(data_dir, machine), machine).positions
    except PositionsError:
        return PositionBook(machine).positions


class ArmView(Widget, can_focus=True):
    """The machine as it is (its status's ``position``), its ``desired`` pose as a ghost, and
    what is planned (``show_plan``, ``show_positions``)."""

    DEFAULT_CSS = """
    ArmView {
        height: 1fr;
        min-height: 6;
    }
    ArmView:focus {
        background-tint: $foreground 3%;
    }
    """
    BINDINGS: ClassVar = [
        Binding("left", "orbit(-1, 0)", "orbit", key_display="←→↑↓"),
        Binding("right", "orbit(1, 0)", "orbit", show=False),
        Binding("up", "orbit(0, 1)", "tilt", show=False),
        Binding("down", "orbit(0, -1)", "tilt", show=False),
        Binding("plus,equals_sign", "zoom(1)", "zoom", key_display="+/−"),
        Binding("minus", "zoom(-1)", "zoom out", show=False),
        Binding("f", "view('front')", "front", show=False),
        Binding("s", "view('side')", "side", show=False),
        Binding("t", "view('top')", "top", show=False),
        Binding("i", "view('isometric')", "isometric", show=False),
        Binding("0", "view('')", "reset view", show=False),
    ]

    view: reactive[View] = reactive(VIEWS["isometric"], layout=False, repaint=False)

    def __init__(self, machine: Machine, model: Unimate2000B | None,
                 source: Callable[[], Status | None], *, view: str = "isometric",
                 id: str | None = None, classes: str | None = None) -> None:
        super().__init__(id=id, classes=classes)
        self.machine = machine
        self.model = model
        self.source = source
        self.home_view = VIEWS[view]
        self.set_reactive(ArmView.view, self.home_view)
        self.arm = ArmScene(model) if model is not None else None
        joint = machine.joints[0]
        self.rig = None if model is not None else RigScene(joint, joint.plant.get("load_kg"))
        self.plan = Plan()
        self.draws = 0  # frames drawn (the idle view's test counts them)
        self.polls = 0  # times it looked at the status while on screen
        self._shown_for: tuple[object, ...] | None = None
        # what the background was drawn for, its projection and the drawing
        self._background: tuple[tuple[object, ...], Projection, DotCanvas] | None = None
        self._drawn: Drawn | None = None
        self._caption = Strip.blank(0)
        self._size = Size(0, 0)

    def on_mount(self) -> None:
        self.set_interval(1.0 / POLL_HZ, self.poll)

    # -- what it shows ------------------------------------------------------------------------

    def show_plan(self, path: np.ndarray | None, kind: str = "joint") -> None:
        """The path of a move being previewed or run, ``(N, J)`` joint rows (None: none);
        ``kind`` 'cartesian' draws it as the line it is, else as the tool's trace."""
        if self.arm is None or path is None or not len(path):
            trace = None
        else:
            trace = tool_trace(self.arm.model, np.asarray(path, dtype=float))
        self.plan = Plan(trace, "cartesian" if kind == "cartesian" else "joint",
                         self.plan.markers)
        self.poll()

    def show_positions(self, positions: Sequence[Position]) -> None:
        """Named positions as labelled markers at their tool points."""
        if self.arm is None or not positions:
            markers: tuple[Marker, ...] = ()
        else:
            points = self.arm.model.forward(np.array([p.joints for p in positions]))[:, :3, 3]
            markers = tuple(Marker(p.name, (float(x), float(y), float(z)))
                            for p, (x, y, z) in zip(positions, points, strict=True))
        self.plan = Plan(self.plan.path, self.plan.kind, markers)
        self.poll()

    # -- keys ---------------------------------------------------------------------------------

    def check_action(self, action: str, parameters: tuple[object, ...]) -> bool | None:
        if action in ("orbit", "zoom", "view"):
            return self.arm is not None  # the rig's schematic has one view
        return True

    def action_orbit(self, d_azimuth: int, d_elevation: int) -> None:
        self.view = self.view.orbited(d_azimuth * ORBIT_DEG, d_elevation * ORBIT_DEG)

    def action_zoom(self, sign: int) -> None:
        self.view = self.view.zoomed(ZOOM_STEP if sign > 0 else 1 / ZOOM_STEP)

    def action_view(self, name: str) -> None:
        self.view = VIEWS.get(name, self.home_view)

    def watch_view(self) -> None:
        self.poll()

    # -- drawing ------------------------------------------------------------------------------

    def poll(self) -> None:
        """Draw if what it would show changed (and it is on screen)."""
        if not self.is_mounted or not self.is_on_screen or self.size.area == 0:
            return
        self.polls += 1
        status = self.source()
        position = tuple(status.position) if status is not None else None
        desired = tuple(status.desired) if status is not None else None
        supply = round(status.supply_mpa, 1) if status is not None and self.rig else None
        # compared as bytes: a NaN (no target, no supply reading) equals itself there
        values = np.array([*(position or ()), *(desired or ()), supply or 0.0]).tobytes()
        shown_for = (values, position is None, self.view, self.size, self.plan)
        if shown_for == self._shown_for:
            return
        self._shown_for = shown_for
        self._draw(position, desired, supply)

    def _draw(self, position: tuple[float, ...] | None, desired: tuple[float, ...] | None,
              supply: float | None) -> None:
        width, height = self.size
        cols, rows = width, max(0, height - 1)
        if self.arm is not None:
            canvas = self._arm_canvas(position, desired, cols, rows)
        else:
            assert self.rig is not None
            target = desired[0] if desired is not None else None
            canvas = self.rig.draw(cols, rows, position[0] if position else float("nan"),
                                   target, float("nan") if supply is None else supply)
        before = self._drawn if self._size == self.size else None
        drawn = canvas.strips(before)
        caption = self._caption_strip(position, width)
        self.draws += 1
        self._drawn, self._size = drawn, self.size
        changed = caption != self._caption or before is None
        self._caption = caption
        if before is None:
            self.refresh()
            return
        regions = [Region(0, r + 1, width, 1) for r in drawn.changed]
        if changed:
            regions.append(Region(0, 0, width, 1))
        if regions:
            self.refresh(*regions)

    def _arm_canvas(self, position: tuple[float, ...] | None,
                    desired: tuple[float, ...] | None, cols: int, rows: int) -> DotCanvas:
        assert self.arm is not None
        reduced = cols < REDUCED[0] or rows < REDUCED[1]
        key = (self.view, cols, rows, self.plan, reduced)
        if self._background is None or self._background[0] != key:
            projection = self.arm.projection(self.view, cols, rows)
            self._background = (key, projection, self.arm.background(projection, cols, rows,
                                                                     self.plan, reduced))
        _, projection, background = self._background
        canvas = background.copy()
        # no target (manual actuation: NaN) is no ghost; a ghost where the arm is, none either
        if (desired is not None and position is not None and np.isfinite(desired).all()
                and not np.allclose(desired, position, atol=1e-3)):
            self.arm.arm(canvas, projection, desired, ghost=True)
        if position is not None and np.isfinite(position).all():
            self.arm.arm(canvas, projection, position)
        return canvas

    def _caption_strip(self, position: tuple[float, ...] | None, width: int) -> Strip:
        view = self.view
        parts: list[str | tuple[str, Style | str]] = []
        if self.arm is not None:
            parts.append((f"{view.name} ×{view.zoom:.2g}", "bold"))
        else:
            parts.append((self.machine.joints[0].name, "bold"))
        if position is None:
            parts.append(("  no status yet", "dim"))
        else:
            levels = limit_levels(position, [j.lower for j in self.machine.joints],
                                  [j.upper for j in self.machine.joints])
            for j in np.flatnonzero(levels).tolist():
                joint = self.machine.joints[j]
                parts += ["  ", (f"● {joint.name} near its limit", JOINT_LEVELS[levels[j]])]
            if self.arm is not None and abs(position[YAW]) < WRIST_NEAR_DEG:
                parts += ["  ", (f"⚠ wrist near singular (Yaw {position[YAW]:.1f}°)",
                                 "bold yellow")]
        if self.arm is not None and self.has_focus and width >= 100:
            parts.append((f"  ·  {KEYS_HELP}", "dim"))
        text = Text.assemble(*parts)
        text.truncate(width)
        return Strip(list(text.render(self.app.console)), text.cell_len).extend_cell_length(
            width)

    def render_line(self, y: int) -> Strip:
        if self._drawn is None or self._size != self.size:
            return Strip.blank(self.size.width)
        if y == 0:
            return self._caption
        lines = self._drawn.lines
        return lines[y - 1] if y - 1 < len(lines) else Strip.blank(self.size.width)

    def on_resize(self) -> None:
        self.poll()

    def on_focus(self) -> None:
        self._shown_for = None  # the caption says the keys while focused
        self.poll()

    def on_blur(self) -> None:
        self._shown_for = None
        self.poll()
