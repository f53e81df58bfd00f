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
    low, high = columns_many(x, y[:, None], x_range, np.array([y_range], dtype=float),
                             np.array([height_px]), width_px)
    return low[0], high[0]


def columns_many(x: np.ndarray, ys: np.ndarray, x_range: tuple[float, float],
                 y_ranges: np.ndarray, heights_px: np.ndarray, width_px: int
                 ) -> tuple[np.ndarray, np.ndarray]:
    """``columns`` of the ``K`` traces ``ys: (N, K)`` over one ``x``, each with its y range
    (``y_ranges: (K, 2)``) and height (``heights_px: (K,)``), in one pass of array operations:
    ``(low, high)``, ``(K, width_px)`` each, the same rows as ``columns`` of each."""
    k = ys.shape[1]
    heights = np.asarray(heights_px, dtype=np.int64)
    low = np.repeat(heights[:, None], width_px, axis=1)
    high = np.full((k, width_px), -1, dtype=np.int64)
    x0, x1 = x_range
    y0, y1 = y_ranges[:, 0], y_ranges[:, 1]
    drawn = y1 > y0
    if len(x) == 0 or x1 <= x0 or not drawn.any():
        return low, high
    if not drawn.all():  # an empty range draws nothing; the others as they are
        some = np.flatnonzero(drawn)
        low[some], high[some] = columns_many(x, ys[:, some], x_range, y_ranges[some],
                                             heights[some], width_px)
        return low, high
    x_scale = width_px / (x1 - x0)
    if len(x) < 2 * width_px:
        # Sparse: sample the line at every pixel column, so gaps between samples are drawn.
        centres = x0 + (np.arange(width_px) + 0.5) / x_scale
        inside = (centres >= x[0]) & (centres <= x[-1])
        values = np.full((k, width_px), np.nan)
        for j in range(k):
            values[j, inside] = np.interp(centres[inside], x, ys[:, j])
        first = last = _rows(values, y0[:, None], y1[:, None], heights[:, None])
    else:
        bins = _bins(x, x_range, width_px)
        values = ys if bins.everything else ys[bins.inside]
        first = np.full((k, width_px), np.nan)
        last = np.full((k, width_px), np.nan)
        # the traces without a gap (a sum is finite only if every term is), binned as every
        # such trace; a trace with a NaN or an overflowing sum by its own runs of columns
        whole = np.isfinite(values.sum(axis=0))
        if whole.any() and len(values):
            some = np.flatnonzero(whole)
            _spans(values[:, some], y0[some], y1[some], heights[some], bins.starts, bins.cols,
                   bins.ends, some, low, high, first, last)
        for j in np.flatnonzero(~whole):
            finite = np.isfinite(values[:, j])
            col = bins.col[finite]
            if len(col) == 0:
                continue
            _spans(values[finite, j][:, None], y0[j], y1[j], heights[j], *_runs(col),
                   np.array([j]), low, high, first, last)
    present = np.isfinite(first)
    previous = np.full((k, width_px), np.nan)
    previous[:, 1:] = last[:, :-1]
    join = present & np.isfinite(previous)
    with np.errstate(invalid="ignore"):
        span_low = np.where(present, np.fmin(first, previous), np.nan)
        span_high = np.where(present, np.fmax(first, previous), np.nan)
    span_low = np.where(join, span_low, first)
    span_high = np.where(join, span_high, first)
    low[present] = np.minimum(low[present], span_low[present].astype(np.int64))
    high[present] = np.maximum(high[present], span_high[present].astype(np.int64))
    return low, high


def _spans(values: np.ndarray, y0: np.ndarray, y1: np.ndarray, heights: np.ndarray,
           starts: np.ndarray, cols: np.ndarray, ends: np.ndarray, traces: np.ndarray,
           low: np.ndarray, high: np.ndarray, first: np.ndarray, last: np.ndarray) -> None:
    """Each run's values ``(n, len(traces))`` into the traces' columns as pixel rows: the
    lowest and highest row a column reaches, and its first and last sample's. A column's
    highest value is its lowest row (``_rows`` never rises as a value does): the extremes
    are found first, and only they, not every sample, are made rows."""
    at = np.ix_(traces, cols)
    low[at] = _rows(np.maximum.reduceat(values, starts, axis=0), y0, y1, heights).T
    high[at] = _rows(np.minimum.reduceat(values, starts, axis=0), y0, y1, heights).T
    first[at] = _rows(values[starts], y0, y1, heights).T
    last[at] = _rows(values[ends], y0, y1, heights).T


