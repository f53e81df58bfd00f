"""Rows of cells in aligned columns, as lines of text, laid out again only where they changed.

A live block (Status' joints, its loop) is a few rows of numbers of which, idle, a few cells
change a tick: every joint's glitch count, the sample number. Laying every row out again
each tick (the widths, the padding, the styles moved to where each cell stands, a limit bar
drawn) was most of the idle Status tab's own work. Here a row that reads as before is the
very line it was, and a cell that changed within its length and its style is written into
its row's line where it stands; only a row whose cells changed length or style, or a table
whose column widths changed, is laid out again.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

from rich.cells import cell_len
from rich.text import Span, Text

Cell = str | Text
GAP = 2  # columns between two of a table's columns


@dataclass(frozen=True)
class Row:
    """A row as laid out: its cells (``_key``), its line, and where each cell's text starts."""

    key: tuple[object, ...]
    line: Text
    starts: tuple[int, ...]


class AlignedRows:
    """A table's rows in columns ``gap`` apart, each line begun with ``edge``, justified by
    column (``"left"`` or ``"right"``); the first row bold when ``header``. An optional
    ``after`` cell follows a row's columns (a limit bar in what the line has left)."""

    def __init__(self, justify: tuple[str, ...], *, edge: str = "", gap: int = GAP,
                 header: bool = False) -> None:
        self.justify = justify
        self.edge = edge
        self.gap = gap
        self.header = header
        self.widths: tuple[int, ...] = ()  # of the columns as last laid out
        self._rows: list[Row] = []
        self.laid_out = 0  # rows laid out whole, not as before or written in (the idle cost)

    @property
    def width(self) -> int:
        """The columns' cells, ``edge`` included, as last laid out (0 before)."""
        if not self.widths:
            return 0
        return len(self.edge) + sum(self.widths) + self.gap * (len(self.widths) - 1)

    def lines(self, rows: Sequence[Sequence[Cell]],
              after: Callable[[int], Sequence[Cell]] | None = None) -> list[Text]:
        """``rows`` (each a cell a column) as lines; ``after(width)`` gives each row's cell
        after its columns, given the columns' width."""
        keys = [tuple(map(_key, row)) for row in rows]
        laid = self._rows
        if len(rows) != len(laid) or self._lengths_changed(keys):
            widths = tuple(max((cell_len(_plain(row[k])) for row in rows), default=0)
                           for k in range(len(self.justify)))
            if widths != self.widths:
                self.widths, laid = widths, []
        if after is not None:
            tails = after(self.width)
            rows = [(*row, tail) for row, tail in zip(rows, tails, strict=True)]
            keys = [(*key, _key(tail)) for key, tail in zip(keys, tails, strict=True)]
        made = [self._again(i, laid[i], tuple(row), key) if i < len(laid)
                else self._laid_out(i, tuple(row), key)
                for i, (row, key) in enumerate(zip(rows, keys, strict=True))]
        self._rows = made
        return [row.line for row in made]

    def _lengths_changed(self, keys: list[tuple[object, ...]]) -> bool:
        """Whether a cell of the columns changed length: only then can a width have."""
        for key, row in zip(keys, self._rows, strict=True):
            was = row.key[:len(key)]
            if key != was and any(
                    len(_plain_of(new)) != len(_plain_of(old))
                    or cell_len(_plain_of(new)) != cell_len(_plain_of(old))
                    for new, old in zip(key, was, strict=True) if new != old):
                return True
        return False

    def _again(self, i: int, row: Row, cells: tuple[Cell, ...], key: tuple[object, ...]) -> Row:
        """Row ``i`` as before, its changed cells written in, or laid out again."""
        if key == row.key:
            return row
        if len(key) != len(row.key):
            return self._laid_out(i, cells, key)
        plain = row.line.plain
        for k, (new, old) in enumerate(zip(key, row.key, strict=True)):
            if new == old:
                continue
            text, was = _plain_of(new), _plain_of(old)
            if (len(text) != len(was) or cell_len(text) != len(text)
                    or cell_len(was) != len(was) or _styles_of(new) != _styles_of(old)):
                return self._laid_out(i, cells, key)
            start = row.starts[k]
            plain = plain[:start] + text + plain[start + len(text):]
        line = Text(plain, spans=list(row.line.spans))  # the same styles where they were
        return Row(key, line, row.starts)

    def _laid_out(self, i: int, cells: tuple[Cell, ...], key: tuple[object, ...]) -> Row:
        """Row ``i`` laid out whole: each cell padded to its column's width, its styles moved
        to where it stands."""
        self.laid_out += 1
        parts, spans, starts, at = [self.edge], [], [], len(self.edge)
        columns_end = at
        for k, cell in enumerate(cells):
            text = _plain(cell)
            if k == len(self.justify):  # the cell after the columns
                columns_end = at
            if k:
                parts.append(" " * self.gap)
                at += self.gap
            width = self.widths[k] if k < len(self.widths) else cell_len(text)
            pad = " " * (width - cell_len(text))
            right = k < len(self.justify) and self.justify[k] == "right"
            start = at + len(pad) if right else at
            parts += [pad, text] if right else [text, pad]
            at += len(pad) + len(text)
            starts.append(start)
            if isinstance(cell, Text):
                if cell.style:
                    spans.append(Span(start, start + len(text), cell.style))
                spans += [span.move(start) for span in cell.spans]
        line = Text("".join(parts), spans=spans)
        if self.header and i == 0:  # the columns' heads, not what follows them
            line.stylize("bold", 0, columns_end if len(cells) > len(self.justify) else at)
        return Row(key, line, tuple(starts))


def _plain(cell: Cell) -> str:
    return cell if isinstance(cell, str) else cell.plain


def _key(cell: Cell) -> object:
    """What a cell draws, as a value (a Text's equality leaves out its own style)."""
    return cell if isinstance(cell, str) else (cell.plain, cell.style, tuple(cell.spans))


def _plain_of(key: object) -> str:
    return key if isinstance(key, str) else key[0]  # type: ignore[index]


def _styles_of(key: object) -> object:
    """What a cell adds to its line's styles (its own style and its spans), where it starts."""
    return None if isinstance(key, str) else key[1:]  # type: ignore[index]
