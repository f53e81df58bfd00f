"""Reduced speed (ISO 10218-1's T1, issue 27 item 4) on the real control subprocess.

Every speed is measured from what the controller recorded or published, never from what the
client planned: the tool point's speed from forward kinematics of each row (desired, and
actual over 0.2 s: an encoder count differenced over one tick reads as a spike, and a jog's
status is sampled every few tens of ms of a lockstep controller; benchmarks/speed_mode.py
prints the actual over 50 ms too), each joint's from its rows. In reduced speed the tool
stays within 250 mm/s and each joint within its jog_speed; the same motions in automatic are
faster than that, so each check can fail.
"""

from __future__ import annotations

import json
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from control import ControlClient
from control.link import NotCommanding
from control.motion import form_plans
from control.motion.cartesian import cartesian_path
from control.motion.robot_model import builtin_unimate
from control.recorder import load_run
from control.rt.commands import SetSpeedMode
from control.rt.layout import Mode
from control.rt.speed_cap import TOOL_SPEED
from control.rt.wire import Message
from hw.machine import load_machine
from tests.conftest import ROOT, ServiceProcess
from tests.control.waiting import wait_until

UNIMATE = load_machine("unimate2000b")
MODEL = builtin_unimate()
JOG_SPEED = np.array([j.jog_speed for j in UNIMATE.joints])
MAX_ACCEL = np.array([j.max_accel for j in UNIMATE.joints])
INOUT, ROTATE = UNIMATE.joint_index("inout"), UNIMATE.joint_index("rotate")
ACTUAL_WINDOW_S = 0.2
# the arm lags and overshoots its desired path a little: its joints' measured speed may pass
# the jog speed by this much (the desired, which the controller caps, may not at all)
ACTUAL_SLACK = 1.1


def speeds(t: np.ndarray, x: np.ndarray, window_s: float = 0.0) -> np.ndarray:
    """Speeds ``(M, ...)`` of rows ``x (N, ...)`` at times ``t (N,)``: row to row, or over
    ``window_s``."""
    later = np.searchsorted(t, t + window_s, side="right") if window_s else np.arange(1, len(t) + 1)
    valid = later < len(t)
    dt = t[later[valid]] - t[valid]
    return (x[later[valid]] - x[valid]) / dt.reshape(-1, *([1] * (x.ndim - 1)))


def tool_speed(t: np.ndarray, q: np.ndarray, window_s: float = 0.0) -> float:
    """The largest speed of the tool point (mm/s) along joint rows ``q (N, 6)``."""
    return float(np.linalg.norm(speeds(t, MODEL.pose(q)[:, :3], window_s), axis=1).max())


def joint_speed(t: np.ndarray, q: np.ndarray, window_s: float = 0.0) -> np.ndarray:
    return np.abs(speeds(t, q, window_s)).max(axis=0)


def figures(t: np.ndarray, desired: np.ndarray, actual: np.ndarray) -> dict[str, object]:
    return {"tool desired": tool_speed(t, desired),
            "tool actual": tool_speed(t, actual, ACTUAL_WINDOW_S),
            "joints desired": joint_speed(t, desired),
            "joints actual": joint_speed(t, actual, ACTUAL_WINDOW_S)}


def assert_reduced(measured: dict[str, object]) -> None:
    print("reduced", measured)
    assert measured["tool desired"] <= TOOL_SPEED + 1e-6
    assert measured["tool actual"] <= TOOL_SPEED
    assert np.all(measured["joints desired"] <= JOG_SPEED + 1e-6)
    assert np.all(measured["joints actual"] <= JOG_SPEED * ACTUAL_SLACK)


def client(tmp_path: Path, speed_mode: str) -> ControlClient:
    return ControlClient("unimate2000b", lockstep=True, data_dir=tmp_path,
                         heartbeat_timeout_s=3.0, speed_mode=speed_mode)


def far_from_home() -> list[float]:
    far = list(UNIMATE.home)
    far[INOUT], far[ROTATE] = 1700.0, 40.0
    return far


