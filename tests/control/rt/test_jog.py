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


# -- the streamed velocity jog -----------------------------------------------------------------


def stream(jog: PositionJog, target: list[float], velocity: float, samples: int,
           renew: bool = True) -> np.ndarray:
    """Up/Down's target each sample while ``velocity`` is streamed (renewed every sample, or
    sent once)."""
    rows = []
    command = [0.0] * 6
    command[UPDOWN] = velocity
    jog.stream(command)
    for _ in range(samples):
        if renew:
            jog.stream(command)
        jog.advance(target)
        rows.append(target[UPDOWN])
    return np.array(rows)


def started(at: float = 0.0) -> tuple[PositionJog, list[float]]:
    jog = PositionJog(UNIMATE, DT)
    target = [1500.0, 0.0, at, 0.0, 0.0, 0.0]
    jog.stop_at(target)
    return jog, target


def test_a_streamed_velocity_moves_the_target_at_it_ramped_within_max_accel() -> None:
    joint = UNIMATE.joints[UPDOWN]
    jog, target = started()
    path = np.concatenate([[0.0], stream(jog, target, 4.0, 1_000)])
    velocity = np.diff(path) / DT
    assert velocity[-500:] == pytest.approx(4.0)
    assert np.abs(np.diff(np.concatenate([[0.0], velocity]))).max() / DT <= \
        joint.max_accel * (1 + 1e-6)


def test_a_streamed_velocity_is_capped_at_jog_speed() -> None:
    jog, target = started()
    velocity = np.diff(stream(jog, target, -1_000.0, 1_000)) / DT
    assert np.abs(velocity).max() == pytest.approx(UNIMATE.joints[UPDOWN].jog_speed)


def test_a_stream_not_renewed_stops_within_its_braking_distance() -> None:
    """The deadman: sent once, the target moves for 150 ms of samples, then brakes at
    max_accel and stops, no farther than v²/2a (and a sample's step) on."""
    joint = UNIMATE.joints[UPDOWN]
    jog, target = started()
    path = stream(jog, target, 6.0, 2_000, renew=False)
    deadman = round(0.150 / DT)
    velocity = np.diff(np.concatenate([[0.0], path])) / DT
    assert velocity[deadman - 2] == pytest.approx(6.0)
    braking = 6.0 ** 2 / (2 * joint.max_accel)
    assert path[-1] - path[deadman - 1] <= braking + 6.0 * DT
    assert not jog.moving and jog.velocity[UPDOWN] == 0.0 and path[-1] == path[-500]
    assert np.abs(np.diff(velocity)).max() / DT <= joint.max_accel * (1 + 1e-6)


def test_a_streamed_jog_slows_before_the_soft_limit_and_rests_inside_it() -> None:
    joint = UNIMATE.joints[UPDOWN]
    low, high = rest_range(joint)
    assert joint.upper - high == pytest.approx(joint.goal_tolerance)
    for velocity, edge in ((100.0, high), (-100.0, low)):
        jog, target = started(at=0.5 * (joint.upper + joint.lower))
        path = np.concatenate([[target[UPDOWN]], stream(jog, target, velocity, 20_000)])
        speed = np.diff(path) / DT
        assert path[-1] == edge and speed[-1] == 0.0
        assert low <= path.min() and path.max() <= high  # never past the edge, then back
        assert np.all(np.diff(path) * np.sign(velocity) >= 0)
        assert np.abs(np.diff(speed)).max() / DT <= 2 * joint.max_accel * (1 + 1e-6)
        pressed = stream(jog, target, velocity, 500)  # held against the edge: it stays
        assert np.all(pressed == edge)
        back = stream(jog, target, -velocity, 500)  # and leaves it the other way at once
        assert abs(back[-1] - edge) > 1.0


def test_position_jog_steps_onto_the_limit_stop_a_goal_tolerance_inside_it() -> None:
    """Issue 25: 1° steps from 27° to 30° left the target on the limit, the arm pressing on
    its stop; now the goal (and the target) stop a goal tolerance inside it."""
    joint = UNIMATE.joints[UPDOWN]
    jog, target = started(at=27.0)
    for _ in range(4):
        jog.move_goal(UPDOWN, min(jog.goal[UPDOWN] + 1.0, joint.upper))
        jog_to_the_end(jog, target)
    assert target[UPDOWN] == pytest.approx(joint.upper - joint.goal_tolerance)
    jog.move_goal(UPDOWN, joint.upper)  # a goal on the limit itself
    jog_to_the_end(jog, target)
    assert target[UPDOWN] == pytest.approx(joint.upper - joint.goal_tolerance)


def test_a_target_held_outside_the_rest_range_is_not_pushed_further_out() -> None:
    joint = UNIMATE.joints[UPDOWN]
    jog = started(at=joint.upper - 0.1)[0]  # the arm was held there
    jog.move_goal(UPDOWN, jog.goal[UPDOWN] + 1.0)
    assert jog.goal[UPDOWN] == joint.upper - 0.1
    jog.move_goal(UPDOWN, jog.goal[UPDOWN] - 1.0)
    assert jog.goal[UPDOWN] == pytest.approx(joint.upper - 1.1)

