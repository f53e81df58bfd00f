"""Cartesian jog planning: the tool on the commanded line, the branch kept, the joints' limits
kept, and a jog that would pass a limit or a singularity refused with its reason."""

from __future__ import annotations

import re

import numpy as np
import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from control.motion import cartesian
from control.motion.cartesian_jog import WRIST_MARGIN_DEG, plan_jog, rotation_about, zone
from control.motion.robot_model import unimate_model
from hw.machine import load_machine
from kinematics.unimate import JOINTS, Unreachable

UNIMATE = load_machine("unimate2000b")
MODEL = unimate_model(UNIMATE)
VMAX = np.array([j.max_speed for j in UNIMATE.joints])
VJOG = np.array([j.jog_speed for j in UNIMATE.joints])
AMAX = np.array([j.max_accel for j in UNIMATE.joints])
DT = 0.005  # coarser than the machine's 1 ms: the line and the branch do not depend on it
START = np.array([1500.0, 10.0, 5.0, 20.0, 30.0, 10.0])
LINE_TOL_MM = 0.5
# A refusal names the joint or the singularity (or the reach) that stops the jog.
REASON = re.compile("|".join([*map(re.escape, JOINTS), "singularity", "out of reach"]))


def on_branch(q: np.ndarray, slot: int) -> np.ndarray:
    """``(N,)`` whether each joint vector is the ``slot`` solution of its own pose, to
    round-off: near the wrist singularity the solution moves by ~1e-14/sin θ5 (rad) for
    round-off in the pose (kinematics/unimate.py's docstring), so the tolerance grows there."""
    batch = MODEL.inverse_batch(MODEL.pose(q), near=q)
    sin5 = np.maximum(np.abs(np.sin(np.radians(q[:, 4]))), 1e-300)
    tol = 1e-6 + np.degrees(1e-12 / sin5)
    return batch.valid[:, slot] & (np.abs(batch.solutions[:, slot] - q).max(axis=1) < tol)


def rotation_vector(r: np.ndarray) -> np.ndarray:
    """Rotation vectors (rad) of rotations ``r (N, 3, 3)`` below 180°."""
    angle = np.arccos(np.clip((np.trace(r, axis1=1, axis2=2) - 1.0) / 2.0, -1.0, 1.0))
    axis = np.stack([r[:, 2, 1] - r[:, 1, 2], r[:, 0, 2] - r[:, 2, 0], r[:, 1, 0] - r[:, 0, 1]],
                    axis=1)
    scale = np.where(angle > 1e-12, angle / (2.0 * np.sin(np.maximum(angle, 1e-12))), 0.5)
    return axis * scale[:, None]


def check_on_line(q0: np.ndarray, d: np.ndarray, frame: str, q: np.ndarray) -> None:
    """Every sample's forward kinematics on the line from q0's pose by d, within the tolerance,
    turning about the commanded axis; the last one at the end."""
    t0, t = MODEL.forward(q0), MODEL.forward(q)
    r0, p0 = t0[:3, :3], t0[:3, 3]
    move = r0 @ d[:3] if frame == "tool" else d[:3]
    omega = np.radians(d[3:])
    p = t[:, :3, 3]
    length = np.linalg.norm(move)
    if length > 0:
        along = np.clip((p - p0) @ move / length**2, 0.0, 1.0)
        off = np.linalg.norm(p - p0 - along[:, None] * move, axis=1)
    else:
        off = np.linalg.norm(p - p0, axis=1)
    assert off.max() <= LINE_TOL_MM, f"{off.max():.3f} mm off the line"
    turned = t[:, :3, :3] @ r0.T if frame == "world" else r0.T @ t[:, :3, :3]
    v = rotation_vector(turned)
    if np.linalg.norm(omega) > 0:
        across = np.linalg.norm(np.cross(v, omega / np.linalg.norm(omega)), axis=1)
        assert np.degrees(across.max()) < 1e-3, "the tool turns about another axis"
    else:
        assert np.degrees(np.abs(v).max()) < 1e-6
    np.testing.assert_allclose(p[-1], p0 + move, atol=1e-6)
    want = rotation_about(omega[None])[0]
    end = r0 @ want if frame == "tool" else want @ r0
    np.testing.assert_allclose(t[-1, :3, :3], end, atol=1e-9)


@st.composite
def jogs(draw: st.DrawFn) -> tuple[np.ndarray, np.ndarray, str]:
    q0 = np.array([draw(st.floats(j.lower, j.upper)) for j in UNIMATE.joints])
    move = [draw(st.floats(-40.0, 40.0)) for _ in range(3)]
    turn = [draw(st.floats(-8.0, 8.0)) for _ in range(3)]
    axes = draw(st.sampled_from(["one", "translation", "rotation", "all"]))
    d = np.array(move + turn)
    if axes == "one":
        d = np.where(np.arange(6) == draw(st.integers(0, 5)), d, 0.0)
    elif axes == "translation":
        d[3:] = 0.0
    elif axes == "rotation":
        d[:3] = 0.0
    if np.abs(d).max() < 0.1:
        d[0] = 1.0
    return q0, d, draw(st.sampled_from(["world", "tool"]))


