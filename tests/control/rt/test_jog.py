"""Position jog: the hold target travels to its goal on a trapezoid at the joint's jog speed
and max_accel, stops on the goal, and follows a goal moved again on the way."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from control.rt.jog import PositionJog, rest_range
from hw.machine import load_machine

UNIMATE = load_machine("unimate2000b")
DT = UNIMATE.sample_time_s
UPDOWN = 2


def travel(jog: PositionJog, target: list[float], ticks: int) -> np.ndarray:
    rows = []
    for _ in range(ticks):
        jog.advance(target)
        rows.append(list(target))
    return np.array(rows)


def jog_to_the_end(jog: PositionJog, target: list[float]) -> np.ndarray:
    rows = []
    while jog.moving:
        jog.advance(target)
        rows.append(list(target))
    return np.array(rows)


@settings(deadline=None)
@given(step=st.floats(-50.0, 50.0).filter(lambda s: abs(s) > 1e-3))
def test_the_target_never_jumps_and_stops_on_the_goal(step: float) -> None:
    jog = PositionJog(UNIMATE, DT)
    target = [1500.0, 0.0, 0.0, 0.0, 0.0, 0.0]
    jog.stop_at(target)
    jog.move_goal(UPDOWN, step)
    joint = UNIMATE.joints[UPDOWN]
    path = np.concatenate([[0.0], jog_to_the_end(jog, target)[:, UPDOWN]])
    velocity = np.diff(path) / DT
    accel = np.diff(np.concatenate([[0.0], velocity, [0.0]])) / DT
    assert np.abs(velocity).max() <= joint.jog_speed * (1 + 1e-9)
    # it lands on the goal in the last tick from under a·dt: those two ticks within 2·a
    assert np.abs(accel[:-2]).max() <= joint.max_accel * (1 + 1e-6)
    assert np.abs(accel[-2:]).max() <= 2 * joint.max_accel * (1 + 1e-6)
    goal = float(np.clip(step, *rest_range(joint)))  # a goal past the rest range stops at it
    assert path[-1] == goal and jog.velocity[UPDOWN] == 0.0
    assert np.all(np.diff(path) * np.sign(step) >= 0), "it went past and came back"


def test_a_long_jog_takes_about_distance_over_jog_speed() -> None:
    jog = PositionJog(UNIMATE, DT)
    target = [1500.0, 0.0, 0.0, 0.0, 0.0, 0.0]
    jog.stop_at(target)
    jog.move_goal(UPDOWN, 25.0)
    joint = UNIMATE.joints[UPDOWN]
    ticks = 0
    while jog.moving:
        jog.advance(target)
        ticks += 1
    expected = 25.0 / joint.jog_speed + joint.jog_speed / joint.max_accel
    assert ticks * DT == pytest.approx(expected, rel=0.02)


def test_a_goal_moved_again_on_the_way_is_followed_without_a_jump() -> None:
    jog = PositionJog(UNIMATE, DT)
    target = [1500.0, 0.0, 0.0, 0.0, 0.0, 0.0]
    jog.stop_at(target)
    jog.move_goal(UPDOWN, 10.0)
    first = travel(jog, target, 300)[:, UPDOWN]
    jog.move_goal(UPDOWN, -5.0)  # reversed before it got there
    second = travel(jog, target, 10_000)[:, UPDOWN]
    path = np.concatenate([[0.0], first, second])
    assert np.abs(np.diff(path)).max() <= UNIMATE.joints[UPDOWN].jog_speed * DT * (1 + 1e-9)
    assert path[-1] == -5.0
