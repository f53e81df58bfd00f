"""The Moves tab's result table shows what means something for the kind of move: a step's
response, a smooth path's tracking error, a sine's amplitude ratio and phase lag; one row
per joint that moved, and no step metrics (rise, settling, overshoot) for a ramp or sine."""

from __future__ import annotations

import numpy as np

from control.motion import moves
from control.motion.plan import MovePlan, summaries
from control.recorder import Run
from hw.machine import load_machine

UNIMATE = load_machine("unimate2000b")
DT = UNIMATE.sample_time_s
HOME = np.array([1500.0, 0.0, 0.0, 0.0, 0.0, 0.0])


def table(plan: MovePlan, lag_s: float = 0.05) -> tuple[tuple[str, ...], list[tuple[str, ...]]]:
    """The columns and rows for ``plan`` followed with a first-order lag."""
    path = plan.path
    actual = path.copy()
    alpha = DT / lag_s
    for k in range(1, len(path)):
        actual[k] = actual[k - 1] + alpha * (path[k - 1] - actual[k - 1])
    t = np.arange(len(path)) * DT
    run = Run.from_machine(UNIMATE, plan.kind, "complete", {}, t, path, actual,
                           np.zeros_like(path))
    rows = summaries(plan, run, UNIMATE)
    return moves.summary_columns(rows), [moves.summary_cells(label, s) for label, s in rows]


def test_a_step_shows_its_response_for_the_joint_that_moved() -> None:
    plan = MovePlan.of_path(moves.step(HOME, 2, 10.0, 2.0, dt=DT, machine=UNIMATE), "step")
    columns, rows = table(plan)
    assert columns == ("joint", "step", "overshoot", "rise s", "settle s", "steady e",
                       "max |e|")
    assert [row[0] for row in rows] == ["Up/Down"]  # not the five that held
    assert rows[0][1] == "+10.00°"


def test_a_ramp_shows_its_tracking_error_and_no_step_metrics() -> None:
    end = HOME + np.array([0.0, 20.0, 0.0, 0.0, 0.0, 0.0])
    plan = MovePlan.of_path(moves.ramp(HOME, end, 2.0, dt=DT, machine=UNIMATE), "ramp")
    columns, rows = table(plan)
    assert columns == ("joint", "travel", "RMS e", "max |e|", "at s", "end e")
    assert [row[0] for row in rows] == ["Rotate"]
    assert rows[0][1] == "20.00°"
    rms, largest = (float(cell.rstrip("°")) for cell in rows[0][2:4])
    assert 0 < rms < largest < 1.0  # 10°/s followed 50 ms late: 0.5° behind at most


def test_a_sine_shows_its_amplitude_ratio_and_phase_lag() -> None:
    end = HOME + np.array([0.0, 0.0, 10.0, 0.0, 0.0, 0.0])
    path = moves.sine(HOME, end, 2.0, 6.0, dt=DT, machine=UNIMATE)
    plan = MovePlan.of_path(path, "sine", meta={"period": 2.0})
    columns, rows = table(plan)
    assert columns == ("joint", "amplitude", "ratio", "lag °", "period s", "RMS e", "max |e|")
    assert not {"rise s", "settle s", "overshoot"} & set(columns)
    (row,) = rows
    assert row[0] == "Up/Down"
    # a 50 ms lag at 0.5 Hz: gain 1/√(1 + (ωτ)²) = 0.988, phase atan(ωτ) = 9.0°
    assert abs(float(row[2]) - 0.988) < 0.01 and abs(float(row[3]) - 9.0) < 1.0
