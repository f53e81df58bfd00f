"""Lockstep that steps on demand: a lockstep controller computes as fast as it can while it
has something to step (a move, manual duty, a position jog travelling, a joint swinging to
its hold target, the rig's initialise) and paces at real time while it merely holds
(``hw.backend.StepClock``, ``Controller.idle``), instead of spinning a core at thousands of
ticks a second; after motion it steps on for a settling time first.

The decision is ticked in-process against test_loop.py's scripted backend; the clock on its
own; then a real lockstep control subprocess, holding, is watched against the wall clock.
"""

from __future__ import annotations

import time

import pytest

from control import ControlClient
from control.motion import moves
from control.motion.plan import path_rows
from control.rt import shm
from control.rt.commands import JogPosition, Manual
from control.rt.layout import ESTOP_WORD, Mode
from control.rt.loop import SETTLE_NS, Controller
from hw.backend import StepClock
from tests.control.rt.test_loop import HOME, UNIMATE, ScriptedBackend, controller_on, start_move
from tests.control.rt.test_loop import ticks as step

MS = 1_000_000


@pytest.fixture
def loop() -> tuple[Controller, ScriptedBackend]:
    with controller_on(UNIMATE) as (controller, backend, _):
        yield controller, backend


def test_holding_still_is_no_motion_and_every_kind_of_motion_is(loop) -> None:
    controller, backend = loop
    assert not controller.in_motion()  # holding where it started
    target = list(controller.modes.position)
    target[1] += 3 * UNIMATE.joints[1].tolerance
    controller.modes.hold_at(target)  # as after a move: the joint swings to its target
    step(controller, backend, 1)
    assert controller.in_motion()
    backend.positions[1] = target[1] - 0.5 * UNIMATE.joints[1].tolerance
    controller.encoders.resync(backend, controller.config.period_ns)
    step(controller, backend, 1)
    assert not controller.in_motion()  # inside its settle band: holding at its target
    controller.channel.deliver(Manual((0.0, 20.0, 0.0, 0.0, 0.0, 0.0)))
    step(controller, backend, 2)
    assert controller.modes.mode == Mode.MANUAL_ACTUATE and controller.in_motion()
    controller.channel.deliver(Manual((0.0,) * 6))
    step(controller, backend, 2)
    assert controller.modes.mode == Mode.MANUAL_ACTUATE and not controller.in_motion()
    start = controller.modes.hold_target[0]
    controller.channel.deliver(JogPosition(0, 0.5))
    step(controller, backend, 2)
    assert controller.modes.jog.moving and controller.in_motion()  # the target travels
    for _ in range(2_000):
        step(controller, backend, 1)
        if not controller.modes.jog.moving:
            break
    assert controller.modes.hold_target[0] == pytest.approx(start + 0.5)
    assert not controller.in_motion()  # arrived, inside the band: holding again
    controller.modes.start_initialise(backend.clock.now_ns())
    assert controller.in_motion()
    controller.modes.hold_here()


def test_a_move_is_motion_to_its_end_and_a_latched_estop_is_none(loop) -> None:
    controller, backend = loop
    path = [HOME] * 5
    segment = start_move(controller, path, "path")
    try:
        for _ in range(len(path) - 1):
            step(controller, backend, 1)
            assert controller.modes.move is not None and controller.in_motion()
        step(controller, backend, 1)
        assert controller.modes.settling and controller.in_motion()  # holding its end
        for _ in range(300):
            if controller.modes.move is None:
                break
            step(controller, backend, 1)
        assert controller.modes.move is None and not controller.in_motion()  # in position
    finally:
        shm.release(segment, unlink=True)
    controller.channel.deliver(Manual((30.0,) * 6))
    step(controller, backend, 1)
    assert controller.in_motion()
    controller.client.words[ESTOP_WORD] += 1
    step(controller, backend, 1)
    assert controller.guards.latched and not controller.in_motion()  # every valve closed


def test_idle_comes_a_settling_time_after_the_last_motion(loop) -> None:
    """The arm settles after a move as fast as the loop computes: a command that follows a
    move at once finds it where a real-time controller would have left it, not mid-swing."""
    controller, backend = loop
    assert not controller.idle(SETTLE_NS)  # started at 0: still settling
    assert controller.idle(SETTLE_NS + 1)
    controller.channel.deliver(Manual((0.0, 20.0, 0.0, 0.0, 0.0, 0.0)))
    step(controller, backend, 1)
    moved = SETTLE_NS + 5 * MS
    assert not controller.idle(moved)
    controller.channel.deliver(Manual((0.0,) * 6))
    step(controller, backend, 1)
    assert not controller.idle(moved + SETTLE_NS)
    assert controller.idle(moved + SETTLE_NS + 1)


def test_an_idle_step_clock_waits_out_its_sleep_on_the_wall_clock() -> None:
    clock = StepClock()
    started = time.monotonic_ns()
    clock.sleep_until(60_000 * MS)  # busy: a minute of simulated time at once
    assert clock.now_ns() == 60_000 * MS
    assert time.monotonic_ns() - started < 30_000 * MS
    clock.idle = True
    started = time.monotonic_ns()
    clock.sleep_until(clock.now_ns() + 30 * MS)
    assert time.monotonic_ns() - started >= 30 * MS
    assert clock.now_ns() == 60_030 * MS


def test_a_holding_lockstep_controller_keeps_to_the_wall_clock_and_a_move_does_not_wait(
        lockstep: ControlClient) -> None:
    """Holding, once settled, its simulated time runs no faster than the wall clock (it ran
    3.6 to 26 times faster, on most of a core); a move after it still completes, whole."""
    settled_s = SETTLE_NS / 1e9 + 0.1
    deadline = time.monotonic() + 30
    while lockstep.status().time_s < settled_s:
        assert time.monotonic() < deadline, "the controller's first two seconds never passed"
        time.sleep(0.01)
    before, wall_before = lockstep.status(), time.monotonic()
    time.sleep(1.0)  # the span watched, not a wait for an effect
    after, wall_after = lockstep.status(), time.monotonic()
    simulated = after.time_s - before.time_s
    assert after.mode == Mode.HOLD and not after.moving
    assert 0 < simulated <= wall_after - wall_before + 0.01, (simulated, after.tick - before.tick)
    here = after.position
    path = moves.step(here, "rotate", here[1] + 2.0, duration=2.0, machine=UNIMATE)
    result = lockstep.wait(lockstep.move(path, kind="step"), timeout=60)
    assert result.complete, result.status
    assert path_rows(result.run) == len(path)
