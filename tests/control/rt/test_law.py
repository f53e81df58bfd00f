"""Eq. 5.1 per joint: hand-computed sequences, one term at a time, then the output stages."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from control.rt.law import REST_EXIT_SAMPLES, DifferenceLaw, pi, pid, preset
from hw.machine import Coefficients, Machine, load_machine
from hw.transmission import output_min_pwm

RIG = load_machine("rig")
UNIMATE = load_machine("unimate2000b")


def plain_machine() -> Machine:
    """The rig with gain_unit 1 and no minimum PWM: the law's arithmetic with nothing around it."""
    (ram,) = RIG.joints
    return replace(RIG, joints=(replace(ram, gain_unit=1.0),))


def one_joint(kp: tuple[float, ...] = (), ki: float = 0.0, kd: float = 0.0,
              w: tuple[float, ...] = (), integral_limit: float = 50.0,
              duty_limit: float = 100.0) -> Coefficients:
    return Coefficients(name="test", note="test", kp=(kp,), ki=(ki,), kd=(kd,), w=(w,),
                        filter=(11.0, -18.0, 9.0, -2.0), filter_divisor=6.0,
                        integral_limit=integral_limit, duty_limit=duty_limit)


def run(law: DifferenceLaw, errors: list[float], j: int = 0) -> list[float]:
    return [law.update(j, e) for e in errors]


def test_p_only() -> None:
    law = DifferenceLaw(plain_machine(), one_joint(kp=(2.0,)), 0.001)
    # u = 2·e; the last, 2·60 = 120, saturates at 100 %
    assert run(law, [1.0, 3.0, -2.0, 60.0]) == pytest.approx([2.0, 6.0, -4.0, 100.0])


def test_pi_integrator_clamps_at_its_limit() -> None:
    law = DifferenceLaw(plain_machine(), one_joint(kp=(1.0,), ki=100.0, integral_limit=3.0), 0.01)
    # ki·e·Δt = 100·1·0.01 = 1 per tick: I = 1, 2, 3, 3 (clamped at 3), then e = −1: I = 2
    # u = e + I = 2, 3, 4, 4, 1
    assert run(law, [1.0, 1.0, 1.0, 1.0, -1.0]) == pytest.approx([2.0, 3.0, 4.0, 4.0, 1.0])
    assert law.state(0).integral == pytest.approx(2.0)


def test_derivative_of_a_ramp_is_its_slope() -> None:
    dt, kd = 0.001, 0.01
    law = DifferenceLaw(plain_machine(), one_joint(kd=kd), dt)
    # e(k) = 0.5·k: slope 0.5/Δt = 500 units/s, so kd·de/dt = 5 once four errors are known.
    # D = kd·(11e(k) − 18e(k−1) + 9e(k−2) − 2e(k−3)) / (6Δt) = kd·S/0.006 with S:
    #   k=1: 11·0.5                          = 5.5  → 9.1667 (history still zero)
    #   k=2: 11·1 − 18·0.5                   = 2    → 3.3333
    #   k=3: 11·1.5 − 18·1 + 9·0.5           = 3    → 5
    #   k=4: 11·2 − 18·1.5 + 9·1 − 2·0.5     = 3    → 5
    #   k=5: 11·2.5 − 18·2 + 9·1.5 − 2·1     = 3    → 5
    assert run(law, [0.5, 1.0, 1.5, 2.0, 2.5]) == pytest.approx(
        [9.166667, 3.333333, 5.0, 5.0, 5.0], rel=1e-6)


def test_rig_pid_of_eq_3_3_sees_error_in_encoder_counts() -> None:
    # the thesis's track set: {Kp, Kd, Ki} = {0.75, 0.002, 0.01}
    law = DifferenceLaw(RIG, RIG.coefficients["thesis_track"], RIG.sample_time_s)
    # 1 mm of error is 10 counts (gain_unit 0.1, errata #18); constant error, Δt = 1 ms:
    #   P = 0.75·10 = 7.5;  I = 0.01·10·0.001 = 0.0001 per tick;  D = 0.002·S/0.006
    #   k=1: S = 110                  D =  36.6667  u = 7.5 + 36.6667 + 0.0001 = 44.1668
    #   k=2: S = 110 − 180 = −70      D = −23.3333  u = 7.5 − 23.3333 + 0.0002 = −15.8331
    #   k=3: S = −70 + 90 = 20        D =   6.6667  u = 7.5 +  6.6667 + 0.0003 =  14.1670
    #   k=4: S = 20 − 20 = 0          D =   0       u = 7.5 + 0.0004           =   7.5004
    assert run(law, [1.0] * 4) == pytest.approx([44.1668, -15.8331, 14.1670, 7.5004], abs=1e-4)


