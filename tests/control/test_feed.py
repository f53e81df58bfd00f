"""Feed override and feed hold, in the controller: the path's time is scaled, so a move at
50 % takes twice as long on the same path, and a hold decelerates along the path and
resumes with no step."""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from control import ControlClient, Mode
from control.motion import form_plans, moves
from control.motion.plan import path_rows
from control.recorder import Run, json_numbers, load_run
from control.rt.feed import MAX_ENTRIES, SPACING_S
from hw.machine import load_machine

UNIMATE = load_machine("unimate2000b")
DT = UNIMATE.sample_time_s
ROTATE = 1
BATCH = 32  # commands sent before waiting for the controller to take them


def wait_until(predicate: Callable[[], bool], what: str, timeout: float = 60.0) -> None:
    deadline = time.monotonic() + timeout
    while not predicate():
        assert time.monotonic() < deadline, f"timed out waiting for {what}"
        time.sleep(0.002)


def ramp_on_rotate(client: ControlClient, change: float = 40.0) -> np.ndarray:
    start = np.array(client.status().position)
    end = start.copy()
    end[ROTATE] += change
    return moves.ramp(start, end, ramp_time=2.0, machine=UNIMATE)


def on_path(run: Run) -> Run:
    """The rows of ``run`` that followed its path, the settle after it left out."""
    k = path_rows(run)
    return replace(run, t=run.t[:k], desired=run.desired[:k], actual=run.actual[:k],
                   duty=run.duty[:k])


def per_tick_change(run: Run) -> np.ndarray:
    """The desired position's largest change per controller tick between recorded rows."""
    ticks = np.maximum(np.round(np.diff(run.t) / run.sample_time_s), 1.0)
    return np.abs(np.diff(run.desired[:, ROTATE])) / ticks


def tracking_rms(run: Run) -> float:
    error = run.desired[:, ROTATE] - run.actual[:, ROTATE]
    return float(np.sqrt(np.mean(error ** 2)))


def test_a_path_at_half_feed_takes_twice_as_long_on_the_same_path(
        lockstep: ControlClient) -> None:
    path = ramp_on_rotate(lockstep)
    full = lockstep.wait(lockstep.move(path, kind="ramp"), timeout=60)
    back = lockstep.wait(lockstep.go_to(path[0]), timeout=60)
    assert full.complete and back.complete
    lockstep.feed_override(0.5)
    wait_until(lambda: lockstep.status().feed_override == 0.5, "the override")
    half = lockstep.wait(lockstep.move(path, kind="ramp"), timeout=60)
    assert half.complete, half.status
    full, half = replace(full, run=on_path(full.run)), replace(half, run=on_path(half.run))
    duration_full, duration_half = full.run.t[-1], half.run.t[-1]
    assert duration_half == pytest.approx(2 * duration_full, rel=0.01)
    # it followed the same path, one row every other tick, and no worse
    np.testing.assert_allclose(half.run.desired, path, atol=1e-9)
    assert tracking_rms(half.run) <= tracking_rms(full.run) * 1.05
    assert per_tick_change(half.run).max() <= per_tick_change(full.run).max() / 2 * 1.001
    assert load_run(half.files.json).meta["feed"] == [[0.0, 0.5]]  # the run on disk says so
    assert lockstep.status().feed_override == 0.5  # it stays for the moves after


