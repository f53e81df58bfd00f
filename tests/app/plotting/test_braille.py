"""The braille raster of the Scope tab: a step is one joined line, NaN leaves a gap, sparse
data stays joined."""

from __future__ import annotations

import numpy as np
from rich.style import Style

from app.plotting.braille import Trace, columns, render


def test_the_braille_raster_joins_a_step_into_one_line() -> None:
    t = np.linspace(0.0, 1.0, 1000)
    y = np.where(t < 0.5, 0.0, 1.0)
    low, high = columns(t, y, (0.0, 1.0), (0.0, 1.0), 40, 40)
    assert (low <= high).all(), "every column drawn"
    jump = int(np.argmax(high - low))
    assert low[jump] == 0 and high[jump] == 39  # the vertical of the step is drawn
    strips = render([Trace(t, y, Style(color="red"))], (0.0, 1.0), (-0.1, 1.1), 20, 5)
    assert len(strips) == 5 and all(s.cell_length == 20 for s in strips)
    assert all(0x2800 <= ord(c) <= 0x28FF or c == " " for s in strips for c in s.text)


def test_the_braille_raster_leaves_nan_gaps_and_sparse_data_joined() -> None:
    t = np.linspace(0.0, 1.0, 2000)
    y = np.where((t > 0.4) & (t < 0.6), np.nan, t)
    low, high = columns(t, y, (0.0, 1.0), (0.0, 1.0), 100, 40)
    assert (low[45:55] > high[45:55]).all()  # nothing drawn where desired is NaN
    sparse_t, sparse_y = np.array([0.0, 1.0]), np.array([0.0, 1.0])
    low, high = columns(sparse_t, sparse_y, (0.0, 1.0), (0.0, 1.0), 50, 50)
    assert (low <= high).all()
