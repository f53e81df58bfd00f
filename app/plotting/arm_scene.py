"""What the arm's view draws (``app.widgets.arm_view``), as pure numpy onto a ``DotCanvas``.

The Unimate 2000B (``ArmScene``): its links through the origins of the link frames
(``Unimate2000B.frames``), the joints on them coloured by how near each is to a limit, the
tool's frame as a triad (x red, y green, z blue), the base, the floor grid; the desired
pose as a dim ghost beneath; the path of a move as the tool's trace (FK of the path's rows,
subsampled) or a Cartesian line; named positions as labelled markers; the reach envelope's
outline, a circle of the farthest reach about the shoulder in the view's plane. The floor,
envelope, path and markers do not move with the arm: ``background`` draws them once per
view and size, and a frame copies it and draws the arm over it.

The single-axis rig (``RigScene``): a schematic of the ram and its load at its position on a
ruler of its stroke, the limits, the target (the desired position) and the supply pressure.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from rich.style import Style

from app.plotting.dot_canvas import DotCanvas
from app.plotting.projection import Projection, View, fit
from hw.machine import Joint
from kinematics.unimate import DH_ORDER, Unimate2000B

AMBER_FRACTION = 0.10  # a joint within this fraction of its range from a limit is amber
RED_FRACTION = 0.02  # and within this, red
YAW = 4  # sin θ5 = 0 is the wrist singularity (control.motion.cartesian_jog)
WRIST_NEAR_DEG = 10.0  # Yaw this close to 0° is marked: ten times the jog's 1° stop margin
PATH_POINTS = 400  # a path's rows are subsampled to about this many tool points
GRID_MM = 1000.0
TRIAD_MM = 250.0
BASE_MM = 200.0
ENVELOPE_POINTS = 180

LINK = Style(color="bright_white", bold=True)
GHOST = Style(color="grey58")
JOINT_LEVELS = (Style(color="#56b6c2", bold=True), Style(color="dark_orange", bold=True),
                Style(color="red", bold=True))
TRIAD = (Style(color="red"), Style(color="green"), Style(color="blue"))
FLOOR = Style(color="grey35")
ENVELOPE = Style(color="grey42")
BASE = Style(color="white")
JOINT_PATH = Style(color="#c678dd")
LINE_PATH = Style(color="#61afef")
MARKER = Style(color="yellow")
WARN = Style(color="yellow", bold=True)
DANGER = Style(color="red", bold=True)
NOTE = Style(color="grey70")


@dataclass(frozen=True)
class Marker:
    """A named position's tool point (mm, base frame) and its name."""

    name: str
    point: tuple[float, float, float]


@dataclass(frozen=True, eq=False)  # equal only to itself: a new plan is a new object
class Plan:
    """What is planned, drawn beneath the arm: ``path (M, 3)`` tool points (mm) or None;
    ``kind`` 'joint' (a joint-space move: the tool's trace) or 'cartesian' (a line);
    ``markers`` the named positions."""

    path: np.ndarray | None = None
    kind: str = "joint"
    markers: tuple[Marker, ...] = ()


def limit_levels(q: Sequence[float], lower: Sequence[float], upper: Sequence[float]
                 ) -> np.ndarray:
    """``(J,)`` 0 clear, 1 within ``AMBER_FRACTION`` of its range from a limit, 2 within
    ``RED_FRACTION`` (or past it)."""
    q, lo, hi = (np.asarray(v, dtype=float) for v in (q, lower, upper))
    room = np.minimum(q - lo, hi - q) / (hi - lo)
    return np.where(room <= RED_FRACTION, 2, np.where(room <= AMBER_FRACTION, 1, 0))


