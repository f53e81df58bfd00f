"""Excitation profiles for tracking_actuate: shape, minimum PWM, sizing, refusals."""

from __future__ import annotations

import numpy as np
import pytest

from control.identify import excitation
from control.identify.excitation import chirp, combine, lfsr_signs, prbs, steps, worst_case
from control.identify.sysid import nominal
from hw.machine import load_machine

UNIMATE = load_machine("unimate2000b")
MIDDLE = np.array(UNIMATE.lower) / 2 + np.array(UNIMATE.upper) / 2
GENERATORS = {"steps": steps, "prbs": prbs, "chirp": chirp}


@pytest.mark.parametrize("kind", GENERATORS)
@pytest.mark.parametrize("joint", range(6))
def test_every_default_profile_drives_one_joint_above_its_minimum_pwm(kind: str,
                                                                      joint: int) -> None:
    profile = GENERATORS[kind](UNIMATE, joint, MIDDLE)
    line = nominal(UNIMATE.joints[joint])
    others = np.delete(profile.duty, joint, axis=1)
    assert profile.joints == (joint,) and not others.any()
    u = profile.duty[:, joint]
    moving = u != 0.0
    assert moving.mean() > 0.9  # the chirp rests a little at its zero crossings
    assert np.all(u[u > 0] > line.d_pos) and np.all(-u[u < 0] > line.d_neg)
    assert np.all(np.abs(u) <= 100.0)
    np.testing.assert_array_equal(u, np.round(u))  # whole UPP steps: played as recorded
    assert (u > 0).any() and (u < 0).any()
    assert profile.meta["excitation"] == kind and profile.meta["joint"] == line.name


@pytest.mark.parametrize("kind", GENERATORS)
@pytest.mark.parametrize("joint", range(6))
def test_the_worst_case_travel_stays_inside_the_limits(kind: str, joint: int) -> None:
    profile = GENERATORS[kind](UNIMATE, joint, MIDDLE)
    spec = UNIMATE.joints[joint]
    gap = excitation.CLEARANCE_FRACTION * (spec.upper - spec.lower)
    assert MIDDLE[joint] + profile.low[:, joint].min() >= spec.lower + gap
    assert MIDDLE[joint] + profile.high[:, joint].max() <= spec.upper - gap


def test_the_nominal_travel_lies_inside_the_worst_case_envelope() -> None:
    profile = prbs(UNIMATE, "rotate", MIDDLE)
    line = nominal(UNIMATE.joints[1])
    travel = np.cumsum(line.steady(profile.duty[:, 1])) * profile.dt
    assert np.all(profile.low[:, 1] <= travel + 1e-9)
    assert np.all(travel <= profile.high[:, 1] + 1e-9)


def test_the_worst_case_moves_faster_the_bad_way_and_slower_back() -> None:
    line = nominal(UNIMATE.joints[1])
    duty = np.array([50.0] * 10 + [-50.0] * 10)
    low, high = worst_case(line, duty, 0.01, margin=1.5, slack=3.0)
    fast = 1.5 * line.k_pos * (50.0 - line.d_pos + 3.0) * 0.01
    slow = line.k_neg / 1.5 * (50.0 - line.d_neg - 3.0) * 0.01
    assert high[9] == pytest.approx(10 * fast)
    assert high[-1] == pytest.approx(10 * fast - 10 * slow)
    slow_up = line.k_pos / 1.5 * (50.0 - line.d_pos - 3.0) * 0.01
    fast_down = 1.5 * line.k_neg * (50.0 - line.d_neg + 3.0) * 0.01
    assert low[-1] == pytest.approx(10 * slow_up - 10 * fast_down)


def test_the_prbs_keeps_its_nominal_travel_bounded_and_differs_by_seed() -> None:
    line = nominal(UNIMATE.joints[2])
    a = prbs(UNIMATE, "updown", MIDDLE, duration=6.0, seed=1)
    b = prbs(UNIMATE, "updown", MIDDLE, duration=6.0, seed=2)
    assert not np.array_equal(a.duty, b.duty)
    travel = np.cumsum(line.steady(a.duty[:, 2])) * a.dt
    room = MIDDLE[2] - UNIMATE.joints[2].lower
    assert np.abs(travel).max() < excitation.BALANCE * room
    bits = a.duty[::50, 2]
    assert len(np.unique(np.abs(bits))) > 5  # multi-level: the whole velocity line is seen


