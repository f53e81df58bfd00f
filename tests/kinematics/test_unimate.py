"""The Unimate 2000B model: Table 4.1, forward_calc, the closed-form inverse (errata #8–#10)."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from control.motion.robot_model import builtin_unimate
from kinematics import Unreachable, unimate, xyz_fixed
from kinematics.unimate import MM_PER_DEGREE, Unimate2000B

MODEL = builtin_unimate()  # Table 4.1 and rtshare.h's limits, from the machine file
LOWER = np.array(MODEL.lower)
UPPER = np.array(MODEL.upper)
WEIGHTS = np.array([1 / MM_PER_DEGREE, 1, 1, 1, 1, 1])
D1, A2, LB, LY = 1066.8, 120.65, 200.0, 440.0  # Table 4.1 typed from the thesis, not the file


def random_joints(n: int, seed: int) -> np.ndarray:
    """``(n, 6)`` joint vectors uniformly inside the limits."""
    return np.random.default_rng(seed).uniform(LOWER, UPPER, (n, 6))


def target(p: np.ndarray) -> np.ndarray:
    """``T`` of poses ``(..., 6)`` (mm, deg) → ``(..., 4, 4)``."""
    p = np.asarray(p, dtype=float)
    t = np.zeros((*p.shape[:-1], 4, 4))
    t[..., :3, :3] = xyz_fixed.rotation(*np.moveaxis(np.radians(p[..., 3:]), -1, 0))
    t[..., :3, 3] = p[..., :3]
    t[..., 3, 3] = 1.0
    return t


def assert_reaches(q: np.ndarray, p: np.ndarray, model: Unimate2000B = MODEL) -> None:
    """FK of joint vectors ``q`` equals pose ``p``: positions to 1e-6 mm, rotations to 1e-9."""
    got = model.forward(q)
    want = np.broadcast_to(target(p), got.shape)
    np.testing.assert_allclose(got[..., :3, 3], want[..., :3, 3], atol=1e-6)
    np.testing.assert_allclose(got[..., :3, :3], want[..., :3, :3], atol=1e-9)


def assert_in_limits(q: np.ndarray) -> None:
    assert np.all(q >= LOWER) and np.all(q <= UPPER), q


def forward_calc(q: np.ndarray) -> np.ndarray:
    """kinematics.h forward_calc (Appendix D) re-typed term by term, vectorised, exact pi."""
    d3 = q[:, 0]
    s1, c1 = np.sin(np.radians(q[:, 1])), np.cos(np.radians(q[:, 1]))
    s2, c2 = np.sin(np.radians(q[:, 2])), np.cos(np.radians(q[:, 2]))
    s4, c4 = np.sin(np.radians(q[:, 3])), np.cos(np.radians(q[:, 3]))
    s5, c5 = np.sin(np.radians(q[:, 4])), np.cos(np.radians(q[:, 4]))
    s6, c6 = np.sin(np.radians(q[:, 5])), np.cos(np.radians(q[:, 5]))
    t = np.zeros((len(q), 4, 4))
    t[:, 0, 0] = (-c6 * c5 * c1 * s2 * c4 - c6 * c5 * c1 * c2 * s4 + c6 * s1 * s5
                  + s6 * c1 * s2 * s4 - s6 * c1 * c2 * c4)
    t[:, 0, 1] = (s6 * c5 * c1 * s2 * c4 + s6 * c5 * c1 * c2 * s4 - s6 * s1 * s5
                  + c6 * c1 * s2 * s4 - c6 * c1 * c2 * c4)
    t[:, 0, 2] = s5 * c1 * s2 * c4 + s5 * c1 * c2 * s4 + s1 * c5
    t[:, 0, 3] = (LY * s5 * c1 * s2 * c4 + LY * s5 * c1 * c2 * s4 + LY * s1 * c5
                  - LB * c1 * s2 * s4 + LB * c1 * c2 * c4 + c1 * c2 * d3 - c1 * A2 * s2)
    t[:, 1, 0] = (-c6 * c5 * s1 * s2 * c4 - c6 * c5 * s1 * c2 * s4 - c6 * c1 * s5
                  + s6 * s1 * s2 * s4 - s6 * s1 * c2 * c4)
    t[:, 1, 1] = (s6 * c5 * s1 * s2 * c4 + s6 * c5 * s1 * c2 * s4 + s6 * c1 * s5
                  + c6 * s1 * s2 * s4 - c6 * s1 * c2 * c4)
    t[:, 1, 2] = s5 * s1 * s2 * c4 + s5 * s1 * c2 * s4 - c1 * c5
    t[:, 1, 3] = (LY * s5 * s1 * s2 * c4 + LY * s5 * s1 * c2 * s4 - LY * c1 * c5
                  - LB * s1 * s2 * s4 + LB * s1 * c2 * c4 + s1 * c2 * d3 - s1 * A2 * s2)
    t[:, 2, 0] = c5 * c6 * c2 * c4 - c5 * c6 * s2 * s4 - s6 * s2 * c4 - s6 * c2 * s4
    t[:, 2, 1] = -c5 * s6 * c2 * c4 + c5 * s6 * s2 * s4 - c6 * c2 * s4 - c6 * s2 * c4
    t[:, 2, 2] = -s5 * c2 * c4 + s5 * s2 * s4
    t[:, 2, 3] = (-s5 * LY * c2 * c4 + s5 * LY * s2 * s4 + LB * c2 * s4 + LB * s2 * c4
                  + s2 * d3 + A2 * c2 + D1)
    t[:, 3, 3] = 1.0
    return t


def thesis_a_matrices(q: np.ndarray) -> list[np.ndarray]:
    """A_1^0 … A_6^5 as printed in section 4.4, one joint vector (actuator order)."""
    d3 = q[0]
    c1, s1, c2, s2, c4, s4, c5, s5, c6, s6 = (
        f(math.radians(v)) for v in q[1:] for f in (math.cos, math.sin))
    return [
        np.array([[c1, 0, s1, 0], [s1, 0, -c1, 0], [0, 1, 0, D1], [0, 0, 0, 1]]),
        np.array([[-s2, 0, c2, -A2 * s2], [c2, 0, s2, A2 * c2], [0, 1, 0, 0], [0, 0, 0, 1]]),
        np.array([[1, 0, 0, 0], [0, 0, 1, 0], [0, -1, 0, d3], [0, 0, 0, 1]]),
        np.array([[c4, 0, s4, 0], [s4, 0, -c4, 0], [0, 1, 0, 0], [0, 0, 0, 1]]),
        np.array([[c5, 0, -s5, 0], [s5, 0, c5, 0], [0, -1, 0, LB], [0, 0, 0, 1]]),
        np.array([[c6, -s6, 0, 0], [s6, c6, 0, 0], [0, 0, 1, LY], [0, 0, 0, 1]]),
    ]


# --- forward -------------------------------------------------------------------------------


def test_forward_equals_the_listings_forward_calc() -> None:
    inside = random_joints(5000, seed=10)
    anywhere = np.random.default_rng(11).uniform(-400, 2500, (5000, 6))
    for q in (inside, anywhere):
        np.testing.assert_allclose(MODEL.forward(q), forward_calc(q), atol=1e-9)


def test_forward_equals_the_thesis_a_matrices_multiplied_eq_4_11() -> None:
    for q in random_joints(200, seed=12):
        want = np.linalg.multi_dot(thesis_a_matrices(q))
        np.testing.assert_allclose(MODEL.forward(q), want, atol=1e-9)


def test_each_dh_row_is_the_thesis_a_matrix() -> None:
    q = random_joints(1, seed=13)[0]
    dh_q = q[[1, 2, 0, 3, 4, 5]]
    for link, v, a in zip(MODEL.links(), dh_q, thesis_a_matrices(q), strict=True):
        np.testing.assert_allclose(link.transform(v), a, atol=1e-12)


def test_a21_is_table_4_2s_two_steps_plus_the_a2_offset() -> None:
    """eq. 4.08: A_2^1 = Rz(90°)·A(α = 90°, θ2); a2 (Table 4.1) is the link length."""
    theta2 = math.radians(17.0)
    rz90 = np.array([[0, -1, 0, 0], [1, 0, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1.0]])
    c2, s2 = math.cos(theta2), math.sin(theta2)
    a21_prime = np.array([[c2, 0, s2, 0], [s2, 0, -c2, 0], [0, 1, 0, 0], [0, 0, 0, 1]])
    two_step = rz90 @ a21_prime
    link = MODEL.links()[1]
    got = link.transform(17.0)
    np.testing.assert_allclose(got[:3, :3], two_step[:3, :3], atol=1e-15)
    np.testing.assert_allclose(got[:3, 3], [-A2 * s2, A2 * c2, 0.0], atol=1e-12)


def test_pose_at_q_zero_is_the_hand_derived_one() -> None:
    """All joints 0 (section 4.4, Figure 4.5): x6 = z0, y6 = -x0, z6 = -y0, so
    P = (d3 + Lb, -Ly, d1 + a2) and R = Rz(0)·Ry(-90°)·Rx(90°)."""
    np.testing.assert_allclose(MODEL.pose(np.zeros(6)),
                               [200.0, -440.0, 1187.45, 90.0, -90.0, 0.0], atol=1e-9)
    t = MODEL.forward(np.zeros(6))
    np.testing.assert_allclose(t[:3, :3], [[0, -1, 0], [0, 0, -1], [1, 0, 0]], atol=1e-15)
    np.testing.assert_allclose(MODEL.pose([1000.0, 0, 0, 0, 0, 0])[:3], [1200.0, -440.0, 1187.45],
                               atol=1e-9)


@pytest.mark.parametrize("batch", [(), (5,), (2, 3), (1, 4, 2)])
def test_forward_and_pose_are_batch_first(batch: tuple[int, ...]) -> None:
    q = random_joints(int(np.prod(batch)), seed=14).reshape(*batch, 6)
    assert MODEL.forward(q).shape == (*batch, 4, 4)
    assert MODEL.pose(q).shape == (*batch, 6)
    np.testing.assert_allclose(MODEL.pose(q).reshape(-1, 6), MODEL.pose(q.reshape(-1, 6)))


def test_pose_angles_give_the_forward_rotation() -> None:
    q = random_joints(5000, seed=15)
    np.testing.assert_allclose(target(MODEL.pose(q)), MODEL.forward(q), atol=1e-9)


@pytest.mark.parametrize("q", [np.zeros(5), np.zeros((3, 7)), 1.0])
def test_forward_rejects_the_wrong_shape(q: object) -> None:
    with pytest.raises(ValueError, match=r"\(\.\.\., 6\)"):
        MODEL.forward(q)


# --- inverse: round trips ------------------------------------------------------------------


def test_batch_round_trip_finds_every_in_limit_configuration() -> None:
    q = random_joints(20_000, seed=20)
    p = MODEL.pose(q)
    result = MODEL.inverse_batch(p, near=q)
    assert result.reachable.all()
    np.testing.assert_allclose(result.best, q, atol=1e-6)
    solutions = result.solutions[result.valid]
    assert_in_limits(solutions)
    rows = np.broadcast_to(np.arange(len(q))[:, None], result.valid.shape)[result.valid]
    assert_reaches(solutions, p[rows])
    assert np.isnan(result.solutions[~result.valid]).all()


def test_batch_with_the_default_near_reaches_every_pose() -> None:
    q = random_joints(20_000, seed=21)
    p = MODEL.pose(q)
    result = MODEL.inverse_batch(p)
    assert result.reachable.all()
    assert_in_limits(result.best)
    assert_reaches(result.best, p)


def test_single_inverse_returns_q_first_and_every_branch_reaches_the_pose() -> None:
    for q in random_joints(300, seed=22):
        p = MODEL.pose(q)
        sols = MODEL.inverse(p, near=q)
        np.testing.assert_allclose(sols[0], q, atol=1e-6)
        assert_in_limits(sols)
        assert_reaches(sols, p)


def test_single_inverse_agrees_with_the_batch() -> None:
    q = random_joints(300, seed=23)
    near = random_joints(300, seed=24)
    p = MODEL.pose(q)
    result = MODEL.inverse_batch(p, near=near)
    for i in range(len(q)):
        sols = MODEL.inverse(p[i], near=near[i])
        batch = result.solutions[i][result.valid[i]]
        assert len(sols) == len(batch)
        np.testing.assert_allclose(sols[0], result.best[i], atol=1e-9)
        order = np.lexsort(sols.T[::-1])
        np.testing.assert_allclose(sols[order], batch[np.lexsort(batch.T[::-1])], atol=1e-9)


def test_solutions_are_distinct_and_sorted_nearest_first() -> None:
    q = random_joints(300, seed=25)
    near = random_joints(300, seed=26)
    counts = []
    for qi, ni in zip(q, near, strict=True):
        sols = MODEL.inverse(MODEL.pose(qi), near=ni)
        distance = (np.abs(sols - ni) * WEIGHTS).sum(axis=1)
        assert np.all(np.diff(distance) >= 0)
        gaps = np.abs(sols[:, None] - sols[None]).max(axis=-1) + np.eye(len(sols))
        assert gaps.min() > 1e-6
        counts.append(len(sols))
    assert max(counts) > 1, "some poses have a second in-limit branch"


def test_distance_is_degrees_plus_in_out_over_mm_per_degree() -> None:
    near = np.array([1500.0, 0.0, 0.0, 0.0, 0.0, 0.0])
    q = np.array([[1510.0, 1.0, -2.0, 0.0, 0.0, 3.0], [1500.0, 0.0, 0.0, 0.0, 0.0, 0.0]])
    np.testing.assert_allclose(unimate.distance(q, near), [10 / MM_PER_DEGREE + 6.0, 0.0])
    assert MM_PER_DEGREE == 10.0


@settings(max_examples=150, deadline=None)
@given(st.tuples(*(st.floats(lo, hi) for lo, hi in zip(MODEL.lower, MODEL.upper, strict=True))))
def test_any_in_limit_configuration_round_trips(q: tuple[float, ...]) -> None:
    q = np.array(q)
    p = MODEL.pose(q)
    if abs(math.sin(math.radians(q[4]))) > 1e-3:
        sols = MODEL.inverse(p, near=q)
        np.testing.assert_allclose(sols[0], q, atol=1e-6)
        assert_reaches(sols, p)
        return
    # ill-conditioned near the wrist singularity (module docstring): the pose is met,
    # the joints may move along the near-family and so past a limit they sit on
    try:
        sols = MODEL.inverse(p, near=q)
    except Unreachable:
        assert np.minimum(q - LOWER, UPPER - q).min() < 1e-2
        return
    assert_reaches(sols, p)


@pytest.mark.parametrize("rotate", [90.0, -90.0, 89.999999, 110.0, -110.0, 0.0])
def test_rotate_at_and_around_90_degrees_round_trips(rotate: float) -> None:
    """The listing divides by cos θ1 and gets d3 wrong at θ1 = ±90° (errata #9)."""
    q = np.array([1500.0, rotate, 12.0, -35.0, 70.0, 150.0])
    sols = MODEL.inverse(MODEL.pose(q), near=q)
    np.testing.assert_allclose(sols[0], q, atol=1e-6)
    assert_reaches(sols, MODEL.pose(q))


@pytest.mark.parametrize("q", [
    [976.0, -110.0, -27.0, -110.0, -169.0, -180.0],
    [2041.0, 110.0, 30.0, 110.0, 174.0, 180.0],
    [2041.0, -110.0, 30.0, -110.0, 174.0, -180.0],
])
def test_configurations_on_the_limits_round_trip_onto_the_limits(q: list[float]) -> None:
    sols = MODEL.inverse(MODEL.pose(q), near=q)
    np.testing.assert_allclose(sols[0], q, atol=1e-6)
    assert_in_limits(sols)


def test_swivel_at_180_takes_the_copy_nearest_near() -> None:
    q = np.array([1500.0, 10.0, 5.0, 20.0, 45.0, 180.0])
    p = MODEL.pose(q)
    assert MODEL.inverse(p, near=[*q[:5], 170.0])[0, 5] == pytest.approx(180.0)
    assert MODEL.inverse(p, near=[*q[:5], -170.0])[0, 5] == pytest.approx(-180.0)


def test_other_geometry_round_trips() -> None:
    model = replace(MODEL, d1=900.0, a2=80.0, lb=150.0, ly=300.0)
    q = random_joints(2000, seed=27)
    result = model.inverse_batch(model.pose(q), near=q)
    np.testing.assert_allclose(result.best, q, atol=1e-6)


# --- singularities -------------------------------------------------------------------------


def test_home_pose_round_trips() -> None:
    """All angles 0 (β = -90°, and θ5 = 0: wrist singular) with In/Out inside its limits."""
    home = np.array([1000.0, 0.0, 0.0, 0.0, 0.0, 0.0])
    p = MODEL.pose(home)
    np.testing.assert_allclose(p, [1200.0, -440.0, 1187.45, 90.0, -90.0, 0.0], atol=1e-9)
    for near in (home, None):
        sols = MODEL.inverse(p, near=near)
        np.testing.assert_allclose(sols[0], home, atol=1e-9)
    np.testing.assert_allclose(MODEL.inverse_batch(p).best, home, atol=1e-9)


def test_wrist_singularity_holds_swivel_or_bend_at_near() -> None:
    """θ5 = 0: the pose fixes only θ2 + θ4 + θ6 and the wrist point; the solutions are
    the family members with near's Swivel and with near's Bend (module docstring)."""
    q = np.array([1400.0, 30.0, 10.0, 40.0, 0.0, 20.0])
    p = MODEL.pose(q)
    sols = MODEL.inverse(p, near=q)
    assert len(sols) == 1  # both holds give q itself, kept once
    np.testing.assert_allclose(sols[0], q, atol=1e-9)
    for bend, swivel in [(40.0, -20.0), (40.0, 35.0), (0.0, 0.0), (-60.0, 120.0)]:
        near = np.array([1500.0, 0.0, 0.0, bend, 0.0, swivel])
        sols = MODEL.inverse(p, near=near)
        assert_reaches(sols, p)
        assert_in_limits(sols)
        held = np.isclose(sols[:, 5], swivel, atol=1e-9) | np.isclose(sols[:, 3], bend, atol=1e-9)
        assert held.all()
        result = MODEL.inverse_batch(p, near=near)
        np.testing.assert_allclose(result.best, sols[0], atol=1e-9)
        assert result.valid.sum() == len(sols)


def test_wrist_singularity_falls_back_to_bend_when_swivel_cannot_be_held() -> None:
    q = np.array([1400.0, 30.0, 10.0, 40.0, 0.0, 20.0])
    near = np.array([1400.0, 30.0, 10.0, 40.0, 0.0, -60.0])  # Swivel -60° needs Bend ≈ 121°
    np.testing.assert_allclose(MODEL.inverse(MODEL.pose(q), near=near), [q], atol=1e-9)


def test_wrist_singularity_unreachable_with_this_near_says_so() -> None:
    p = MODEL.pose([976.0, 0.0, 30.0, 0.0, 0.0, 0.0])
    with pytest.raises(Unreachable, match=r"^outside the joint limits: Up/Down would be 39\.1°.*"
                                          r"wrist singular: Swivel held at 120° or Bend at -110°"):
        MODEL.inverse(p, near=[976.0, 0.0, 30.0, -110.0, 0.0, 120.0])
    assert not MODEL.inverse_batch(p, near=[976.0, 0.0, 30.0, -110.0, 0.0, 120.0]).reachable


def test_exactly_singular_poses_batch_matches_single() -> None:
    q = random_joints(500, seed=28)
    q[:, 4] = 0.0
    near = random_joints(500, seed=29)
    p = MODEL.pose(q)
    result = MODEL.inverse_batch(p, near=near)
    assert result.reachable.mean() > 0.8
    for i in range(len(q)):
        try:
            sols = MODEL.inverse(p[i], near=near[i])
        except Unreachable:
            assert not result.reachable[i]
            continue
        np.testing.assert_allclose(sols[0], result.best[i], atol=1e-9)
        assert len(sols) == result.valid[i].sum()
        assert_reaches(sols, p[i])


@pytest.mark.parametrize("yaw", [1e-12, -1e-9, 1e-7, 1e-4])
def test_near_the_wrist_singularity_every_branch_still_reaches_the_pose(yaw: float) -> None:
    q = np.array([1400.0, 30.0, 10.0, 40.0, yaw, 20.0])
    p = MODEL.pose(q)
    sols = MODEL.inverse(p, near=q)
    assert_reaches(sols, p)
    assert_in_limits(sols)


def test_wrist_point_on_the_rotate_axis_holds_rotate_at_near() -> None:
    """The wrist point's reach from the Rotate axis is c2·d3 - a2·s2 + Lb·c(θ2 + θ4)
    (App. A (8)), zero at θ2 = 0, d3 = -Lb·cθ4: outside the Unimate's In/Out limits, so
    shown on a model without them. θ1 is then free and kept at near's."""
    model = replace(MODEL, lower=(-3000.0, -180.0, -180.0, -180.0, -180.0, -180.0),
                    upper=(3000.0, 180.0, 180.0, 180.0, 180.0, 180.0))
    q = np.array([-LB * math.cos(math.radians(30.0)), 25.0, 0.0, 30.0, 50.0, 10.0])
    t = model.forward(q)
    assert np.hypot(*(t[:2, 3] - LY * t[:2, 2])) < 1e-9
    p = model.pose(q)
    np.testing.assert_allclose(model.inverse(p, near=q)[0], q, atol=1e-6)
    np.testing.assert_allclose(model.inverse_batch(p, near=q).best, q, atol=1e-6)
    other = model.inverse(p, near=[q[0], -40.0, *q[2:]])
    assert other[0, 1] == pytest.approx(-40.0)
    assert_reaches(other, p, model)


# --- inverse: unreachable poses and bad input ----------------------------------------------


def test_far_pose_is_out_of_reach_beyond_in_out() -> None:
    q = np.array([2041.0, 10.0, 5.0, 0.0, 30.0, 0.0])
    p = MODEL.pose(q)
    p[:3] *= 1.5
    with pytest.raises(Unreachable, match=r"^out of reach: In/Out would be [\d.]+ mm, "
                                          r"[\d.]+ mm beyond 976…2041 mm"):
        MODEL.inverse(p)
    assert not MODEL.inverse_batch(p).reachable
    assert np.isnan(MODEL.inverse_batch(p).best).all()


def test_close_pose_is_out_of_reach_short_of_in_out() -> None:
    p = MODEL.pose([976.0, 0.0, 0.0, 0.0, 30.0, 0.0])
    p[0] -= 300.0
    with pytest.raises(Unreachable, match=r"^out of reach: In/Out would be [\d.]+ mm, "
                                          r"[\d.]+ mm short of 976…2041 mm"):
        MODEL.inverse(p)


def test_pose_outside_a_joint_limit_names_the_joint_and_value() -> None:
    q = np.array([1500.0, 20.0, 35.0, 10.0, 40.0, 30.0])
    with pytest.raises(Unreachable, match=r"^outside the joint limits: Up/Down would be 35\.0°, "
                                          r"outside -27…30°$"):
        MODEL.inverse(MODEL.pose(q), near=q)


def test_arm_point_inside_the_a2_offset_has_no_real_up_down_root() -> None:
    """Wrist point 100 mm out from the shoulder, tool along -y0 with the home orientation
    (wrist singular): with Swivel at 0 the arm point is 100 mm from the Up/Down axis, and
    with Bend at 0 the offset is a2 itself; both inside a2."""
    p = np.array([100.0, -440.0, 1066.8, 90.0, -90.0, 0.0])
    with pytest.raises(Unreachable, match=r"^out of reach: the arm point is 100\.0 mm from the "
                                          r"Up/Down axis, inside the a2 = 120.65 mm offset"):
        MODEL.inverse(p)
    assert not MODEL.inverse_batch(p).reachable


def test_unreachable_is_a_value_error() -> None:
    assert issubclass(Unreachable, ValueError)


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
@pytest.mark.parametrize("where", [0, 4])
def test_nan_and_inf_raise_value_error(bad: float, where: int) -> None:
    p = MODEL.pose(np.array([1500.0, 0, 0, 0, 30, 0]))
    p[where] = bad
    with pytest.raises(ValueError, match="finite") as info:
        MODEL.inverse(p)
    assert not isinstance(info.value, Unreachable)
    with pytest.raises(ValueError, match="finite"):
        MODEL.inverse_batch(np.stack([p, p]))
    with pytest.raises(ValueError, match="finite"):
        MODEL.inverse(MODEL.pose(np.array([1500.0, 0, 0, 0, 30, 0])), near=p)
    with pytest.raises(ValueError, match="finite"):
        MODEL.inverse_batch(np.zeros(6), near=p)
    with pytest.raises(ValueError, match="finite"):
        MODEL.forward(p)


@pytest.mark.parametrize("p", [np.zeros(5), np.zeros((2, 6)), "abc"])
def test_single_inverse_rejects_anything_but_one_pose(p: object) -> None:
    with pytest.raises(ValueError):
        MODEL.inverse(p)


def test_inputs_are_not_mutated() -> None:
    """The listing converts its input angles to radians in place (errata #10)."""
    q = random_joints(50, seed=30)
    p = MODEL.pose(q)
    q_before, p_before = q.copy(), p.copy()
    MODEL.forward(q)
    MODEL.pose(q)
    MODEL.inverse(p[0], near=q[0])
    MODEL.inverse_batch(p, near=q)
    MODEL.inverse_batch(p, near=q[0])
    np.testing.assert_array_equal(q, q_before)
    np.testing.assert_array_equal(p, p_before)
    as_list = p[0].tolist()
    MODEL.inverse(as_list)
    assert as_list == p_before[0].tolist()


@pytest.mark.parametrize("batch", [(), (4,), (2, 3)])
def test_inverse_batch_shapes(batch: tuple[int, ...]) -> None:
    n = int(np.prod(batch))
    q = random_joints(n, seed=31).reshape(*batch, 6)
    p = MODEL.pose(q)
    for near in (None, q[(0,) * len(batch)] if batch else q, q):
        result = MODEL.inverse_batch(p, near=near)
        assert result.solutions.shape == (*batch, 8, 6)
        assert result.valid.shape == (*batch, 8)
        assert result.best.shape == (*batch, 6)
        assert result.reachable.shape == batch
        assert result.reachable.all()


def test_inverse_batch_rejects_a_mismatched_near() -> None:
    with pytest.raises(ValueError, match="near"):
        MODEL.inverse_batch(np.zeros((3, 6)), near=np.zeros((2, 6)))


def test_model_rejects_bad_limits() -> None:
    with pytest.raises(ValueError, match="Up/Down limits 30…-27"):
        replace(MODEL, lower=(976.0, -110.0, 30.0, -110.0, -169.0, -180.0),
                upper=(2041.0, 110.0, -27.0, 110.0, 174.0, 180.0))
    with pytest.raises(ValueError, match="6 lower and 6 upper"):
        replace(MODEL, lower=(0.0,) * 5)
