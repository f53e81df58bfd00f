"""Exported plots read well (issue 26, item 8): a joint that holds still is drawn on a span of
encoder counts with labels inside its panel, the velocity panel shows no spike for a wrong
encoder reading and does not lag a step, and the E-stop, a fault and a stall are marked
where they happened. Read back from the SVG file, through its own tick labels."""

from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from app.plotting.figure import Figure
from app.plotting.run_plot import export, joint_figure, overview, velocity
from app.plotting.strips import LABEL_WIDTH
from app.plotting.svg import PANEL_W
from control.recorder import Run
from hw.machine import load_machine

NS = {"svg": "http://www.w3.org/2000/svg"}
UNIMATE = load_machine("unimate2000b")
ROTATE, UPDOWN = 1, 2
GLITCH = 0.62  # deg: the Yaw word of commit f88bf46, one 3 ms scan off
CHAR_W = 7.7  # px: the widest DejaVu Sans digit at 12 px, as the SVG reckons it


@dataclass(frozen=True)
class DrawnPanel:
    title: str
    left: float  # px: the panel's own box, its neighbours' start past it
    frame: tuple[float, float, float, float]  # the plot's box: left, top, right, bottom
    y_ticks: list[tuple[float, str, float]]  # (label's right end px, text, its value)
    polylines: list[np.ndarray]  # points px
    marks: list[tuple[float, str, str, float]]  # (data-t, kind, label, line's x px)
    x_scale: tuple[float, float]  # s = a·px + b, from the time axis's tick labels
    y_scale: tuple[float, float]  # value = a·px + b, from the y axis's tick labels


def drawn(svg: Path) -> list[DrawnPanel]:
    root = ET.parse(svg).getroot()
    found = []
    for group in root.iterfind("svg:g[@class='panel']", NS):
        frame = group.find("svg:rect[@class='frame']", NS)
        x, y = float(frame.get("x")), float(frame.get("y"))
        box = (x, y, x + float(frame.get("width")), y + float(frame.get("height")))
        y_ticks = [(float(e.get("x")), e.text, float(e.text))
                   for e in group.iterfind("svg:text[@class='ytick']", NS)]
        y_px = [float(e.get("y")) - 4 for e in group.iterfind("svg:text[@class='ytick']", NS)]
        x_ticks = [(float(e.get("x")), float(e.text))
                   for e in group.iterfind("svg:text[@class='xtick']", NS)]
        marks = [(float(g.get("data-t")), g.get("data-kind"), g.find("svg:text", NS).text,
                  float(g.find("svg:line", NS).get("x1")))
                 for g in group.iterfind("svg:g[@class='mark']", NS)]
        polylines = [np.array([[float(v) for v in pair.split(",")]
                               for pair in line.get("points").split()])
                     for line in group.iterfind("svg:polyline[@class='line']", NS)]
        found.append(DrawnPanel(
            group.find("svg:text[@class='title']", NS).text,
            x // PANEL_W * PANEL_W, box, y_ticks, polylines, marks,
            tuple(np.polyfit([p for p, _ in x_ticks], [v for _, v in x_ticks], 1)),
            tuple(np.polyfit(y_px, [v for *_, v in y_ticks], 1))))
    return found


def run(status: str = "complete", gaps: list[list[float]] | None = None) -> Run:
    """2 s at 1 ms: Rotate ramps 0 → 10° at 20°/s from 0.3 s, read in encoder counts, one
    reading 0.62° off for 3 ms at 1.2 s; Up/Down holds at 4.6° and never moves; the other
    joints hold at 0."""
    t = np.arange(2000) * 1e-3
    desired = np.zeros((len(t), UNIMATE.n_joints))
    desired[:, ROTATE] = np.clip((t - 0.3) * 20.0, 0.0, 10.0)
    desired[:, UPDOWN] = 4.6
    count = UNIMATE.joints[ROTATE].encoder.gradient
    actual = desired.copy()
    actual[:, ROTATE] = np.round(desired[:, ROTATE] / count) * count
    actual[1200:1203, ROTATE] += GLITCH
    duty = np.zeros_like(desired)
    duty[:, ROTATE] = np.where((t > 0.3) & (t < 0.8), 35.0, 0.0)
    meta = {"moving": [ROTATE], "gaps": gaps or []}
    return Run.from_machine(UNIMATE, "ramp", status, {}, t, desired, actual, duty, meta=meta)


def svg_of(figure: object, tmp_path: Path) -> list[DrawnPanel]:
    return drawn(export(tmp_path / "plot", figure)[0])