def test_lfsr_signs_are_a_maximal_length_sequence() -> None:
    signs = lfsr_signs(31, seed=3)  # a 5-bit register: one whole period
    assert signs.sum() == 1.0  # 16 ones and 15 zeros
    circular = np.array([signs @ np.roll(signs, lag) for lag in range(31)])
    assert circular[0] == 31.0 and np.all(circular[1:] == -1.0)  # white, as an m-sequence is
    assert not np.array_equal(lfsr_signs(31, seed=3), lfsr_signs(31, seed=4))
    with pytest.raises(ValueError, match="at most 16 bits"):
        lfsr_signs(70_000)


def test_the_chirp_sweeps_up_in_frequency_from_a_sized_start() -> None:
    profile = chirp(UNIMATE, "swivel", MIDDLE, duration=4.0, f1=8.0)
    u = profile.duty[:, 5]
    crossings = np.flatnonzero(np.diff(np.sign(u[u != 0])) != 0)
    gaps = np.diff(crossings)
    assert gaps[:3].mean() > 3 * gaps[-3:].mean()
    assert 0.0 < profile.meta["f0_hz"] < 8.0
    with pytest.raises(ValueError, match="0 < f0 < f1"):
        chirp(UNIMATE, "swivel", MIDDLE, f0=9.0, f1=8.0)


def test_steps_alternate_direction_at_rising_levels() -> None:
    profile = steps(UNIMATE, "bend", MIDDLE, levels=3, hold_s=0.2)
    levels = profile.duty[::200, 3]
    assert len(levels) == 6 and np.all(np.sign(levels) == [1, -1, 1, -1, 1, -1])
    assert np.all(np.diff(np.abs(levels[::2])) > 0)


def test_an_amplitude_inside_the_minimum_pwm_is_refused() -> None:
    with pytest.raises(ValueError, match=r"In/Out: amplitude 20 % does not clear its minimum "
                                         r"PWM .*use more than"):
        prbs(UNIMATE, "inout", MIDDLE, amplitude=20.0)


def test_a_profile_that_could_reach_an_end_stop_is_refused() -> None:
    near_top = MIDDLE.copy()
    near_top[2] = 25.0
    with pytest.raises(ValueError, match=r"Up/Down: the profile could reach .* beyond "
                                         r"-27…30° less .* clearance: lower the amplitude"):
        prbs(UNIMATE, "updown", near_top, duration=20.0)


def test_a_coupled_reading_is_checked_in_both_coordinates() -> None:
    start = MIDDLE.copy()
    start[3], start[4] = 60.0, 150.0  # Yaw actuator at 90°, reading at 150° (Bend included)
    with pytest.raises(ValueError, match="Yaw: the profile could reach"):
        prbs(UNIMATE, "yaw", start, duration=4.0)
    high_yaw = MIDDLE.copy()
    high_yaw[4] = 120.0
    yaw = steps(UNIMATE, "yaw", high_yaw, amplitude=40.0)
    bend = steps(UNIMATE, "bend", high_yaw)
    assert combine(yaw, machine=UNIMATE).joints == (4,)
    with pytest.raises(ValueError, match=r"Yaw: .*worst case of its reading, which includes Bend"):
        combine(bend, yaw, machine=UNIMATE)
    with pytest.raises(ValueError, match="different start positions"):
        combine(steps(UNIMATE, "bend", MIDDLE), yaw, machine=UNIMATE)


def test_combine_runs_joints_together_and_refuses_a_joint_twice() -> None:
    profiles = [prbs(UNIMATE, j, MIDDLE, duration=2.0 + j, seed=j) for j in range(6)]
    both = combine(*profiles, machine=UNIMATE)
    assert both.joints == tuple(range(6)) and len(both.duty) == len(profiles[-1].duty)
    for j, p in enumerate(profiles):
        np.testing.assert_array_equal(both.duty[:len(p.duty), j], p.duty[:, j])
        assert not both.duty[len(p.duty):, j].any()
    with pytest.raises(ValueError, match="same joint"):
        combine(profiles[0], profiles[0], machine=UNIMATE)


def test_bad_arguments_are_refused() -> None:
    with pytest.raises(ValueError, match="start must be 6"):
        prbs(UNIMATE, 0, MIDDLE[:3])
    with pytest.raises(ValueError, match="bit_s must be at least one sample"):
        prbs(UNIMATE, 0, MIDDLE, bit_s=0.0)
    with pytest.raises(ValueError, match="margin must be at least 1"):
        steps(UNIMATE, 0, MIDDLE, margin=0.5)
    with pytest.raises(KeyError, match="no joint 'elbow'"):
        steps(UNIMATE, "elbow", MIDDLE)
