"""Lines of text made to fit a width without cutting a word in half.

The header's lines are longer than an 80-column screen leaves them: a line of parts
drops its least needed parts first, and what still does not fit ends at a word with "…".
"""

from __future__ import annotations

from collections.abc import Sequence

from rich.text import Text

ELLIPSIS = "…"


def clip_words(text: Text, width: int) -> Text:
    """``text`` if it fits in ``width`` cells, else its words up to the last that fits and "…"
    (a first word longer than the width is the one thing cut, there being no other way)."""
    if text.cell_len <= width:
        return text
    room = max(width - 1, 0)  # a column for the "…"
    cut = text.plain.rfind(" ", 0, room + 1)
    keep = text[:cut] if cut > 0 else text[:room]
    keep.rstrip()
    return keep + Text(ELLIPSIS, "dim")


def fit_parts(parts: Sequence[tuple[Text, int]], width: int) -> Text:
    """The parts of a line (each a text and its rank: 0 always kept, higher dropped sooner;
    the later of two of one rank first) joined, as many as fit in ``width`` cells, in order;
    clipped at a word if even the rank-0 parts do not fit."""
    kept = list(range(len(parts)))
    by_drop = sorted(kept, key=lambda i: (parts[i][1], i), reverse=True)
    for i in by_drop:
        if sum(parts[k][0].cell_len for k in kept) <= width or parts[i][1] == 0:
            break
        kept.remove(i)
    return clip_words(Text("").join(parts[k][0] for k in kept), width)