def test_observer_as_printed_latches_at_full_duty() -> None:
    """Section 3.6.2 as printed (errata #12): u(k+1) = 95.1u(k) − 11.1u(k−1) + 0.01[8.42e(k)
    − 7.51e(k−1)]. Its output recursion z² − 95.1z + 11.1 has a pole at 94.98, so any output
    grows ~95-fold a tick: it reaches the 100 % limit on the third tick and stays there whatever
    the error does. The preset is kept to show this, not to be used."""
    observer = preset("observer", RIG)
    assert "as printed, unverified" in observer.note
    poles = np.roots([1.0, -observer.w[0][0], -observer.w[0][1]])
    assert max(abs(poles)) == pytest.approx(94.98, abs=0.01)
    law = DifferenceLaw(RIG, observer, RIG.sample_time_s)
    # error 1 mm = 10 counts:
    #   k=1: 0.0842·10                                  = 0.842
    #   k=2: 95.1·0.842 + 0.0842·10 − 0.0751·10         = 80.0742 + 0.091 = 80.1652
    #   k=3: 95.1·80.1652 − 11.1·0.842 + 0.091          = 7614.4 → 100 (saturated)
    #   k=4: 95.1·100 − 11.1·80.1652 + 0.091            = 8620.3 → 100
    assert run(law, [1.0] * 4) == pytest.approx([0.842, 80.1652, 100.0, 100.0], abs=1e-4)
    # the error reverses; 95.1·100 − 11.1·100 = 8400 swamps the error taps: still +100 %
    assert run(law, [-1.0] * 5) == [100.0] * 5


def test_minimum_pwm_maps_onto_the_starting_duty_of_the_valve_side() -> None:
    law = DifferenceLaw(UNIMATE, pi(UNIMATE, 1.0, 0.0), UNIMATE.sample_time_s)
    inout = UNIMATE.joints[0]  # section 5.4.1: the valve moves it from +26 % / −17 %
    assert (inout.min_pwm_pos, inout.min_pwm_neg) == (26.0, 17.0)
    assert inout.polarity == -1  # so a positive output u is negative valve duty: −17 % side
    assert law.update(0, 0.0) == 0.0  # exactly 0 stays 0 (no chatter at rest)
    assert law.update(0, 1e-9) == pytest.approx(17.0)  # tiny positive → that side's minimum
    assert law.update(0, -1e-9) == pytest.approx(-26.0)
    assert law.update(0, 50.0) == pytest.approx(0.83 * 50 + 17)  # (1 − 17/100)·u + 17 = 58.5
    assert law.update(0, -50.0) == pytest.approx(0.74 * -50 - 26)  # −63
    assert law.update(0, 100.0) == pytest.approx(100.0)
    assert law.update(0, 1e6) == pytest.approx(100.0)  # saturated first, then mapped: 100
    assert law.update(0, -1e6) == pytest.approx(-100.0)
    rig = DifferenceLaw(RIG, pi(RIG, 1.0, 0.0), RIG.sample_time_s)
    assert output_min_pwm(RIG.joints[0]) == (0.0, 0.0) and rig.update(0, 1e-9) > 0


def test_duty_limit_after_saturation() -> None:
    # the thesis's hold set (function.c): Kp 0.5, Ki 0.05, duty ≤ 20 %
    law = DifferenceLaw(RIG, RIG.coefficients["thesis_hold"], RIG.sample_time_s)
    # 100 mm = 1000 counts: 0.5·1000 = 500 → 100 → 20
    assert law.update(0, 100.0) == 20.0
    assert law.update(0, -100.0) == -20.0
    law.reset()
    # 2 mm = 20 counts: 0.5·20 + 0.05·20·0.001 = 10.001, inside the limit
    assert law.update(0, 2.0) == pytest.approx(10.001)


