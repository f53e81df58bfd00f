"""A run's plot exported as SVG is drawn from its data: one polyline per line, its points on
the data (every sample of a short run, the min and max of each pixel of a long one, ending
at the last sample), axes with ticks and labels, and nothing fetched from the network."""

from __future__ import annotations

import re
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest

from app.plotting.figure import Figure
from app.plotting.run_plot import export, joint_figure, overview
from control.recorder import Run

NS = {"svg": "http://www.w3.org/2000/svg"}


def step_run(samples: int, dt: float = 0.001) -> Run:
    """Rotate steps 0 → 10° and follows with a 50 ms lag; Up/Down holds at 4.6°."""
    t = np.arange(samples) * dt
    desired = np.zeros((samples, 2))
    desired[t >= 0.1, 0] = 10.0
    desired[:, 1] = 4.6
    actual = desired.copy()
    actual[:, 0] = np.where(t >= 0.1, 10.0 * (1.0 - np.exp(-(t - 0.1) / 0.05)), 0.0)
    duty = np.stack([40.0 * (desired[:, 0] - actual[:, 0]) / 10.0, np.zeros(samples)], axis=1)
    return Run("unimate2000b", "step", "complete", "2026-11-25T01:00:00+00:00", dt, {},
               ("Rotate", "Up/Down"), ("deg", "deg"), t, desired, actual, duty)


def panels(svg: Path) -> list[tuple[tuple[float, float, float, float], list[np.ndarray]]]:
    """Each panel's plot box ``(left, top, right, bottom)`` px and its polylines' points."""
    root = ET.parse(svg).getroot()
    assert root.tag == "{http://www.w3.org/2000/svg}svg"
    found = []
    for group in root.iterfind("svg:g[@class='panel']", NS):
        frame = group.find("svg:rect[@class='frame']", NS)
        assert frame is not None
        x, y = float(frame.get("x")), float(frame.get("y"))
        box = (x, y, x + float(frame.get("width")), y + float(frame.get("height")))
        lines = [np.array([[float(v) for v in pair.split(",")]
                           for pair in line.get("points").split()])
                 for line in group.iterfind("svg:polyline[@class='line']", NS)]
        found.append((box, lines))
    return found


def to_data(points: np.ndarray, box: tuple[float, float, float, float],
            x_range: tuple[float, float], y_range: tuple[float, float]) -> np.ndarray:
    """Pixel points back to data coordinates through the panel's axes."""
    left, top, right, bottom = box
    x = x_range[0] + (points[:, 0] - left) / (right - left) * (x_range[1] - x_range[0])
    y = y_range[0] + (bottom - points[:, 1]) / (bottom - top) * (y_range[1] - y_range[0])
    return np.stack([x, y], axis=1)


def write(figure: Figure, tmp_path: Path) -> Path:
    written = export(tmp_path / "plots" / "run-plotsix", figure)
    assert written == [tmp_path / "plots" / "run-plotsix.svg"]
    return written[0]


def test_a_short_run_is_drawn_through_every_sample(tmp_path: Path) -> None:
    run = step_run(300)
    figure = overview(run, [0, 1])
    drawn = panels(write(figure, tmp_path))
    assert len(drawn) == len(figure.panels) == 4  # position and duty of two joints
    for (box, lines), panel in zip(drawn, figure.panels, strict=True):
        assert len(lines) == len(panel.lines)
        for points, line in zip(lines, panel.lines, strict=True):
            assert len(points) == 300
            data = to_data(points, box, panel.x_range(), panel.y_range())
            x_px = (box[2] - box[0]) / (run.t[-1] - run.t[0])  # s per px, both ways
            y_px = (box[3] - box[1]) / np.ptp(panel.y_range())
            assert np.abs(data[:, 0] - line.x).max() <= 0.06 / x_px
            assert np.abs(data[:, 1] - line.y).max() <= 0.06 / y_px


def test_a_long_run_keeps_its_extremes_and_ends_at_its_last_sample(tmp_path: Path) -> None:
    run = step_run(3_400)  # more samples than the panel has pixels
    figure = joint_figure(run, 0)
    drawn = panels(write(figure, tmp_path))
    assert len(drawn) == 4
    for (box, lines), panel in zip(drawn, figure.panels, strict=True):
        assert len(lines) == len(panel.lines)
        points, line = lines[-1], panel.lines[-1]  # the actual response, or the only line
        pixels = box[2] - box[0]
        assert pixels <= len(points) <= 2 * pixels + 3 < len(line.x)
        data = to_data(points, box, panel.x_range(), panel.y_range())
        x_px = np.ptp(panel.x_range()) / (box[2] - box[0])
        y_px = np.ptp(panel.y_range()) / (box[3] - box[1])
        finite = line.y[np.isfinite(line.y)]
        drawn_t = line.x[np.isfinite(line.y)]  # the velocity estimate has no ends
        assert data[0, 0] == pytest.approx(drawn_t[0], abs=0.06 * x_px)
        assert data[-1, 0] == pytest.approx(drawn_t[-1], abs=0.06 * x_px)  # the last sample
        assert data[:, 1].max() == pytest.approx(finite.max(), abs=0.06 * y_px)
        assert data[:, 1].min() == pytest.approx(finite.min(), abs=0.06 * y_px)


def test_the_svg_has_axes_labels_and_fetches_nothing(tmp_path: Path) -> None:
    svg = write(overview(step_run(500), [0, 1], "step run"), tmp_path)
    text = svg.read_text(encoding="utf-8")
    root = ET.fromstring(text)
    words = ["".join(e.itertext()) for e in root.iter("{http://www.w3.org/2000/svg}text")]
    assert "step run" in words and "time (s)" in words
    assert "Rotate (deg)" in words and "Rotate duty (%)" in words
    assert {"0", "0.1", "0.2", "0.3", "0.4"} <= set(words)  # the time axis's round ticks
    # the SVG namespace is a name, not a fetch; nothing else names a network address
    assert re.findall(r"https?://[^\"' )]*", text) == ["http://www.w3.org/2000/svg"]
    assert not [e for e in root.iter() if any("href" in key for key in e.attrib)]
    assert not re.search(r"@import|@font-face|<script|<style|<image", text)
