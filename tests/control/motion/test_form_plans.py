"""The Moves forms' rules and plans, shared by the TUI and ``servodesk move``: one rule gives
one message wherever it is typed, a plan is the same from either, and a saved run is
summarised as its move was (the approach left out)."""

from __future__ import annotations

import numpy as np
import pytest

from app.widgets.fields import position_check
from control.motion import form_plans, moves
from control.motion.acceptance import accept
from control.motion.fields import FieldError, position_rule
from control.motion.plan import run_summaries, summaries
from control.recorder import Run
from hw.machine import load_machine

UNIMATE = load_machine("unimate2000b")
RIG = load_machine("rig")
MIDDLE = np.array([(j.lower + j.upper) / 2 for j in UNIMATE.joints])


@pytest.mark.parametrize("text", ["", "x", "nan", "-30", "40", "1e400"])
def test_the_forms_field_and_the_rule_refuse_with_the_same_words(text: str) -> None:
    updown = UNIMATE.joints[2]
    with pytest.raises(FieldError) as refused:
        position_rule(updown, UNIMATE, "target").parse(text)
    message = str(refused.value)
    assert message.startswith("Up/Down target")
    shown = position_check(updown, UNIMATE, "target").validate(text)
    assert shown.failure_descriptions == [message]


def test_a_rule_aimed_at_another_joint_takes_its_limits_and_name() -> None:
    rule = position_rule(UNIMATE.joints[2], UNIMATE, "end", optional=True)
    rule.aim(UNIMATE.joints[0], UNIMATE, "end")
    assert rule.parse("") is None and rule.parse("1000") == 1000.0
    with pytest.raises(FieldError, match=r"In/Out end 5mm is outside 976…2041mm"):
        rule.parse("5")


def test_a_step_plan_is_the_step_path_with_its_fields_as_meta() -> None:
    plan = form_plans.step(UNIMATE, MIDDLE, 2, 10.0, start=1.0, duration=2.0, dt=1e-3)
    start = MIDDLE.copy()
    start[2] = 1.0
    assert np.array_equal(plan.path, moves.step(start, 2, 10.0, 2.0, dt=1e-3, machine=UNIMATE))
    assert (plan.title, plan.moving) == ("step Up/Down to 10°", (2,))
    assert plan.meta == {"joint": "Up/Down", "start": 1.0, "target": 10.0}


def test_go_to_names_the_joint_outside_its_limits() -> None:
    target = MIDDLE.copy()
    target[3] = 500.0
    with pytest.raises(ValueError, match="Bend"):
        form_plans.go_to(UNIMATE, MIDDLE, target, 0.5, dt=1e-3)
    plan = form_plans.go_to(UNIMATE, MIDDLE, MIDDLE + 1.0, 0.5, dt=1e-3)
    assert np.allclose(plan.path[-1], MIDDLE + 1.0) and plan.kind == "go_to"


@pytest.mark.parametrize("speed", [0.001, 1e-5])
def test_a_go_to_longer_than_a_move_may_last_is_refused_naming_the_limit(speed: float) -> None:
    """Rotate 40° at a thousandth of its speed would take 1,250 s (1.25 M samples, 60 MB of
    path), at 1e-5 of it 125,000 s (a MemoryError): each is a ValueError naming the move
    limit, found from the joints' limits before the path is sampled."""
    target = MIDDLE.copy()
    target[1] += 40.0
    with pytest.raises(ValueError, match=r"^the go to would take [\d,.]+ s, longer than a "
                                         r"move may last \(the move limit, 600 s\): raise the "
                                         r"speed, or go part of the way first$"):
        form_plans.go_to(UNIMATE, MIDDLE, target, speed, dt=1e-3)
    assert len(form_plans.go_to(UNIMATE, MIDDLE, target, 0.01, dt=1e-3).path) < 600_001


def test_go_to_starts_a_joint_resting_just_past_its_limit_on_it() -> None:
    resting = np.array([-0.1])  # the rig on its bottom stop, inside its 1 mm tolerance
    plan = form_plans.go_to(RIG, resting, RIG.home, 0.5, dt=1e-3)
    assert plan.path[0, 0] == 0.0 and plan.path[-1, 0] == RIG.home[0]
    accepted = accept(plan, resting, RIG, 1e-3)  # the rules every move meets, no approach
    assert accepted.approach == 0 and np.array_equal(accepted.path, plan.path)
    with pytest.raises(ValueError, match=r"Ram .*jog it back inside its limits first"):
        accept(form_plans.go_to(RIG, np.array([-5.0]), RIG.home, 0.5, dt=1e-3),
               np.array([-5.0]), RIG, 1e-3)


@pytest.mark.parametrize("text, message", [
    ("", "type at least one point"),
    ("1 2 3 4 5 6\n\n1 2", "point line 3: 2 numbers; type 6 joint positions"),
    ("1 2 three 4 5 6", "point line 1: '1 2 three 4 5 6' is not numbers"),
])
def test_via_points_name_the_line(text: str, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        form_plans.via_point_rows(text, UNIMATE, cartesian=False)


def test_a_saved_run_is_summarised_as_its_move_was_the_approach_left_out() -> None:
    plan = form_plans.ramp(RIG, np.array([0.0]), 0, 80.0, 1.5, start=40.0, dt=1e-3)
    plan = plan.approached(np.array([0.0]), RIG, 1e-3)
    assert plan.approach > 0
    desired = plan.path
    actual = desired - 0.5
    t = np.arange(len(desired)) * 1e-3
    run = Run.from_machine(RIG, plan.kind, "complete", RIG.track, t, desired, actual,
                           np.zeros_like(actual),
                           meta={"approach_samples": plan.approach, "moving": [0]})
    [(label, summary)] = run_summaries(run, RIG)
    assert [(label, summary)] == summaries(plan, run, RIG)
    assert summary.METRIC == "tracking"  # a ramp's result is its tracking error
    assert summary.travel == pytest.approx(40.0)  # from the ramp's start, not 0
    open_loop = Run.from_machine(RIG, "set_pulse", "complete", RIG.track, t, desired, actual,
                                 np.zeros_like(actual), meta={"open_loop": True})
    assert run_summaries(open_loop, RIG) == []
