"""A ``Figure`` as an SVG drawn from its data: axes with round ticks, a light grid, each line
a polyline (reduced to the min and max of every horizontal pixel first, so peaks stay),
titles and legends. Self-contained: no script, no stylesheet, nothing fetched (fonts are
the viewer's own sans-serif)."""

from __future__ import annotations

import math
from collections.abc import Callable
from xml.sax.saxutils import escape

import numpy as np

from app.plotting.figure import Figure, Mark, Panel, decimate, nice_ticks, tick_text

FONT = "DejaVu Sans, Helvetica, Arial, sans-serif"
PANEL_W, PANEL_H = 560, 260  # a panel's box, px
MARGIN = {"left": 70, "right": 20, "top": 34, "bottom": 44}
TITLE_H = 36
CHAR_W = 7.7  # px: the widest of DejaVu Sans's digits at 12 px (0.636 em), for text that must fit
TICK_GAP = 6  # px between a y tick's label and the frame


def figure_svg(figure: Figure, columns: int | None = None) -> str:
    """The figure as SVG text, its panels in ``columns`` (the figure's, else 1 or 2)."""
    count = len(figure.panels)
    cols = columns or figure.columns or (1 if count < 4 else 2)
    rows = max(1, math.ceil(count / cols))
    width = cols * PANEL_W
    height = TITLE_H + rows * PANEL_H
    parts = [
        f'<svg xmlns="http://www.w3.org/2000/svg" width="{width}" height="{height}" '
        f'viewBox="0 0 {width} {height}" font-family="{FONT}" font-size="12">',
        f"<title>{escape(figure.title)}</title>",
        f'<rect width="{width}" height="{height}" fill="white"/>',
        f'<text x="{width / 2:.0f}" y="24" text-anchor="middle" font-size="16" '
        f'font-weight="bold">{escape(figure.title)}</text>',
    ]
    for k, panel in enumerate(figure.panels):
        x, y = (k % cols) * PANEL_W, TITLE_H + (k // cols) * PANEL_H
        last_row = k + cols >= count
        parts.append(_panel(panel, k, x, y, figure.x_label if last_row else ""))
    parts.append("</svg>")
    return "\n".join(parts) + "\n"


def _panel(panel: Panel, k: int, left: float, top: float, x_label: str) -> str:
    x0, x1 = panel.x_range()
    y0, y1 = panel.y_range()
    y_ticks = nice_ticks(y0, y1)
    widest = max(len(_label(v, y_ticks)) for v in y_ticks)
    # the y labels sit inside this panel's own margin, however many digits they need
    px0 = left + max(MARGIN["left"], CHAR_W * widest + TICK_GAP + 4)
    px1 = left + PANEL_W - MARGIN["right"]
    py0, py1 = top + PANEL_H - MARGIN["bottom"], top + MARGIN["top"]  # y grows downward

    def sx(v: np.ndarray | float) -> np.ndarray | float:
        return px0 + (np.asarray(v) - x0) * (px1 - px0) / (x1 - x0)

    def sy(v: np.ndarray | float) -> np.ndarray | float:
        return py0 + (np.asarray(v) - y0) * (py1 - py0) / (y1 - y0)

    out = [f'<g class="panel"><rect class="frame" x="{px0:.1f}" y="{py1:.1f}" '
           f'width="{px1 - px0:.1f}" height="{py0 - py1:.1f}" fill="none" stroke="#888"/>']
    out += _ticks(nice_ticks(x0, x1), sx, "x", py0, py1)
    out += _ticks(y_ticks, sy, "y", px0, px1)
    if panel.zero_line and y0 < 0 < y1:
        out.append(f'<line x1="{px0:.1f}" x2="{px1:.1f}" y1="{sy(0.0):.1f}" y2="{sy(0.0):.1f}" '
                   'stroke="#444" stroke-dasharray="4 3"/>')
    clip = f"panel{k}"
    out.append(f'<clipPath id="{clip}"><rect x="{px0:.1f}" y="{py1:.1f}" '
               f'width="{px1 - px0:.1f}" height="{py0 - py1:.1f}"/></clipPath>')
    for line in panel.lines:
        for xs, ys in _runs(line.x, line.y, int(px1 - px0)):
            points = " ".join(f"{a:.1f},{b:.1f}" for a, b in zip(sx(xs), sy(ys), strict=True))
            out.append(f'<polyline class="line" clip-path="url(#{clip})" fill="none" '
                       f'stroke="{line.color}" '
                       f'stroke-width="1.4" points="{points}"/>')
    for row, mark in enumerate(panel.marks):
        out.append(_mark(mark, float(sx(mark.t)), (px0, px1), (py1, py0), row))
    legend_x = px1
    legend = []
    for line in reversed([line for line in panel.lines if line.label]):
        label = escape(line.label)
        legend.append(f'<text x="{legend_x:.1f}" y="{top + 20:.1f}" text-anchor="end">'
                      f"{label}</text>")
        legend_x -= 7 * len(line.label) + 6
        legend.append(f'<line x1="{legend_x - 18:.1f}" x2="{legend_x - 2:.1f}" '
                      f'y1="{top + 16:.1f}" y2="{top + 16:.1f}" stroke="{line.color}" '
                      'stroke-width="2.5"/>')
        legend_x -= 30
    title = _fit(panel.title + (f" ({panel.unit})" if panel.unit else ""),
                 legend_x + (6 if legend else 0) - (left + 8))
    out.append(f'<text class="title" x="{left + 8:.1f}" y="{top + 20:.1f}" '
               f'font-weight="bold">{escape(title)}</text>')
    out += legend
    if x_label:
        out.append(f'<text x="{(px0 + px1) / 2:.1f}" y="{py0 + 36:.1f}" text-anchor="middle">'
                   f"{escape(x_label)}</text>")
    out.append("</g>")
    return "\n".join(out)


def _mark(mark: Mark, x: float, across: tuple[float, float], down: tuple[float, float],
          row: int) -> str:
    """A vertical line at the mark's time and its label inside the plot, beside the line on
    the side with room (marks near each other take the next row down)."""
    top, bottom = down
    room = across[1] - x if x < (across[0] + across[1]) / 2 else x - across[0]
    anchor, dx = ("start", 4) if x < (across[0] + across[1]) / 2 else ("end", -4)
    label = _fit(mark.label, room - 8, size=11)
    y = top + 13 + 13 * (row % 4)
    return (f'<g class="mark" data-t="{mark.t:.6g}" data-kind="{escape(mark.kind)}">'
            f'<line x1="{x:.1f}" x2="{x:.1f}" y1="{top:.1f}" y2="{bottom:.1f}" '
            f'stroke="{mark.color}" stroke-width="1.6" stroke-dasharray="6 3"/>'
            f'<text x="{x + dx:.1f}" y="{y:.1f}" text-anchor="{anchor}" font-size="11" '
            f'fill="{mark.color}" stroke="white" stroke-width="3" paint-order="stroke">'
            f'{escape(label)}</text></g>')


def _fit(text: str, width: float, size: float = 12) -> str:
    """``text`` cut (with …) to what fits ``width`` px at ``size`` px."""
    most = max(1, int(width / (CHAR_W * size / 12)))
    return text if len(text) <= most else text[:max(0, most - 1)].rstrip() + "…"


def _label(value: float, ticks: list[float]) -> str:
    return tick_text(value, ticks[1] - ticks[0] if len(ticks) > 1 else 1.0)


def _ticks(values: list[float], scale: Callable[[float], object], axis: str, a: float,
           b: float) -> list[str]:
    out = []
    for v in values:
        p = float(scale(v))
        text = escape(_label(v, values))
        if axis == "x":
            out.append(f'<line x1="{p:.1f}" x2="{p:.1f}" y1="{b:.1f}" y2="{a:.1f}" '
                       'stroke="#e4e4e4"/>')
            out.append(f'<text class="xtick" x="{p:.1f}" y="{a + 16:.1f}" '
                       f'text-anchor="middle">{text}</text>')
        else:
            out.append(f'<line x1="{a:.1f}" x2="{b:.1f}" y1="{p:.1f}" y2="{p:.1f}" '
                       'stroke="#e4e4e4"/>')
            out.append(f'<text class="ytick" x="{a - TICK_GAP:.1f}" y="{p + 4:.1f}" '
                       f'text-anchor="end">{text}</text>')
    return out


def _runs(x: np.ndarray, y: np.ndarray, pixels: int) -> list[tuple[np.ndarray, np.ndarray]]:
    """The finite stretches of a line, each reduced to about two points a pixel."""
    finite = np.isfinite(x) & np.isfinite(y)
    edges = np.flatnonzero(np.diff(np.r_[0, finite.astype(np.int8), 0]))
    runs = []
    for a, b in zip(edges[::2], edges[1::2], strict=True):
        if b - a >= 1:
            runs.append(decimate(x[a:b], y[a:b], 2 * max(1, pixels)))
    return runs
