"""A plot as data: panels of lines, drawn in the terminal (``app.plotting.strips``, the
braille raster) and exported as an SVG (``app.plotting.svg``) from the same record, so an
export shows exactly the data the screen plots.

Colours are hex, which both Rich and SVG read.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

DESIRED = "#e8453c"  # plotsix.m: desired 'r-'
ACTUAL = "#3d8bfd"  # plotsix.m: actual 'b'
DUTY = "#2fae5f"
ERROR = "#c94fd6"
VELOCITY = "#16b3c9"
APPROACH = "#9a9a9a"  # the approach ramp in front of a move (MovePlan.approach)
PROPOSED = "#e0a526"
ESTOP = "#b00020"
FAULT = "#d9731a"
STALL = "#6d6d6d"
FLAT_SPAN = 1.0  # the y span (its unit) of a line that holds still, when the panel sets none
END_PAD = 0.03  # of the time span, after a mark at the end (an E-stop ends its run)


@dataclass(frozen=True)
class Line:
    """One series: ``y (N,)`` over ``x (N,)`` increasing; NaN breaks the line."""

    x: np.ndarray
    y: np.ndarray
    color: str
    label: str = ""


@dataclass(frozen=True)
class Mark:
    """A moment of the run drawn across the panel: the E-stop, a fault, a stall (s)."""

    t: float
    label: str
    color: str
    kind: str = ""


@dataclass(frozen=True)
class Panel:
    """One plot: a title, its lines over a shared x axis (s), the y unit; ``floor`` is the
    least span of its y axis (a joint that holds still: a few encoder counts), ``marks``
    the moments drawn across it."""

    title: str
    lines: tuple[Line, ...]
    unit: str = ""
    zero_line: bool = False
    floor: float = 0.0
    marks: tuple[Mark, ...] = ()

    def x_range(self) -> tuple[float, float]:
        """Every line's time and every mark's, from 0 when the first sample is just after it;
        a mark at the end gets room after it, so its line stands clear of the frame."""
        xs = [x for line in self.lines for x in (_finite_ends(line.x))]
        marks = [m.t for m in self.marks if math.isfinite(m.t)]
        if not xs + marks:
            return 0.0, 1.0
        lo, hi = min(xs + marks), max(xs + marks)
        if hi <= lo:
            return lo, lo + 1.0
        if 0.0 < lo <= 0.01 * (hi - lo):  # a run's first sample, a tick after its start
            lo = 0.0
        return (lo, hi + END_PAD * (hi - lo)) if marks and max(marks) >= hi else (lo, hi)

    def y_range(self, floor: float = 0.0) -> tuple[float, float]:
        """Around every line's values with 5 % to spare, at least ``floor`` (or the panel's)
        wide: a line that holds still is drawn mid-panel on a span that shows it still, not
        its last digit's noise."""
        values = [v for line in self.lines for v in _finite_ends(line.y, extremes=True)]
        if self.zero_line:
            values.append(0.0)
        if not values:
            return -1.0, 1.0
        lo, hi = min(values), max(values)
        least = max(floor, self.floor)
        if not least and hi - lo <= 1e-9 * max(1.0, abs(hi)):
            least = FLAT_SPAN
        half = max((hi - lo) / 2 * 1.05, least / 2)
        mid = (hi + lo) / 2
        return mid - half, mid + half


@dataclass(frozen=True)
class Figure:
    """Panels in reading order, laid out in ``columns`` (0: as many as fit)."""

    title: str
    panels: tuple[Panel, ...]
    columns: int = 0
    x_label: str = "time (s)"


def decimate(t: np.ndarray, y: np.ndarray, points: int) -> tuple[np.ndarray, np.ndarray]:
    """About ``points`` samples of ``y(t)`` (three more at most) keeping each bucket's min
    and max in time order, so peaks stay; the samples past the last whole bucket are one
    more bucket, and the last sample is kept, so the line ends where the data does."""
    n = len(t)
    buckets = max(1, points // 2)
    if n <= points:
        return t, y
    size = n // buckets
    cut = size * buckets
    tt, yy = _extremes(t[:cut].reshape(buckets, size), y[:cut].reshape(buckets, size))
    if cut < n:
        rest_t, rest_y = _extremes(t[None, cut:], y[None, cut:])
        tt, yy = np.r_[tt, rest_t], np.r_[yy, rest_y]
    if tt[-1] != t[-1]:
        tt, yy = np.r_[tt, t[-1]], np.r_[yy, y[-1]]
    return tt, yy


def _extremes(tb: np.ndarray, yb: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each row's min and max of ``yb (B, S)`` with their times, in time order."""
    finite = np.isfinite(yb)
    lo_i = np.argmin(np.where(finite, yb, np.inf), axis=1)
    hi_i = np.argmax(np.where(finite, yb, -np.inf), axis=1)
    first = np.minimum(lo_i, hi_i)
    second = np.maximum(lo_i, hi_i)
    rows = np.arange(len(tb))
    tt = np.stack([tb[rows, first], tb[rows, second]], axis=1).ravel()
    yy = np.stack([yb[rows, first], yb[rows, second]], axis=1).ravel()
    return tt, yy


def _finite_ends(values: np.ndarray, extremes: bool = False) -> list[float]:
    """The first and last finite values (or the smallest and largest)."""
    finite = values[np.isfinite(values)]
    if not len(finite):
        return []
    if extremes:
        return [float(finite.min()), float(finite.max())]
    return [float(finite[0]), float(finite[-1])]


def nice_ticks(lo: float, hi: float, most: int = 6) -> list[float]:
    """Round values (1, 2 or 5 × 10ⁿ apart) from ``lo`` to ``hi``, at most ``most`` of them."""
    span = hi - lo
    if not (math.isfinite(span) and span > 0):
        return [lo]
    raw = span / max(1, most - 1)
    power = 10.0 ** math.floor(math.log10(raw))
    step = next(k * power for k in (1, 2, 5, 10) if k * power >= raw)
    first = math.ceil(lo / step - 1e-9) * step
    count = math.floor((hi - first) / step + 1e-9) + 1
    return [first + k * step for k in range(count)]


def tick_text(value: float, step: float) -> str:
    """A tick label with the decimals its spacing needs."""
    digits = max(0, -math.floor(math.log10(step) + 1e-9)) if step > 0 else 0
    text = f"{value:.{digits}f}"
    return "0" if text.lstrip("-").strip("0.") == "" else text
