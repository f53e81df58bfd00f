"""The feed rate on its own: it follows the override or a hold no faster than the joints
may accelerate along the path; it says since when a move is held, by a hold or the override
at 0; and the timeline it records stays bounded however often the operator acts."""

from __future__ import annotations

import numpy as np
import pytest

from control.rt.feed import MAX_ENTRIES, SPACING_S, FeedRate
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
    assert feed.rate == 0.25 and feed.changes.entries == [(0.5, 0.25)]


def test_a_hold_still_on_at_the_end_is_recorded_up_to_then() -> None:
    feed = FeedRate(UNIMATE, DT)
    pauses: list[tuple[float, float]] = []
    feed.start_move([], pauses)
    feed.pause(1.0)
    feed.end_move(3.5)
    assert pauses == [(1.0, 2.5)] and not feed.paused


def test_the_override_at_0_holds_the_move_from_when_it_was_set() -> None:
    """An override of 0 holds the move as a feed hold does (the controller ends either after
    max_pause_s): held since it was first set to 0, by whichever came first of it and a hold,
    and no longer once the override is above 0 again."""
    feed = FeedRate(UNIMATE, DT)
    feed.start_move([], [])
    assert feed.held_since is None
    feed.set_override(0.0, 2.0)
    feed.set_override(0.0, 3.0)  # set again: still held since the first
    assert (feed.held_since, feed.held_by) == (2.0, "feed override 0 %")
    feed.pause(4.0)
    assert (feed.held_since, feed.held_by) == (2.0, "feed override 0 %")
    feed.set_override(0.5, 5.0)
    assert (feed.held_since, feed.held_by) == (4.0, "feed hold")
    feed.resume(6.0)
    assert feed.held_since is None
    feed.set_override(0.0, 7.0)
    feed.end_move(8.0)
    feed.start_move([], [])  # a move started at override 0 is held from its start
    assert feed.held_since == 0.0


def test_a_slider_dragged_for_ten_minutes_keeps_a_bounded_true_timeline() -> None:
    """An override change every 10 ms for ten minutes (60,000): the run keeps fewer than
    MAX_ENTRIES, in order, at least 50 ms apart, spanning the move, each one a value the
    override really had, the last the override as last set; a hold key pressed every 20 ms
    likewise keeps a bounded list of holds that covers every hold."""
    feed = FeedRate(UNIMATE, DT)
    changes: list[tuple[float, float]] = []
    pauses: list[tuple[float, float]] = []
    feed.start_move(changes, pauses)
    values = [0.3 + 0.6 * (k % 97) / 96 for k in range(60_000)]
    for k, value in enumerate(values):
        feed.set_override(value, k * 0.01)
    assert len(changes) < MAX_ENTRIES
    times = np.array([t for t, _ in changes])
    assert np.all(np.diff(times) >= SPACING_S - 1e-9)
    assert times[0] == 0.0 and times[-1] > 590.0
    assert {v for _, v in changes} <= set(values) and changes[-1][1] == values[-1]
    for k in range(30_000):
        feed.pause(600.0 + k * 0.02)
        feed.resume(600.0 + k * 0.02 + 0.01)
    assert 0 < len(pauses) < MAX_ENTRIES
    assert pauses[0][0] == 600.0
    assert pauses[-1][0] + pauses[-1][1] == pytest.approx(600.0 + 29_999 * 0.02 + 0.01)
