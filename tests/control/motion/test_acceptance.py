"""The one set of path acceptance rules: kinds, rows, smoothness, the start, duty profiles;
and every generator's paths at its limits pass its own kind's rules."""

from __future__ import annotations

import math

import numpy as np
import pytest

from control.motion import acceptance, moves, trajectory
from control.motion.acceptance import MoveRefused, accept, check_path, check_profile
from control.motion.cartesian import cartesian_path
from control.motion.plan import MovePlan, approach_ramp
from control.motion.robot_model import builtin_unimate
from control.rt.commands import DUTY_KINDS, MOVE_KINDS, SMOOTH_KINDS, STEP_KINDS
from hw.machine import load_machine

UNIMATE = load_machine("unimate2000b")
RIG = load_machine("rig")
DT = UNIMATE.sample_time_s
HOME = np.array([1500.0, 0.0, 0.0, 0.0, 0.0, 0.0])
UPDOWN = 2


def jumping_path() -> np.ndarray:
    """Up/Down holds, jumps 5° at sample 300 (t = 0.3 s), holds again."""
    path = np.tile(HOME, (1000, 1))
    path[300:, UPDOWN] += 5.0
    return path


def test_every_kind_is_smooth_step_or_duty() -> None:
    """(The control process reads them without numpy: tests/control/rt/test_process.py.)"""
    assert SMOOTH_KINDS | STEP_KINDS | DUTY_KINDS == MOVE_KINDS
    assert not SMOOTH_KINDS & STEP_KINDS and not (SMOOTH_KINDS | STEP_KINDS) & DUTY_KINDS
    assert sorted(STEP_KINDS) == ["multi_step", "step"]
    assert sorted(DUTY_KINDS) == ["set_pulse", "tracking_actuate"]
    assert acceptance.SMOOTH_KINDS is SMOOTH_KINDS  # one classification


def test_a_jump_is_refused_as_a_path_saying_where_how_much_and_the_fix() -> None:
    with pytest.raises(MoveRefused) as refused:
        check_path(jumping_path(), "path", UNIMATE, DT)
    message = str(refused.value)
    assert message.startswith("Up/Down moves +5 deg in 0.001 s at sample 300 (t = 0.300 s): "
                              "5000 deg/s, 200 times its max_speed 25 deg/s")
    assert "that change needs at least 0.2 s" in message
    assert "or send it as a step move (kind 'step') if the jump is meant" in message
    assert refused.value.index == 300


def test_the_same_jump_is_accepted_as_a_step() -> None:
    for kind in STEP_KINDS:
        check_path(jumping_path(), kind, UNIMATE, DT)


def test_a_corner_is_refused_for_its_acceleration() -> None:
    """The thesis's linear ramp (no machine: no blends) turns a corner at its end."""
    start = HOME.copy()
    end = HOME + np.array([0, 0, 10.0, 0, 0, 0])
    corner = moves.ramp(start, end, 2.0, 3.0, dt=DT)
    with pytest.raises(MoveRefused, match=r"^Up/Down starts from rest at \+5 deg/s at sample 0 "
                                          r"\(t = 0.000 s\): 5000 deg/s², 33.3 times its "
                                          r"max_accel 150 deg/s²"):
        check_path(corner, "ramp", UNIMATE, DT)
    check_path(moves.ramp(start, end, 2.0, 3.0, machine=UNIMATE), "ramp", UNIMATE, DT)


def test_a_path_that_ends_moving_is_refused() -> None:
    path = np.tile(HOME, (500, 1))
    path[:, 1] += 0.001 * np.arange(500) ** 2 / 2 * 0.1  # Rotate from rest at 100°/s²
    with pytest.raises(MoveRefused, match=r"Rotate is still moving at \+49.85 deg/s on its last "
                                          r"sample, where the controller holds it at sample 499"):
        check_path(path, "path", UNIMATE, DT)


