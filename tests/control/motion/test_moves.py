"""Desired paths of the thesis's inputs and the step-response summary."""

from __future__ import annotations

import math

import numpy as np
import pytest

from control.motion import moves
from control.motion.moves import SETTLE_TAIL_S, StepSummary, summary
from hw.machine import load_machine

UNIMATE = load_machine("unimate2000b")
RIG = load_machine("rig")
HOME = np.array([1500.0, 0.0, 0.0, 0.0, 0.0, 0.0])  # in limits on every Unimate joint
DT = 0.001


def test_step_moves_one_joint_at_the_second_sample() -> None:
    path = moves.step(HOME, 2, 10.0, 3.0, dt=DT, machine=UNIMATE)
    assert path.shape == (3001, 6)  # t = 0 … 3 s inclusive
    assert path[0].tolist() == HOME.tolist()  # the pose the step starts from
    assert np.all(path[1:, 2] == 10.0)
    assert np.all(path[:, [0, 1, 3, 4, 5]] == HOME[[0, 1, 3, 4, 5]])
    by_key = moves.step(HOME, "updown", 10.0, 3.0, machine=UNIMATE)  # dt from the machine
    assert np.array_equal(by_key, path)


def test_step_without_a_machine_as_the_client_calls_it() -> None:
    path = moves.step(HOME.tolist(), joint=2, target=10.0, duration=3.0, dt=DT)
    assert path.shape == (3001, 6) and path[-1, 2] == 10.0


def test_default_duration_is_travel_at_max_speed_plus_the_settle_tail() -> None:
    path = moves.step(HOME, "inout", 1900.0, machine=UNIMATE)  # 400 mm at 400 mm/s
    assert len(path) == round((1.0 + SETTLE_TAIL_S) / DT) + 1


def test_multi_step_moves_every_joint_at_once() -> None:
    targets = [1200.0, 10.0, -5.0, 20.0, -30.0, 45.0]
    path = moves.multi_step(HOME, targets, 2.0, machine=UNIMATE)
    assert path.shape == (2001, 6)
    assert path[0].tolist() == HOME.tolist()
    assert np.all(path[1:] == targets)


def test_rig_sequence_dwells_at_each_position() -> None:
    path = moves.rig_sequence(200.0, [(600.0, 1.0), (400.0, 0.5), (200.0, 2.0)], machine=RIG)
    assert path.shape == (1 + 1000 + 500 + 2000, 1)
    q = path[:, 0]
    assert q[0] == 200.0
    assert np.all(q[1:1001] == 600.0) and np.all(q[1001:1501] == 400.0)
    assert np.all(q[1501:] == 200.0)


def test_ramp_is_linear_between_blends_at_max_accel_then_holds() -> None:
    start, end = np.array([200.0]), np.array([600.0])
    path = moves.ramp(start, end, ramp_time=2.0, total_duration=3.0, machine=RIG)
    q = path[:, 0]
    assert path.shape == (3001, 1)
    accel = RIG.joints[0].max_accel  # 8000 mm/s²: blends of 25 ms
    blend = 2.0 / 2 - np.sqrt(2.0**2 / 4 - 400.0 / accel)
    speed = np.diff(q) / DT
    cruise = speed[100:1900]
    assert cruise == pytest.approx(np.full(1800, 400.0 / (2.0 - blend)))  # 202.6 mm/s
    assert np.abs(np.diff(q, 2)).max() / DT**2 <= accel * (1 + 1e-9)
    assert q[0] == 200.0 and q[1000] == pytest.approx(400.0)  # halfway at half the ramp time
    assert q[2000] == pytest.approx(600.0)
    assert np.all(q[2000:] == 600.0)
    assert len(moves.ramp(start, end, 2.0, machine=RIG)) == round((2.0 + SETTLE_TAIL_S) / DT) + 1


def test_a_ramp_without_a_machine_keeps_the_thesis_corners() -> None:
    path = moves.ramp([200.0], [600.0], ramp_time=2.0, total_duration=3.0, dt=DT)
    assert np.diff(path[:2001, 0]) / DT == pytest.approx(np.full(2000, 200.0))


