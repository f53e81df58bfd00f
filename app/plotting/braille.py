"""A braille-dot raster for live plots: numpy arrays in, one ``Strip`` per text row out.

Each text cell holds a 2 × 4 grid of dots (Unicode U+2800–U+28FF), so a
``cols × rows`` area is a ``2·cols × 4·rows`` pixel raster. A trace is reduced
to one vertical span of pixels per pixel column (its min…max there, joined to
the previous column's last value so the line stays connected), which makes the
cost depend on the width of the plot, not on the number of samples: six joints
× 2,000 points render in a few milliseconds (``benchmarks/ui.py``).
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from rich.segment import Segment
from rich.style import Style
from textual.strip import Strip

BRAILLE_BASE = 0x2800
# Dot bit of pixel (row within cell, column within cell), Unicode braille numbering.
_DOT_BITS = np.array([[0x01, 0x08], [0x02, 0x10], [0x04, 0x20], [0x40, 0x80]], dtype=np.uint16)


@dataclass(frozen=True)
class Trace:
    """One line of a plot: ``x: (N,)`` increasing, ``y: (N,)``; NaN in ``y`` breaks the line."""

    x: np.ndarray
    y: np.ndarray
    style: Style


def columns(x: np.ndarray, y: np.ndarray, x_range: tuple[float, float],
            y_range: tuple[float, float], width_px: int, height_px: int
            ) -> tuple[np.ndarray, np.ndarray]:
    """Pixel rows ``(low, high)`` covered by a trace in each pixel column, ``(width_px,)`` each.

    Row 0 is the top. A column the trace does not reach has ``low > high``.
    """
    x0, x1 = x_range
    y0, y1 = y_range
    low = np.full(width_px, height_px, dtype=np.int64)
    high = np.full(width_px, -1, dtype=np.int64)
    if len(x) == 0 or x1 <= x0 or y1 <= y0:
        return low, high
    x_scale = width_px / (x1 - x0)
    if len(x) < 2 * width_px:
        # Sparse: sample the line at every pixel column, so gaps between samples are drawn.
        centres = x0 + (np.arange(width_px) + 0.5) / x_scale
        inside = (centres >= x[0]) & (centres <= x[-1])
        values = np.full(width_px, np.nan)
        values[inside] = np.interp(centres[inside], x, y)
        first = last = _rows(values, y0, y1, height_px)
    else:
        bins = _bins(x, x_range, width_px)
        values = y[bins.inside]
        if np.isfinite(values).all():  # the columns' samples as binned for every such trace
            starts, cols, ends = bins.starts, bins.cols, bins.ends
        else:
            col = bins.col[np.isfinite(values)]
            values = values[np.isfinite(values)]
            starts, cols, ends = _runs(col)
        if len(values) == 0:
            return low, high
        rows = _rows(values, y0, y1, height_px)
        low[cols] = np.minimum.reduceat(rows, starts)
        high[cols] = np.maximum.reduceat(rows, starts)
        first = np.full(width_px, np.nan)
        last = np.full(width_px, np.nan)
        first[cols] = rows[starts]
        last[cols] = rows[ends]
    present = np.isfinite(first)
    previous = np.r_[np.nan, last[:-1]]
    join = present & np.isfinite(previous)
    with np.errstate(invalid="ignore"):
        span_low = np.where(present, np.fmin(first, previous), np.nan)
        span_high = np.where(present, np.fmax(first, previous), np.nan)
    span_low = np.where(join, span_low, first)
    span_high = np.where(join, span_high, first)
    low[present] = np.minimum(low[present], span_low[present].astype(np.int64))
    high[present] = np.maximum(high[present], span_high[present].astype(np.int64))
    return low, high


@dataclass(frozen=True)
class _Bins:
    """The samples of one ``x`` in pixel columns: those inside the plot (``inside``), their
    columns (``col``), and the runs of samples in one column (``_runs``)."""

    inside: np.ndarray
    col: np.ndarray
    starts: np.ndarray
    cols: np.ndarray
    ends: np.ndarray


# The last few binnings, by the very array binned (held, so that its id is not reused): the
# Scope's traces share one time axis, binned once a frame instead of once a trace.
_BINNED: list[tuple[np.ndarray, tuple[float, float], int, _Bins]] = []
BINNED_KEPT = 4


def _bins(x: np.ndarray, x_range: tuple[float, float], width_px: int) -> _Bins:
    for binned, at, width, bins in _BINNED:
        if binned is x and at == x_range and width == width_px:
            return bins
    x0, x1 = x_range
    col = np.floor((x - x0) * (width_px / (x1 - x0))).astype(np.int64)
    inside = (col >= 0) & (col < width_px)
    col = col[inside]
    bins = _Bins(inside, col, *_runs(col))
    _BINNED.insert(0, (x, x_range, width_px, bins))
    del _BINNED[BINNED_KEPT:]
    return bins


def _runs(col: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Each run of equal columns in ``col``: its first index, its column, its last index."""
    starts = np.flatnonzero(np.r_[True, col[1:] != col[:-1]]) if len(col) else col
    ends = np.r_[starts[1:], len(col)] - 1 if len(col) else col
    return starts, col[starts], ends


def _rows(values: np.ndarray, y0: float, y1: float, height_px: int) -> np.ndarray:
    """Pixel row of each value (top row 0), the nearest, clipped onto the plot; NaN stays NaN.

    The middle of the range is a row's middle, not the edge between two: a flat line in the
    middle of an auto-scaled plot (a joint at rest) stays on its row however its noise goes,
    where flooring flipped it between two rows, and the row was drawn again, every frame."""
    with np.errstate(invalid="ignore"):
        rows = np.floor((y1 - values) * (height_px / (y1 - y0)) + 0.5)
    return np.clip(rows, 0, height_px - 1)


