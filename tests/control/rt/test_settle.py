"""The end condition of a move (control/rt/settle.py), sample by sample: in position means
within the goal tolerance and slower than the stopped speed for a whole 100 ms window, so
one reading neither passes nor fails it; out of goal_time it names each joint and why."""

from __future__ import annotations

import pytest

from control.rt.settle import GoalCheck
from hw.machine import load_machine

UNIMATE = load_machine("unimate2000b")
GOAL = [1300.0, 0.0, 0.0, 0.0, 90.0, 0.0]
MS = 1_000_000


def run(check: GoalCheck, positions, start: int = 1) -> tuple[int, str]:
    """Sample ``positions(k)`` each millisecond from ``start``; (k, verdict) at the first one."""
    k = start
    while not (verdict := check.sample(k * MS, positions(k))):
        k += 1
    return k, verdict


def test_at_rest_on_the_goal_is_complete_after_two_windows() -> None:
    check = GoalCheck(UNIMATE, GOAL, 0, 0.001)
    k, verdict = run(check, lambda k: GOAL)
    assert verdict == "complete" and k == 201  # the speed's window fills, then one in position
    assert check.record()["settle_s"] == (0.101,) * 6


def test_one_reading_out_of_the_band_delays_it_and_fails_nothing() -> None:
    check = GoalCheck(UNIMATE, GOAL, 0, 0.001)
    bend = UNIMATE.joint_index("bend")

    def positions(k: int) -> list[float]:
        q = list(GOAL)
        q[bend] += 0.6 if k == 150 else 0.0  # one reading 0.6° off (the goal is 0.5°)
        return q

    k, verdict = run(check, positions)
    assert verdict == "complete" and k == 251 + 100  # its speed is judged over 100 ms too
    assert check.record()["settle_s"][bend] == pytest.approx(0.251)


def test_inside_the_band_but_moving_is_not_in_position() -> None:
    check = GoalCheck(UNIMATE, GOAL, 0, 0.001)
    yaw = UNIMATE.joint_index("yaw")

    def positions(k: int) -> list[float]:
        q = list(GOAL)
        q[yaw] += 0.4 * (-1) ** (k // 37)  # swinging ±0.4°, inside 0.5°
        return q

    k, verdict = run(check, positions)
    assert k == 2000 and verdict.startswith("unsettled: Yaw 0.40° from its goal, moving 8 "), \
        verdict
    assert verdict.endswith(" after 2 s") and check.record()["settle_s"][yaw] is None


def test_out_of_goal_time_names_every_joint_not_in_position() -> None:
    check = GoalCheck(UNIMATE, GOAL, 0, 0.001)
    inout, bend = UNIMATE.joint_index("inout"), UNIMATE.joint_index("bend")

    def positions(k: int) -> list[float]:
        q = list(GOAL)
        q[inout] += 3.0  # 3 mm off for good
        q[bend] += 2.0 if k < 1990 else 0.0  # there at 1.99 s, too late
        return q

    k, verdict = run(check, positions)
    assert k == 2000
    assert verdict == ("unsettled: In/Out 3.00mm from its goal; Bend 0.00° from its goal, "
                       "moving 20 deg/s after 2 s"), verdict
    record = check.record()
    assert record["settle_s"][inout] is None and record["goal_error"][inout] == 3.0


def test_every_joint_in_position_but_not_for_a_window_yet_names_those() -> None:
    check = GoalCheck(UNIMATE, GOAL, 0, 0.001)
    bend = UNIMATE.joint_index("bend")

    def positions(k: int) -> list[float]:
        q = list(GOAL)
        q[bend] += 2.0 if k < 1850 else 0.0  # there at 1.85 s, stopped by 1.95 s
        return q

    k, verdict = run(check, positions)
    assert (k, verdict) == (2000, "unsettled: Bend 0.00° from its goal, in position only for "
                                  "its last 0.050 s after 2 s")