def test_a_fast_joint_move_is_slowed_in_reduced_speed_and_not_in_automatic(
        tmp_path: Path) -> None:
    with client(tmp_path, "reduced") as robot:
        assert robot.speed_mode == "reduced" and robot.status().speed_mode == "reduced"
        reduced = robot.wait(robot.go_to(far_from_home(), speed=1.0), 120)
        assert reduced.complete, reduced.status
        assert reduced.run.meta["speed_mode"] == "reduced"
        assert "speed_mode_changes" not in reduced.run.meta
        assert_reduced(figures(reduced.run.t, reduced.run.desired, reduced.run.actual))
        # In/Out alone: its jog speed binds, and is measured exactly (no bound between): the
        # feed is held to the cap as the path speeds up, not brought down to it at its accel
        here = np.array(robot.status().position)
        ramp = form_plans.ramp(UNIMATE, here, INOUT, UNIMATE.joints[INOUT].upper - 100.0, 1.0,
                               dt=robot.dt)  # 240 mm/s, reached at In/Out's max_accel
        alone = robot.wait(robot.run(ramp), 120)
        fastest = joint_speed(alone.run.t, alone.run.desired)[INOUT]
        print(f"In/Out alone: {fastest:.2f} mm/s, its jog speed {JOG_SPEED[INOUT]:g}")
        assert JOG_SPEED[INOUT] * 0.99 < fastest <= JOG_SPEED[INOUT] + 1e-6
        robot.set_speed_mode("automatic")
        assert robot.status().speed_mode == "automatic"
        automatic = robot.wait(robot.go_to(UNIMATE.home, speed=1.0), 120)
        assert automatic.run.meta["speed_mode"] == "automatic"
        fast = figures(automatic.run.t, automatic.run.desired, automatic.run.actual)
        print("automatic", fast)
        assert fast["tool desired"] > 2 * TOOL_SPEED and fast["tool actual"] > 2 * TOOL_SPEED
        assert reduced.run.t[-1] > 3 * automatic.run.t[-1]


def test_a_fast_cartesian_line_is_slowed_in_reduced_speed_and_not_in_automatic(
        tmp_path: Path) -> None:
    """A straight tool line of 600 mm, planned as fast as the joints allow."""
    home = np.array(UNIMATE.home)
    start = MODEL.pose(home)[:3]
    side = np.array([0.0, 300.0, 0.0])
    line = cartesian_path(home, [start + side, start + 2 * side], UNIMATE,
                          dt=UNIMATE.sample_time_s).q
    back = cartesian_path(line[-1], [start + side, start], UNIMATE, dt=UNIMATE.sample_time_s).q
    with client(tmp_path, "reduced") as robot:
        robot.wait(robot.go_to(home, speed=1.0), 60)
        reduced = robot.wait(robot.move(line, kind="cartesian"), 120)
        assert reduced.complete, reduced.status
        assert_reduced(figures(reduced.run.t, reduced.run.desired, reduced.run.actual))
        robot.set_speed_mode("automatic")
        automatic = robot.wait(robot.move(back, kind="cartesian"), 120)
        fast = figures(automatic.run.t, automatic.run.desired, automatic.run.actual)
        print("automatic", fast)
        assert fast["tool desired"] > 2 * TOOL_SPEED and fast["tool actual"] > 2 * TOOL_SPEED