def raster(trace: Trace, x_range: tuple[float, float], y_range: tuple[float, float],
           cols: int, rows: int) -> np.ndarray:
    """Braille dot bits of one trace, ``(rows, cols)`` uint16 (0: empty cell)."""
    height_px = 4 * rows
    low, high = columns(trace.x, trace.y, x_range, y_range, 2 * cols, height_px)
    pixel_rows = np.arange(height_px)[:, None]
    mask = (pixel_rows >= low[None, :]) & (pixel_rows <= high[None, :])
    cells = mask.reshape(rows, 4, cols, 2).astype(np.uint16) * _DOT_BITS[None, :, None, :]
    return cells.sum(axis=(1, 3), dtype=np.uint16)


def hline(y: float, y_range: tuple[float, float], cols: int, rows: int) -> np.ndarray:
    """Dot bits of a dotted horizontal line at ``y`` (a zero line), ``(rows, cols)``."""
    out = np.zeros((rows, cols), dtype=np.uint16)
    y0, y1 = y_range
    if not y0 <= y <= y1 or rows == 0:
        return out
    row = int(min(4 * rows - 1, np.floor((y1 - y) * 4 * rows / (y1 - y0))))
    out[row // 4, ::2] = _DOT_BITS[row % 4, 0]
    return out


def vline(x: float, x_range: tuple[float, float], cols: int, rows: int) -> np.ndarray:
    """Dot bits of a dotted vertical line at ``x`` (a moment: the E-stop), ``(rows, cols)``."""
    out = np.zeros((rows, cols), dtype=np.uint16)
    x0, x1 = x_range
    if not x0 <= x <= x1 or cols == 0:
        return out
    col = int(min(2 * cols - 1, np.floor((x - x0) * 2 * cols / (x1 - x0))))
    out[:, col // 2] = _DOT_BITS[0, col % 2] | _DOT_BITS[2, col % 2]
    return out


class Rows:
    """A plot's rows as last drawn (dot bits, owners, styles and the strips made of them), so
    that the next frame makes a strip only for a row that changed: a live plot at rest, or
    scrolling flat lines, draws the same rows frame after frame."""

    def __init__(self) -> None:
        self.codes: np.ndarray | None = None
        self.owner: np.ndarray | None = None
        self.styles: list[Style] = []
        self.strips: list[Strip] = []
        self.framed: list[tuple[Strip, str, Strip]] = []  # a row, its label, the two as one

    def changed(self, codes: np.ndarray, owner: np.ndarray, styles: list[Style]) -> np.ndarray:
        """Which rows differ from the last drawn (every row, if the plot's shape changed)."""
        if (self.codes is None or self.owner is None or self.codes.shape != codes.shape
                or self.styles != styles):
            return np.ones(codes.shape[0], dtype=bool)
        return (self.codes != codes).any(axis=1) | (self.owner != owner).any(axis=1)


def render(traces: Sequence[Trace], x_range: tuple[float, float],
           y_range: tuple[float, float], cols: int, rows: int,
           guide: Style | None = None, guide_y: float | None = None,
           marks: Sequence[tuple[float, Style]] = (), drawn: Rows | None = None
           ) -> list[Strip]:
    """Draw ``traces`` (later ones on top) into ``rows`` strips of ``cols`` cells.

    A cell shared by several traces shows the dots of all of them in the colour
    of the topmost. ``guide_y`` draws a dotted line (a zero line) in ``guide``;
    each of ``marks`` a dotted vertical line at its time in its style, beneath the traces;
    ``drawn``: the plot's rows as last drawn, whose unchanged strips are used again.
    """
    if cols <= 0 or rows <= 0:
        return [Strip.blank(max(cols, 0)) for _ in range(max(rows, 0))]
    codes = np.zeros((rows, cols), dtype=np.uint16)
    owner = np.full((rows, cols), -1, dtype=np.int16)
    styles: list[Style] = [t.style for t in traces]
    if guide_y is not None:
        bits = hline(guide_y, y_range, cols, rows)
        codes |= bits
        owner[bits > 0] = len(styles)
        styles.append(guide or Style(dim=True))
    for x, style in marks:
        bits = vline(x, x_range, cols, rows)
        codes |= bits
        owner[bits > 0] = len(styles)
        styles.append(style)
    for index, trace in enumerate(traces):
        bits = raster(trace, x_range, y_range, cols, rows)
        codes |= bits
        owner[bits > 0] = index
    if drawn is None:
        return strips(codes, owner, styles)
    changed = drawn.changed(codes, owner, styles)
    made = iter(strips(codes[changed], owner[changed], styles))
    before = drawn.strips if len(drawn.strips) == rows else [None] * rows
    drawn.strips = [next(made) if new else old for new, old in zip(changed, before, strict=True)]
    drawn.codes, drawn.owner, drawn.styles = codes, owner, styles
    return drawn.strips


def strips(codes: np.ndarray, owner: np.ndarray, styles: Sequence[Style]) -> list[Strip]:
    """Turn dot bits and the owning style index of each cell into one Strip per row."""
    chars = np.where(codes > 0, codes.astype(np.uint32) + BRAILLE_BASE, ord(" "))
    text = chars.astype("<u4").tobytes().decode("utf-32-le")
    cols = codes.shape[1]
    out = []
    for r in range(codes.shape[0]):
        line = text[r * cols:(r + 1) * cols]
        who = owner[r]
        cuts = np.flatnonzero(who[1:] != who[:-1]) + 1
        bounds = [0, *cuts.tolist(), cols]
        segments = []
        for a, b in itertools.pairwise(bounds):
            index = int(who[a])
            segments.append(Segment(line[a:b], styles[index] if index >= 0 else None))
        out.append(Strip(segments, cols))
    return out
