"""X-Y-Z fixed angles (eq. 4.04, 4.05, errata #15)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from kinematics.xyz_fixed import GIMBAL_TOL, angles, rotation


def rx(t: float) -> np.ndarray:
    return np.array([[1, 0, 0], [0, math.cos(t), -math.sin(t)], [0, math.sin(t), math.cos(t)]])


def ry(t: float) -> np.ndarray:
    return np.array([[math.cos(t), 0, math.sin(t)], [0, 1, 0], [-math.sin(t), 0, math.cos(t)]])


def rz(t: float) -> np.ndarray:
    return np.array([[math.cos(t), -math.sin(t), 0], [math.sin(t), math.cos(t), 0], [0, 0, 1]])


def random_rotations(rng: np.random.Generator, n: int) -> np.ndarray:
    """Uniform random rotations from unit quaternions, ``(n, 3, 3)``."""
    quaternions = rng.normal(size=(4, n))
    w, x, y, z = quaternions / np.linalg.norm(quaternions, axis=0)
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
        np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
        np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
    ], -2)


@settings(max_examples=200)
@given(st.floats(-7, 7), st.floats(-7, 7), st.floats(-7, 7))
def test_rotation_is_gamma_about_x_then_beta_about_y_then_alpha_about_z(
    gamma: float, beta: float, alpha: float,
) -> None:
    np.testing.assert_allclose(rotation(gamma, beta, alpha), rz(alpha) @ ry(beta) @ rx(gamma),
                               atol=1e-12)


def test_rotation_matches_eq_4_04_term_by_term() -> None:
    g, b, a = 0.3, -0.7, 2.1
    cg, sg, cb, sb, ca, sa = (math.cos(g), math.sin(g), math.cos(b), math.sin(b),
                              math.cos(a), math.sin(a))
    eq_4_04 = np.array([
        [ca * cb, ca * sb * sg - sa * cg, ca * sb * cg + sa * sg],
        # the thesis prints r22 as sa*sb*sg - ca*cg; the listing has + ca*cg
        [sa * cb, sa * sb * sg + ca * cg, sa * sb * cg - ca * sg],
        [-sb, cb * sg, cb * cg],
    ])
    np.testing.assert_allclose(rotation(g, b, a), eq_4_04, atol=1e-15)


def test_rotation_broadcasts_and_is_batch_first() -> None:
    r = rotation(np.zeros((4, 1)), np.linspace(-1, 1, 3), 0.5)
    assert r.shape == (4, 3, 3, 3)
    np.testing.assert_allclose(r[2, 1], rotation(0.0, 0.0, 0.5), atol=1e-15)


def test_angles_recover_angles_away_from_the_degeneracy() -> None:
    rng = np.random.default_rng(5)
    n = 10_000
    want = np.stack([rng.uniform(-math.pi, math.pi, n), rng.uniform(-1.5, 1.5, n),
                     rng.uniform(-math.pi, math.pi, n)], axis=-1)
    got = angles(rotation(*want.T))
    np.testing.assert_allclose(got, want, atol=1e-9)


def test_angles_round_trip_random_rotations() -> None:
    r = random_rotations(np.random.default_rng(6), 20_000)
    np.testing.assert_allclose(rotation(*np.moveaxis(angles(r), -1, 0)), r, atol=1e-12)


@pytest.mark.parametrize("beta", [math.pi / 2, -math.pi / 2])
@pytest.mark.parametrize("gamma", [-3.0, -1.0, 0.0, 0.4, 2.5])
@pytest.mark.parametrize("alpha", [-2.0, 0.0, 0.7, math.pi])
def test_at_beta_90_alpha_is_zero_and_the_rotation_round_trips(
    beta: float, gamma: float, alpha: float,
) -> None:
    r = rotation(gamma, beta, alpha)
    g, b, a = angles(r)
    assert a == 0.0
    assert b == pytest.approx(beta, abs=1e-12)
    # errata #15: only γ - α (β = +90°) or γ + α (β = -90°) is defined; γ from r12, r22
    assert g == pytest.approx(math.atan2(-r[2, 0] * r[0, 1], r[1, 1]), abs=1e-12)
    np.testing.assert_allclose(rotation(g, b, a), r, atol=1e-12)


@pytest.mark.parametrize("offset", [1e-15, 1e-13, 1e-11, 1e-9, 1e-6])
@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_near_beta_90_the_rotation_still_round_trips(offset: float, sign: float) -> None:
    for gamma, alpha in [(0.3, -1.2), (-2.9, 3.0), (1.0, 1.0)]:
        r = rotation(gamma, sign * (math.pi / 2 - offset), alpha)
        np.testing.assert_allclose(rotation(*angles(r)), r, atol=1e-12)


def test_gimbal_tolerance_is_round_off_sized() -> None:
    assert 1e-15 < GIMBAL_TOL <= 1e-12


def test_unimate_home_orientation() -> None:
    """Frame 6 at the all-zero Unimate pose: x6 = z0, y6 = -x0, z6 = -y0 (section 4.4)."""
    r = np.array([[0.0, -1.0, 0.0], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0]])
    np.testing.assert_allclose(np.degrees(angles(r)), [90.0, -90.0, 0.0], atol=1e-12)


def test_listing_formulas_fail_at_beta_90_and_ours_do_not() -> None:
    """Euler_calc's atan2s take α and γ from round-off at β = -90° (errata #15)."""
    # the Unimate's home orientation as a DH product leaves it: r11, r21, r32, r33 are noise
    r = np.array([[6e-17, -1.0, 0.0], [-1e-16, 0.0, -1.0], [1.0, 4e-17, -1e-17]])
    listing = (math.atan2(r[2, 1], r[2, 2]), math.atan2(-r[2, 0], math.hypot(r[0, 0], r[1, 0])),
               math.atan2(r[1, 0], r[0, 0]))
    assert not np.allclose(rotation(*listing), r, atol=0.1)
    np.testing.assert_allclose(rotation(*angles(r)), r, atol=1e-12)


def test_angles_reject_the_wrong_shape() -> None:
    with pytest.raises(ValueError, match=r"\(\.\.\., 3, 3\)"):
        angles(np.eye(4))