def test_set_coefficients_mid_sequence_keeps_the_integrator() -> None:
    law = DifferenceLaw(plain_machine(), one_joint(ki=100.0), 0.01)
    assert run(law, [1.0, 1.0]) == pytest.approx([1.0, 2.0])  # I = 1, 2
    law.set_coefficients(one_joint(ki=50.0))
    assert law.update(0, 1.0) == pytest.approx(2.5)  # I = 2 + 50·1·0.01; a reset would give 0.5


def test_a_set_with_no_integral_action_drops_the_integral_and_a_kept_one_fits_its_limit() -> None:
    """An integral kept by a set with ki 0 would never unwind: a frozen offset that minimum PWM
    turns into the valve's starting duty, so a zeroed hold crept Rotate on (a suite run: 13°
    in 30 s). A set with integral action keeps it, clamped at its own limit."""
    rotate = UNIMATE.joint_index("rotate")
    law = DifferenceLaw(UNIMATE, UNIMATE.hold, 0.01)
    law.update(rotate, 0.1)  # a sample off its target: a little integral, as a loaded start leaves
    assert law.state(rotate).integral != 0.0
    zero = replace(UNIMATE.hold, kp=((0.0,),) * 6, ki=(0.0,) * 6, kd=(0.0,) * 6, w=((),) * 6,
                   kv=(0.0,) * 6)
    law.set_coefficients(zero)
    assert law.state(rotate).integral == 0.0
    assert law.update(rotate, 1.5) == 0.0  # outside the deadband, the valve stays shut

    small = DifferenceLaw(plain_machine(), one_joint(ki=100.0), 0.01)
    run(small, [1.0] * 5)  # I = 5
    small.set_coefficients(one_joint(ki=100.0, integral_limit=3.0))
    assert small.state(0).integral == 3.0
    assert small.update(0, 0.0) == pytest.approx(3.0)


def test_set_coefficients_keeps_the_error_history_for_the_derivative() -> None:
    law = DifferenceLaw(plain_machine(), one_joint(kp=(1.0,)), 0.001)
    run(law, [1.0, 2.0, 3.0])
    law.set_coefficients(one_joint(kd=0.001))
    # history 4, 3, 2, 1 seen across the switch: 0.001·(44 − 54 + 18 − 2)/0.006 = 1
    assert law.update(0, 4.0) == pytest.approx(1.0)


def test_longer_taps_after_a_switch_read_zeros_beyond_the_old_history() -> None:
    law = DifferenceLaw(plain_machine(), one_joint(kp=(1.0,)), 0.001)
    run(law, [5.0])
    law.set_coefficients(one_joint(kp=(1.0, 0.5, 0.25, 0.125, 0.0625, 1.0)))
    assert len(law.state(0).errors) == 6
    # 1·2 + 0.5·5, then zeros: e(k−2) … e(k−5) were never seen
    assert law.update(0, 2.0) == pytest.approx(4.5)


def test_reset_clears_histories_and_integrators() -> None:
    law = DifferenceLaw(plain_machine(), one_joint(kp=(1.0, 1.0), ki=100.0, w=(0.5,)), 0.01)
    run(law, [1.0, 2.0])
    law.reset()
    state = law.state(0)
    assert state.integral == 0.0
    assert set(state.errors) == {0.0} and set(state.outputs) == {0.0}


def test_the_w_taps_weigh_the_final_output() -> None:
    law = DifferenceLaw(plain_machine(), one_joint(kp=(10.0,), w=(0.5,), duty_limit=15.0), 0.001)
    # k=1: 10·1 = 10;  k=2: 0.5·10 + 10 = 15;  k=3: 0.5·15 + 10 = 17.5 → 15 (duty limit),
    # and 15, the value sent, is what the next tick weighs: k=4: 0.5·15 + 0 = 7.5
    assert run(law, [1.0, 1.0, 1.0, 0.0]) == pytest.approx([10.0, 15.0, 15.0, 7.5])
    assert law.state(0).outputs == (7.5,)