def test_rows_must_be_finite_and_inside_the_limits_whatever_the_kind() -> None:
    path = np.tile(HOME, (100, 1))
    path[40, UPDOWN] = 35.0
    for kind in ("path", "step"):
        with pytest.raises(MoveRefused, match=r"Up/Down target 35° is outside -27…30° \(machine "
                                              r"unimate2000b\) at sample 40 \(t = 0.040 s\)"):
            check_path(path, kind, UNIMATE, DT)
    path[40, UPDOWN] = math.nan
    with pytest.raises(MoveRefused, match="Up/Down target nan is not a number"):
        check_path(path, "step", UNIMATE, DT)
    with pytest.raises(MoveRefused, match=r"a path is \(N, 6\) joint positions"):
        check_path(path[:, :3], "path", UNIMATE, DT)


def test_a_yaw_target_its_actuator_cannot_reach_from_where_bend_is_is_refused() -> None:
    """Yaw reads its actuator plus Bend (rtshare.h joint_dep); the stops act on the actuator,
    so Yaw −150° with Bend at +90° would need the actuator at −240°, past its −169° stop."""
    path = np.tile(HOME, (10, 1))
    path[:, 3] = 90.0
    path[5:, 4] = -150.0
    with pytest.raises(MoveRefused, match=r"Yaw -150° with Bend at 90° puts Yaw's actuator at "
                                          r"-240.0°, past its stops -169…174° .* at sample 5"):
        check_path(path, "step", UNIMATE, DT)
    path[:, 3] = 0.0
    check_path(path, "step", UNIMATE, DT)


def test_kinds_and_what_they_carry() -> None:
    with pytest.raises(MoveRefused, match="unknown move kind 'wiggle'"):
        check_path(jumping_path(), "wiggle", UNIMATE, DT)
    with pytest.raises(MoveRefused, match="a set_pulse move plays a duty profile, not a desired"):
        check_path(jumping_path(), "set_pulse", UNIMATE, DT)
    with pytest.raises(MoveRefused, match="a ramp move follows a desired path, not a duty"):
        accept(MovePlan("ramp", "ramp", profile=np.zeros((10, 6))), None, UNIMATE, DT)


def test_duty_profiles_are_finite_and_within_100_percent() -> None:
    profile = np.zeros((50, 1))
    check_profile(profile, RIG)
    profile[7, 0] = 120.0
    with pytest.raises(MoveRefused, match=r"Ram duty 120.0 at sample 7 is not a number in "
                                          r"-100…100 %"):
        check_profile(profile, RIG)
    profile[7, 0] = math.inf
    with pytest.raises(MoveRefused, match="Ram duty inf at sample 7"):
        accept(MovePlan("set_pulse", "pulse", profile=profile), None, RIG, DT)
    with pytest.raises(MoveRefused, match=r"a duty profile is \(N, 1\), got \(50, 2\)"):
        check_profile(np.zeros((50, 2)), RIG)


def test_a_path_that_starts_here_runs_as_it_is() -> None:
    path = moves.step(HOME + np.array([1.0, 0.2, 0, 0, 0, 0]), UPDOWN, 5.0, 2.0, machine=UNIMATE)
    plan = MovePlan.of_path(path, "step")
    assert accept(plan, HOME, UNIMATE, DT) is plan  # every joint within its tolerance


def test_a_path_that_starts_away_is_accepted_only_with_the_approach_in_front() -> None:
    start = HOME.copy()
    start[1] = 20.0  # Rotate 20° away (tolerance 0.5°)
    plan = accept(MovePlan.of_path(jumping_path() + start - HOME, "step"), HOME, UNIMATE, DT)
    assert plan.approach == len(approach_ramp(HOME, start, UNIMATE, DT)) > 0
    assert plan.path[0] == pytest.approx(HOME)
    check_path(plan.path[:plan.approach + 1], "path", UNIMATE, DT)  # the approach is smooth
    with pytest.raises(MoveRefused, match="Rotate is at 0° and the path starts at 20°, 20° "
                                          r"away \(tolerance 0.5°\): a move starts where the "
                                          "robot is"):
        acceptance.check_start(start, HOME, UNIMATE)


def test_the_rules_name_the_callers_sample_not_the_approachs() -> None:
    start = HOME.copy()
    start[0] = 1600.0
    path = jumping_path() + start - HOME
    with pytest.raises(MoveRefused, match=r"at sample 300 \(t = 0.300 s\)"):
        accept(MovePlan.of_path(path, "path"), HOME, UNIMATE, DT)


