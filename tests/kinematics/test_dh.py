"""Denavit–Hartenberg chains (eq. 4.02, 4.03)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from kinematics.dh import DHLink, forward

ANGLE = st.floats(-720.0, 720.0)
LENGTH = st.floats(-2000.0, 2000.0)


def eq_4_02(alpha_deg: float, a: float, d: float, theta_deg: float) -> np.ndarray:
    """eq. 4.02 typed from the thesis, one link, scalars."""
    ct, st_ = math.cos(math.radians(theta_deg)), math.sin(math.radians(theta_deg))
    ca, sa = math.cos(math.radians(alpha_deg)), math.sin(math.radians(alpha_deg))
    return np.array([
        [ct, -st_ * ca, st_ * sa, a * ct],
        [st_, ct * ca, -ct * sa, a * st_],
        [0.0, sa, ca, d],
        [0.0, 0.0, 0.0, 1.0],
    ])


@settings(max_examples=100)
@given(alpha=ANGLE, a=LENGTH, d=LENGTH, theta=ANGLE, q=ANGLE)
def test_revolute_link_is_eq_4_02_with_the_joint_added_to_theta(
    alpha: float, a: float, d: float, theta: float, q: float,
) -> None:
    got = DHLink(alpha, a, d, theta).transform(q)
    np.testing.assert_allclose(got, eq_4_02(alpha, a, d, theta + q), atol=1e-9)


@settings(max_examples=100)
@given(alpha=ANGLE, a=LENGTH, d=LENGTH, theta=ANGLE, q=LENGTH)
def test_prismatic_link_is_eq_4_02_with_the_joint_added_to_d(
    alpha: float, a: float, d: float, theta: float, q: float,
) -> None:
    got = DHLink(alpha, a, d, theta, prismatic=True).transform(q)
    np.testing.assert_allclose(got, eq_4_02(alpha, a, d + q, theta), atol=1e-9)


def random_chain(rng: np.random.Generator, n: int) -> list[DHLink]:
    return [
        DHLink(*rng.uniform(-180, 180, 1), *rng.uniform(-500, 500, 2), *rng.uniform(-180, 180, 1),
               prismatic=bool(rng.integers(2)))
        for _ in range(n)
    ]


def test_forward_is_the_product_of_the_link_transforms_eq_4_03() -> None:
    rng = np.random.default_rng(1)
    links = random_chain(rng, 5)
    q = rng.uniform(-300, 300, (100, 5))
    got = forward(links, q)
    for qi, ti in zip(q, got, strict=True):
        want = np.eye(4)
        for link, v in zip(links, qi, strict=True):
            want = want @ eq_4_02(link.alpha_deg, link.a, link.d + v * link.prismatic,
                                  link.theta_deg + v * (not link.prismatic))
        np.testing.assert_allclose(ti, want, atol=1e-9)


def test_forward_splits_anywhere_along_the_chain() -> None:
    rng = np.random.default_rng(2)
    links = random_chain(rng, 6)
    q = rng.uniform(-300, 300, (50, 6))
    for k in range(1, 6):
        split = forward(links[:k], q[:, :k]) @ forward(links[k:], q[:, k:])
        np.testing.assert_allclose(forward(links, q), split, atol=1e-9)


def test_forward_gives_rigid_transforms() -> None:
    rng = np.random.default_rng(3)
    t = forward(random_chain(rng, 6), rng.uniform(-300, 300, (1000, 6)))
    r = t[:, :3, :3]
    np.testing.assert_allclose(r @ r.transpose(0, 2, 1), np.broadcast_to(np.eye(3), r.shape),
                               atol=1e-12)
    np.testing.assert_allclose(np.linalg.det(r), 1.0, atol=1e-12)
    np.testing.assert_array_equal(t[:, 3], np.broadcast_to([0.0, 0.0, 0.0, 1.0], (1000, 4)))


@pytest.mark.parametrize("batch", [(), (7,), (2, 3), (4, 1, 2)])
def test_forward_is_batch_first(batch: tuple[int, ...]) -> None:
    rng = np.random.default_rng(4)
    links = random_chain(rng, 3)
    q = rng.uniform(-90, 90, (*batch, 3))
    t = forward(links, q)
    assert t.shape == (*batch, 4, 4)
    flat = forward(links, q.reshape(-1, 3))
    np.testing.assert_allclose(t.reshape(-1, 4, 4), flat, atol=1e-12)


def test_forward_does_not_mutate_its_input() -> None:
    q = np.array([[10.0, 20.0, 30.0]])
    before = q.copy()
    forward([DHLink(90, 1, 2, 3), DHLink(0, 1, 0, 0, prismatic=True), DHLink(-90, 0, 5, 0)], q)
    np.testing.assert_array_equal(q, before)


@pytest.mark.parametrize("q", [[1.0, 2.0], [1.0, 2.0, 3.0, 4.0], 5.0])
def test_forward_rejects_the_wrong_number_of_joints(q: float | list[float]) -> None:
    with pytest.raises(ValueError, match=r"shape \(\.\.\., 3\)"):
        forward([DHLink(0, 1, 0, 0)] * 3, q)


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_forward_rejects_nan_and_inf(bad: float) -> None:
    with pytest.raises(ValueError, match="finite"):
        forward([DHLink(0, 1, 0, 0)] * 2, [[0.0, 0.0], [bad, 0.0]])


def test_forward_rejects_an_empty_chain() -> None:
    with pytest.raises(ValueError, match="at least one link"):
        forward([], np.zeros(0))
