"""The supervisor on synthetic joints: each case drives one actuator with a duty and a
reading the test dictates, both signs, and checks the verdict and when it comes."""

from __future__ import annotations

import math

import pytest

from control.rt.supervisor import Supervisor
from hw.machine import load_machine
from hw.transmission import output_min_pwm

RIG = load_machine("rig")  # one joint: sampled every tick
UNIMATE = load_machine("unimate2000b")
PERIOD = 1_000_000


def drive(machine, j: int, duty: float, speed: float, *, error: float = math.nan,
          ms: int = 400, desired_speed: float = 0.0, at: float | None = None):
    """Tick a supervisor ``ms`` ms: joint ``j`` at ``duty`` %, its actuator moving at ``speed``
    units/s from ``at`` (default mid-range), its error ``error`` (nan: open loop). The first
    trip and its tick, or None."""
    supervisor = Supervisor(machine, PERIOD)
    n = machine.n_joints
    a = [0.5 * (jt.lower + jt.upper) for jt in machine.joints]
    if at is not None:
        a[j] = at
    duties, velocity = [0.0] * n, [0.0] * n
    duties[j], velocity[j] = duty, desired_speed
    closed = not math.isnan(error)
    for k in range(ms * n):  # one joint sampled per tick
        now = k * PERIOD
        a[j] += speed * PERIOD / 1e9
        desired = [q + (error if i == j and closed else 0.0) for i, q in enumerate(a)]
        trip = supervisor.sample(now, a, a, desired, velocity, duties, closed)
        if trip is not None:
            return trip, k / n
    return None


def nominal(joint, u: float) -> float:
    p = output_min_pwm(joint)[0 if u > 0 else 1]
    return math.copysign(joint.max_speed * (abs(u) - p) / (100 - p), u)


@pytest.mark.parametrize("duty", [60.0, -60.0])
def test_a_joint_moving_as_its_duty_says_is_never_faulted_however_far_behind(duty) -> None:
    for machine, j in ((RIG, 0), (UNIMATE, 1), (UNIMATE, 4)):
        joint = machine.joints[j]
        v = nominal(joint, duty)
        assert drive(machine, j, duty, 0.4 * v, error=math.copysign(100.0, duty)) is None
        assert drive(machine, j, duty, 0.4 * v) is None  # open loop


@pytest.mark.parametrize("duty", [60.0, -60.0])
def test_a_jammed_valve_trips_within_the_window(duty) -> None:
    """The valve open, the actuator slower than a quarter of what it should be: following
    error once the window has been seen (within 250 ms, the issue's bound)."""
    joint = UNIMATE.joints[1]
    trip, at_ms = drive(UNIMATE, 1, duty, 0.1 * nominal(joint, duty),
                        error=math.copysign(10.0, duty))
    assert not trip.feedback and trip.joint == 1 and "should have moved it" in trip.message
    assert at_ms <= 250


@pytest.mark.parametrize("duty", [60.0, -60.0])
def test_a_reading_that_never_moves_under_an_open_valve_is_a_feedback_fault(duty) -> None:
    trip, at_ms = drive(RIG, 0, duty, 0.0)
    assert trip.feedback and "has not moved" in trip.message and at_ms <= 250


@pytest.mark.parametrize("duty", [60.0, -60.0])
def test_a_reading_that_moves_against_its_valve_is_a_feedback_fault(duty) -> None:
    joint = UNIMATE.joints[5]
    trip, _ = drive(UNIMATE, 5, duty, -0.5 * nominal(joint, duty))
    assert trip.feedback and "the other way" in trip.message


def test_a_joint_with_no_duty_and_an_error_that_does_not_close_trips() -> None:
    trip, at_ms = drive(UNIMATE, 3, 0.0, 0.0, error=20.0)
    assert not trip.feedback and "its duty has been zero" in trip.message and at_ms <= 250


def test_an_error_inside_the_limit_is_not_judged() -> None:
    joint = UNIMATE.joints[2]
    assert drive(UNIMATE, 2, 0.0, 0.0, error=0.9 * joint.min_following_error) is None


def test_the_limit_grows_with_the_desired_speed_as_linuxcncs_ferror() -> None:
    joint = UNIMATE.joints[2]
    error = 0.5 * joint.following_error  # beyond MIN_FERROR, inside FERROR at max speed
    assert drive(UNIMATE, 2, 0.0, 0.0, error=error) is not None
    assert drive(UNIMATE, 2, 0.0, 0.0, error=error, desired_speed=joint.max_speed) is None


def test_a_valve_under_its_minimum_pwm_is_not_expected_to_move_anything() -> None:
    joint = UNIMATE.joints[0]
    assert drive(UNIMATE, 0, 0.9 * output_min_pwm(joint)[0], 0.0) is None


@pytest.mark.parametrize("closed", [True, False])
def test_a_joint_resting_on_its_limit_with_its_valve_pushing_there_is_no_feedback_fault(
        closed: bool) -> None:
    """Issue 25: a target on 30.00° left Up/Down a count short, on its stop, the integrator
    opening the valve against it: that was called a frozen encoder. Resting on the limit the
    valve pushes toward, it is not; pushing away from it, or still anywhere else, it is."""
    joint = UNIMATE.joints[2]
    count = abs(joint.encoder.gradient)
    error = 0.5 * count if closed else math.nan
    for duty, at in ((60.0, joint.upper - 0.45 * count), (-60.0, joint.lower + 0.3 * count)):
        assert drive(UNIMATE, 2, duty, 0.0, at=at, error=math.copysign(error, duty)) is None
        trip, _ = drive(UNIMATE, 2, -duty, 0.0, at=at, error=math.copysign(error, -duty))
        assert trip.feedback and "has not moved" in trip.message
    trip, _ = drive(UNIMATE, 2, 60.0, 0.0, at=joint.upper - 2 * joint.goal_tolerance,
                    error=error)
    assert trip.feedback and "has not moved" in trip.message


def test_a_joint_pushed_onto_its_limit_past_its_target_is_tripped_as_held_wrong() -> None:
    """On the stop with the valve pushing into it while the target is 0.5° back inside (a
    law whose integral wound up on the way holds it there): not a frozen encoder, and not
    let be either."""
    joint = UNIMATE.joints[2]
    at = joint.upper - 0.45 * abs(joint.encoder.gradient)
    trip, _ = drive(UNIMATE, 2, 60.0, 0.0, at=at, error=-joint.goal_tolerance)
    assert not trip.feedback and "onto its limit stop" in trip.message
    assert "0.50° past its target" in trip.message