@dataclass(frozen=True)
class _Bins:
    """The samples of one ``x`` in pixel columns: those inside the plot (``inside``), their
    columns (``col``), and the runs of samples in one column (``_runs``)."""

    inside: np.ndarray
    col: np.ndarray
    starts: np.ndarray
    cols: np.ndarray
    ends: np.ndarray
    everything: bool  # every sample inside (a live window): no copy of the inside ones


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
    bins = _Bins(inside, col, *_runs(col), bool(inside.all()))
    _BINNED.insert(0, (x, x_range, width_px, bins))
    del _BINNED[BINNED_KEPT:]
    return bins


def _runs(col: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Each run of equal columns in ``col``: its first index, its column, its last index."""
    starts = np.flatnonzero(np.r_[True, col[1:] != col[:-1]]) if len(col) else col
    ends = np.r_[starts[1:], len(col)] - 1 if len(col) else col
    return starts, col[starts], ends


def _rows(values: np.ndarray, y0: float | np.ndarray, y1: float | np.ndarray,
          height_px: int | np.ndarray) -> np.ndarray:
    """Pixel row of each value (top row 0), the nearest, clipped onto the plot; NaN stays NaN.
    (The range and height per trace broadcast along the last axis.)

    The middle of the range is a row's middle, not the edge between two: a flat line in the
    middle of an auto-scaled plot (a joint at rest) stays on its row however its noise goes,
    where flooring flipped it between two rows, and the row was drawn again, every frame."""
    with np.errstate(invalid="ignore"):
        rows = np.floor((y1 - values) * (height_px / (y1 - y0)) + 0.5)
    return np.clip(rows, 0, np.asarray(height_px) - 1)


def raster(trace: Trace, x_range: tuple[float, float], y_range: tuple[float, float],
           cols: int, rows: int) -> np.ndarray:
    """Braille dot bits of one trace, ``(rows, cols)`` uint16 (0: empty cell)."""
    low, high = columns(trace.x, trace.y, x_range, y_range, 2 * cols, 4 * rows)
    return _cells(low[None], high[None], rows, cols)[0]


def _cells(low: np.ndarray, high: np.ndarray, rows: int, cols: int) -> np.ndarray:
    """Braille dot bits ``(K, rows, cols)`` of ``K`` traces' pixel spans ``(K, 2·cols)``: in
    each cell row, the span's first and end pixel rows there pick its dots from a table."""
    top = 4 * np.arange(rows)[None, :, None]
    first = np.clip(low[:, None, :] - top, 0, 4)
    end = np.clip(high[:, None, :] - top + 1, 0, 4)
    dots = first * 5 + end
    return _SPAN_DOTS[0][dots[..., 0::2]] | _SPAN_DOTS[1][dots[..., 1::2]]


def _span_dots() -> np.ndarray:
    """``[column within cell, 5·first + end]``: the dots of pixel rows first…end−1 of a cell."""
    table = np.zeros((2, 25), dtype=np.uint16)
    for side in (0, 1):
        for first in range(5):
            for end in range(first + 1, 5):
                table[side, first * 5 + end] = np.bitwise_or.reduce(_DOT_BITS[first:end, side])
    return table


_SPAN_DOTS = _span_dots()


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
        # the plot's title row and time axis as last drawn, each with what it was drawn from
        self.title: tuple[object, Strip] | None = None
        self.axis: tuple[object, Strip] | None = None

    def changed(self, codes: np.ndarray, owner: np.ndarray, styles: list[Style]) -> np.ndarray:
        """Which rows differ from the last drawn (every row, if the plot's shape changed)."""
        if (self.codes is None or self.owner is None or self.codes.shape != codes.shape
                or self.styles != styles):
            return np.ones(codes.shape[0], dtype=bool)
        return (self.codes != codes).any(axis=1) | (self.owner != owner).any(axis=1)


@dataclass(frozen=True)
class Canvas:
    """One plot of ``render_many``: its traces (later ones on top) over ``x_range`` and
    ``y_range`` in ``cols × rows`` cells, a dotted line at ``guide_y`` (a zero line) in
    ``guide``, each of ``marks`` a dotted vertical line at its time in its style beneath the
    traces, and ``drawn``: its rows as last drawn, whose unchanged strips are used again."""

    traces: Sequence[Trace]
    x_range: tuple[float, float]
    y_range: tuple[float, float]
    cols: int
    rows: int
    guide: Style | None = None
    guide_y: float | None = None
    marks: Sequence[tuple[float, Style]] = ()
    drawn: Rows | None = None


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
    return render_many([Canvas(traces, x_range, y_range, cols, rows, guide, guide_y, marks,
                               drawn)])[0]


def render_many(canvases: Sequence[Canvas]) -> list[list[Strip]]:
    """``render`` of each canvas, their traces rastered together: those over the same time
    axis and width in one pass of array operations (the Scope's twelve plots, a frame), not
    a pass a trace; then a strip made for each row that changed."""
    bits = _raster_all(canvases)
    out = []
    for c, canvas in enumerate(canvases):
        cols, rows = canvas.cols, canvas.rows
        if cols <= 0 or rows <= 0:
            out.append([Strip.blank(max(cols, 0)) for _ in range(max(rows, 0))])
            continue
        codes = np.zeros((rows, cols), dtype=np.uint16)
        owner = np.full((rows, cols), -1, dtype=np.int16)
        styles: list[Style] = [t.style for t in canvas.traces]
        if canvas.guide_y is not None:
            line = hline(canvas.guide_y, canvas.y_range, cols, rows)
            codes |= line
            owner[line > 0] = len(styles)
            styles.append(canvas.guide or Style(dim=True))
        for x, style in canvas.marks:
            line = vline(x, canvas.x_range, cols, rows)
            codes |= line
            owner[line > 0] = len(styles)
            styles.append(style)
        for index in range(len(canvas.traces)):
            trace_bits = bits[c, index]
            codes |= trace_bits
            owner[trace_bits > 0] = index
        out.append(_strips_of(codes, owner, styles, canvas.drawn))
    return out


def _raster_all(canvases: Sequence[Canvas]) -> dict[tuple[int, int], np.ndarray]:
    """Each trace's dot bits, by (canvas, trace): the traces grouped by their time axis (the
    array itself), x range and width, each group rastered at once."""
    groups: dict[tuple[int, tuple[float, float], int], list[tuple[int, int]]] = {}
    for c, canvas in enumerate(canvases):
        if canvas.cols <= 0 or canvas.rows <= 0:
            continue
        for index, trace in enumerate(canvas.traces):
            key = (id(trace.x), canvas.x_range, canvas.cols)
            groups.setdefault(key, []).append((c, index))
    bits: dict[tuple[int, int], np.ndarray] = {}
    for (_, x_range, cols), members in groups.items():
        traces = [canvases[c].traces[index] for c, index in members]
        ys = np.stack([t.y for t in traces], axis=1)
        y_ranges = np.array([canvases[c].y_range for c, _ in members], dtype=float)
        rows = [canvases[c].rows for c, _ in members]
        low, high = columns_many(traces[0].x, ys, x_range, y_ranges, 4 * np.array(rows),
                                 2 * cols)
        cells = _cells(low, high, max(rows), cols)
        for k, member in enumerate(members):
            bits[member] = cells[k, :rows[k]]
    return bits


def _strips_of(codes: np.ndarray, owner: np.ndarray, styles: list[Style], drawn: Rows | None
               ) -> list[Strip]:
    """The strips of a canvas's cells; with ``drawn``, made only for the rows that changed."""
    if drawn is None:
        return strips(codes, owner, styles)
    rows = codes.shape[0]
    changed = drawn.changed(codes, owner, styles)
    if not changed.any() and len(drawn.strips) == rows:  # a plot at rest: as drawn
        return drawn.strips
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