def test_unimate_hold_acts_per_joint() -> None:
    law = DifferenceLaw(UNIMATE, UNIMATE.coefficients["thesis_hold"], UNIMATE.sample_time_s)
    # Up/Down hold: Kp 11, Ki 100; 1° error: 11 + 100·1·0.001 = 11.1; polarity −1, so the
    # valve's negative side (26 %, section 5.4.1) starts it: (1 − 26/100)·11.1 + 26
    assert law.update(2, 1.0) == pytest.approx(0.74 * 11.1 + 26)
    assert law.state(0).integral == 0.0  # other joints untouched


def test_a_non_finite_error_is_refused_with_the_joint_name() -> None:
    law = DifferenceLaw(UNIMATE, UNIMATE.hold, UNIMATE.sample_time_s)
    with pytest.raises(ValueError, match="Up/Down: error nan"):
        law.update(2, float("nan"))
    assert law.state(2).integral == 0.0  # the state is not poisoned


def test_coefficients_must_fit_the_machine() -> None:
    with pytest.raises(ValueError, match="kp has 1 entries, machine unimate2000b has 6 joints"):
        DifferenceLaw(UNIMATE, RIG.track, 0.001)
    with pytest.raises(ValueError, match="sample time"):
        DifferenceLaw(RIG, RIG.track, 0.0)


def test_pid_pi_and_preset_build_coefficient_sets() -> None:
    c = pid(UNIMATE, kp=[1, 2, 3, 4, 5, 6], ki=0.5, kd=0.01)
    assert c.kp == ((1,), (2,), (3,), (4,), (5,), (6,))
    assert c.ki == (0.5,) * 6 and c.kd == (0.01,) * 6
    assert c.filter == (11, -18, 9, -2) and c.filter_divisor == 6 and c.integral_limit == 50
    assert c.w == ((),) * 6
    p = pi(UNIMATE, kp=(20, 25, 30, 3, 4, 20), ki=(200, 20, 90, 3, 20, 80))
    thesis = preset("thesis_pi", UNIMATE)  # section 5.4.2
    assert (p.kp, p.ki, p.kd) == (thesis.kp, thesis.ki, thesis.kd)
    assert p.note.startswith("P.I. of section 5.4.2")
    with pytest.raises(ValueError, match="kp: expected one gain or 6, got 2"):
        pid(UNIMATE, kp=[1, 2], ki=0, kd=0)
    with pytest.raises(KeyError, match=r"no coefficient set 'observer'.*hold, track, "
                                       r"thesis_hold, thesis_track, thesis_pi"):
        preset("observer", UNIMATE)


@given(st.lists(st.floats(-1e4, 1e4), min_size=1, max_size=50),
       st.integers(0, UNIMATE.n_joints - 1))
def test_output_is_zero_or_between_min_pwm_and_the_limit(errors: list[float], j: int) -> None:
    law = DifferenceLaw(UNIMATE, UNIMATE.coefficients["thesis_track"], UNIMATE.sample_time_s)
    joint = UNIMATE.joints[j]
    up, down = output_min_pwm(joint)
    for e in errors:
        u = law.update(j, e)
        assert u == 0.0 or up <= u <= 100.0 or -100.0 <= u <= -down


def test_velocity_feed_forward_adds_kv_times_the_desired_velocity() -> None:
    machine = load_machine("rig")
    base = pid(machine, 0.0, 0.0, 0.0)
    with_ff = Coefficients(**{**base.__dict__, "kv": (0.05,)})
    law = DifferenceLaw(machine, with_ff, 0.001)
    assert law.update(0, 0.0, velocity=200.0) == pytest.approx(10.0)  # 0.05 %/(mm/s) x 200 mm/s
    assert law.update(0, 0.0, velocity=0.0) == 0.0
    assert DifferenceLaw(machine, base, 0.001).update(0, 0.0, velocity=200.0) == 0.0