def sampled(robot: ControlClient, start: Callable[[], None],
            stream: tuple[list[float], float] | None = None
            ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The status's time, desired and position as often as it can be read, from ``start()``
    until the hold target has stood still 0.3 s of the controller's time. ``stream``: a
    velocity jog ``(velocity, seconds)`` renewed from this loop every 20 ms of the controller's
    time for that long (its deadman is 150 ms; a lockstep controller's time runs fast)."""
    rows: list[tuple[float, tuple[float, ...], tuple[float, ...]]] = []
    start()
    began = sent = robot.status().time_s
    deadline = time.monotonic() + 60
    still_since = None
    while time.monotonic() < deadline:
        status = robot.status()
        if stream and status.time_s - began < stream[1] and status.time_s - sent >= 0.02:
            robot.jog_velocity(stream[0])
            sent = status.time_s
        if rows and status.time_s == rows[-1][0]:
            continue
        if rows and status.desired == rows[-1][1] and status.time_s > 0.2 + rows[0][0]:
            still_since = still_since or status.time_s
            if status.time_s - still_since > 0.3:
                break
        else:
            still_since = None
        rows.append((status.time_s, status.desired, status.position))
    t = np.array([r[0] for r in rows])
    return t, np.array([r[1] for r in rows]), np.array([r[2] for r in rows])


@pytest.mark.parametrize("jog", ["position", "velocity"])
def test_jogs_are_slowed_in_reduced_speed_and_not_in_automatic(tmp_path: Path, jog: str) -> None:
    """Rotate jogged at its jog speed with the arm half out: the tool's arc is faster than
    250 mm/s in automatic (15°/s at about 1.5 m), within it in reduced."""
    measured = {}
    with client(tmp_path, "reduced") as robot:
        for mode, sign in (("reduced", 1.0), ("automatic", -1.0)):
            robot.set_speed_mode(mode)
            if jog == "position":
                rows = sampled(robot, lambda s=sign: robot.jog_position(ROTATE, s * 20.0))
            else:
                velocity = [0.0] * UNIMATE.n_joints
                velocity[ROTATE] = sign * JOG_SPEED[ROTATE]
                rows = sampled(robot, lambda v=velocity: robot.jog_velocity(v), (velocity, 1.5))
            measured[mode] = figures(*rows)
    assert_reduced(measured["reduced"])
    print("automatic", measured["automatic"])
    assert measured["automatic"]["tool desired"] > 1.4 * TOOL_SPEED


def test_switching_to_reduced_mid_move_slows_it_without_a_jump(tmp_path: Path) -> None:
    """Automatic go-to, reduced speed set a third of the way: the feed comes down along the
    path (the desired velocity continuous, within the joints' acceleration), then stays
    within the reduced limits; the run says when. Automatic is refused while it moves."""
    with client(tmp_path, "automatic") as robot:
        handle = robot.go_to(far_from_home(), speed=0.5)  # long enough to switch within
        wait_until(lambda: robot.status().move_done > robot.status().move_total // 3, 60,
                   "a third of the move")
        robot.set_speed_mode("reduced")
        with pytest.raises(ValueError, match="only at rest"):
            robot.set_speed_mode("automatic")
        assert robot.speed_mode == "reduced"
        result = robot.wait(handle, 120)
    assert result.complete, result.status
    run = result.run
    assert run.meta["speed_mode"] == "automatic"
    [[switched_s, mode]] = run.meta["speed_mode_changes"]
    assert mode == "reduced" and 0 < switched_s < run.t[-1]
    path = slice(0, run.meta["path_samples"])
    t, desired, actual = run.t[path], run.desired[path], run.actual[path]
    velocity = speeds(t, desired)
    accel = np.abs(np.diff(velocity, axis=0)) / np.diff(t[:-1]).reshape(-1, 1)
    print(f"switched at {switched_s} s; largest acceleration {accel.max(axis=0)}")
    assert np.all(accel.max(axis=0) <= 1.5 * MAX_ACCEL)
    before = t < switched_s
    assert tool_speed(t[before], desired[before]) > 2 * TOOL_SPEED  # it was fast
    after = t > switched_s + 1.0  # the feed down to the cap takes < 0.4 s at half max_accel
    assert_reduced(figures(t[after], desired[after], actual[after]))


def test_open_loop_duty_is_refused_in_reduced_speed(tmp_path: Path) -> None:
    with client(tmp_path, "reduced") as robot:
        robot.jog_joint(ROTATE, 30.0)
        refused = robot.wait_event("refused")
        assert "open-loop duty" in refused.message and "automatic" in refused.message
        assert robot.status().mode == Mode.HOLD
        profile = np.zeros((200, UNIMATE.n_joints))
        profile[:, ROTATE] = 30.0
        result = robot.wait(robot.actuate(profile), 30)
        assert result.status.startswith("refused: reduced speed")


def test_only_the_commander_switches_the_speed_mode(controller_service: ServiceProcess) -> None:
    """An observer's switch is refused by its client (nothing sent) and, sent anyway, by the
    service; the commander's reaches the controller, and every client's status shows it."""
    commander = ControlClient.attach(controller_service.socket, name="commander")
    observer = ControlClient.attach(controller_service.socket, name="observer")
    try:
        assert observer.speed_mode == "automatic"
        with pytest.raises(NotCommanding):
            observer.set_speed_mode("reduced")
        observer.link.put(Message(SetSpeedMode("reduced")))  # past the client's own check
        refused = observer.wait_event("refused", match=lambda e: "speed mode" in e.message)
        assert "take it first" in refused.message
        assert commander.speed_mode == "automatic"
        commander.take_command()
        commander.set_speed_mode("reduced")
        wait_until(lambda: observer.speed_mode == "reduced", 10, "the observer to see reduced")
        with pytest.raises(NotCommanding):
            observer.set_speed_mode("automatic")
        assert commander.speed_mode == "reduced"
    finally:
        observer.close()
        commander.close()


def test_servodesk_move_reduced_runs_in_reduced_speed(tmp_path: Path) -> None:
    """``servodesk move goto --reduced``: the JSON and the run's metadata say reduced, and the
    tool stayed within 250 mm/s; without it, automatic and faster (as before)."""
    targets = ",".join(f"{q:g}" for q in far_from_home())
    for options, mode in ((["--reduced"], "reduced"), ([], "automatic")):
        done = subprocess.run([sys.executable, "-m", "app", "move", "goto", "--targets", targets,
                               "--speed", "1", "--lockstep", "--json", "--data-dir",
                               str(tmp_path), *options], cwd=ROOT, capture_output=True,
                              text=True, timeout=120)
        assert done.returncode == 0, done.stderr
        report = json.loads(done.stdout)
        run = load_run(Path(report["run"]["json"]))
        assert report["speed_mode"] == run.meta["speed_mode"] == mode
        fastest = tool_speed(run.t, run.desired)
        assert fastest <= TOOL_SPEED + 1e-6 if mode == "reduced" else fastest > 2 * TOOL_SPEED