def tool_trace(model: Unimate2000B, path: np.ndarray, points: int = PATH_POINTS) -> np.ndarray:
    """``(M, 3)`` tool points (mm) of a joint path ``(N, 6)``: FK of every k-th row and the
    last, in one batch."""
    step = max(1, len(path) // points)
    rows = np.r_[np.arange(0, len(path), step), len(path) - 1]
    return model.forward(path[rows])[:, :3, 3]


class ArmScene:
    """The Unimate's drawing for one model (lengths, limits) and its workspace."""

    def __init__(self, model: Unimate2000B) -> None:
        self.model = model
        arm = math.hypot(model.upper[0], model.a2)  # the longest boom from the shoulder
        self.shoulder = np.array([0.0, 0.0, model.d1])
        self.reach = arm + model.lb + model.ly  # the farthest a tool point is from the shoulder

    def projection(self, view: View, cols: int, rows: int) -> Projection:
        """``view`` fitted to the reach envelope: the sphere of ``reach`` about the shoulder,
        whose outline is a circle in every view."""
        u, v = view.axes()[:2]
        extent = self.shoulder + self.reach * np.array([u, -u, v, -v])
        return fit(view, extent, 2 * cols, 4 * rows)

    def background(self, projection: Projection, cols: int, rows: int, plan: Plan,
                   reduced: bool) -> DotCanvas:
        """The floor, the reach envelope, the base, the planned path and the markers: what a
        frame draws the arm over. ``reduced`` (a small view) leaves out the grid and labels."""
        canvas = DotCanvas(cols, rows)
        if not reduced:
            self._floor(canvas, projection)
        self._envelope(canvas, projection, gap=2 if reduced else 1)
        half = BASE_MM / 2
        square = np.array([[-half, -half, 0], [half, -half, 0], [half, half, 0],
                           [-half, half, 0], [-half, -half, 0]])
        canvas.polyline(projection.pixels(square), BASE)
        if plan.path is not None and len(plan.path):
            style = LINE_PATH if plan.kind == "cartesian" else JOINT_PATH
            canvas.polyline(projection.pixels(plan.path), style, gap=0 if plan.kind ==
                            "cartesian" else 1)
        for marker in plan.markers:
            xy = projection.pixels(np.array(marker.point))
            canvas.blobs(xy[None], MARKER)
            if not reduced:
                col, row = canvas.cell(xy)
                canvas.label(col + 1, row, marker.name[:12], MARKER)
        return canvas

    def _floor(self, canvas: DotCanvas, projection: Projection) -> None:
        r = GRID_MM * math.floor(self.reach / GRID_MM)
        ticks = np.arange(-r, r + 1.0, GRID_MM)
        a = np.concatenate([np.c_[ticks, np.full_like(ticks, -r), np.zeros_like(ticks)],
                            np.c_[np.full_like(ticks, -r), ticks, np.zeros_like(ticks)]])
        b = np.concatenate([np.c_[ticks, np.full_like(ticks, r), np.zeros_like(ticks)],
                            np.c_[np.full_like(ticks, r), ticks, np.zeros_like(ticks)]])
        canvas.segments(projection.pixels(a), projection.pixels(b), FLOOR, gap=2)

    def _envelope(self, canvas: DotCanvas, projection: Projection, gap: int) -> None:
        angle = np.linspace(0.0, 2 * math.pi, ENVELOPE_POINTS + 1)
        u, v = projection.axes[0], projection.axes[1]
        circle = (self.shoulder + self.reach * (np.cos(angle)[:, None] * u
                                                + np.sin(angle)[:, None] * v))
        canvas.polyline(projection.pixels(circle), ENVELOPE, gap=gap)

    def arm(self, canvas: DotCanvas, projection: Projection, q: Sequence[float], *,
            ghost: bool = False) -> np.ndarray:
        """Draw the arm at joints ``q (6,)``: links, joints (coloured by ``limit_levels``)
        and the tool's triad, or all of it dim as a ``ghost``. Returns the pixels ``(7, 2)``
        of the frame origins (0 the base, 6 the tool point)."""
        frames = self.model.frames(np.asarray(q, dtype=float))
        origins = projection.pixels(frames[:, :3, 3])
        chain = origins[[0, 1, 2, 3, 5, 6]]
        if ghost:
            canvas.polyline(chain, GHOST)
            return origins
        tool = frames[6]
        ends = tool[:3, 3] + max(TRIAD_MM, 5.0 / projection.scale) * tool[:3, :3].T
        tips = projection.pixels(ends)[::-1]  # z, y, x: x on top where they cross
        canvas.segments(np.r_[chain[:-1], np.repeat(origins[6][None], 3, axis=0)],
                        np.r_[chain[1:], tips], [LINK] * 5 + [TRIAD[2], TRIAD[1], TRIAD[0]])
        levels = limit_levels(q, self.model.lower, self.model.upper)
        order = np.argsort(levels, kind="stable")  # the worst on top where two share a cell
        canvas.blobs(self._joint_points(origins)[order],
                     [JOINT_LEVELS[k] for k in levels[order]])
        if abs(q[YAW]) < WRIST_NEAR_DEG:
            col, row = canvas.cell(origins[5])
            style = DANGER if abs(q[YAW]) < WRIST_NEAR_DEG / 10 else WARN
            canvas.label(col + 1, row - 1, f"⚠ Yaw {q[YAW]:.1f}°", style)
        return origins

    @staticmethod
    def _joint_points(origins: np.ndarray) -> np.ndarray:
        """``(6, 2)``: where each actuator's joint is drawn, in actuator order: a revolute one
        at the origin of the frame its axis passes through (z_{i-1}), In/Out mid-boom and
        Rotate mid-column."""
        at = np.empty((6, 2))
        for i, actuator in enumerate(DH_ORDER):
            at[actuator] = origins[i]
        at[0] = (origins[2] + origins[3]) / 2  # In/Out slides the boom
        at[1] = (origins[0] + origins[1]) / 2  # Rotate turns the column
        return at

    def draw(self, view: View, cols: int, rows: int, q: Sequence[float],
             desired: Sequence[float] | None = None, plan: Plan = Plan(), *,
             reduced: bool = False) -> DotCanvas:
        """A whole frame at once (the view caches its background instead)."""
        projection = self.projection(view, cols, rows)
        canvas = self.background(projection, cols, rows, plan, reduced)
        if desired is not None:
            self.arm(canvas, projection, desired, ghost=True)
        self.arm(canvas, projection, q)
        return canvas


class RigScene:
    """The rig's ram and load on a ruler of its stroke (mm, bottom stop 0 at the bottom)."""

    def __init__(self, joint: Joint, load_kg: float | None) -> None:
        self.joint = joint
        self.load_kg = load_kg

    def draw(self, cols: int, rows: int, position: float, target: float | None,
             supply_mpa: float) -> DotCanvas:
        canvas = DotCanvas(cols, rows)
        w, h = canvas.width_px, canvas.height_px
        if w < 8 or h < 20:
            return canvas
        lo, hi = self.joint.lower, self.joint.upper
        top, bottom = 12.0, h - 6.0  # pixel rows of the top of the stroke and the floor
        barrel_top = bottom - (bottom - top) * 0.35
        travel = barrel_top - top - (bottom - top) * 0.12  # the load's rise over the stroke

        def row(p: float) -> float:  # the load's lower edge at ram position p
            return barrel_top - 1 - travel * (p - lo) / (hi - lo)

        x0 = max(2.0, w * 0.18)
        barrel = (x0, x0 + max(6.0, w * 0.16))
        mid = sum(barrel) / 2
        canvas.segments(np.array([[0.0, bottom]]), np.array([[w - 1.0, bottom]]), FLOOR)
        self._box(canvas, barrel[0], barrel_top, barrel[1], bottom, BASE)
        level = int(limit_levels([position], [lo], [hi])[0])
        rod_top = row(position)
        canvas.segments(np.array([[mid, barrel_top]]), np.array([[mid, rod_top]]), LINK)
        load = (barrel[0] - 2, rod_top - (bottom - top) * 0.1, barrel[1] + 2, rod_top)
        self._box(canvas, *load, JOINT_LEVELS[level], fill=True)
        ruler = barrel[1] + max(6.0, w * 0.1)
        canvas.segments(np.array([[ruler, row(hi)]]), np.array([[ruler, row(lo)]]), NOTE)
        for limit in (lo, hi):
            y = row(limit)
            canvas.segments(np.array([[ruler - 3, y]]), np.array([[ruler + 3, y]]), DANGER)
            col, r = canvas.cell(np.array([ruler + 4, y]))
            canvas.label(col + 1, r, f"limit {limit:g} {self.joint.unit}", DANGER)
        if target is not None and math.isfinite(target):
            y = row(target)
            canvas.segments(np.array([[barrel[0] - 4, y]]), np.array([[ruler, y]]), JOINT_PATH,
                            gap=1)
            canvas.label(0, 1, f"target {target:.1f} {self.joint.unit}", JOINT_PATH)
        load_text = f" · {self.load_kg:g} kg" if self.load_kg else ""
        canvas.label(0, 0, f"{self.joint.name} {position:.1f} {self.joint.unit}"
                     f"{load_text}", JOINT_LEVELS[level])
        supply = f"supply {supply_mpa:.1f} MPa" if math.isfinite(supply_mpa) else "supply –"
        col, r = canvas.cell(np.array([barrel[1] + 2, (barrel_top + bottom) / 2]))
        canvas.label(col + 1, r, supply, NOTE)
        return canvas

    @staticmethod
    def _box(canvas: DotCanvas, x0: float, y0: float, x1: float, y1: float, style: Style,
             fill: bool = False) -> None:
        if fill:
            ys = np.arange(math.floor(y0), math.floor(y1) + 1, dtype=float)
            canvas.segments(np.c_[np.full_like(ys, x0), ys], np.c_[np.full_like(ys, x1), ys],
                            style)
            return
        corners = np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1], [x0, y0]])
        canvas.polyline(corners, style)