def test_inside_the_deadband_at_rest_the_valve_stays_inside_its_overlap() -> None:
    """Issue 24: the P.I. of the hold integrates a one-count error, so without a deadband the
    output crosses zero and min-PWM compensation steps the valve from +25 % to −28 % and back
    (Bend). At rest, once within half the deadband, the law sees no error: the integral stops
    and what it holds goes out uncompensated, clipped to the minimum PWM, inside the spool's
    overlap, until the error is past the deadband REST_EXIT_SAMPLES samples running."""
    bend = 3
    count = UNIMATE.joints[bend].encoder.gradient
    up, down = output_min_pwm(UNIMATE.joints[bend])
    c = replace(UNIMATE.hold, deadband=(0.0,) * 3 + (2 * count,) + (0.0,) * 2)
    law = DifferenceLaw(UNIMATE, c, UNIMATE.sample_time_s)
    assert law.update(bend, 3 * count) > up  # P and I act, compensated past the minimum PWM
    assert law.update(bend, 1.5 * count) > up  # inside the deadband, not yet within half
    held = law.state(bend).integral
    glitch = [2.5] * (REST_EXIT_SAMPLES - 1)  # a wrong reading of a few samples
    inside = [law.update(bend, e * count) for e in (0.9, 1.8, -1.8, *glitch, 0.0, *glitch)]
    assert inside == pytest.approx([held] * len(inside))
    assert law.state(bend).integral == held
    assert law.update(bend, 2.5 * count) > up  # the last sample running past it ends the rest
    law = DifferenceLaw(UNIMATE, replace(c, kp=((0.0,),) * 6, ki=(5e4,) * 6),
                        UNIMATE.sample_time_s)
    law.update(bend, -1.0)  # the integral to −50 %
    assert law.update(bend, 0.5 * count) == -down  # a large integral: at the overlap's edge
    none = DifferenceLaw(UNIMATE, UNIMATE.coefficients["thesis_hold"], UNIMATE.sample_time_s)
    assert none.update(bend, 0.5 * count) > up and none.update(bend, -0.5 * count) < -down
    law.reset()
    assert law.update(bend, 0.5 * count) == 0.0  # reset: no integral, resting at once


def test_integral_separation_holds_the_integral_while_the_other_terms_ask_for_much() -> None:
    """Issue 24: conditional integration beyond saturation: at 0.75 % a count a 30-count error
    asks for 22.5 %, over a separation of 20 %: the integral holds; at 20 counts it grows."""
    c = replace(one_joint(kp=(0.75,), ki=1.0), integral_separation=20.0)
    law = DifferenceLaw(plain_machine(), c, 0.001)
    law.update(0, 30.0)
    assert law.state(0).integral == 0.0
    law.update(0, 20.0)
    assert law.state(0).integral == pytest.approx(20.0 * 0.001)
    none = DifferenceLaw(plain_machine(), one_joint(kp=(0.75,), ki=1.0), 0.001)
    none.update(0, 30.0)
    assert none.state(0).integral == pytest.approx(30.0 * 0.001)


def test_integral_separation_never_holds_a_step_that_unwinds_the_integral() -> None:
    """An integral wound up on the way to a goal must unwind past it, however large the error
    that unwinds it: held there, it kept a jogged Up/Down past its goal, on the stop at its
    limit (issue 25). Wound to +15 %, a −30-count error (−22.5 % of feedback) unwinds it."""
    c = replace(one_joint(kp=(0.75,), ki=1.0, integral_limit=100.0), integral_separation=20.0)
    law = DifferenceLaw(plain_machine(), c, 0.001)
    run(law, [1.0] * 15_000)  # 0.75 % of feedback: integrated, to 15 %
    wound = law.state(0).integral
    assert wound == pytest.approx(15.0)
    law.update(0, -30.0)
    assert law.state(0).integral == pytest.approx(wound - 30.0 * 0.001)
    fresh = DifferenceLaw(plain_machine(), c, 0.001)
    fresh.update(0, -30.0)  # not wound: the feedback alone asks for much, this way: held
    assert fresh.state(0).integral == 0.0


def test_a_move_ignores_the_deadband() -> None:
    """While the path moves (a desired velocity) a one-count error is acted on, compensated."""
    bend = 3
    count = UNIMATE.joints[bend].encoder.gradient
    up, _ = output_min_pwm(UNIMATE.joints[bend])
    law = DifferenceLaw(UNIMATE, UNIMATE.track, UNIMATE.sample_time_s)
    assert law.update(bend, 0.5 * count, velocity=0.0) == 0.0
    assert law.update(bend, 0.5 * count, velocity=1.0) > up

