"""Move plans: the approach in front of a path that starts elsewhere, and the summaries that
leave it out, by the move's kind, for the joints it moved (what the TUI and a script calling
``ControlClient.run`` both get, and what the run's JSON holds)."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest

from control.motion import moves
from control.motion.moves import SineSummary, StepSummary, TrackingSummary
from control.motion.plan import (
    MovePlan,
    approach_ramp,
    from_records,
    moving_joints,
    result_records,
    run_summaries,
    summaries,
)
from control.recorder import Run
from hw.machine import load_machine

UNIMATE = load_machine("unimate2000b")
RIG = load_machine("rig")
DT = UNIMATE.sample_time_s
HOME = np.array([1500.0, 0.0, 0.0, 0.0, 0.0, 0.0])


def run_of(path: np.ndarray, actual: np.ndarray, machine=UNIMATE, kind: str = "step") -> Run:
    t = np.arange(len(path)) * DT
    return Run.from_machine(machine, kind, "complete", {}, t, path, actual, np.zeros_like(path))


def test_a_path_that_starts_here_gets_no_approach() -> None:
    path = moves.step(HOME + np.array([0.5, 0.1, 0, 0, 0, 0]), 2, 10.0, 2.0, dt=DT, machine=UNIMATE)
    plan = MovePlan.of_path(path, "step")
    assert plan.approached(HOME, UNIMATE, DT) is plan  # within every joint's tolerance


def test_a_path_that_starts_elsewhere_gets_a_ramp_to_its_start_at_half_speed() -> None:
    start = HOME.copy()
    start[1] = 20.0  # Rotate 20° away at half of 60°/s and 300°/s²: 20/30 + 30/150 s, then 0.5
    path = moves.step(start, 2, 10.0, 2.0, dt=DT, machine=UNIMATE)
    plan = MovePlan.of_path(path, "step").approached(HOME, UNIMATE, DT)
    assert plan.approach == len(approach_ramp(HOME, start, UNIMATE, DT))
    assert plan.approach * DT == pytest.approx(20.0 / 30.0 + 30.0 / 150.0 + 0.5, abs=2 * DT)
    assert plan.path[0] == pytest.approx(HOME) and plan.path[plan.approach] == pytest.approx(start)
    rotate = plan.path[:plan.approach + 1, 1]
    assert np.abs(np.diff(rotate)).max() <= 30.0 * DT * (1 + 1e-9)  # half of max_speed
    assert np.abs(np.diff(rotate, 2)).max() <= 150.0 * DT**2 * (1 + 1e-9)  # half of max_accel
    assert plan.approached(HOME, UNIMATE, DT).approach == plan.approach  # not twice


def test_a_duty_profile_has_no_approach() -> None:
    plan = MovePlan("set_pulse", "pulse", profile=np.full((10, 1), 20.0))
    assert plan.approached(np.array([900.0]), RIG, DT) is plan


def test_moving_joints_are_those_whose_desired_changes() -> None:
    path = np.tile(HOME, (5, 1))
    path[:, 3] = np.linspace(0, 1, 5)
    assert moving_joints(path) == (3,)


def test_summaries_leave_the_approach_out_and_list_joints_that_moved() -> None:
    start = HOME.copy()
    start[0] = 1600.0
    plan = MovePlan.of_path(moves.step(start, 2, 10.0, 2.0, dt=DT, machine=UNIMATE),
                            "step").approached(HOME, UNIMATE, DT)
    rows = summaries(plan, run_of(plan.path, plan.path), UNIMATE)
    assert [label for label, _ in rows] == ["Up/Down"]  # In/Out moved only in the approach
    (_, s), = rows
    assert s.step == pytest.approx(10.0) and s.overshoot == 0.0


def test_a_rig_sequence_is_summarised_step_by_step() -> None:
    path = moves.rig_sequence(np.array([200.0]), [(600.0, 3.0), (200.0, 3.0)], dt=DT,
                              machine=RIG)
    plan = MovePlan("multi_step", "sequence", path, meta={"steps": [[600, 3], [200, 3]]},
                    moving=(0,))
    rows = summaries(plan, run_of(path, path, RIG, "multi_step"), RIG)
    assert [label for label, _ in rows] == ["Ram step 1", "Ram step 2"]
    assert [s.step for _, s in rows] == pytest.approx([400.0, -400.0])


def test_a_joint_whose_target_is_within_its_tolerance_did_not_move() -> None:
    """Multi-step targets typed to two decimals put the other joints a few thousandths away:
    no overshoot of thousands of per cent for a joint that held (issue 13)."""
    targets = HOME + np.array([0.004, -0.003, 8.0, 0.002, 0.0, 0.0])
    path = moves.multi_step(HOME, targets, 3.0, dt=DT, machine=UNIMATE)
    plan = MovePlan("multi_step", "multi-step", path, moving=moving_joints(path))
    assert plan.moving == (0, 1, 2, 3)
    actual = path + 0.2 * np.sin(np.arange(len(path)) * DT * 7)[:, None]  # holding noise
    rows = summaries(plan, run_of(path, actual, kind="multi_step"), UNIMATE)
    assert [label for label, _ in rows] == ["Up/Down"]
    assert isinstance(rows[0][1], StepSummary) and rows[0][1].overshoot_pct < 5


def test_a_smooth_path_is_summarised_by_its_tracking_error() -> None:
    end = HOME + np.array([100.0, 0.0, 0.0, 10.0, 0.0, 0.0])
    path = moves.ramp(HOME, end, 2.0, dt=DT, machine=UNIMATE)
    lag = 30  # samples: the actual 30 ms behind
    actual = np.concatenate([np.repeat(path[:1], lag, axis=0), path[:-lag]])
    for kind in ("ramp", "path", "via_points", "cartesian", "end_point"):
        plan = MovePlan(kind, kind, path, moving=moving_joints(path))
        rows = summaries(plan, run_of(path, actual, kind=kind), UNIMATE)
        assert [label for label, _ in rows] == ["In/Out", "Bend"]
        inout = rows[0][1]
        assert isinstance(inout, TrackingSummary) and inout.travel == pytest.approx(100.0)
        error = path[:, 0] - actual[:, 0]
        assert inout.max_abs_error == pytest.approx(np.abs(error).max())
        assert inout.rms_error == pytest.approx(np.sqrt(np.mean(error**2)))
        assert inout.final_error == pytest.approx(0.0)  # it catches up in the hold
        assert inout.max_error_time_s == pytest.approx(np.argmax(np.abs(error)) * DT)


def test_a_sine_is_summarised_by_amplitude_ratio_and_phase_lag() -> None:
    end = HOME.copy()
    end[1] = 20.0
    path = moves.sine(HOME, end, 2.0, 5.0, dt=DT, machine=UNIMATE)
    lag = 50  # samples at 1 ms behind a 2 s period: 9°
    actual = np.concatenate([np.repeat(path[:1], lag, axis=0), path[:-lag]])
    actual[:, 1] = 10.0 + 0.8 * (actual[:, 1] - 10.0)
    run = run_of(path, actual, kind="sine")
    for meta in ({"period": 2.0}, {}):  # the form's period, or estimated from the desired
        plan = MovePlan("sine", "sine", path, meta=meta, moving=(1,))
        ((label, s),) = summaries(plan, run, UNIMATE)
        assert label == "Rotate" and isinstance(s, SineSummary)
        assert s.period_s == pytest.approx(2.0, rel=1e-3) and s.periods == 2.0
        assert s.amplitude == pytest.approx(10.0, rel=1e-3)
        assert s.amplitude_ratio == pytest.approx(0.8, abs=2e-3)
        assert s.phase_lag_deg == pytest.approx(9.0, abs=0.1)


def test_a_sine_stopped_in_its_first_half_period_is_not_fitted() -> None:
    end = HOME.copy()
    end[1] = 20.0
    path = moves.sine(HOME, end, 2.0, 5.0, dt=DT, machine=UNIMATE)[:700]  # aborted at 0.7 s
    plan = MovePlan("sine", "sine", path, meta={"period": 2.0}, moving=(1,))
    ((_, s),) = summaries(plan, run_of(path, path, kind="sine"), UNIMATE)
    assert s.amplitude_ratio is None and "less than half a period" in s.notes[0]


def test_results_are_json_records() -> None:
    path = moves.step(HOME, 2, 10.0, 2.0, dt=DT, machine=UNIMATE)
    plan = MovePlan("step", "step", path, moving=(2,))
    actual = path.copy()
    actual[:, 2] = np.nan  # nothing recorded: NaN metrics are written as null
    (record,) = result_records(summaries(plan, run_of(path, actual), UNIMATE))
    assert record["label"] == "Up/Down" and record["metric"] == "step"
    assert record["step"] is None and record["overshoot"] is None
    assert record["notes"] == ["no valid samples"]
    json.dumps(record, allow_nan=False)


@pytest.mark.parametrize("kind", ["step", "ramp", "sine"])
def test_a_saved_run_gives_the_results_saved_with_it(kind: str) -> None:
    """``runs show`` reports what the move reported when it ended, not a recomputation from
    the samples as rounded to be written; a run saved without results is summarised from its
    samples."""
    end = HOME + np.array([0.0, 0.0, 10.0, 0.0, 0.0, 0.0])
    path = {"step": moves.step(HOME, 2, 10.0, 2.0, dt=DT, machine=UNIMATE),
            "ramp": moves.ramp(HOME, end, 2.0, dt=DT, machine=UNIMATE),
            "sine": moves.sine(HOME, end, 2.0, 6.0, dt=DT, machine=UNIMATE)}[kind]
    actual = np.vstack([path[:1], path[:-1]]) + 0.01  # a sample late, a little off
    meta = {"period": 2.0} if kind == "sine" else {}
    rows = summaries(MovePlan.of_path(path, kind, meta), run_of(path, actual, kind=kind), UNIMATE)
    assert [s.METRIC for _, s in rows] == [{"ramp": "tracking"}.get(kind, kind)]
    records = json.loads(json.dumps(result_records(rows)))
    assert from_records(records) == rows
    rounded = np.round(actual, 1)  # not what the move saw
    saved = Run.from_machine(UNIMATE, kind, "complete", {}, np.arange(len(path)) * DT, path,
                             rounded, np.zeros_like(path),
                             meta={**meta, "approach_samples": 0, "moving": [2]})
    assert run_summaries(replace(saved, meta={**saved.meta, "results": records}),
                         UNIMATE) == rows
    assert run_summaries(saved, UNIMATE) != rows  # from the samples written
