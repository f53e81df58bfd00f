"""The transmission: encoder decode and calibration, coupling, polarity and down-scaling,
per tick and in batch, checked against the machine files' numbers (rtshare.h, section 3.6)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from hw.gray import binary_to_gray
from hw.machine import EncoderCal, MachineError, load_machine
from hw.transmission import Transmission, output_min_pwm, output_of, valve_duty

UNIMATE = load_machine("unimate2000b")
RIG = load_machine("rig")
YAW, BEND = 4, 3

finite = st.floats(-1e4, 1e4, allow_nan=False)


def test_a_gray_word_decodes_through_rtshare_calibration() -> None:
    t = Transmission(UNIMATE)
    out = [0.0] * 6
    counts = [1000, 4000, 2000, 1800, 3900, 2500]
    t.actuators_from_words([binary_to_gray(c) for c in counts], [0] * 6, out)
    for j, c in enumerate(counts):
        cal = UNIMATE.joints[j].encoder
        assert out[j] == pytest.approx(cal.gradient * c + cal.constant)
        assert t.count_of(j, out[j]) == pytest.approx(c)


def test_a_word_wider_than_the_table_still_decodes() -> None:
    t = Transmission(replace(UNIMATE, encoder_bits=24))
    assert t.gray_decode == []
    out = [0.0] * 6
    t.actuators_from_words([binary_to_gray(1 << 20)] * 6, [0] * 6, out)
    assert out[0] == pytest.approx(UNIMATE.joints[0].encoder.gradient * (1 << 20)
                                   + UNIMATE.joints[0].encoder.constant)


def test_quadrature_counts_are_taken_from_the_zero() -> None:
    t = Transmission(RIG)
    out = [0.0]
    cal = RIG.joints[0].encoder
    t.actuators_from_words([1500], [500], out)
    assert out[0] == pytest.approx(cal.gradient * 1000 + cal.constant)


def test_the_yaw_reading_includes_bend_and_the_inverse_takes_it_out() -> None:
    t = Transmission(UNIMATE)
    a = [1500.0, 10.0, 5.0, 30.0, 20.0, -40.0]
    q = [0.0] * 6
    t.joints_from_actuators(a, q)
    assert q[YAW] == pytest.approx(20.0 + UNIMATE.joints[YAW].encoder.coupling * 30.0)
    assert [q[j] for j in (0, 1, 2, 3, 5)] == [a[j] for j in (0, 1, 2, 3, 5)]
    back = [0.0] * 6
    t.actuators_from_joints(q, back)
    assert back == pytest.approx(a)


@given(st.lists(finite, min_size=6, max_size=6))
def test_the_batch_maps_agree_with_the_per_tick_maps(a: list[float]) -> None:
    t = Transmission(UNIMATE)
    q = [0.0] * 6
    t.joints_from_actuators(a, q)
    assert t.joints_of(np.array([a, a]))[1] == pytest.approx(q)
    assert t.actuators_of(np.array(q)) == pytest.approx(a, abs=1e-9)


def test_a_chain_of_couplings_is_evaluated_partner_first() -> None:
    joints = list(UNIMATE.joints)
    joints[BEND] = replace(joints[BEND], encoder=EncoderCal(0.06, -110.0, YAW, 0.5))
    joints[YAW] = replace(joints[YAW], encoder=EncoderCal(0.08, -169.0, 5, 2.0))
    t = Transmission(replace(UNIMATE, joints=tuple(joints)))
    q = [0.0] * 6
    t.joints_from_actuators([0.0, 0.0, 0.0, 1.0, 1.0, 1.0], q)
    assert q[YAW] == pytest.approx(1.0 + 2.0 * 1.0)
    assert q[BEND] == pytest.approx(1.0 + 0.5 * q[YAW])


def test_a_cycle_of_couplings_is_a_machine_error() -> None:
    joints = list(UNIMATE.joints)
    joints[BEND] = replace(joints[BEND], encoder=EncoderCal(0.06, -110.0, YAW, 0.5))
    with pytest.raises(MachineError, match="cycle"):
        Transmission(replace(UNIMATE, joints=tuple(joints)))


def test_reading_bounds_include_the_partners_travel() -> None:
    t = Transmission(UNIMATE)
    low = np.zeros((1, 6))
    high = np.zeros((1, 6))
    low[0, BEND], high[0, BEND] = -2.0, 3.0
    low[0, YAW], high[0, YAW] = -1.0, 1.0
    lo, hi = t.reading_bounds(low, high)
    c = UNIMATE.joints[YAW].encoder.coupling
    assert lo[0, YAW] == pytest.approx(-1.0 + min(-2.0 * c, 3.0 * c))
    assert hi[0, YAW] == pytest.approx(1.0 + max(-2.0 * c, 3.0 * c))
    assert (lo[0, BEND], hi[0, BEND]) == (-2.0, 3.0)


def test_valve_duty_scales_downward_output_then_applies_polarity() -> None:
    (ram,) = RIG.joints
    assert valve_duty(ram, 50.0) == 50.0
    assert valve_duty(ram, -50.0) == pytest.approx(-26.9)  # 0.538·(−50), section 3.6
    inout = UNIMATE.joints[0]  # polarity −1, errata #17
    assert valve_duty(inout, 50.0) == -50.0
    assert valve_duty(inout, -50.0) == 50.0
    assert valve_duty(inout, 0.0) == 0.0


@given(st.floats(-100, 100, allow_nan=False))
def test_valve_duties_of_every_joint_are_valve_duty_and_output_of_undoes_it(u: float) -> None:
    for machine in (UNIMATE, RIG):
        t = Transmission(machine)
        out = [0.0] * machine.n_joints
        t.valve_duties([u] * machine.n_joints, out)
        for joint, valve in zip(machine.joints, out, strict=True):
            assert valve == valve_duty(joint, u)
            assert output_of(joint, valve) == pytest.approx(u)


def test_output_min_pwm_follows_polarity() -> None:
    for joint in UNIMATE.joints:
        up, down = output_min_pwm(joint)
        assert valve_duty(joint, up) in (joint.min_pwm_pos, -joint.min_pwm_neg)
        assert (up if joint.polarity < 0 else down) == joint.min_pwm_neg
