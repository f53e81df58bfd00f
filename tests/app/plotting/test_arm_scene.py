"""The arm's drawing checked against the kinematics: a known pose lands on the cells worked out
by hand from forward kinematics, joints near a limit change colour, the ghost, the path and the
markers are drawn where they belong, and a frame rebuilds only the rows that changed."""

from __future__ import annotations

import math

import numpy as np
import pytest

from app.plotting.arm_scene import (
    FLOOR,
    GHOST,
    JOINT_LEVELS,
    JOINT_PATH,
    LINE_PATH,
    LINK,
    MARKER,
    TRIAD,
    ArmScene,
    Marker,
    Plan,
    RigScene,
    limit_levels,
    tool_trace,
)
from app.plotting.dot_canvas import DotCanvas
from app.plotting.projection import VIEWS
from control.motion.robot_model import builtin_unimate
from hw.machine import load_machine

MODEL = builtin_unimate()
MACHINE = load_machine("unimate2000b")
HOME = np.array(MACHINE.home)  # In/Out 1300 mm, Yaw 90°, the rest 0
COLS, ROWS = 160, 45
MARGIN = 0.04  # projection.fit's default


def styles_at(canvas: DotCanvas, col: int, row: int) -> object:
    index = canvas.owner[row, col]
    return canvas.styles[index] if index >= 0 and canvas.codes[row, col] else None


def cells_in(canvas: DotCanvas, style: object) -> set[tuple[int, int]]:
    if style not in canvas.styles:
        return set()
    rows, cols = np.nonzero((canvas.owner == canvas.styles.index(style))
                            & ((canvas.codes > 0) | (canvas.text > 0)))
    return set(zip(cols.tolist(), rows.tolist(), strict=True))