def test_an_override_set_mid_move_slows_the_rest_of_it(lockstep: ControlClient) -> None:
    """50 % set a tenth of the way into a ramp at full feed: the rest takes twice as long
    (before, a move begun at 100 % kept its fast path and ignored the change)."""
    path = ramp_on_rotate(lockstep)
    handle = lockstep.move(path, kind="ramp")
    wait_until(lambda: lockstep.status().move_done > len(path) // 10, "a tenth of the ramp")
    lockstep.feed_override(0.5)
    result = lockstep.wait(handle, timeout=60)
    assert result.complete, result.status
    (set_at, value), = result.run.meta["feed"]
    rest = (len(path) - 1) * DT - set_at  # of the path's time, after the change
    assert value == 0.5 and on_path(result.run).t[-1] - set_at == pytest.approx(2 * rest,
                                                                             rel=0.02)


def test_pause_decelerates_along_the_path_and_resume_has_no_step(
        lockstep: ControlClient) -> None:
    path = ramp_on_rotate(lockstep, change=60.0)
    handle = lockstep.move(path, kind="ramp")
    wait_until(lambda: lockstep.status().move_done > len(path) // 2, "the middle of the ramp")
    lockstep.pause()
    wait_until(lambda: lockstep.status().feed_rate == 0.0, "the feed hold")
    status = lockstep.status()
    assert status.paused and status.moving and status.mode == Mode.FOLLOW_TRACK
    held_at, held_from = status.move_done, status.time_s
    # held longer than the supervisor's window: still following, nothing tripped
    wait_until(lambda: lockstep.status().time_s > held_from + 1.0, "a second of hold")
    status = lockstep.status()
    assert status.move_done == held_at and not status.estop and status.moving
    lockstep.resume()
    result = lockstep.wait(handle, timeout=60)
    assert result.complete, result.status
    moving = per_tick_change(result.run)
    steady = np.abs(np.diff(path[:, ROTATE])).max()
    assert moving.max() <= steady * 1.001, "the desired position stepped"
    (paused_at, length), = result.run.meta["pauses"]
    assert length >= 1.0 and 0 < paused_at < result.run.t[-1]
    np.testing.assert_allclose(result.run.desired[-1], path[-1], atol=1e-9)


def test_an_estop_during_a_feed_hold_ends_the_move(lockstep: ControlClient) -> None:
    path = ramp_on_rotate(lockstep)
    handle = lockstep.move(path, kind="ramp")
    wait_until(lambda: lockstep.status().move_done > 100, "the ramp under way")
    lockstep.pause()
    wait_until(lambda: lockstep.status().paused, "the feed hold")
    lockstep.estop()
    result = lockstep.wait(handle, timeout=60)
    assert not result.complete and "E-stop" in result.status
    assert lockstep.status().estop and not lockstep.status().paused


def test_a_hold_past_max_pause_ends_the_move_holding(tmp_path: Path) -> None:
    text = (Path(__file__).parents[2] / "hw/machines/unimate2000b.toml").read_text()
    machine = tmp_path / "short_pause.toml"
    machine.write_text(text + "\n[supervisor]\nmax_pause_s = 1\n")
    with ControlClient(machine, lockstep=True, data_dir=tmp_path,
                       heartbeat_timeout_s=3.0) as client:
        path = ramp_on_rotate(client)
        handle = client.move(path, kind="ramp")
        wait_until(lambda: client.status().move_done > 100, "the ramp under way")
        client.pause()
        result = client.wait(handle, timeout=60)
        assert not result.complete and "held longer than 1 s" in result.status
        assert client.status().mode == Mode.HOLD and not client.status().estop


def test_an_override_of_0_past_max_pause_ends_the_move_holding(tmp_path: Path) -> None:
    """feed_override(0) mid-move holds it as a feed hold does, and like one it is ended after
    max_pause_s (1 s in this machine file), saying why; before, it held for ever."""
    text = (Path(__file__).parents[2] / "hw/machines/unimate2000b.toml").read_text()
    machine = tmp_path / "short_pause.toml"
    machine.write_text(text + "\n[supervisor]\nmax_pause_s = 1\n")
    with ControlClient(machine, lockstep=True, data_dir=tmp_path,
                       heartbeat_timeout_s=3.0) as client:
        path = ramp_on_rotate(client)
        handle = client.move(path, kind="ramp")
        wait_until(lambda: client.status().move_done > 100, "the ramp under way")
        set_at = client.status().time_s
        client.feed_override(0.0)
        wait_until(lambda: client.status().feed_rate == 0.0, "the move held")
        held_at = client.status().move_done
        result = client.wait(handle, timeout=60)
        assert not result.complete
        assert result.status == ("fault: feed override 0 %: the move was held longer than "
                                 "1 s; ended, holding"), result.status
        status = client.status()
        assert status.mode == Mode.HOLD and not status.estop
        assert status.time_s - set_at > 1.0  # the controller's time: not before max_pause_s
        assert result.run.samples == held_at < len(path)  # held still until it was ended


def test_thousands_of_feed_changes_keep_a_bounded_timeline(lockstep: ControlClient) -> None:
    """A slider dragged hard: 5,000 override changes during one move, five times the
    MAX_ENTRIES a timeline keeps (20,000 took 2.9 s and guarded no more). The run's JSON keeps
    at most MAX_ENTRIES of them, at least 50 ms of the move apart, in order, and ending on
    the override as last set; before, it kept every one."""
    start = np.array(lockstep.status().position)
    end = start.copy()
    end[ROTATE] += 30.0  # 5 s at full feed: left over after the changes, the lockstep's time
    path = moves.ramp(start, end, ramp_time=5.0, machine=UNIMATE)
    handle = lockstep.move(path, kind="ramp")
    wait_until(lambda: lockstep.status().move_done > 100, "the ramp under way")
    # each one new; so slow that the ramp lasts hours of the controller's time meanwhile
    changes = 5 * MAX_ENTRIES
    values = [0.001 + 0.001 * k / changes for k in range(changes)]
    for k, value in enumerate(values):
        lockstep.feed_override(value)
        if k % BATCH == BATCH - 1:  # the client queues a few dozen commands, no more
            wait_until(lambda v=value: lockstep.status().feed_override == v, "the override")
    lockstep.feed_override(1.0)
    result = lockstep.wait(handle, timeout=120)
    assert result.complete, result.status  # every change arrived during the move
    feed = load_run(result.files.json).meta["feed"]
    assert 2 <= len(feed) < MAX_ENTRIES, len(feed)
    times = np.array([t for t, _ in feed])
    assert np.all(np.diff(times) >= SPACING_S - 1e-9)
    assert {v for _, v in feed[:-1]} <= set(json_numbers(values)) and feed[-1][1] == 1.0


def test_pause_without_a_move_is_refused(lockstep: ControlClient) -> None:
    lockstep.pause()
    event = lockstep.wait_event("refused", timeout=10)
    assert "no move is running" in event.message


@pytest.mark.parametrize("value", [-0.1, 1.5, float("nan")])
def test_an_override_outside_0_to_1_is_refused_and_nothing_sent(
        lockstep: ControlClient, value: float) -> None:
    with pytest.raises(ValueError, match="feed override"):
        lockstep.feed_override(value)
    assert lockstep.status().feed_override == 1.0


# -- every kind of move: the override changed mid-move changes its speed (issue 25 item 1) ------

START = np.array([1500.0, 0.0, 5.0, 20.0, 30.0, 10.0])
TOLERANCE = np.array([j.tolerance for j in UNIMATE.joints])
MAX_ACCEL = np.array([j.max_accel for j in UNIMATE.joints])


def _moved(here: np.ndarray, joint: int, change: float) -> np.ndarray:
    q = here.copy()
    q[joint] += change
    return q


def _tool(q: np.ndarray) -> np.ndarray:
    from control.motion.robot_model import unimate_model

    return unimate_model(UNIMATE).forward(q)[:3, 3]


KINDS = {  # each starts at rest at START and runs 3 s or more
    "path": lambda c, q: c.move(moves.ramp(q, _moved(q, ROTATE, 40.0), 3.0, machine=UNIMATE)),
    "ramp": lambda c, q: c.run(form_plans.ramp(UNIMATE, q, ROTATE, q[ROTATE] - 40.0, 3.0,
                                               dt=DT)),
    "sine": lambda c, q: c.run(form_plans.sine(UNIMATE, q, ROTATE, q[ROTATE] + 30.0, 3.0, 4.0,
                                               dt=DT)),
    "go_to": lambda c, q: c.go_to(_moved(_moved(q, ROTATE, -60.0), 2, 5.0), 0.5),
    "positions go at 0.1": lambda c, q: c.go_to(_moved(q, 0, 150.0), 0.1),
    "approach": lambda c, q: c.run(form_plans.ramp(UNIMATE, q, ROTATE, q[ROTATE] + 20.0, 2.0,
                                                   start=q[ROTATE] - 60.0, dt=DT)),
    "via_points": lambda c, q: c.run(form_plans.via_points(
        UNIMATE, q, np.array([_moved(q, ROTATE, 40.0), _moved(q, ROTATE, -20.0)]), 0.5, False,
        dt=DT)),
    "cartesian": lambda c, q: c.run(form_plans.via_points(
        UNIMATE, q, _tool(q) + np.array([[0.0, 60.0, -60.0], [0.0, 0.0, -120.0]]), 0.25, True,
        dt=DT)),
    "cartesian_jog": lambda c, q: c.jog_cartesian([0.0, 0.0, -100.0, 0.0, 0.0, 0.0],
                                                  speed=0.25),
}


@pytest.fixture(scope="module")
def shared(tmp_path_factory: pytest.TempPathFactory) -> Iterator[ControlClient]:
    """One lockstep controller for the kinds: each test starts from rest at ``START``."""
    client = ControlClient("unimate2000b", lockstep=True, heartbeat_timeout_s=3.0,
                           data_dir=tmp_path_factory.mktemp("feed-kinds"))
    yield client
    client.close()


@pytest.mark.parametrize("kind", list(KINDS))
def test_an_override_changed_mid_move_changes_the_speed_of_every_kind(
        shared: ControlClient, kind: str) -> None:
    """50 % set a quarter of the way into a move of each kind, the issue's list (a Positions
    go at speed 0.1 kept its speed): the path's rows come a tick apart before, two ticks apart
    from the end of the rate's ramp (within 0.3 s) to the path's end, and the desired
    velocity changes by no more than each joint's max_accel all along."""
    client = shared
    client.feed_override(1.0)
    assert client.wait(client.go_to(START, 0.5), timeout=60).status
    wait_until(lambda: np.all(np.abs(np.array(client.status().position) - START) < TOLERANCE),
               "the arm at rest at the start")
    handle = KINDS[kind](client, np.array(client.status().position))
    wait_until(lambda: client.status().move_done > handle.samples // 4 or handle.done.is_set(),
               "a quarter of the move")
    client.feed_override(0.5)
    result = client.wait(handle, timeout=120)
    client.feed_override(1.0)
    run = result.run
    (set_at, value), = run.meta["feed"]
    rows = path_rows(run)
    t = run.t[:rows]
    interval = np.round(np.diff(t) / DT, 6)
    before, after = t[1:] <= set_at, t[:-1] >= set_at + 0.3
    assert value == 0.5 and after.sum() > 0.5 / DT / 2, (set_at, t[-1])
    assert np.all(interval[before] == 1.0)
    assert np.all(interval[after] == 2.0), np.unique(interval[after])
    velocity = np.diff(run.desired[:rows], axis=0) / np.diff(t)[:, None]
    accel = np.abs(np.diff(velocity, axis=0)) / np.diff(t)[1:, None]
    assert np.all(accel <= MAX_ACCEL * 1.05), (accel / MAX_ACCEL).max(axis=0)
