"""The plotext plots of runs: decimation keeps every peak, and plotdata.m's steady velocity."""

from __future__ import annotations

import numpy as np
import pytest

from app.plotting.figure import decimate
from app.plotting.run_plot import steady_velocity


def test_decimation_keeps_every_peak() -> None:
    t = np.linspace(0.0, 1.0, 20_000)
    y = np.sin(40 * t)
    y[12_345] = 5.0
    tt, yy = decimate(t, y, 400)
    assert len(tt) <= 400 and yy.max() == 5.0 and yy.min() == pytest.approx(-1.0, abs=1e-3)


def test_steady_velocity_is_plotdatas_second_half_slope() -> None:
    t = np.linspace(0.0, 2.0, 201)
    assert steady_velocity(t, 3.0 * t + 1.0) == pytest.approx(3.0)
