"""ControlClient.jog_cartesian on the simulated Unimate, for real: the tool moves by the
displacement along the commanded line, and a jog past a limit is refused with nothing sent."""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np
import pytest

from control import ControlClient, Mode
from control.motion.cartesian_jog import Step, StepQueue
from control.motion.robot_model import unimate_model
from hw.machine import load_machine
from kinematics.unimate import Unreachable
from tests.control.waiting import wait_until

UNIMATE = load_machine("unimate2000b")
MODEL = unimate_model(UNIMATE)
START = np.array([1500.0, 10.0, 5.0, 20.0, 30.0, 10.0])
TOLERANCE = np.array([j.tolerance for j in UNIMATE.joints])



@pytest.fixture(scope="module")
def controller(tmp_path_factory: pytest.TempPathFactory) -> Iterator[ControlClient]:
    """One controller for the module: every test jogs from rest at ``START`` (``robot``)."""
    client = ControlClient("unimate2000b", lockstep=True,
                           data_dir=tmp_path_factory.mktemp("cartesian-jog-runs"),
                           heartbeat_timeout_s=3.0)
    yield client
    client.close()


@pytest.fixture
def robot(controller: ControlClient) -> ControlClient:
    """The module's controller, released, holding at rest at ``START``."""
    controller.check()
    if controller.latched:
        controller.reset()
        wait_until(lambda: not controller.status().estop, 10, "the E-stop released")
    result = controller.wait(controller.go_to(START, speed=1.0), timeout=60)
    assert result.complete, result.status
    # at full speed Yaw swings a few degrees for a while after the move: a jog planned
    # from where it is then starts from a moving joint, which in lockstep has moved on by
    # the time the move arrives (the controller refuses its row 0); these tests jog from rest
    wait_until(lambda: settled(controller, START), 30, "the arm settled at the start")
    controller.poll_events()  # each test sees its own events only
    return controller


def tool_band(q: np.ndarray) -> float:
    """How far (mm) the tool point can be from where the joints are meant to be when each
    joint is within a quarter of its settle tolerance: Σ |∂p/∂q_j| · tolerance_j / 4."""
    p = MODEL.forward(q)[:3, 3]
    nudged = MODEL.forward(q + np.diag(TOLERANCE / 4))[:, :3, 3]
    return float(np.linalg.norm(nudged - p, axis=1).sum())


def settled(robot: ControlClient, target: np.ndarray) -> bool:
    return bool(np.all(np.abs(np.array(robot.status().position) - target) <= TOLERANCE / 4))


def test_a_cartesian_jog_moves_the_tool_by_the_displacement(robot: ControlClient) -> None:
    before = MODEL.pose(np.array(robot.status().position))
    result = robot.wait(robot.jog_cartesian([20.0, -10.0, 5.0, 0.0, 0.0, 0.0]), timeout=60)
    assert result.complete and result.run.kind == "cartesian_jog", result.status
    desired = result.run.desired
    commanded = MODEL.pose(desired)
    # the commanded tool runs on the line, from where it was to the displacement
    step = commanded[:, :3] - commanded[0, :3]
    line = np.array([20.0, -10.0, 5.0]) / np.linalg.norm([20.0, -10.0, 5.0])
    off = np.linalg.norm(step - np.outer(step @ line, line), axis=1)
    assert off.max() < 0.5
    np.testing.assert_allclose(commanded[-1] - commanded[0], [20.0, -10.0, 5.0, 0, 0, 0],
                               atol=1e-6)
    # and the simulated arm follows it there: the measured tool moved by the displacement,
    # within what the joints' settle bands allow at the start and at the end (the simulated
    # Bend hunts within its band at a standstill, as a hydraulic joint with stiction does)
    wait_until(lambda: settled(robot, desired[-1]), 30, "the arm settled at the jog's end")
    after = MODEL.pose(np.array(robot.status().position))
    moved = after[:3] - before[:3]
    band = tool_band(START) + tool_band(desired[-1])  # ~20 mm: Bend's 1° at 640 mm is 11
    assert np.linalg.norm(moved - [20.0, -10.0, 5.0]) < band, (moved, band)