def test_the_shortest_ramp_time_keeps_speed_and_acceleration() -> None:
    # In/Out, 400 mm/s and 2000 mm/s²: 600 mm take 600/400 + 400/2000 s; 40 mm never reach
    # full speed (triangular): 2·√(40/2000) s
    here = np.array([1200.0, 0, 0, 0, 0, 0])
    assert moves.min_ramp_time(here, here + np.array([600.0, 0, 0, 0, 0, 0]), UNIMATE) == \
        pytest.approx(1.7)
    assert moves.min_ramp_time(here, here + np.array([40.0, 0, 0, 0, 0, 0]), UNIMATE) == \
        pytest.approx(2 * np.sqrt(0.02))
    assert moves.min_ramp_time(here, here + np.array([600.0, 0, 0, 0, 0, 0]), UNIMATE, 0.5) == \
        pytest.approx(600 / 200 + 200 / 1000)
    path = moves.ramp(here, here + np.array([600.0, 0, 0, 0, 0, 0]), 1.7, machine=UNIMATE)
    assert np.abs(np.diff(path[:, 0])).max() / DT <= 400.0 * (1 + 1e-9)


def test_sine_reaches_end_at_half_the_period() -> None:
    path = moves.sine([200.0], [600.0], period=2.0, duration=4.0, machine=RIG)
    q = path[:, 0]
    assert path.shape == (4001, 1)
    assert q[0] == pytest.approx(200.0)
    assert q[1000] == pytest.approx(600.0)  # T/2
    assert q[500] == pytest.approx(400.0)  # T/4: halfway
    assert q[2000] == pytest.approx(200.0) and q[3000] == pytest.approx(600.0)
    assert q.min() >= 200.0 - 1e-9 and q.max() <= 600.0 + 1e-9


def test_a_sine_stops_at_rest_on_its_last_whole_half_period() -> None:
    path = moves.sine([200.0], [600.0], period=2.0, duration=3.5, machine=RIG)
    q = path[:, 0]
    assert path.shape == (3501, 1)
    assert q[3000] == pytest.approx(600.0) and np.all(q[3000:] == q[3000])  # 3 half periods


def test_hold_path_is_constant() -> None:
    path = moves.hold_path(HOME, 0.5, machine=UNIMATE)
    assert path.shape == (501, 6) and np.all(path == HOME)


def test_times_match_the_samples() -> None:
    t = moves.times(4, DT)
    assert t.tolist() == pytest.approx([0.0, 0.001, 0.002, 0.003])


