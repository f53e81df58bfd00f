"""A joint driven into its limit, and a joint that falls too far behind (following error):
motion stops on that joint, with a message naming it, and the run up to then is on disk.

Lockstep simulator: the real control process, computing as fast as it can, so
a few seconds of motion take a fraction of that.
"""

from __future__ import annotations

import dataclasses
import time

import numpy as np

from control import Mode
from control.motion import moves
from control.recorder import as_written, load_run
from hw.machine import load_machine

UNIMATE = load_machine("unimate2000b")
INOUT, ROTATE, UPDOWN, BEND = (UNIMATE.joint_index(k) for k in ("inout", "rotate", "updown",
                                                                 "bend"))
UPDOWN_STOP = UNIMATE.joints[UPDOWN].upper - 2 * abs(UNIMATE.joints[UPDOWN].encoder.gradient)


def test_a_jogged_joint_stops_at_its_limit_and_only_that_joint(controller, until) -> None:
    """Manual actuation drives Up/Down up and Rotate round: Up/Down's valve closes at its
    30° limit with a fault naming it, while Rotate's valve stays open and Rotate keeps
    moving: the limit stops the joint, not the robot."""
    client = controller(lockstep=True)
    duty = [0.0] * 6
    duty[UPDOWN], duty[ROTATE] = 60.0, 30.0
    client.jog(duty)
    fault = client.wait_event("fault", 30.0, lambda e: e.payload["kind"] == "limit")
    assert fault.payload["joint"] == UPDOWN
    assert fault.message.startswith("Up/Down at ")
    assert fault.message.endswith("reached its limit -27…30°: its valve is closed toward it")
    until(lambda: client.status().valve[UPDOWN] == 0.0, 2.0, "Up/Down's valve to close")
    status = client.status()
    assert status.mode == Mode.MANUAL_ACTUATE and status.valve[ROTATE] != 0.0
    rotate = status.position[ROTATE]
    until(lambda: client.status().position[ROTATE] > rotate + 1.0, 5.0, "Rotate to go on")
    assert client.status().position[UPDOWN] <= UNIMATE.joints[UPDOWN].upper


def test_a_profile_into_a_limit_records_the_duty_actually_sent(controller) -> None:
    """tracking_actuate plays 60 % on Up/Down into its limit: the move completes, the fault
    names Up/Down, and the saved run (used for identification) shows 0 % on Up/Down from
    the tick it stopped, because that is what the valve got."""
    client = controller(lockstep=True)
    profile = np.zeros((3000, 6))
    profile[:, UPDOWN], profile[:, ROTATE] = 60.0, 30.0
    result = client.wait(client.actuate(profile), timeout=60)
    assert result.complete, result.status
    fault = client.wait_event("fault", 5.0, lambda e: e.payload["kind"] == "limit")
    assert fault.payload["joint"] == UPDOWN
    run = load_run(result.files.json)
    at_limit = np.flatnonzero(run.actual[:, UPDOWN] >= UPDOWN_STOP)
    assert len(at_limit) > 100
    assert np.all(run.duty[at_limit, ROTATE] == 30.0)
    assert np.all(run.duty[at_limit, UPDOWN] == 0.0), "the run records duty the valve never got"


