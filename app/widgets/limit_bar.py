"""Where a joint is within its limits, as one line of text: ``├───○──●──────┤``.

``●`` is the position, ``○`` the desired position; the bar turns yellow in the
outer ``WARN_FRACTION`` of the range and red at a limit. A Rich renderable, so
it fits any table cell it is put in. ``LimitWatch`` tells when a joint the controller
reported at a limit has left it.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from rich.console import Console, ConsoleOptions, RenderResult
from rich.measure import Measurement
from rich.text import Text

WARN_FRACTION = 0.05
# a joint reported at a limit has left it this far inside (of its range): well past the two
# encoder counts where the guard stops its duty, so one resting there does not flicker
CLEAR_FRACTION = 0.01


class LimitBar:
    """``position`` (and ``desired``, NaN for none) between ``lower`` and ``upper``."""

    def __init__(self, position: float, lower: float, upper: float,
                 desired: float = math.nan, width: int | None = None) -> None:
        self.position = position
        self.lower = lower
        self.upper = upper
        self.desired = desired
        self.width = width

    def __rich_measure__(self, console: Console, options: ConsoleOptions) -> Measurement:
        return Measurement(8, self.width or options.max_width)

    def __rich_console__(self, console: Console, options: ConsoleOptions) -> RenderResult:
        yield self.text(self.width or options.max_width)

    def fraction(self, value: float) -> float:
        return (value - self.lower) / (self.upper - self.lower)

    def text(self, width: int) -> Text:
        return self.drawn(self.marks(width))

    def marks(self, width: int) -> tuple[int, int, int, str]:
        """What the bar draws at ``width``: its inner cells, the cells of ``○`` and ``●`` (-1
        for none) and its style; two bars of the same marks draw the same text."""
        inner = max(2, width - 2)
        desired = self._cell(self.desired, inner) if math.isfinite(self.desired) else -1
        position = self._cell(self.position, inner) if math.isfinite(self.position) else -1
        f = self.fraction(self.position) if math.isfinite(self.position) else 0.5
        style = ("bold red" if f <= 0 or f >= 1 else
                 "yellow" if f < WARN_FRACTION or f > 1 - WARN_FRACTION else "green")
        return inner, desired, position, style

    @staticmethod
    def drawn(marks: tuple[int, int, int, str]) -> Text:
        """The bar of ``marks`` (``marks``)."""
        inner, desired, position, style = marks
        cells = ["─"] * inner
        if desired >= 0:
            cells[desired] = "○"
        if position >= 0:
            cells[position] = "●"
        return Text.assemble(("├", "dim"), ("".join(cells), style), ("┤", "dim"))

    def _cell(self, value: float, inner: int) -> int:
        return min(inner - 1, max(0, int(self.fraction(value) * inner)))


class LimitWatch:
    """The joints reported at a limit (``reported``), each until a status published after
    the report shows it back inside by ``CLEAR_FRACTION`` of its range (``cleared``): one
    published before it (the UI's sampler behind the event, or a lockstep simulator far
    ahead of real time) shows where the joint was on its way to the limit."""

    def __init__(self, lower: Sequence[float], upper: Sequence[float]) -> None:
        self.lower = tuple(lower)
        self.upper = tuple(upper)
        self.reports: dict[int, float] = {}  # joint → when its report arrived (Unix time, s)

    @property
    def at(self) -> set[int]:
        return set(self.reports)

    def reported(self, joint: int, wall: float) -> None:
        self.reports[joint] = wall

    def cleared(self, position: Sequence[float], wall: float) -> list[int]:
        """The joints reported at a limit that ``position``, published at ``wall`` (Unix
        time, s), shows clear of both; forgotten."""
        out = []
        for j, since in sorted(self.reports.items()):
            margin = CLEAR_FRACTION * (self.upper[j] - self.lower[j])
            if wall > since and self.lower[j] + margin < position[j] < self.upper[j] - margin:
                out.append(j)
        for j in out:
            del self.reports[j]
        return out