def test_a_joint_that_holds_still_has_a_span_of_counts_and_labels_inside_its_panel(
        tmp_path: Path) -> None:
    panels = svg_of(overview(run(), [ROTATE, UPDOWN]), tmp_path)
    updown = next(p for p in panels if p.title == "Up/Down (deg)")
    values = [v for *_, v in updown.y_ticks]
    count = UNIMATE.joints[UPDOWN].encoder.gradient
    assert 5 * count <= max(values) - min(values) <= 1.0  # not ±1e-9, not a whole degree
    assert min(values) <= 4.6 <= max(values)
    for panel in panels:
        assert panel.y_ticks
        for right, text, _ in panel.y_ticks:  # right-aligned: the text runs leftwards
            assert right - CHAR_W * len(text) >= panel.left, (panel.title, text)
        assert len(panel.title) * CHAR_W <= PANEL_W - 16, panel.title


def test_the_estop_and_a_stall_are_marked_when_they_happened(tmp_path: Path) -> None:
    stopped = run("estop: operator E-stop, with a 0.1 s controller stall", [[0.25, 0.12]])
    for figure in (overview(stopped, [ROTATE, UPDOWN]), joint_figure(stopped, ROTATE)):
        for panel in svg_of(figure, tmp_path):
            by_kind = {kind: (t, label, x) for t, kind, label, x in panel.marks}
            assert set(by_kind) == {"estop", "stall"}, panel.title
            a, b = panel.x_scale
            t, label, x = by_kind["estop"]
            assert t == pytest.approx(stopped.t[-1]) and a * x + b == pytest.approx(t, abs=0.01)
            assert label == "E-stop: operator E-stop"
            assert x < panel.frame[2] - 5  # clear of the frame, though the run ends there
            t, label, x = by_kind["stall"]
            assert (t, label) == (0.25, "stall 0.12 s")
            assert a * x + b == pytest.approx(0.25, abs=0.01)


def test_a_fault_is_marked_and_a_complete_run_has_no_mark(tmp_path: Path) -> None:
    faulted = run("fault: following error: Rotate 3.1° behind; holding")
    marks = [m for p in svg_of(joint_figure(faulted, ROTATE), tmp_path) for m in p.marks]
    assert {(kind, label[:30]) for _, kind, label, _ in marks} == {
        ("fault", "fault: following error: Rotate")}
    assert not [m for p in svg_of(joint_figure(run(), ROTATE), tmp_path) for m in p.marks]


def test_the_velocity_has_no_spike_for_a_wrong_reading_and_does_not_lag(tmp_path: Path) -> None:
    ramp = run()
    panel = svg_of(joint_figure(ramp, ROTATE), tmp_path)[3]
    assert panel.title.startswith("Rotate velocity")
    a, b = panel.y_scale
    drawn_v = np.concatenate([a * line[:, 1] + b for line in panel.polylines])
    assert drawn_v.max() == pytest.approx(20.0, abs=1.0)  # the ramp's speed, no spike past it
    assert drawn_v.min() > -1.0
    v = velocity(ramp.t, ramp.actual[:, ROTATE])
    assert np.abs(v[1150:1250]).max() < 0.5  # at rest around the wrong reading
    half_up = ramp.t[np.argmax(v > 10.0)]
    half_down = ramp.t[500 + np.argmax(v[500:] < 10.0)]
    assert half_up == pytest.approx(0.3, abs=0.002)  # half speed within 2 ms of the start
    assert half_down == pytest.approx(0.8, abs=0.002)  # and of the end: no lag


def test_the_text_export_and_the_runs_tab_draw_the_marks_too(tmp_path: Path) -> None:
    """The braille drawing (``--format txt`` at 160 columns, the Runs tab): a dotted column at
    the E-stop, across a panel where nothing else is drawn but the held line."""
    stopped = run("estop: operator E-stop")
    held = Figure("Up/Down held", overview(stopped, [UPDOWN]).panels[:1])
    text = export(tmp_path / "plot", held, formats=("txt",))[0].read_text(encoding="utf-8")
    assert "┃ E-stop: operator E-stop" in text
    rows = [line.split("┤", 1)[1] for line in text.splitlines() if "┤" in line]
    across = [c for c in range(min(map(len, rows))) if all(row[c] != " " for row in rows)]
    x0, x1 = held.panels[0].x_range()
    cols = 160 - LABEL_WIDTH - 1
    assert len(across) == 1 and abs(across[0] - (stopped.t[-1] - x0) / (x1 - x0) * cols) <= 1