def test_a_move_longer_than_the_move_limit_is_refused_approach_and_all() -> None:
    """600 s is the longest move (it is sent and recorded whole, and a saved run is read
    back within that bound): a path of 600 s runs, one sample more does not, nor a 600 s
    path with an approach in front, nor a duty profile past 600 s."""
    still = np.tile(HOME, (600_001, 1))
    assert len(accept(MovePlan.of_path(still, "path"), HOME, UNIMATE, DT).path) == 600_001
    longer = np.tile(HOME, (600_002, 1))
    with pytest.raises(MoveRefused, match=r"^the path move would take 600\.001 s, longer than "
                                          r"a move may last \(the move limit, 600 s\): split "
                                          r"it into shorter moves$"):
        accept(MovePlan.of_path(longer, "path"), HOME, UNIMATE, DT)
    away = HOME + np.array([50.0, 0, 0, 0, 0, 0])
    with pytest.raises(MoveRefused, match=r"^the path move with its [\d.]+ s approach would "
                                          r"take 60\d\.\d{3} s, longer than a move may "
                                          r"last"):
        accept(MovePlan.of_path(still, "path"), away, UNIMATE, DT)
    with pytest.raises(MoveRefused, match="the move limit, 600 s"):
        accept(MovePlan("set_pulse", "pulse", profile=np.zeros((600_002, 6))), None, UNIMATE,
               DT)


def test_a_joint_beyond_its_limit_cannot_start_a_move() -> None:
    here = HOME.copy()
    here[UPDOWN] = 33.0  # 3° past its upper limit, 0.3° tolerance
    with pytest.raises(MoveRefused, match=r"Up/Down is at 33°, outside its limits -27…30° by "
                                          r"more than its tolerance 0.3°: .*jog it back"):
        accept(MovePlan.of_path(jumping_path(), "step"), here, UNIMATE, DT)


def test_a_rig_resting_just_below_its_stop_starts_on_it() -> None:
    path = moves.step([0.0], 0, 300.0, 2.0, machine=RIG)
    plan = MovePlan.of_path(path, "step")
    assert accept(plan, np.array([-0.1]), RIG, DT) is plan


FAR = HOME + np.array([500, 100, 25, 100, 150, 170])


@pytest.mark.parametrize("make", [
    lambda: moves.ramp(HOME, FAR, moves.min_ramp_time(HOME, FAR, UNIMATE), machine=UNIMATE),
    lambda: moves.sine(HOME, HOME + np.array([100, 0, 0, 0, 0, 0]), math.pi * math.sqrt(0.1), 3.0,
                       machine=UNIMATE),
    lambda: moves.sine(HOME, HOME + np.array([500, 0, 0, 0, 0, 0]), 500 * math.pi / 400, 4.0,
                       machine=UNIMATE),
    lambda: trajectory.via_path(np.vstack([HOME, HOME + np.array([400, 60, 20, 90, -60, 150]),
                                           HOME + np.array([100, -30, -20, 0, 40, 0])]), UNIMATE).q,
    lambda: cartesian_path(np.array([1400.0, -20, 5, -10, 30, 20]),
                           builtin_unimate().pose(np.array([1400.0, -20, 5, -10, 30, 20]))[:3]
                           + np.array([[150.0, 300, -80], [-100, 500, 100]]), UNIMATE).q,
    lambda: approach_ramp(HOME, FAR, UNIMATE, DT),
], ids=["ramp", "sine-accel", "sine-speed", "via_path", "cartesian", "approach"])
def test_every_generator_at_its_limits_passes_its_own_kinds_rules(make) -> None:
    """The differences of a path that keeps the limits never exceed them: these reach at
    most 1 + 2·10⁻¹⁰ of them (measured), so the 1 % tolerance is all for rounding."""
    path = make()
    rested = np.vstack([path[:1], path, path[-1:]])
    speed = np.abs(np.diff(rested, axis=0)).max(axis=0) / DT
    accel = np.abs(np.diff(rested, 2, axis=0)).max(axis=0) / DT**2
    worst = max(np.max(speed / [j.max_speed for j in UNIMATE.joints]),
                np.max(accel / [j.max_accel for j in UNIMATE.joints]))
    assert 0.45 < worst <= 1.0 + 1e-9
    check_path(path, "path", UNIMATE, DT)
