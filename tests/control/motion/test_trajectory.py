"""Joint-space via-point trajectories: continuity, limits, monotone segments, refusals."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from control.motion.trajectory import MONOTONE_CAP, peak_ratios, via_path, via_velocities
from hw.machine import load_machine

UNIMATE = load_machine("unimate2000b")
DT = UNIMATE.sample_time_s
VMAX = np.array([j.max_speed for j in UNIMATE.joints])
AMAX = np.array([j.max_accel for j in UNIMATE.joints])
LOWER, UPPER = np.array(UNIMATE.lower), np.array(UNIMATE.upper)
VIAS = np.array([
    [1500.0, 0.0, 0.0, 0.0, 0.0, 0.0],
    [1700.0, 30.0, 10.0, -20.0, 0.0, 90.0],
    [1600.0, 60.0, 10.0, 20.0, 30.0, -90.0],
    [1200.0, -30.0, -20.0, 20.0, 30.0, 0.0],
])


def sampled_speed_and_accel(q: np.ndarray, dt: float = DT) -> tuple[np.ndarray, np.ndarray]:
    """Peak |Δq|/dt and |Δ²q|/dt² per joint of a sampled path: what the loop is asked to do."""
    return (np.abs(np.diff(q, axis=0)).max(axis=0, initial=0.0) / dt,
            np.abs(np.diff(q, n=2, axis=0)).max(axis=0, initial=0.0) / dt**2)  # ≥ 3 samples


def test_passes_through_every_via_point_on_a_sample() -> None:
    path = via_path(VIAS, UNIMATE)
    assert path.via_index[0] == 0 and path.via_index[-1] == len(path.t) - 1
    np.testing.assert_array_equal(path.q[path.via_index], VIAS)
    np.testing.assert_allclose(path.via_t, path.via_index * DT)
    np.testing.assert_allclose(path.t, np.arange(len(path.t)) * DT)


def test_starts_and_ends_at_rest() -> None:
    path = via_path(VIAS, UNIMATE)
    for k in (0, -1):
        np.testing.assert_allclose(path.qd[k], 0.0, atol=1e-9)
        np.testing.assert_allclose(path.qdd[k], 0.0, atol=1e-9)


def test_position_velocity_and_acceleration_are_continuous() -> None:
    path = via_path(VIAS, UNIMATE)
    # one sample moves a joint by at most its speed limit, the velocity by at most the
    # acceleration limit: no step anywhere, in particular not at the via points
    assert np.all(np.abs(np.diff(path.q, axis=0)) <= VMAX * DT * (1 + 1e-9))
    assert np.all(np.abs(np.diff(path.qd, axis=0)) <= AMAX * DT * (1 + 1e-6))
    # the analytic velocity is the derivative of the sampled position
    central = (path.q[2:] - path.q[:-2]) / (2 * DT)
    np.testing.assert_allclose(central, path.qd[1:-1], atol=1e-3 * VMAX.max())
    # nor a step in acceleration: within a sample it changes by a few % of its limit at most
    assert np.all(np.abs(np.diff(path.qdd, axis=0)) <= 0.1 * AMAX)


def test_speed_and_acceleration_limits_hold_and_are_reached() -> None:
    path = via_path(VIAS, UNIMATE)
    speed, accel = sampled_speed_and_accel(path.q)
    assert np.all(speed <= VMAX * (1 + 1e-9))
    assert np.all(accel <= AMAX * (1 + 1e-6))
    # time-optimal-ish: every segment has a joint at one of its limits (within rounding)
    h = np.diff(path.via_t)
    assert np.all(peak_ratios(VIAS, h, VMAX, AMAX).max(axis=1) > 0.97)


def test_speed_fraction_slows_the_path_down() -> None:
    fast = via_path(VIAS, UNIMATE)
    slow = via_path(VIAS, UNIMATE, speed_fraction=0.5)
    speed, accel = sampled_speed_and_accel(slow.q)
    assert np.all(speed <= 0.5 * VMAX * (1 + 1e-9)) and np.all(accel <= 0.5 * AMAX * (1 + 1e-6))
    assert slow.duration > fast.duration


def test_segments_never_overshoot_their_via_points() -> None:
    path = via_path(VIAS, UNIMATE)
    for i in range(len(VIAS) - 1):
        segment = path.q[path.via_index[i]:path.via_index[i + 1] + 1]
        low = np.minimum(VIAS[i], VIAS[i + 1])
        high = np.maximum(VIAS[i], VIAS[i + 1])
        assert np.all(segment >= low - 1e-9) and np.all(segment <= high + 1e-9)


def test_a_joint_that_keeps_its_value_between_two_via_points_does_not_move() -> None:
    path = via_path(VIAS, UNIMATE)
    yaw = path.q[path.via_index[0]:path.via_index[1] + 1, 4]  # Yaw is 0 at via points 0 and 1
    np.testing.assert_array_equal(yaw, 0.0)


def test_via_velocity_is_zero_where_a_joint_reverses_and_capped_elsewhere() -> None:
    q = np.array([[0.0], [10.0], [5.0], [6.0], [100.0]])
    h = np.array([1.0, 1.0, 1.0, 1.0])
    v = via_velocities(q, h)[:, 0]
    assert v[0] == v[-1] == 0.0
    assert v[1] == 0.0 and v[2] == 0.0  # reversal at 10 and at 5
    assert 0.0 < v[3] <= MONOTONE_CAP * 1.0  # slopes 1 and 94: capped at twice the smaller


def test_given_durations_are_kept_and_checked() -> None:
    path = via_path(VIAS, UNIMATE, durations=[3.0, 4.0, 5.0])
    np.testing.assert_allclose(path.via_t, [0.0, 3.0, 7.0, 12.0])
    with pytest.raises(ValueError, match=r"segment from via point 2 to 3 .* too fast for "
                                         r"(In/Out|Rotate|Up/Down).*at least"):
        via_path(VIAS, UNIMATE, durations=[3.0, 4.0, 0.5])


@pytest.mark.parametrize(("row", "joint", "value"), [(1, 2, 35.0), (2, 0, 900.0)])
def test_a_via_point_outside_the_limits_is_refused_by_point_and_joint(row: int, joint: int,
                                                                       value: float) -> None:
    vias = VIAS.copy()
    vias[row, joint] = value
    name = UNIMATE.joints[joint].name
    with pytest.raises(ValueError, match=rf"via point {row}: {name} target .* is outside"):
        via_path(vias, UNIMATE)


def test_malformed_via_points_are_refused() -> None:
    with pytest.raises(ValueError, match="M ≥ 2"):
        via_path(VIAS[:1], UNIMATE)
    with pytest.raises(ValueError, match=r"\(M, 6\)"):
        via_path(VIAS[:, :5], UNIMATE)
    with pytest.raises(ValueError, match="via point 1: Rotate is nan"):
        via_path(np.vstack([VIAS[0], [1500, np.nan, 0, 0, 0, 0]]), UNIMATE)
    with pytest.raises(ValueError, match="via points 1 and 2 are the same"):
        via_path(np.vstack([VIAS[:2], VIAS[1:2]]), UNIMATE)
    with pytest.raises(ValueError, match="speed_fraction"):
        via_path(VIAS, UNIMATE, speed_fraction=1.5)


@settings(max_examples=30, deadline=None)
@given(st.lists(st.lists(st.floats(0.0, 1.0), min_size=6, max_size=6), min_size=2,
                max_size=5), st.floats(0.2, 1.0))
def test_any_via_points_inside_the_limits_give_a_smooth_path_inside_them(
        fractions: list[list[float]], speed: float) -> None:
    vias = LOWER + np.array(fractions) * (UPPER - LOWER)
    if np.any(np.all(np.diff(vias, axis=0) == 0.0, axis=1)):
        return
    path = via_path(vias, UNIMATE, speed_fraction=speed)
    assert np.all(path.q >= LOWER - 1e-9) and np.all(path.q <= UPPER + 1e-9)
    speed_seen, accel_seen = sampled_speed_and_accel(path.q)
    assert np.all(speed_seen <= speed * VMAX * (1 + 1e-9))
    assert np.all(accel_seen <= speed * AMAX * (1 + 1e-6))
    np.testing.assert_array_equal(path.q[path.via_index], vias)