def test_the_home_pose_lands_on_the_cells_worked_out_from_forward_kinematics() -> None:
    scene = ArmScene(MODEL)
    x, y, z = MODEL.forward(HOME)[:3, 3]
    assert (round(x, 1), round(y, 1), round(z, 1)) == (1500.0, 0.0, 747.4)  # 1300 + Lb, d1+a2−Ly
    # front view fitted to the reach sphere about the shoulder (0, 0, d1): the shoulder is the
    # raster's middle, and 2·reach spans (1 − 2·margin) of the shorter side, 4·45 = 180 pixels
    reach = math.hypot(MODEL.upper[0], MODEL.a2) + MODEL.lb + MODEL.ly
    scale = (1 - 2 * MARGIN) * (4 * ROWS) / (2 * reach)
    tool_px = (COLS + scale * x, 2 * ROWS - scale * (z - MODEL.d1))
    tool_cell = (int(tool_px[0]) // 2, int(tool_px[1]) // 4)
    base_cell = (COLS // 2, int(2 * ROWS + scale * MODEL.d1) // 4)
    canvas = scene.draw(VIEWS["front"], COLS, ROWS, HOME)
    assert styles_at(canvas, *tool_cell) in TRIAD  # the triad starts at the tool point
    assert styles_at(canvas, *base_cell) is not None  # the column stands on the base
    projection = scene.projection(VIEWS["front"], COLS, ROWS)
    assert projection.scale == pytest.approx(scale)
    np.testing.assert_allclose(projection.pixels([x, y, z]), tool_px)


def test_each_view_drops_the_axis_it_looks_along() -> None:
    scene = ArmScene(MODEL)
    point = np.array([700.0, -300.0, 400.0])
    for name, axis in (("front", 1), ("side", 0), ("top", 2)):
        projection = scene.projection(VIEWS[name], COLS, ROWS)
        moved = point.copy()
        moved[axis] += 500.0
        np.testing.assert_allclose(projection.pixels(moved), projection.pixels(point),
                                   atol=1e-9)
    iso = scene.projection(VIEWS["isometric"], COLS, ROWS)
    diagonal = np.array([1.0, 1.0, -1.0]) / math.sqrt(3)  # the line of sight at az −45°
    np.testing.assert_allclose(iso.pixels(point + 800 * diagonal),
                               iso.pixels(point), atol=1e-9)


def test_the_side_view_puts_a_tool_in_the_arm_plane_on_the_column() -> None:
    scene = ArmScene(MODEL)
    projection = scene.projection(VIEWS["side"], COLS, ROWS)
    tool = MODEL.forward(HOME)[:3, 3]  # y = 0: seen from +x it is in line with the column
    assert projection.pixels(tool)[0] == pytest.approx(COLS)


@pytest.mark.parametrize(("q", "level"), [(1508.5, 0), (2041.0 - 0.09 * 1065, 1),
                                          (976.0 + 0.015 * 1065, 2), (2050.0, 2)])
def test_a_joint_is_amber_within_ten_percent_of_a_limit_and_red_within_two(
        q: float, level: int) -> None:
    assert limit_levels([q], [976.0], [2041.0]).tolist() == [level]


def test_a_joint_near_its_limit_is_drawn_in_its_colour() -> None:
    scene = ArmScene(MODEL)
    clear = scene.draw(VIEWS["isometric"], COLS, ROWS, HOME)
    near = HOME.copy()
    near[2] = MACHINE.joints[2].upper - 0.5  # Up/Down 0.5° from its 30° limit: under 2 %
    red = scene.draw(VIEWS["isometric"], COLS, ROWS, near)
    assert not cells_in(clear, JOINT_LEVELS[2]) and cells_in(red, JOINT_LEVELS[2])
    near[2] = MACHINE.joints[2].upper - 3.0  # 5 % of its 57°
    amber = scene.draw(VIEWS["isometric"], COLS, ROWS, near)
    assert cells_in(amber, JOINT_LEVELS[1]) and not cells_in(amber, JOINT_LEVELS[2])


def test_the_wrist_singularity_is_marked_as_the_arm_comes_near_it() -> None:
    scene = ArmScene(MODEL)
    text = lambda q: "".join(s.text for s in scene.draw(VIEWS["front"], COLS, ROWS, q)  # noqa: E731
                             .strips().lines)
    assert "Yaw" not in text(HOME)
    near = HOME.copy()
    near[4] = 4.0
    assert "⚠ Yaw 4.0°" in text(near)


def test_the_ghost_the_path_and_the_markers_are_drawn_beneath_the_arm() -> None:
    scene = ArmScene(MODEL)
    target = HOME + np.array([300.0, 40.0, 10.0, 20.0, -30.0, 45.0])
    path = np.linspace(HOME, target, 3000)
    park = MODEL.forward(np.array(MACHINE.park))[:3, 3]
    plan = Plan(tool_trace(MODEL, path), "joint", (Marker("park", tuple(park)),))
    canvas = scene.draw(VIEWS["isometric"], COLS, ROWS, HOME, target, plan)
    projection = scene.projection(VIEWS["isometric"], COLS, ROWS)
    ghost_tool = canvas.cell(projection.pixels(MODEL.forward(target)[:3, 3]))
    assert cells_in(canvas, GHOST) and ghost_tool in cells_in(canvas, GHOST) | cells_in(
        canvas, JOINT_PATH)  # the trace ends where the ghost's tool is
    trace = cells_in(canvas, JOINT_PATH)
    assert len(trace) > 8
    mid = canvas.cell(projection.pixels(MODEL.forward(path[1500])[:3, 3]))
    assert any(abs(c - mid[0]) <= 1 and abs(r - mid[1]) <= 1 for c, r in trace)
    marker = canvas.cell(projection.pixels(park))
    assert marker in cells_in(canvas, MARKER)
    assert "park" in canvas.strips().lines[marker[1]].text
    assert cells_in(canvas, LINK) and cells_in(canvas, FLOOR)


def test_a_cartesian_line_is_drawn_as_a_line_and_a_small_view_leaves_out_the_decorations(
        ) -> None:
    scene = ArmScene(MODEL)
    line = np.linspace([1200.0, -400.0, 800.0], [1600.0, 400.0, 800.0], 50)
    plan = Plan(line, "cartesian", (Marker("park", (1000.0, 0.0, 800.0)),))
    canvas = scene.draw(VIEWS["top"], COLS, ROWS, HOME, None, plan)
    assert len(cells_in(canvas, LINE_PATH)) > 10 and not cells_in(canvas, JOINT_PATH)
    small = scene.draw(VIEWS["top"], 40, 12, HOME, None, plan, reduced=True)
    assert not cells_in(small, FLOOR) and "park" not in "".join(
        s.text for s in small.strips().lines)
    assert cells_in(small, LINK)


def test_a_frame_rebuilds_only_the_rows_that_changed() -> None:
    scene = ArmScene(MODEL)
    first = scene.draw(VIEWS["front"], COLS, ROWS, HOME).strips()
    same = scene.draw(VIEWS["front"], COLS, ROWS, HOME).strips(first)
    assert same.changed == () and all(a is b for a, b in zip(first.lines, same.lines,
                                                             strict=True))
    moved = HOME.copy()
    moved[3] = 20.0  # Bend: only the wrist and the tool move
    after = scene.draw(VIEWS["front"], COLS, ROWS, moved).strips(same)
    assert 0 < len(after.changed) < ROWS // 2
    assert all(after.lines[r] is same.lines[r] for r in range(ROWS) if r not in after.changed)


def test_the_rig_shows_its_ram_limits_target_and_supply() -> None:
    joint = load_machine("rig").joints[0]
    canvas = RigScene(joint, 300.0).draw(60, 20, 600.0, 900.0, 13.3)
    text = "\n".join(s.text for s in canvas.strips().lines)
    for words in ("limit 0 mm", "limit 1200 mm", "Ram 600.0 mm · 300 kg", "supply 13.3 MPa",
                  "target 900.0"):
        assert words in text
    assert cells_in(canvas, JOINT_LEVELS[0]) and cells_in(canvas, JOINT_PATH)
    low = RigScene(joint, 300.0).draw(60, 20, 5.0, None, float("nan"))
    assert cells_in(low, JOINT_LEVELS[2]) and "supply –" in "".join(
        s.text for s in low.strips().lines)