@pytest.mark.parametrize(("make", "message"), [
    (lambda: moves.step(HOME, 2, 35.0, 3.0, machine=UNIMATE),
     r"Up/Down target 35° is outside -27…30° \(machine unimate2000b\)"),
    (lambda: moves.step(HOME, 2, math.nan, 3.0, machine=UNIMATE),
     "target: Up/Down value nan is not a number"),
    (lambda: moves.step(HOME, 2, 10.0, 0.0, machine=UNIMATE),
     "duration must be a positive number of seconds, got 0"),
    (lambda: moves.step(HOME, 2, 10.0, math.inf, machine=UNIMATE),
     "duration must be a positive number of seconds, got inf"),
    (lambda: moves.step(HOME, 2, 10.0, 0.0004, machine=UNIMATE),
     r"duration 0.0004 s is shorter than one sample \(0.001 s\)"),
    (lambda: moves.step(HOME, 7, 10.0, 1.0, machine=UNIMATE), "joint index 7 is outside 0…5"),
    (lambda: moves.step(HOME, 2, 10.0, 1.0), r"give the sample time dt \(s\) or the machine"),
    (lambda: moves.step([3000.0, 0, 0, 0, 0, 0], 2, 10.0, 1.0, machine=UNIMATE),
     "start: In/Out target 3000mm is outside 976…2041mm"),
    (lambda: moves.multi_step(HOME, [1500.0, 0, 0, 0, 0], 1.0, machine=UNIMATE),
     r"targets must have 6 joint values, got shape \(5,\)"),
    (lambda: moves.multi_step(HOME, [1500.0, 0, 0, 0, 200.0, 0], 1.0, machine=UNIMATE),
     "Yaw target 200° is outside -169…174°"),
    (lambda: moves.rig_sequence(200.0, [(600.0, 1.0), (1300.0, 1.0)], machine=RIG),
     "step 2: Ram target 1300mm is outside 0…1200mm"),
    (lambda: moves.rig_sequence(200.0, [(600.0, -1.0)], machine=RIG),
     "step 1 dwell must be a positive number of seconds, got -1"),
    (lambda: moves.rig_sequence(200.0, [], machine=RIG), "at least one"),
    (lambda: moves.ramp([200.0], [600.0], 0.0, machine=RIG),
     "ramp_time must be a positive number of seconds, got 0"),
    (lambda: moves.ramp([200.0], [600.0], 2.0, 1.0, machine=RIG),
     "total_duration 1 s is shorter than ramp_time 2 s"),
    (lambda: moves.ramp([200.0], [1000.0], 0.5, machine=RIG),
     "Ram cannot ramp 800 mm in 0.5 s .* within its max_speed and max_accel "
     r"\(800 mm/s, 8000 mm/s², machine rig\): make ramp_time at least 1.1 s"),
    (lambda: moves.ramp([200.0], [210.0], 0.05, machine=RIG),
     "Ram cannot ramp 10 mm in 0.05 s .*make ramp_time at least 0.0707 s"),
    (lambda: moves.sine([200.0], [600.0], 2.0, 0.5, machine=RIG),
     "duration 0.5 s is shorter than half the period .*make duration at least 1 s"),
    (lambda: moves.sine([200.0], [210.0], 0.1, 1.0, machine=RIG),
     "Ram would accelerate at 1.974e\\+04 mm/s², above its max_accel 8000 mm/s² .*make period "
     "at least 0.157 s"),
    (lambda: moves.sine([200.0], [600.0], -2.0, 4.0, machine=RIG),
     "period must be a positive number of seconds, got -2"),
    (lambda: moves.sine([200.0], [600.0], 1.0, 4.0, machine=RIG),
     "Ram would move at 1256.64 mm/s.*make period at least 1.57 s"),
    (lambda: moves.hold_path([math.inf], 1.0, machine=RIG),
     "hold position: Ram value inf is not a number"),
])
def test_inputs_are_validated_with_messages_that_say_what(make, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        make()


# -- summary ---------------------------------------------------------------------------------


def second_order(t: np.ndarray, zeta: float, wn: float) -> np.ndarray:
    """Unit step response of wn² / (s² + 2ζwn·s + wn²), ζ < 1."""
    wd = wn * math.sqrt(1 - zeta**2)
    decay = np.exp(-zeta * wn * t)
    return 1 - decay * (np.cos(wd * t) + zeta / math.sqrt(1 - zeta**2) * np.sin(wd * t))


def stepped(zeta: float, wn: float, initial: float, size: float,
            duration: float = 4.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A step at t = dt (as moves.step makes it) and the response, starting at t = dt."""
    t = moves.times(round(duration / DT) + 1, DT)
    desired = np.where(t > 0, initial + size, initial)[:, None]
    actual = (initial + size * second_order(np.maximum(t - DT, 0.0), zeta, wn))[:, None]
    return t, desired, actual


def test_second_order_step_matches_the_analytic_figures() -> None:
    from scipy.optimize import brentq  # here: collecting the module need not load scipy.optimize

    zeta, wn, size, tol = 0.3, 10.0, 400.0, 8.0  # rig: 200 → 600 mm, 2 % band
    t, desired, actual = stepped(zeta, wn, 200.0, size)
    (s,) = summary(t, desired, actual, RIG.joints, tolerance=tol)

    def y(x: float) -> float:
        return float(second_order(np.array([x]), zeta, wn)[0])

    wd = wn * math.sqrt(1 - zeta**2)
    overshoot = math.exp(-math.pi * zeta / math.sqrt(1 - zeta**2))  # 37.2 %, peak at π/wd
    t10, t90 = brentq(lambda x: y(x) - 0.1, 0, 0.2), brentq(lambda x: y(x) - 0.9, 0, math.pi / wd)
    # last exit from the ±2 % band: scan the analytic response's extrema, then solve exactly
    extrema = [k * math.pi / wd for k in range(1, 40)]
    last = max(k for k in extrema if abs(y(k) - 1) > tol / size)
    t_settle = brentq(lambda x: abs(y(x) - 1) - tol / size, last, last + math.pi / wd)

    assert (s.initial, s.final, s.step) == (200.0, 600.0, 400.0)
    assert s.overshoot_pct == pytest.approx(100 * overshoot, abs=0.01)
    assert s.overshoot == pytest.approx(size * overshoot, abs=0.05)
    assert s.rise_time_s == pytest.approx(t90 - t10, abs=1e-4)
    assert s.settling_time_s == pytest.approx(t_settle, abs=1e-4)
    assert s.steady_state_error == pytest.approx(0.0, abs=0.01)
    assert s.max_abs_error == pytest.approx(size)  # at t = dt, before the ram moves
    assert s.notes == ()


def test_a_downward_step_is_measured_in_its_own_direction() -> None:
    t, desired, actual = stepped(0.5, 12.0, 600.0, -400.0)
    (s,) = summary(t, desired, actual, RIG.joints, tolerance=8.0)
    overshoot = math.exp(-math.pi * 0.5 / math.sqrt(1 - 0.25))  # 16.3 %
    assert s.step == -400.0
    assert s.overshoot_pct == pytest.approx(100 * overshoot, abs=0.01)
    assert s.rise_time_s is not None and s.rise_time_s > 0


def test_a_steady_offset_shows_as_steady_state_error() -> None:
    t, desired, actual = stepped(0.7, 10.0, 200.0, 400.0)
    offset = actual - 0.5 * (1 - np.exp(-t / 0.2))[:, None]  # gravity sag, section 3.6.1
    (s,) = summary(t, desired, offset, RIG.joints)
    assert s.steady_state_error == pytest.approx(0.5, abs=1e-3)  # desired − actual > 0


def test_a_joint_that_did_not_move() -> None:
    t = moves.times(1000, DT)
    path = moves.multi_step(HOME, [1500.0, 10.0, 0.0, 0.0, 0.0, 0.0], 0.999, machine=UNIMATE)
    actual = path + np.random.default_rng(1).normal(0, 0.01, path.shape)
    actual[:, 1] = HOME[1] + 10.0 * second_order(t, 0.7, 30.0)
    rows = summary(t, path, actual, UNIMATE.joints)
    still = rows[0]
    assert (still.step, still.overshoot, still.overshoot_pct) == (0.0, 0.0, 0.0)
    assert still.settling_time_s == 0.0 and still.rise_time_s is None
    assert "no step" in still.notes[0]
    assert rows[1].step == 10.0 and rows[1].rise_time_s is not None


def test_nans_in_actual_are_ignored_with_a_note() -> None:
    t, desired, actual = stepped(0.3, 10.0, 200.0, 400.0)
    clean = summary(t, desired, actual, RIG.joints, tolerance=8.0)[0]
    actual[[5, 900, 2500], 0] = np.nan  # encoder glitches
    (s,) = summary(t, desired, actual, RIG.joints, tolerance=8.0)
    assert s.notes == ("3 of 4001 samples with NaN ignored",)
    assert s.overshoot_pct == pytest.approx(clean.overshoot_pct, abs=0.01)
    assert s.settling_time_s == pytest.approx(clean.settling_time_s, abs=1e-3)
    assert math.isfinite(s.rms_error)


def test_short_and_empty_runs_do_not_crash() -> None:
    for n in (0, 1, 2, 3):
        t = moves.times(n, DT)
        desired = np.full((n, 1), 600.0)
        if n:
            desired[0] = 200.0
        (s,) = summary(t, desired, np.full((n, 1), 200.0), RIG.joints)
        assert isinstance(s, StepSummary)
    all_nan = summary(moves.times(3, DT), np.zeros((3, 1)), np.full((3, 1), np.nan), RIG.joints)
    assert all_nan[0].notes == ("no valid samples",)


def test_a_response_that_never_settles_says_so() -> None:
    t, desired, actual = stepped(0.02, 10.0, 200.0, 400.0, duration=1.0)  # barely damped
    (s,) = summary(t, desired, actual, RIG.joints)
    assert s.settling_time_s is None
    assert any("did not settle within ±1" in note for note in s.notes)


def test_summary_checks_shapes() -> None:
    with pytest.raises(ValueError, match=r"desired and actual \(N, 6\)"):
        summary(moves.times(3, DT), np.zeros((3, 1)), np.zeros((3, 1)), UNIMATE.joints)


def test_a_start_resting_just_past_a_limit_begins_on_it() -> None:
    rig = load_machine("rig")
    path = moves.step([-0.1], 0, 100.0, 2.0, machine=rig)  # on the bottom stop after Initialise
    assert path[0, 0] == 0.0 and path[-1, 0] == 100.0
    with pytest.raises(ValueError, match="start: Ram target -5mm is outside 0…1200mm"):
        moves.step([-5.0], 0, 100.0, 2.0, machine=rig)
