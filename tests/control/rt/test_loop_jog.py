"""The streamed velocity jog in the loop, ticked in-process (``tests/control/rt/test_loop.py``'s
scripted backend, its arm following the hold target exactly): the deadman counts the loop's
ticks, a renewed stream keeps moving, taken as sent whatever the feed override, and a record
that fails its checks, or comes while latched, moves nothing."""

from __future__ import annotations

import pytest

from control.rt.commands import FeedOverride, JogVelocity
from control.rt.jog import DEADMAN_S
from control.rt.layout import Mode
from tests.control.rt.test_loop import (
    UNIMATE,
    _bypassing_checks,
    controller_on,
    events,
    ticks,
)

UPDOWN = 2
DT = 0.001


@pytest.fixture
def rig():
    with controller_on(UNIMATE) as parts:
        yield parts


def follow(controller, backend, n: int) -> list[float]:
    """Tick ``n`` times, the arm where the hold target is; Up/Down's target each tick."""
    seen = []
    for _ in range(n):
        backend.positions[:] = controller.modes.hold_target
        ticks(controller, backend, 1)
        seen.append(controller.modes.hold_target[UPDOWN])
    return seen


def velocity(v: float) -> JogVelocity:
    command = [0.0] * UNIMATE.n_joints
    command[UPDOWN] = v
    return JogVelocity(tuple(command))


def test_the_deadman_counts_the_loops_ticks(rig) -> None:
    controller, backend, client = rig
    start = controller.modes.hold_target[UPDOWN]
    controller.channel.deliver(velocity(5.0))
    seen = follow(controller, backend, 1_000)
    deadman = round(DEADMAN_S / DT)
    cruising = (seen[deadman - 2] - seen[deadman - 3]) / DT
    assert cruising == pytest.approx(5.0)
    assert seen[-1] - start == pytest.approx(5.0 * DEADMAN_S, rel=0.01)
    assert seen[-1] == seen[-300] and not controller.modes.jog.moving
    assert controller.modes.mode == Mode.HOLD and events(client) == []


def test_a_stream_renewed_within_the_deadman_keeps_moving(rig) -> None:
    controller, backend, _ = rig
    start = controller.modes.hold_target[UPDOWN]
    for _ in range(10):  # every 100 ticks, 1 s in all
        controller.channel.deliver(velocity(4.0))
        follow(controller, backend, 100)
    assert controller.modes.jog.velocity[UPDOWN] == pytest.approx(4.0)
    travelled = controller.modes.hold_target[UPDOWN] - start
    assert travelled == pytest.approx(4.0 * 1.0 - 4.0 ** 2 / (2 * UNIMATE.joints[UPDOWN].max_accel),
                                      rel=0.01)


def test_the_stream_is_taken_as_sent_whatever_the_feed_override(rig) -> None:
    controller, backend, _ = rig
    controller.channel.deliver(FeedOverride(0.5))
    ticks(controller, backend, 1)
    for _ in range(5):
        controller.channel.deliver(velocity(4.0))
        follow(controller, backend, 100)
    assert controller.modes.jog.velocity[UPDOWN] == pytest.approx(4.0)


@pytest.mark.parametrize("command", [
    _bypassing_checks(JogVelocity, velocity=(1.0,) * 5),
    _bypassing_checks(JogVelocity, velocity=(0.0, 0.0, float("nan"), 0.0, 0.0, 0.0)),
    _bypassing_checks(JogVelocity, velocity=[1.0] * 6),
], ids=["five velocities", "nan", "a list"])
def test_a_velocity_jog_that_fails_its_checks_on_arrival_is_refused_and_moves_nothing(
        rig, command: object) -> None:
    controller, backend, client = rig
    before = list(controller.modes.hold_target)
    controller.channel.deliver(command)
    follow(controller, backend, 200)
    (refused,) = [p for name, p in events(client) if name == "refused"]
    assert refused["reason"], refused
    assert controller.modes.hold_target == before


def test_a_velocity_jog_while_latched_is_refused_and_zeros_without_a_stream_say_nothing(
        rig) -> None:
    controller, backend, client = rig
    controller.channel.deliver(velocity(0.0))  # nothing streamed: nothing to stop
    ticks(controller, backend, 2)
    assert events(client) == []
    controller.latch_estop("test")
    events(client)
    controller.channel.deliver(velocity(5.0))
    ticks(controller, backend, 200)
    (refused,) = [p for name, p in events(client) if name == "refused"]
    assert "E-stop latched" in refused["reason"]
    assert not controller.modes.jog.moving
