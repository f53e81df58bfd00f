"""The feed rate on its own: it follows the override or a hold no faster than the joints
may accelerate along the path."""

from __future__ import annotations

import numpy as np
import pytest

from control.feed import FeedRate
from hw.machine import load_machine

UNIMATE = load_machine("unimate2000b")
DT = UNIMATE.sample_time_s
ROTATE = 1


def test_the_rate_changes_within_half_the_joints_acceleration() -> None:
    feed = FeedRate(UNIMATE, DT)
    feed.start_move([], [])
    velocity = [0.0, UNIMATE.joints[ROTATE].max_speed, 0.0, 0.0, 0.0, 0.0]
    feed.pause(0.0)
    rates = []
    while feed.rate > 0.0:
        feed.advance(velocity)
        rates.append(feed.rate)
    accel = np.abs(np.diff([1.0, *rates])) / DT * velocity[ROTATE]
    assert accel.max() <= UNIMATE.joints[ROTATE].max_accel / 2 * (1 + 1e-9)
    stopping = len(rates) * DT
    expected = velocity[ROTATE] / (UNIMATE.joints[ROTATE].max_accel / 2)
    assert stopping == pytest.approx(expected, abs=2 * DT)


def test_no_path_velocity_changes_the_rate_at_once() -> None:
    feed = FeedRate(UNIMATE, DT)
    feed.start_move([], [])
    feed.set_override(0.25, 0.5)
    feed.advance([0.0] * 6)
    assert feed.rate == 0.25 and feed.changes == [(0.5, 0.25)]


def test_a_hold_still_on_at_the_end_is_recorded_up_to_then() -> None:
    feed = FeedRate(UNIMATE, DT)
    pauses: list[tuple[float, float]] = []
    feed.start_move([], pauses)
    feed.pause(1.0)
    feed.end_move(3.5)
    assert pauses == [(1.0, 2.5)] and not feed.paused