# -- the listings' slips (errata), for the thesis's timing mode ---------------------------------


def test_the_derivative_slip_multiplies_by_dt_where_eq_3_3_divides() -> None:
    dt, kd = 0.001, 0.01
    law = DifferenceLaw(plain_machine(), one_joint(kd=kd), dt, frozenset({"derivative"}))
    # PDcontrol.c: (11e(k) − 18e(k−1) + 9e(k−2) − 2e(k−3)) / 6 * SampleTime: S·kd·Δt/6
    assert run(law, [0.5, 1.0, 1.5, 2.0]) == pytest.approx(
        [kd * s * dt / 6 for s in (5.5, 2.0, 3.0, 3.0)], rel=1e-9)


def test_the_integral_slip_sums_the_oldest_error_of_four() -> None:
    law = DifferenceLaw(plain_machine(), one_joint(ki=100.0), 0.01,
                        frozenset({"integral_oldest"}))
    # Distance[0], the oldest of four: zero for three ticks, then the first error
    run(law, [1.0, 2.0, 3.0])
    assert law.state(0).integral == 0.0
    run(law, [4.0])
    assert law.state(0).integral == pytest.approx(100.0 * 1.0 * 0.01)


def test_the_minimum_pwm_slip_adds_pmin_unscaled() -> None:
    up, _ = output_min_pwm(UNIMATE.joints[0])
    c = pi(UNIMATE, kp=1.0, ki=0.0)
    law = DifferenceLaw(UNIMATE, c, 0.001, frozenset({"min_pwm"}))
    fixed = DifferenceLaw(UNIMATE, c, 0.001)
    e = 10.0 * UNIMATE.joints[0].gain_unit  # u = 10 % before the minimum-PWM map
    assert law.update(0, e) == pytest.approx(10.0 + up)  # (1 − pmin/100) is 1 in int division
    assert fixed.update(0, e) == pytest.approx((1 - up / 100) * 10.0 + up)


def test_an_unknown_slip_is_refused() -> None:
    with pytest.raises(ValueError, match="unknown slips"):
        DifferenceLaw(plain_machine(), one_joint(kp=(1.0,)), 0.001, frozenset({"typo"}))


def test_the_integral_does_not_wind_up_while_saturated() -> None:
    # section 3.6.1's anti-windup intent (errata #31): 400 mm below the target the rig's
    # PID is saturated, so the integral stays put; the listing's clamp alone (slip "windup")
    # sums Ki·e·Δt = 0.01 · 4000 counts · 1 ms = 0.04 % a tick
    pi_only = replace(preset("thesis_track", RIG), kd=(0.0,))  # no derivative kick on the step
    law = DifferenceLaw(RIG, pi_only, 1e-3)
    printed = DifferenceLaw(RIG, pi_only, 1e-3, slips=frozenset({"windup"}))
    for _ in range(100):
        assert law.update(0, 400.0) == printed.update(0, 400.0) == 100.0
    assert law.state(0).integral == 0.0
    assert printed.state(0).integral == pytest.approx(100 * 0.01 * 4000 * 1e-3)
    law.update(0, 1.0)  # unsaturated (0.75 % per count): it integrates again
    assert law.state(0).integral == pytest.approx(0.01 * 10 * 1e-3)


@pytest.mark.parametrize("dt", [0.001, 0.0005])
def test_the_integral_and_the_derivative_are_of_seconds_whatever_the_sample_time(dt) -> None:
    """At 1 kHz or 2 kHz (``sample_time_ms`` 1 or 0.5) the same error signal in time gives
    the same integral and derivative terms: ki·Δt and kd/(p·Δt) carry the period."""
    integral = DifferenceLaw(plain_machine(), one_joint(ki=10.0), dt)
    steps = round(0.1 / dt)  # e = 2 for 0.1 s: ∫ki·e dt = 10·2·0.1 = 2
    assert run(integral, [2.0] * steps)[-1] == pytest.approx(2.0)
    derivative = DifferenceLaw(plain_machine(), one_joint(kd=0.01), dt)
    ramp = [300.0 * dt * k for k in range(1, 11)]  # 300 units/s: kd·de/dt = 3
    assert run(derivative, ramp)[-1] == pytest.approx(3.0)
