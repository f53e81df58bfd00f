"""Numbers as decimal text, a block of them at a time: how a run's tables are written
(``control/recorder.py``) without a Python call per number.

Writing. A number is written ``±m·10⁻ˢ``: the digits of the integer ``m`` with a point
``s`` digits from their end, no trailing zero after the point (``Cells``). ``fixed`` finds
``m`` and ``s`` of a number at so many decimals, as ``'%.2f' % x`` does; ``shortest`` of
the shortest text that reads back to the same float, as ``repr(x)`` does. Both work in
float64 with error-free products (Dekker's) and sums (Knuth's), so they round as Python
does, exact ties included. What they leave to Python itself (``Cells.odd``, written by
``Cells.spell``), a few numbers in a run: one Python writes with an exponent (below 10⁻⁴
or from 10¹⁵ on), a power of two (its neighbours are not equally far), one whose shortest
text float64 cannot settle (within 2⁻⁴⁶ of a boundary), one past 10¹⁸ at its decimals,
NaN and ±inf. ``slots`` puts
each text in a slot of bytes, four digits at a time; ``Block`` lays slots side by side and
``lines`` makes rows of blocks into lines of text. Every step is a numpy operation on a
block of numbers, which lets go of the GIL while it runs: another thread (a client's
monitor thread) waits at most a step for it, never a table.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

POW10 = 10 ** np.arange(19, dtype=np.int64)  # 1 … 10¹⁸, exact
P10 = 10.0 ** np.arange(23)  # 1 … 10²², exact doubles
_SPLITTER = 134217729.0  # 2²⁷ + 1: Veltkamp's split of a double into two 26-bit halves
TOL = 2.0 ** -46  # far above the relative error of the float64 steps below (2⁻⁵²)
MAX_M = 9.9e17  # an m past this could have 19 digits, more than POW10 and an int64 hold
SHORTEST_RANGE = (1.0001e-4, 1e15)  # where repr writes no exponent (a margin at the low end)
ZERO, POINT, MINUS, NEWLINE = (ord(c) for c in "0.-\n")
# the four ASCII digits of 0 … 9999, as one little-endian word each (text order in memory)
_FOURS = ((np.arange(10_000)[:, None] // np.array([1000, 100, 10, 1]) % 10 + ZERO)
          .astype(np.uint8).view("<u4").ravel())  # in numpy: the list took 25 ms at import
_KEEP = np.array([0, 0xFF000000, 0xFFFF0000, 0xFFFFFF00, 0xFFFFFFFF], dtype="<u4")  # last k
Spell = Callable[[float, int], str]  # the text of an odd value of a column, as Python writes it


@dataclass(frozen=True)
class Cells:
    """A block of numbers as text: ``-`` where ``neg``, the digits of ``mag`` with a point
    ``s`` digits from their end (``mag`` has no trailing zero after it), except where
    ``odd``, which ``spell(value, column)`` writes from ``values``. Arrays of one shape,
    ``(N,)`` or ``(N, k)``: a column is an index of the last axis."""

    neg: np.ndarray
    mag: np.ndarray
    s: np.ndarray
    odd: np.ndarray
    values: np.ndarray
    spell: Spell

    @classmethod
    def of(cls, values: np.ndarray, neg: np.ndarray, mag: np.ndarray, s: np.ndarray,
           odd: np.ndarray, spell: Spell) -> Cells:
        """Cells with ``mag`` and ``s`` cleared where odd, and trailing zeros dropped."""
        mag = np.where(odd, 0, mag)
        s = np.where(odd, 0, s).astype(np.int64)
        for _ in range(int(s.max(initial=0))):
            ends_in_zero = (s > 0) & (mag % 10 == 0)
            if not ends_in_zero.any():
                break
            mag = np.where(ends_in_zero, mag // 10, mag)
            s = s - ends_in_zero
        return cls(neg & ~odd, mag, s, odd, values, spell)


def counting(start: int, stop: int) -> Cells:
    """``start … stop-1`` as ``'%d'`` writes them (option.c SaveData's sample number)."""
    count = np.arange(start, stop, dtype=np.int64)
    nothing = np.zeros(count.size, dtype=bool)
    return Cells(nothing, count, np.zeros_like(count), nothing, count.astype(float),
                 lambda value, _: f"{value:.0f}")


def fixed(values: np.ndarray, decimals: int | np.ndarray, spell: Spell, *,
          negative_zero: bool = False) -> Cells:
    """``values`` at ``decimals`` (a number, or one per column), rounded as ``'%.Nf'`` rounds
    (to the nearest, of the exact binary value, half to even), trailing zeros dropped; a
    value that rounds to 0 is ``0``, or ``-0`` if it is negative and ``negative_zero``."""
    x = np.asarray(values, dtype=np.float64)
    wanted = np.broadcast_to(np.asarray(decimals, dtype=np.int64), x.shape)
    d = np.minimum(wanted, len(P10) - 1)
    a = np.abs(x)
    with np.errstate(invalid="ignore", over="ignore"):
        odd = ~np.isfinite(a) | (a * P10[d] >= MAX_M) | (wanted != d)
        a = np.where(odd, 0.0, a)
        hi, lo = _times_power(a, *_split(a), d)
        whole = np.rint(hi)
        rest, err = _two_sum(hi - whole, lo)  # a·10ᵈ = whole + rest + err, exactly
        step = np.rint(rest)  # past 2⁵³, lo may be several units
        rest = rest - step
    near = whole.astype(np.int64) + step.astype(np.int64)  # within a half of a·10ᵈ
    half_odd = (err == 0) & (near % 2 == 1)  # an exact tie goes to the even neighbour
    up = (rest > 0.5) | ((rest == 0.5) & ((err > 0) | half_odd))
    down = (rest < -0.5) | ((rest == -0.5) & ((err < 0) | half_odd))
    mag = near + up - down
    neg = np.signbit(x) & ((mag > 0) | negative_zero)
    return Cells.of(x, neg, mag, d, odd, spell)


def shortest(values: np.ndarray, spell: Spell) -> Cells:
    """The shortest decimals that read back as each of ``values``, as ``repr`` writes them
    (of several as short, the nearest), without the ``.0`` of a whole number; -0.0 is ``0``."""
    x = np.asarray(values, dtype=np.float64)
    a = np.abs(x)
    low, high = SHORTEST_RANGE
    with np.errstate(invalid="ignore"):
        whole = np.isfinite(a) & (a == np.floor(a)) & (a < high)
        fraction = ~whole & (a >= low) & (a < high) & (np.frexp(a)[0] != 0.5)
    mag = np.where(whole, a, 0.0).astype(np.int64)
    s = np.zeros(x.shape, dtype=np.int64)
    odd = ~whole & ~fraction
    at = np.flatnonzero(fraction)
    if at.size:
        m, places, unsure = _shortest_fraction(a.ravel()[at])
        mag.ravel()[at], s.ravel()[at], odd.ravel()[at] = m, places, unsure
    return Cells.of(x, np.signbit(x) & (mag > 0), mag, s, odd, spell)


def _split(a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``a`` as two doubles of 26 bits each, whose products are exact (Veltkamp)."""
    c = _SPLITTER * a
    high = c - (c - a)
    return high, a - high


P10_HIGH, P10_LOW = _split(P10)


def _times_power(x: np.ndarray, high: np.ndarray, low: np.ndarray, s: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray]:
    """``x·10ˢ`` exactly, as ``hi + lo`` (Dekker's product; ``high + low`` is ``x`` split)."""
    ph, pl = P10_HIGH[s], P10_LOW[s]
    hi = x * P10[s]
    return hi, ((high * ph - hi) + high * pl + low * ph) + low * pl


def _two_sum(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``a + b`` exactly, as the rounded sum and its error (Knuth)."""
    total = a + b
    back = total - a
    return total, (a - (total - back)) + (b - back)


@dataclass(frozen=True)
class _Fractions:
    """Positive non-whole numbers to find the shortest decimals of, with what every trial
    needs: their halves (``_split``) and half the gap to their neighbours."""

    x: np.ndarray
    high: np.ndarray
    low: np.ndarray
    half_gap: np.ndarray

    @classmethod
    def of(cls, x: np.ndarray) -> _Fractions:
        return cls(x, *_split(x), np.spacing(x) / 2)

    def __getitem__(self, at: np.ndarray) -> _Fractions:
        return _Fractions(self.x[at], self.high[at], self.low[at], self.half_gap[at])

    def nearest(self, s: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """For each number and its ``s``: the integer ``m`` nearest ``x·10ˢ``, whether
        ``m·10⁻ˢ`` reads back as ``x`` (it lies within ``half_gap`` of it), and whether
        float64 cannot tell (a tie that matters, or a boundary within its error)."""
        hi, lo = _times_power(self.x, self.high, self.low, s)
        whole = np.rint(hi)  # hi - whole is exact
        rest = (hi - whole) + lo
        step = np.rint(rest)
        distance = np.abs(rest - step)  # from x·10ˢ to its nearest integer
        reach = self.half_gap * P10[s]
        unsure = (((np.abs(distance - 0.5) < TOL) & (reach > 0.5 - TOL))
                  | (np.abs(distance - reach) < TOL * reach) | (whole >= MAX_M))
        m = np.where(unsure, 0.0, whole).astype(np.int64) + step.astype(np.int64)
        return m, distance < reach, unsure


def _shortest_fraction(x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(m, s, unsure)`` of positive non-whole ``x`` in ``SHORTEST_RANGE``, no power of
    two: the least ``s`` whose nearest ``m·10⁻ˢ`` reads back as ``x``. Reading back only
    gets surer as ``s`` grows, and most positions of a path need 16 or 17 significant
    digits: 16 are tried first, then 15 or 17, and a search finds the rest."""
    numbers = _Fractions.of(x)
    e = np.floor(np.log10(x)).astype(np.int64)  # x = d.ddd·10ᵉ, or e is one too many
    first = 15 - e
    m1, back1, unsure = numbers.nearest(first)
    second = np.where(back1, first - 1, first + 1)
    m2, back2, unclear = numbers.nearest(second)
    unsure |= unclear
    m, s = np.where(back1, m1, m2), np.where(back1, first, second)
    rest = np.flatnonzero((back1 == back2) & ~unsure)  # both read back, or neither
    if rest.size:
        found, places, unclear = _search(
            numbers[rest], np.where(back1, 0, second)[rest],
            np.where(back1, second, 17 - e)[rest], m2[rest], back1[rest])
        m[rest], s[rest], unsure[rest] = found, places, unclear
    return m, s, unsure


def _search(numbers: _Fractions, lo: np.ndarray, hi: np.ndarray, m: np.ndarray,
            hi_tried: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Bisect between ``lo`` (does not read back) and ``hi`` (does, if ``hi_tried``; else
    17 significant digits, or 18 if ``e`` was one too many, which must)."""
    unsure = np.zeros(lo.shape, dtype=bool)
    while (at := np.flatnonzero((hi - lo > 1) & ~unsure)).size:
        s = (lo[at] + hi[at]) // 2
        found, back, unclear = numbers[at].nearest(s)
        unsure[at] |= unclear
        good, bad = back & ~unclear, ~back & ~unclear
        hi[at[good]], m[at[good]], hi_tried[at[good]] = s[good], found[good], True
        lo[at[bad]] = s[bad]
    at = np.flatnonzero(~hi_tried & ~unsure)
    if at.size:
        found, back, unclear = numbers[at].nearest(hi[at])
        unsure[at] |= unclear | ~back
        m[at] = found
    return m, hi, unsure


def slots(cells: Cells) -> np.ndarray:
    """Each cell's text right-aligned in a slot as wide as the widest, padded with NULs:
    ``cells.neg.shape + (width,)`` bytes. A slot may hold NULs inside a text too (between
    its sign and its digits, its point and the digits after it): ``lines`` drops them all."""
    whole = cells.mag // POW10[np.minimum(cells.s, 18)]  # m < 10¹⁸: with s past 18 it is
    part = cells.mag - whole * POW10[np.minimum(cells.s, 18)]  # all after the point
    places = int(cells.s.max(initial=0))
    integer = _digits(whole, len(str(int(whole.max(initial=0)))),
                      np.maximum(np.searchsorted(POW10, whole, side="right"), 1))
    parts = [(cells.neg.view(np.uint8) * np.uint8(MINUS))[..., None], integer]
    if places:
        parts += [((cells.s > 0).view(np.uint8) * np.uint8(POINT))[..., None],
                  _digits(part, places, cells.s)]
    slot = np.concatenate(parts, axis=-1)
    if cells.odd.any():
        slot = _spelled(slot, cells)
    return slot


def _digits(number: np.ndarray, count: int, shown: np.ndarray) -> np.ndarray:
    """The last ``count`` digits of each ``number``, of which the last ``shown`` are kept,
    NULs before them: ``number.shape + (count,)`` bytes, made four at a time."""
    groups = -(-count // 4)
    words = np.empty((*number.shape, groups), dtype="<u4")
    rest = number
    for g in range(groups):  # from the end
        above = rest // 10_000
        words[..., groups - 1 - g] = (_FOURS[rest - above * 10_000]
                                      & _KEEP[np.clip(shown - 4 * g, 0, 4)])
        rest = above
    return words.view(np.uint8)[..., 4 * groups - count:]


def _spelled(slot: np.ndarray, cells: Cells) -> np.ndarray:
    """``slot`` with the odd cells' texts, as ``cells.spell`` writes them, in their place."""
    where = np.nonzero(cells.odd)
    columns = where[-1].tolist() if cells.odd.ndim > 1 else [0] * len(where[0])
    texts = [cells.spell(v, c).encode()
             for v, c in zip(cells.values[where].tolist(), columns, strict=True)]
    width = max(slot.shape[-1], *map(len, texts))
    if width > slot.shape[-1]:
        slot = np.concatenate([np.zeros((*slot.shape[:-1], width - slot.shape[-1]),
                                        dtype=np.uint8), slot], axis=-1)
    slot[where] = 0
    for at, text in zip(zip(*where, strict=True), texts, strict=True):
        slot[at][width - len(text):] = np.frombuffer(text, dtype=np.uint8)
    return slot


@dataclass(frozen=True)
class Block:
    """Rows of cells side by side, ``text (N, width)`` bytes, each cell followed by a byte
    for the separator, at the columns ``ends``."""

    text: np.ndarray
    ends: tuple[int, ...]

    @classmethod
    def of(cls, *columns: np.ndarray) -> Block:
        """Slots ``(N, width)`` of one column each, or ``(N, k, width)`` of k columns, all
        with the same k: each row reads column 0 of every argument, then column 1, …"""
        parts = [c if c.ndim == 3 else c[:, None, :] for c in columns]
        n, k = parts[0].shape[:2]
        cell = sum(p.shape[2] + 1 for p in parts)
        text = np.zeros((n, k, cell), dtype=np.uint8)
        ends, at = [], 0
        for p in parts:
            text[:, :, at:at + p.shape[2]] = p
            at += p.shape[2] + 1
            ends.append(at - 1)
        return cls(text.reshape(n, k * cell),
                   tuple(j * cell + end for j in range(k) for end in ends))


def lines(blocks: Sequence[Block], sep: bytes) -> np.ndarray:
    """The rows of ``blocks`` side by side as lines of text (ASCII bytes, ``uint8``): ``sep``
    between cells, ``\\n`` after each row's last, every NUL of a slot dropped (by numpy,
    which lets go of the GIL meanwhile, where ``bytes.translate`` would hold it)."""
    text = np.concatenate([b.text for b in blocks], axis=1)
    at = 0
    for b in blocks:
        text[:, [at + end for end in b.ends]] = ord(sep)
        at += b.text.shape[1]
    text[:, -1] = NEWLINE
    return text[text != 0]
