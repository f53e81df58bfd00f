"""A move ends in position (issue 24): on the real control process and the simulated Unimate,
``complete`` only once every joint is within its goal tolerance of the path's end and
stopped, ``unsettled`` (naming the joint, still holding) when that does not come within the
machine's goal_time, SETTLING on the status in between; a Cartesian jog after a fast move
starts from where the arm was commanded, not from where it swings."""

from __future__ import annotations

import re
import time
from dataclasses import replace

import numpy as np
import pytest

from control import ControlClient, Mode
from control.motion.plan import path_rows
from control.motion.robot_model import unimate_model
from control.recorder import load_run
from hw.machine import GOAL_WINDOW_S, load_machine

UNIMATE = load_machine("unimate2000b")
MODEL = unimate_model(UNIMATE)
GOAL = np.array([j.goal_tolerance for j in UNIMATE.joints])
STOPPED = np.array([j.stopped_speed for j in UNIMATE.joints])
START = np.array([1300.0, 10.0, 5.0, 20.0, 30.0, 10.0])


def in_position_at_the_end(run, goal: np.ndarray) -> None:
    """The run's last 100 ms: every joint within its goal tolerance of ``goal``, and slower
    than its stopped speed over the window."""
    rows = round(GOAL_WINDOW_S / run.sample_time_s)
    last = run.actual[-rows - 1:]
    assert np.all(np.abs(last - goal) <= GOAL + 1e-9), np.abs(last - goal).max(axis=0)
    speed = np.abs(last[-1] - last[0]) / (run.t[-1] - run.t[-rows - 1])
    assert np.all(speed <= STOPPED), speed


def watch(client: ControlClient, handle) -> list:
    """Every status of ``handle``'s move seen until it ends (polled as fast as it goes)."""
    seen = []
    while not handle.done.is_set():
        status = client.status()
        if status.move_id == handle.move_id:
            seen.append(status)
        time.sleep(0.0005)
    return seen


def test_a_go_to_is_complete_only_in_position_and_settling_is_seen_after_its_path(
        lockstep: ControlClient) -> None:
    """The operator's move: In/Out +50 mm and Bend +10° at half speed. The old controller said
    complete at the path's last row with Bend 3.8° off and swinging; now complete means every
    joint is in position in the run's last rows, or the move says which joint is not."""
    here = np.array(lockstep.status().position)
    target = here.copy()
    target[0] += 50.0
    target[3] += 10.0
    handle = lockstep.go_to(target, speed=0.5)
    seen = watch(lockstep, handle)
    result = lockstep.wait(handle, timeout=60)
    settling = [s for s in seen if s.settling]
    assert settling, "no status with SETTLING between the path's end and the move's end"
    assert all(s.move_done == s.move_total == handle.samples and s.mode == Mode.HOLD
               for s in settling)  # the path over: it holds the end
    np.testing.assert_allclose(settling[-1].desired, target, atol=1e-9)
    run = result.run
    assert path_rows(run) == handle.samples < run.samples  # the settle is in the run
    settle = result.settle
    assert load_run(result.files.json).meta["settle"] == settle  # the run's JSON has it
    if result.complete:
        in_position_at_the_end(run, target)
        assert all(t is not None and t <= settle["goal_time_s"] for t in settle["settle_s"])
    else:
        assert result.unsettled, result.status
        out = [j.name for j, t in zip(UNIMATE.joints, settle["settle_s"], strict=True)
               if t is None]
        assert out and all(name in result.status for name in out), (out, result.status)
        for j in (UNIMATE.joint_index(name) for name in out):
            error = abs(settle["goal_error"][j])
            assert f"{UNIMATE.joints[j].name} {error:.2f}°" in result.status or \
                error <= GOAL[j], result.status
        assert run.t[-1] - settle["path_end_s"] == pytest.approx(settle["goal_time_s"], abs=0.01)


def test_a_move_that_cannot_settle_ends_unsettled_naming_the_joint_and_holds_its_end(
        lockstep: ControlClient) -> None:
    """Hold gains zeroed and a step of Rotate in the path's last row: nothing brings Rotate to
    the end, so after goal_time the move ends unsettled, naming Rotate and its error, and the
    controller holds the end (not where Rotate is)."""
    zero = replace(UNIMATE.hold, name="zero", kp=((0.0,),) * 6, ki=(0.0,) * 6,
                   kd=(0.0,) * 6, w=((),) * 6)
    lockstep.set_coefficients("hold", zero, override="test: a joint that cannot settle")
    here = np.array(lockstep.status().position)
    path = np.tile(here, (200, 1))
    path[-1, 1] += 2.0
    handle = lockstep.move(path, kind="step")
    seen = watch(lockstep, handle)
    result = lockstep.wait(handle, timeout=60)
    assert result.unsettled and not result.complete, result.status
    assert re.fullmatch(r"unsettled: Rotate [12]\.\d\d° from its goal after 2 s",
                        result.status), result.status
    assert [s for s in seen if s.settling]
    settle = result.settle
    assert settle["settle_s"][1] is None and abs(settle["goal_error"][1]) > 1.9
    assert sum(t is None for t in settle["settle_s"]) == 1  # the others came in position
    status = lockstep.status()
    assert status.mode == Mode.HOLD and not status.moving and not status.settling
    assert status.desired[1] == pytest.approx(path[-1, 1], abs=1e-9)  # it holds the end
    lockstep.set_coefficients("hold", UNIMATE.hold)


def test_a_cartesian_jog_right_after_a_fast_go_to_ends_on_its_line(
        lockstep: ControlClient) -> None:
    """The operator's jog 0.85 s after a go_to began started from the swinging pose and ended
    36 mm off in z. Now a step waits for the move in progress to end and its line starts
    where the arm was commanded: its end pose is the go_to's target pose plus the
    displacement (within 1 mm), whatever the wrist does."""
    lockstep.wait(lockstep.go_to(START, speed=1.0), timeout=60)
    target = START.copy()
    target[0] += 50.0
    target[3] += 10.0
    go_to = lockstep.go_to(target, speed=1.0)
    while lockstep.status().move_id != go_to.move_id:  # the go_to is under way
        time.sleep(0.0005)
    asked = MODEL.pose(target) + np.array([0.0, 0.0, -30.0, 0.0, 0.0, 0.0])
    handle = lockstep.jog_cartesian([0.0, 0.0, -30.0, 0.0, 0.0, 0.0])
    np.testing.assert_allclose(handle.meta["end_pose"][:3], asked[:3], atol=1.0)
    ended = lockstep.wait(go_to, timeout=30).status  # before the jog, not superseded by it
    assert ended.startswith(("complete", "unsettled")), ended
    result = lockstep.wait(handle, timeout=60)
    assert result.status.startswith(("complete", "unsettled")), result.status
    end = MODEL.pose(result.run.desired[path_rows(result.run) - 1])
    np.testing.assert_allclose(end[:3], asked[:3], atol=1.0)
