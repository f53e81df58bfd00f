"""Every link frame of a chain at once (``dh.frames``, ``Unimate2000B.frames``): the drawing of
the arm (app/plotting/arm_scene.py) takes its links' points from these."""

from __future__ import annotations

import numpy as np
import pytest

from control.motion.robot_model import builtin_unimate
from kinematics import dh

MODEL = builtin_unimate()


def random_joints(n: int, seed: int) -> np.ndarray:
    return np.random.default_rng(seed).uniform(MODEL.lower, MODEL.upper, (n, 6))


def test_the_last_frame_is_forward_and_the_first_the_base() -> None:
    q = random_joints(500, 1)
    frames = MODEL.frames(q)
    assert frames.shape == (500, 7, 4, 4)
    np.testing.assert_allclose(frames[:, -1], MODEL.forward(q), atol=1e-9)
    np.testing.assert_array_equal(frames[:, 0], np.broadcast_to(np.eye(4), (500, 4, 4)))


def test_each_frame_is_forward_of_the_chain_up_to_it() -> None:
    links = MODEL.links()
    q_dh = random_joints(50, 2)[:, [1, 2, 0, 3, 4, 5]]
    frames = dh.frames(links, q_dh)
    for i in range(1, 7):
        np.testing.assert_allclose(frames[:, i], dh.forward(links[:i], q_dh[:, :i]), atol=1e-9)


def test_the_wrist_point_is_the_tool_point_less_the_tool_length_along_its_approach() -> None:
    q = random_joints(200, 3)
    frames = MODEL.frames(q)
    tool = frames[:, 6]
    wrist = tool[:, :3, 3] - MODEL.ly * tool[:, :3, 2]
    np.testing.assert_allclose(frames[:, 5, :3, 3], wrist, atol=1e-9)
    np.testing.assert_allclose(frames[:, 1, :3, 3], [[0.0, 0.0, MODEL.d1]] * 200, atol=1e-9)


@pytest.mark.parametrize("shape", [(), (3,), (2, 4)])
def test_frames_is_batch_first(shape: tuple[int, ...]) -> None:
    q = random_joints(int(np.prod(shape)), 4).reshape(*shape, 6)
    assert MODEL.frames(q).shape == (*shape, 7, 4, 4)


@pytest.mark.parametrize("bad", [[0.0] * 5, [np.nan, 0, 0, 0, 0, 0]])
def test_frames_refuses_what_forward_refuses(bad: list[float]) -> None:
    with pytest.raises(ValueError, match="joint"):
        MODEL.frames(bad)