def test_a_tool_frame_rotation_turns_the_tool_about_its_own_axis(robot: ControlClient) -> None:
    wait_until(lambda: settled(robot, START), 30, "the arm settled at the start")
    result = robot.wait(robot.jog_cartesian([0, 0, 0, 0, 0, 10.0], frame="tool"), timeout=60)
    assert result.complete, result.status
    first, last = MODEL.forward(result.run.desired[[0, -1]])
    np.testing.assert_allclose(last[:3, 3], first[:3, 3], atol=1e-6)  # the tool point stays
    turned = first[:3, :3].T @ last[:3, :3]  # about the tool's z axis, by 10°
    assert np.degrees(np.arctan2(turned[1, 0], turned[0, 0])) == pytest.approx(10.0, abs=1e-6)


def test_an_unreachable_jog_raises_and_sends_nothing(robot: ControlClient) -> None:
    before = robot.status()
    with pytest.raises(Unreachable, match=r"In/Out would be 204\d\.\d mm, past its limits"):
        robot.jog_cartesian([5000.0, 0, 0, 0, 0, 0])
    with pytest.raises(Unreachable, match=r"Bend would be 110\.\d°, past its limits"):
        robot.jog_cartesian([0, 0, 0, -40.0, 0, 0])
    status = robot.status()
    assert status.mode == Mode.HOLD
    assert status.desired == before.desired  # the hold target never moved
    result = robot.wait(robot.jog_cartesian([5.0, 0, 0, 0, 0, 0]), timeout=60)
    assert result.complete  # and the next jog runs as usual


def test_a_small_tool_turn_by_the_wrist_singularity_stops_naming_the_joint(
        robot: ControlClient) -> None:
    """Issue 25 item 2: at the simulator's start pose (Yaw 2.5°) γ +5° in the tool frame moved
    In/Out 70 mm, Bend 70° and Swivel 64°; now it stops before it starts, and says why."""
    home = np.array(MODEL.mid_range)
    assert robot.wait(robot.go_to(home, speed=1.0), timeout=60).complete
    before = robot.status()
    with pytest.raises(Unreachable, match=r"at the start: Bend would need \d+°/s, over its "
                                          r"max_speed 90°/s.*near the wrist singularity"):
        robot.jog_cartesian([0, 0, 0, 5.0, 0, 0], frame="tool")
    assert robot.status().desired == before.desired  # nothing sent


def test_in_the_singularity_zone_a_jog_runs_with_every_joint_within_its_jog_speed(
        robot: ControlClient) -> None:
    """At Yaw 15° a world α turn at 10°/s would need Bend at 44°/s: it runs slower, with no
    joint's commanded speed above its jog speed."""
    near = np.array([1508.5, 0.0, 1.5, 0.0, 15.0, 0.0])
    assert robot.wait(robot.go_to(near, speed=1.0), timeout=60).complete
    result = robot.wait(robot.jog_cartesian([0, 0, 0, 0, 0, 5.0]), timeout=60)
    assert result.complete, result.status
    desired = result.run.desired
    speed = np.abs(np.diff(desired, axis=0)).max(axis=0) / robot.dt
    jog_speed = np.array([j.jog_speed for j in UNIMATE.joints])
    assert (speed <= jog_speed * 1.001).all(), speed
    assert speed[3] > 0.9 * jog_speed[3]  # Bend sets the pace


def test_steps_asked_while_one_runs_are_queued_as_far_as_they_fit(robot: ControlClient) -> None:
    """Issue 25 item 4: about 144 mm from In/Out's limit along x, ten 20 mm steps: the first runs,
    six more are queued (planned one after the other from its end), three are refused naming
    In/Out; the six run as one jog after it."""
    near_limit = np.array([1897.0, 0.0, 1.5, 0.0, 30.0, 0.0])
    assert robot.wait(robot.go_to(near_limit, speed=1.0), timeout=60).complete
    start = MODEL.pose(np.array(robot.status().desired))
    first = robot.jog_cartesian([20.0, 0, 0, 0, 0, 0])
    queue = StepQueue(UNIMATE, robot.dt)
    reasons = [queue.add(first.plan.path[-1], Step((20.0, 0, 0, 0, 0, 0), "world"))
               for _ in range(9)]
    assert [bool(r) for r in reasons] == [False] * 6 + [True] * 3, reasons
    assert all("In/Out would be" in r for r in reasons[6:]), reasons
    assert robot.wait(first, timeout=60).complete
    step = queue.next()
    assert step is not None and step.displacement == (120.0, 0, 0, 0, 0, 0)
    assert queue.next() is None
    assert robot.wait(robot.jog_cartesian(step.displacement), timeout=60).complete
    moved = MODEL.pose(np.array(robot.status().desired)) - start
    np.testing.assert_allclose(moved, [140.0, 0, 0, 0, 0, 0], atol=1e-6)