def test_a_following_error_aborts_the_move_and_holds_where_the_joint_is(controller,
                                                                       measured) -> None:
    """In/Out's valve jams at 30 % of its opening mid-step: its duty saturates and In/Out
    crawls, so the move is aborted with a following-error fault naming In/Out within the
    supervisor's window (measured), the run up to the abort is on disk, and the robot holds
    where In/Out got to, not at the step's target (where the jammed valve may then fail to
    hold it, a feedback fault). Jammed shut, nothing would move at all: that is a feedback
    fault at once (test_feedback.py)."""
    client = controller(lockstep=True)
    start = np.array(client.status().position)
    path = moves.step(start, INOUT, start[INOUT] + 400.0, duration=4.0, machine=UNIMATE)
    handle = client.move(path, kind="step")
    client.inject("jam_valve", INOUT, 0.7)
    result = client.wait(handle, timeout=60)
    assert result.status.startswith("fault: following error: In/Out is "), result.status
    assert "a jammed valve" in result.status and result.status.endswith("; holding")
    fault = client.wait_event("fault", 5.0, lambda e: e.payload["kind"] == "following_error")
    assert fault.payload["joint"] == INOUT
    saved = load_run(result.files.json)
    assert saved == as_written(result.run) and 0 < saved.samples < len(path)
    np.testing.assert_allclose(result.run.desired, path[:saved.samples], atol=1e-9)
    moving = np.flatnonzero(saved.desired[:, INOUT] != start[INOUT])[0]
    trip_ms = measured("jammed_valve_trip_ms", (saved.samples - moving) * client.dt * 1e3, "ms")
    assert trip_ms <= 250
    status = client.status()
    assert status.mode == Mode.HOLD and not status.moving
    assert abs(status.desired[INOUT] - saved.actual[-1, INOUT]) < 5.0
    # a valve that opens to 30 % cannot hold either: the small duty of hold leaves it shut
    assert not status.estop or status.fault.startswith("feedback fault: In/Out's valve")


def test_a_joint_that_cannot_hold_gets_its_valves_closed(controller, until, measured) -> None:
    """Bend stops responding while holding (its hold gains zeroed: the gain check refuses
    such a set, so the test overrides it) and its target is jogged 40° away: within 250 ms
    of Bend falling past its following-error limit (the controller's clock, from its
    status) the controller closes every valve and latches, with a fault naming Bend."""
    client = controller()
    hold = UNIMATE.hold
    dead_bend = dataclasses.replace(
        hold, name="dead_bend",
        kp=tuple((0.0,) if j == BEND else k for j, k in enumerate(hold.kp)),
        ki=tuple(0.0 if j == BEND else k for j, k in enumerate(hold.ki)))
    client.set_coefficients("hold", dead_bend, override="test: Bend made unable to hold")
    client.jog_position(BEND, 40.0)  # the target travels at Bend's jog speed; Bend stays
    bend = UNIMATE.joints[BEND]  # the limit at the jog's speed (LinuxCNC's, supervisor.md)
    limit = max(bend.min_following_error, bend.following_error * bend.jog_speed / bend.max_speed)
    behind_at = None  # the controller's time when Bend first fell past its limit
    deadline = time.monotonic() + 10.0
    while not (status := client.status()).estop:
        if behind_at is None and abs(status.desired[BEND] - status.position[BEND]) > limit:
            behind_at = status.time_s
        assert time.monotonic() < deadline, "no latch"
    trip_ms = measured("zeroed_hold_gains_trip_ms", (status.time_s - behind_at) * 1e3, "ms")
    assert trip_ms <= 250 + 20  # the status is polled: allow a few ticks of lag
    fault = client.wait_event("fault", 30.0, lambda e: e.payload["kind"] == "following_error")
    assert fault.payload["joint"] == BEND
    assert fault.message.startswith("following error: Bend is ")
    assert "while holding; valves closed: check the joint, then reset" in fault.message
    until(lambda: client.status().estop, 2.0, "the latch")
    status = client.status()
    assert status.valve == (0.0,) * 6 and status.fault.startswith("following error: Bend")


def test_steps_of_any_size_inside_the_limits_complete(controller) -> None:
    """Each joint steps across 90 % of its range and back to the middle: errors far beyond
    any following-error distance, closed at the speed the saturated valve gives, so every
    step completes (the rule for steps, docs/supervisor.md). Each step's path lasts the
    longest crossing at full duty and 2 s more."""
    client = controller(lockstep=True)
    for j, joint in enumerate(UNIMATE.joints):
        here = np.array(client.status().position)
        low = joint.lower + 0.05 * (joint.upper - joint.lower)
        high = joint.upper - 0.05 * (joint.upper - joint.lower)
        duration = 0.9 * (joint.upper - joint.lower) / joint.full_duty_speed + 2.0
        for target in (low, high, here[j]):
            path = moves.step(here, j, target, duration=duration, machine=UNIMATE)
            result = client.wait(client.move(path, kind="step"), timeout=120)
            assert result.complete, (joint.name, target, result.status)
            here = np.array(client.status().position)
            assert abs(here[j] - target) < 5 * joint.tolerance, (joint.name, here[j], target)