@settings(max_examples=1000, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(jogs())
@example((np.array([977.0, 34.0, 0.0, -1.0, 1e-6, 158.0]), np.array([1.0, 0, 0, 0, 0, 0]),
          "tool"))  # a start at the wrist singularity: round-off in the branch check
@example((np.array(MODEL.mid_range), np.array([0, 0, 0, 5.0, 0, 0]), "tool"))  # issue 25
def test_random_jogs_keep_the_branch_and_the_line_or_are_refused_with_a_reason(
        jog: tuple[np.ndarray, np.ndarray, str]) -> None:
    q0, d, frame = jog
    try:
        plan = plan_jog(q0, d, UNIMATE, frame=frame, dt=DT)
    except Unreachable as exc:
        assert REASON.search(str(exc)), str(exc)
        return
    assert on_branch(plan.q, plan.branch).all(), "a sample left the start's branch"
    assert on_branch(q0[None], plan.branch)[0]
    yaw = plan.q[:, 4]
    assert len(set(np.sign(yaw[np.abs(yaw) > 1e-9]))) <= 1, "Yaw changed sign: the wrist flipped"
    check_on_line(q0, d, frame, plan.q)
    np.testing.assert_array_equal(plan.q[0], q0)
    assert (plan.q >= UNIMATE.lower).all() and (plan.q <= UNIMATE.upper).all()
    # the singularity zone: no joint faster than its jog speed, and none travelling farther
    # than its max_speed covers in the time the jog takes at the Cartesian jog speed
    assert cartesian.limit_ratio(plan.q, DT, VJOG, AMAX) <= 1.0 + 1e-6
    assert (np.ptp(plan.q, axis=0) <= VMAX * nominal_time(d) * 1.05 + 1e-9).all()


def nominal_time(d: np.ndarray) -> float:
    """How long the jog ``d`` takes at the Cartesian jog speed, ramps aside (s)."""
    mm, deg = UNIMATE.cartesian_jog_speed
    return max(np.linalg.norm(d[:3]) / mm, np.linalg.norm(d[3:]) / deg)


def test_a_small_tool_turn_by_the_wrist_singularity_never_swings_a_joint() -> None:
    """Issue 25: at the simulator's start (Yaw 2.5°) γ +5° in the tool frame moved In/Out
    70 mm, Bend 70° and Swivel 64°. Now it stops at once, naming the joint and why."""
    with pytest.raises(Unreachable, match=r"γ \+5° \(tool frame\): at the start: Bend would "
                                          r"need \d+°/s, over its max_speed 90°/s, .*near the "
                                          r"wrist singularity \(Yaw 2\.50°"):
        plan_jog(MODEL.mid_range, [0, 0, 0, 5.0, 0, 0], UNIMATE, frame="tool")


def test_in_the_zone_a_jog_slows_so_that_no_joint_passes_its_jog_speed() -> None:
    """At Yaw 15° a world α turn needs Bend at twice its jog speed at 10°/s: the jog runs
    at about half the Cartesian jog speed, Bend at its jog speed (it ran at 44°/s before)."""
    q0 = np.array([1508.5, 0.0, 1.5, 0.0, 15.0, 0.0])
    plan = plan_jog(q0, [0, 0, 0, 0, 0, 5.0], UNIMATE)
    speed = np.abs(np.diff(plan.q, axis=0)).max(axis=0) / UNIMATE.sample_time_s
    assert speed[3] == pytest.approx(VJOG[3], rel=0.02)
    assert (speed <= VJOG * (1 + 1e-6)).all()
    assert plan.duration > 2 * 5.0 / UNIMATE.cartesian_jog_speed[1]


def test_the_zone_says_which_axes_slow_or_stop_and_why() -> None:
    start = zone(MODEL.mid_range, UNIMATE, "tool")  # Yaw 2.5°
    assert start.near and start.yaw == 2.5
    assert start.scale[3] == 0.0 and JOINTS[start.joint[3]] == "Bend"  # γ stops
    assert (start.scale[:3] == 1.0).all()  # translations run at full speed
    middle = zone([1508.5, 0.0, 1.5, 0.0, 15.0, 0.0], UNIMATE, "world")
    assert 0.4 < middle.scale[5] < 0.6 and JOINTS[middle.joint[5]] == "Bend"
    assert not zone(START, UNIMATE, "world").near


def test_the_jacobian_is_the_derivative_of_the_pose() -> None:
    rng = np.random.default_rng(25)
    for _ in range(20):
        q = np.array([rng.uniform(j.lower, j.upper) for j in UNIMATE.joints])
        jacobian = MODEL.jacobian(q)
        for j in range(6):
            h = np.eye(6)[j] * 1e-5
            plus, minus = MODEL.forward(q + h), MODEL.forward(q - h)
            np.testing.assert_allclose((plus[:3, 3] - minus[:3, 3]) / 2e-5, jacobian[:3, j],
                                       atol=1e-6)
            turn = rotation_vector((plus[:3, :3] @ minus[:3, :3].T)[None])[0]
            np.testing.assert_allclose(np.degrees(turn) / 2e-5, jacobian[3:, j], atol=1e-6)


def test_most_jogs_from_ordinary_configurations_are_planned() -> None:
    """The property above is not satisfied by refusing everything: from configurations
    inside the middle of every joint's range, 5 mm and 1° jogs along one axis all plan."""
    rng = np.random.default_rng(14)
    lower, upper = np.array(UNIMATE.lower), np.array(UNIMATE.upper)
    middle, half = (lower + upper) / 2, (upper - lower) / 4
    planned = 0
    for _ in range(100):
        q0 = middle + half * rng.uniform(-1.0, 1.0, 6)
        q0[4] = rng.choice([-1.0, 1.0]) * rng.uniform(20.0, 80.0)  # away from the wrist's
        axis = rng.integers(6)
        d = np.zeros(6)
        d[axis] = rng.choice([-1.0, 1.0]) * (5.0 if axis < 3 else 1.0)
        plan = plan_jog(q0, d, UNIMATE, frame=str(rng.choice(["world", "tool"])), dt=DT)
        planned += len(plan.q) > 1
    assert planned == 100


def test_a_translation_runs_at_the_cartesian_jog_speed_and_stops_on_the_target() -> None:
    plan = plan_jog(START, [40.0, 0, 0, 0, 0, 0], UNIMATE)
    p = MODEL.pose(plan.q)[:, :3]
    speed = np.linalg.norm(np.diff(p, axis=0), axis=1) / UNIMATE.sample_time_s
    assert speed.max() == pytest.approx(UNIMATE.cartesian_jog_speed[0], rel=0.01)
    assert speed[0] < 1.0 and speed[-1] < 1.0  # from rest, to rest
    # 40 mm at 25 mm/s with 100 mm/s² ramps: 1.6 s + 0.25 s
    assert plan.duration == pytest.approx(40.0 / 25.0 + 25.0 / 100.0, abs=0.002)


def test_speed_scales_the_jog() -> None:
    full = plan_jog(START, [20.0, 0, 0, 0, 0, 0], UNIMATE, dt=DT)
    half = plan_jog(START, [20.0, 0, 0, 0, 0, 0], UNIMATE, dt=DT, speed=0.5)
    assert half.duration == pytest.approx(2 * full.duration, rel=0.02)


@pytest.mark.parametrize("speed", [1e-3, 1e-5, 1e-200])
def test_a_jog_longer_than_a_move_may_last_is_refused_before_it_is_sampled(
        speed: float) -> None:
    """50 mm at a thousandth of the jog speed takes 2,250 s; at 1e-5 of it 225,000 s (225 M
    samples at the machine's 1 ms: a MemoryError before); at 1e-200 its acceleration is no
    float at all (a ZeroDivisionError before). Each is a ValueError naming the move limit."""
    with pytest.raises(ValueError, match=r"^the jog would take [\d,.inf]+ s, longer than a move "
                                         r"may last \(the move limit, 600 s\): jog a shorter "
                                         r"way, or faster$"):
        plan_jog(START, [50, 0, 0, 0, 0, 0], UNIMATE, speed=speed)


def test_a_tool_z_jog_moves_along_the_approach_vector() -> None:
    plan = plan_jog(START, [0, 0, 10.0, 0, 0, 0], UNIMATE, frame="tool")
    t0, t1 = MODEL.forward(START), MODEL.forward(plan.q[-1])
    np.testing.assert_allclose(t1[:3, 3] - t0[:3, 3], 10.0 * t0[:3, 2], atol=1e-6)
    np.testing.assert_allclose(t1[:3, :3], t0[:3, :3], atol=1e-9)


def test_a_world_alpha_jog_adds_to_alpha_and_keeps_the_tool_point() -> None:
    plan = plan_jog(START, [0, 0, 0, 0, 0, 5.0], UNIMATE)
    p0, p1 = MODEL.pose(START), MODEL.pose(plan.q[-1])
    np.testing.assert_allclose(p1[:3], p0[:3], atol=1e-6)
    np.testing.assert_allclose(p1[3:], p0[3:] + np.array([0, 0, 5.0]), atol=1e-6)


def near_wrist() -> np.ndarray:
    return np.array([1500.0, 10.0, 5.0, 20.0, 4.0, 10.0])  # Yaw 4°: near the singularity


def test_a_jog_into_the_wrist_singularity_is_refused_naming_it() -> None:
    # it stops where Yaw comes within 1° of 0°, or before, where a wrist joint would have
    # to swing faster than its max_speed (the zone's hard stop): either way it says so
    with pytest.raises(Unreachable, match=r"β \+10° \(tool frame\): at \d+% of the way.*"
                                          r"(Yaw would come within 1° of 0°|near the wrist "
                                          r"singularity \(Yaw \d\.\d+°)"):
        plan_jog(near_wrist(), [0, 0, 0, 0, 10.0, 0], UNIMATE, frame="tool")


def test_a_jog_away_from_the_wrist_singularity_is_planned() -> None:
    plan = plan_jog(near_wrist(), [0, 0, 0, 0, -10.0, 0], UNIMATE, frame="tool")
    assert plan.q[-1, 4] > near_wrist()[4]


def test_stop_short_stops_before_the_singularity_and_says_why() -> None:
    plan = plan_jog(near_wrist(), [0, 0, 0, 0, 10.0, 0], UNIMATE, frame="tool",
                    stop_short=True)
    assert "wrist singularity" in plan.stopped
    assert np.abs(plan.q[:, 4]).min() >= WRIST_MARGIN_DEG
    assert plan.q[-1, 4] < 3.0  # it went most of the way there (Bend's max_speed stops it)
    assert 0.0 < plan.displacement[4] < 10.0
    check_on_line(near_wrist(), plan.displacement, "tool", plan.q)


def test_a_jog_past_a_joint_limit_is_refused_naming_the_joint() -> None:
    with pytest.raises(Unreachable, match=r"joint limit: Bend would be 110\.\d°, past its "
                                          r"limits -110…110°"):
        plan_jog(START, [0, 0, 0, -40.0, 0, 0], UNIMATE)


def test_a_jog_that_would_wrap_swivel_past_its_limit_names_it() -> None:
    near_limit = np.array([1500.0, 10.0, 5.0, 20.0, 30.0, 178.0])
    with pytest.raises(Unreachable, match=r"joint limit: Swivel would pass its limit 180°"):
        plan_jog(near_limit, [0, 0, 0, 0, 0, 5.0], UNIMATE, frame="tool")


def test_stop_short_stops_before_the_limit() -> None:
    plan = plan_jog(START, [0, 0, 0, -40.0, 0, 0], UNIMATE, stop_short=True)
    assert "joint limit: Bend" in plan.stopped
    assert plan.q[:, 3].max() < 110.0


def test_a_jog_out_of_the_workspace_is_refused_naming_the_joint() -> None:
    with pytest.raises(Unreachable, match=r"x \+5000 mm \(world frame\): at 1\d% of the "
                                          r"way .*In/Out would be 204\d\.\d mm, past"):
        plan_jog(START, [5000.0, 0, 0, 0, 0, 0], UNIMATE)


def test_a_jog_that_makes_a_joint_crawl_near_the_singularity_is_refused() -> None:
    almost = np.array([1500.0, 10.0, 5.0, 20.0, 1.2, 10.0])
    with pytest.raises(Unreachable, match=r"at the start: (Swivel|Bend) would need \d+°/s, over "
                                          r"its max_speed .*near the wrist singularity"):
        plan_jog(almost, [0, 0, 0, 5.0, 0, 0], UNIMATE, frame="tool")


@pytest.mark.parametrize(("d", "options", "message"), [
    ([1.0, 2.0], {}, r"6 finite numbers"),
    ([np.nan, 0, 0, 0, 0, 0], {}, r"6 finite numbers"),
    ([0.0] * 6, {}, r"moves nothing"),
    ([1.0, 0, 0, 0, 0, 0], {"frame": "base"}, r"frame must be one of world, tool"),
    ([1.0, 0, 0, 0, 0, 0], {"speed": 0.0}, r"speed must be in \(0, 1\]"),
    ([1.0, 0, 0, 0, 0, 0], {"speed": 2.0}, r"speed must be in \(0, 1\]"),
])
def test_bad_input_is_a_clear_error(d: list[float], options: dict, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        plan_jog(START, d, UNIMATE, **options)


def test_the_rig_has_no_cartesian_jog() -> None:
    with pytest.raises(ValueError, match=r"machine rig has no unimate2000b kinematics"):
        plan_jog([100.0], [1.0, 0, 0, 0, 0, 0], load_machine("rig"))


def test_a_start_outside_the_limits_is_refused() -> None:
    with pytest.raises(ValueError, match=r"start: .*In/Out"):
        plan_jog([900.0, 0, 0, 0, 30.0, 0], [1.0, 0, 0, 0, 0, 0], UNIMATE)
