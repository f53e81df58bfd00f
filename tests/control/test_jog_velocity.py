"""Jogs on the control subprocess: the streamed velocity jog (issue 25 item 3, the
controller's side) and position jogs up to a soft limit (item 5): the hold target moves at
the velocity streamed, brakes when the stream stops (the deadman), and every jog comes to
rest inside the soft limit with no fault."""

from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np
import pytest

from control import ControlClient, Mode
from control.motion import moves
from control.rt.jog import DEADMAN_S, rest_range
from hw.machine import load_machine

UNIMATE = load_machine("unimate2000b")
UPDOWN = 2
JOINT = UNIMATE.joints[UPDOWN]
COUNT = abs(JOINT.encoder.gradient)


def wait_until(predicate: Callable[[], bool], what: str, timeout: float = 60.0) -> None:
    deadline = time.monotonic() + timeout
    while not predicate():
        assert time.monotonic() < deadline, f"timed out waiting for {what}"
        time.sleep(0.002)


def ticks_pass(client: ControlClient, ticks: int) -> None:
    start = client.status().tick
    wait_until(lambda: client.status().tick >= start + ticks, f"{ticks} ticks")


def velocity(v: float) -> list[float]:
    command = [0.0] * UNIMATE.n_joints
    command[UPDOWN] = v
    return command


def at_27(client: ControlClient) -> None:
    """Up/Down to 27°, 3° below its upper limit, by a full-speed go_to: the jogs under test
    start there (a position jog there at jog speed took 4 s of the test's 6)."""
    here = client.status().position
    goal = [27.0 if j == UPDOWN else q for j, q in enumerate(here)]
    assert client.wait(client.go_to(goal, speed=1.0), timeout=60).complete
    wait_until(lambda: abs(client.status().position[UPDOWN] - 27.0) < JOINT.tolerance,
               "Up/Down at 27°")


def faults(client: ControlClient) -> list[str]:
    return [e.message for e in client.poll_events() if e.kind in ("fault", "estop")]


def test_a_velocity_sent_once_moves_the_target_for_the_deadman_and_stops(
        lockstep: ControlClient) -> None:
    """Lockstep: the deadman counts controller ticks, so one command moves Up/Down's target
    for 150 ms of ticks at the velocity (ramped within max_accel), then it brakes to a stop:
    about v·0.15 s in all, whatever the wall clock did."""
    start = lockstep.status().desired[UPDOWN]
    lockstep.jog_velocity(velocity(5.0))
    ticks_pass(lockstep, 2_000)
    status = lockstep.status()
    travel = status.desired[UPDOWN] - start
    assert travel == pytest.approx(5.0 * DEADMAN_S, rel=0.05), travel
    ticks_pass(lockstep, 500)
    assert lockstep.status().desired[UPDOWN] == status.desired[UPDOWN]  # stopped there
    assert not status.estop and faults(lockstep) == []


def test_a_streamed_velocity_moves_the_target_at_it_and_stops_within_its_braking_distance(
        realtime: ControlClient) -> None:
    """Real time, streamed at 50 Hz for 1 s at 4°/s: the target moves 4° (the ramps at
    either end cancel), and once the stream stops it goes on no farther than the deadman's
    150 ms and its braking distance."""
    start = realtime.status().desired[UPDOWN]
    began = time.monotonic()
    while time.monotonic() - began < 1.0:
        realtime.jog_velocity(velocity(4.0))
        time.sleep(0.02)
    elapsed = time.monotonic() - began
    last = realtime.status().desired[UPDOWN]
    wait_until(lambda: not _moving(realtime), "the target to stop")
    end = realtime.status().desired[UPDOWN]
    braking = 4.0 ** 2 / (2 * JOINT.max_accel)
    assert end - last <= 4.0 * (DEADMAN_S + 0.02) + braking
    assert end - start == pytest.approx(4.0 * (elapsed + DEADMAN_S), rel=0.1)
    assert faults(realtime) == []


def _moving(client: ControlClient) -> bool:
    first = client.status()
    time.sleep(0.02)
    return client.status().desired[UPDOWN] != first.desired[UPDOWN]


def test_a_velocity_jog_held_toward_a_limit_rests_inside_it_with_no_fault(
        realtime: ControlClient) -> None:
    high = rest_range(JOINT)[1]
    at_27(realtime)
    began = time.monotonic()
    while time.monotonic() - began < 2.5:  # 3° at 6.25°/s: at the limit after half a second
        realtime.jog_velocity(velocity(100.0))
        status = realtime.status()
        assert status.desired[UPDOWN] <= high
        time.sleep(0.02)
    assert status.desired[UPDOWN] == pytest.approx(high)
    wait_until(lambda: abs(realtime.status().position[UPDOWN] - high) < JOINT.goal_tolerance,
               "Up/Down to rest")
    status = realtime.status()
    assert not status.estop and status.position[UPDOWN] < JOINT.upper - COUNT
    assert faults(realtime) == []


def test_position_jogs_in_one_degree_steps_up_to_the_limit_trip_nothing(
        lockstep: ControlClient) -> None:
    """Issue 25, reproduced: Up/Down in 1° steps from 27° to 30° left the target on 30.00°,
    the arm on its stop at 29.99° and the E-stop latched with "feedback fault … frozen
    encoder". Now the target stops a goal tolerance inside the limit, the arm rests there,
    and a second's hold later nothing has tripped."""
    at_27(lockstep)
    for _ in range(4):  # the last one asks for 31°
        lockstep.jog_position(UPDOWN, 1.0)
        ticks_pass(lockstep, 1_500)
    ticks_pass(lockstep, 3_000)
    status = lockstep.status()
    assert not status.estop, status.fault
    assert status.desired[UPDOWN] == pytest.approx(JOINT.upper - JOINT.goal_tolerance)
    assert abs(status.position[UPDOWN] - status.desired[UPDOWN]) < JOINT.goal_tolerance
    assert faults(lockstep) == []


def test_a_velocity_jog_is_refused_while_a_move_runs_and_checked_when_built(
        lockstep: ControlClient) -> None:
    with pytest.raises(ValueError, match="6 velocities"):
        lockstep.jog_velocity([1.0] * 5)
    with pytest.raises(ValueError, match="finite"):
        lockstep.jog_velocity(velocity(float("nan")))
    start = np.array(lockstep.status().position)
    end = start.copy()
    end[1] += 20.0
    handle = lockstep.move(moves.ramp(start, end, ramp_time=4.0, machine=UNIMATE))
    wait_until(lambda: lockstep.status().mode == Mode.FOLLOW_TRACK, "the move to start")
    lockstep.jog_velocity(velocity(5.0))
    refused = lockstep.wait_event("refused")
    assert "velocity jog" in refused.message and "a move is running" in refused.message
    assert lockstep.wait(handle, timeout=60).complete


def test_a_streamed_velocity_is_taken_as_sent_whatever_the_feed_override(
        lockstep: ControlClient) -> None:
    """The override is the streamer's to apply (a Cartesian servo scales its reference by
    it): at 50 % the one command of the deadman test goes as far as at 100 %."""
    lockstep.feed_override(0.5)
    ticks_pass(lockstep, 10)
    start = lockstep.status().desired[UPDOWN]
    lockstep.jog_velocity(velocity(5.0))
    ticks_pass(lockstep, 2_000)
    travel = lockstep.status().desired[UPDOWN] - start
    assert travel == pytest.approx(5.0 * DEADMAN_S, rel=0.05), travel
