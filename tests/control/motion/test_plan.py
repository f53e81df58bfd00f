"""Move plans: the approach in front of a path that starts elsewhere, and the summaries that
leave it out (what the TUI and a script calling ``ControlClient.run`` both get)."""

from __future__ import annotations

import numpy as np
import pytest

from control.motion import moves
from control.motion.plan import MovePlan, approach_ramp, moving_joints, summaries
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
