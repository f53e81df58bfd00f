"""A braille canvas for drawings (the arm's view): line segments, dots and text labels drawn
in batches of numpy arrays, one ``Strip`` per text row out.

The cells are the Scope's braille raster's (``app.plotting.braille``): a cell holds 2 × 4
pixels, and one colour, the last layer's drawn into it. A segment becomes as many pixels as
it is long, all segments of a call at once (no Python loop per point), so a frame's cost
follows what is drawn, not how finely the arm is sampled. A label's characters replace the
cells they cover.
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Self

import numpy as np
from rich.segment import Segment
from rich.style import Style
from textual.strip import Strip

from app.plotting.braille import BRAILLE_BASE

# Dot bit of pixel (row within cell, column within cell): the Unicode braille numbering.
DOT_BITS = np.array([[0x01, 0x08], [0x02, 0x10], [0x04, 0x20], [0x40, 0x80]], dtype=np.uint16)
SPACE = ord(" ")
BLOB = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0], [1.0, 1.0]]) - 0.5  # a dot's 4 pixels


class DotCanvas:
    """``cols × rows`` cells, ``2·cols × 4·rows`` pixels (row 0 the top)."""

    def __init__(self, cols: int, rows: int) -> None:
        self.cols, self.rows = max(cols, 0), max(rows, 0)
        self.codes = np.zeros((self.rows, self.cols), dtype=np.uint16)
        self.owner = np.full((self.rows, self.cols), -1, dtype=np.int16)
        self.text = np.zeros((self.rows, self.cols), dtype=np.uint32)  # 0: no label here
        self.styles: list[Style] = []
        self._index: dict[Style, int] = {}

    @property
    def width_px(self) -> int:
        return 2 * self.cols

    @property
    def height_px(self) -> int:
        return 4 * self.rows

    def copy(self) -> Self:
        """An independent canvas with what this one holds (a cached background)."""
        out = type(self)(self.cols, self.rows)
        out.codes, out.owner, out.text = self.codes.copy(), self.owner.copy(), self.text.copy()
        out.styles, out._index = list(self.styles), dict(self._index)
        return out

    def _style(self, style: Style) -> int:
        index = self._index.get(style)
        if index is None:
            index = self._index[style] = len(self.styles)
            self.styles.append(style)
        return index

    def _styles(self, style: Style | Sequence[Style], n: int) -> np.ndarray:
        """``(n,)`` style indices: one style for all, or one each."""
        if isinstance(style, Style):
            return np.full(n, self._style(style), dtype=np.int16)
        return np.array([self._style(s) for s in style], dtype=np.int16)

    def pixels(self, xy: np.ndarray, style: Style | Sequence[Style]) -> None:
        """Set pixels ``xy (K, 2)`` (column, row; fractional ones floored, those off the canvas
        left out) in ``style`` (one, or one per pixel), which then colours their cells: the
        later pixel's where two share one."""
        xy = np.asarray(xy, dtype=float).reshape(-1, 2)
        self._set(xy, self._styles(style, len(xy)))

    def _set(self, xy: np.ndarray, owner: np.ndarray) -> None:
        with np.errstate(invalid="ignore"):
            x, y = np.floor(xy[:, 0]), np.floor(xy[:, 1])
            ok = (x >= 0) & (x < self.width_px) & (y >= 0) & (y < self.height_px)
        if not ok.any():
            return
        x, y = x[ok].astype(np.intp), y[ok].astype(np.intp)
        r, c = y // 4, x // 2
        np.bitwise_or.at(self.codes, (r, c), DOT_BITS[y % 4, x % 2])
        self.owner[r, c] = owner[ok]

    def segments(self, a: np.ndarray, b: np.ndarray, style: Style | Sequence[Style], *,
                 gap: int = 0) -> None:
        """Lines from ``a (K, 2)`` to ``b (K, 2)`` (pixels) in ``style`` (one, or one per
        segment; a later segment's colour on top); ``gap`` > 0 dots them, one pixel on, ``gap``
        off. A segment with a NaN end is left out."""
        a = np.asarray(a, dtype=float).reshape(-1, 2)
        b = np.asarray(b, dtype=float).reshape(-1, 2)
        owner = self._styles(style, len(a))
        keep = np.isfinite(a).all(axis=1) & np.isfinite(b).all(axis=1)
        a, b, owner = a[keep], b[keep], owner[keep]
        if not len(a):
            return
        # a segment far off the canvas (zoomed in) is cut to a length the canvas can show
        limit = 4.0 * (self.width_px + self.height_px)
        a, b = np.clip(a, -limit, limit), np.clip(b, -limit, limit)
        steps = np.ceil(np.abs(b - a).max(axis=1)).astype(np.intp) + 1
        which = np.repeat(np.arange(len(a)), steps)
        first = np.cumsum(steps) - steps
        k = np.arange(len(which)) - first[which]
        if gap:
            on = k % (gap + 1) == 0
            which, k = which[on], k[on]
        t = (k / np.maximum(steps - 1, 1)[which])[:, None]
        self._set(a[which] + t * (b[which] - a[which]), owner[which])

    def polyline(self, xy: np.ndarray, style: Style, *, gap: int = 0) -> None:
        """A line through ``xy (K, 2)`` in order; a NaN row breaks it."""
        xy = np.asarray(xy, dtype=float).reshape(-1, 2)
        if len(xy) >= 2:
            self.segments(xy[:-1], xy[1:], style, gap=gap)
        elif len(xy) == 1:
            self.pixels(xy, style)

    def blobs(self, xy: np.ndarray, style: Style | Sequence[Style]) -> None:
        """A 2 × 2 pixel dot at each of ``xy (K, 2)`` in ``style`` (one, or one each): a
        joint, a marker."""
        xy = np.asarray(xy, dtype=float).reshape(-1, 2)
        owner = np.repeat(self._styles(style, len(xy)), 4)
        self._set((xy[:, None, :] + BLOB[None]).reshape(-1, 2), owner)

    def label(self, col: int, row: int, text: str, style: Style) -> None:
        """``text`` in the cells from (``col``, ``row``) on, cut at the canvas's edge."""
        if not 0 <= row < self.rows or col >= self.cols or not text:
            return
        start = max(col, 0)
        text = text[start - col:self.cols - col]
        if not text:
            return
        end = start + len(text)
        self.text[row, start:end] = np.frombuffer(text.encode("utf-32-le"), dtype="<u4")
        self.owner[row, start:end] = self._style(style)

    def cell(self, xy: np.ndarray) -> tuple[int, int]:
        """The cell (column, row) of pixel ``xy (2,)``."""
        return int(np.floor(xy[0])) // 2, int(np.floor(xy[1])) // 4

    def strips(self, before: Drawn | None = None) -> Drawn:
        """One Strip per row: the braille dots, labels over them, each run of cells in the
        style of the layer that owns it. A row equal to ``before``'s (the last frame of the
        same size) keeps its Strip: a moving arm rebuilds only the rows it crosses."""
        chars = np.where(self.codes > 0, self.codes.astype(np.uint32) + BRAILLE_BASE, SPACE)
        chars = np.where(self.text > 0, self.text, chars)
        who = np.where((self.codes > 0) | (self.text > 0), self.owner, -1)
        styles = tuple(self.styles)
        shared = min(len(styles), len(before.styles)) if before is not None else 0
        if (before is not None and before.chars.shape == chars.shape
                and before.styles[:shared] == styles[:shared]):
            changed = ((before.chars != chars) | (before.who != who)).any(axis=1)
            lines = list(before.lines)
        else:
            changed = np.ones(self.rows, dtype=bool)
            lines = [Strip.blank(self.cols)] * self.rows
        rows = np.flatnonzero(changed)
        if len(rows):
            text = chars[rows].astype("<u4").tobytes().decode("utf-32-le")
            for k, r in enumerate(rows.tolist()):
                lines[r] = self._strip(text[k * self.cols:(k + 1) * self.cols], who[r])
        return Drawn(tuple(lines), chars, who, styles, tuple(rows.tolist()))

    def _strip(self, line: str, who: np.ndarray) -> Strip:
        cuts = np.flatnonzero(who[1:] != who[:-1]) + 1
        segments = []
        for a, b in itertools.pairwise([0, *cuts.tolist(), self.cols]):
            index = int(who[a])
            segments.append(Segment(line[a:b], self.styles[index] if index >= 0 else None))
        return Strip(segments, self.cols)


@dataclass(frozen=True)
class Drawn:
    """A canvas turned into ``lines`` (one Strip a row), with what they were made of (for the
    next frame's comparison) and ``changed``: the rows rebuilt this time."""

    lines: tuple[Strip, ...]
    chars: np.ndarray
    who: np.ndarray
    styles: tuple[Style, ...]
    changed: tuple[int, ...]
