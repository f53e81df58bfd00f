"""Section 6.4 Cartesian paths: constant γ and β, α with Rotate, one branch, limits; pose files."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from control.motion import cartesian
from control.motion.cartesian import (
    PoseFileError,
    cartesian_path,
    parse_poses,
    path_from_poses,
    read_poses,
)
from control.motion.robot_model import builtin_unimate
from hw.machine import load_machine
from kinematics import unimate, xyz_fixed
from kinematics.unimate import Unimate2000B

UNIMATE = load_machine("unimate2000b")
MODEL = builtin_unimate()
DT = UNIMATE.sample_time_s
VMAX = np.array([j.max_speed for j in UNIMATE.joints])
AMAX = np.array([j.max_accel for j in UNIMATE.joints])
START = np.array([1400.0, -20.0, 5.0, -10.0, 30.0, 20.0])
TOOL = MODEL.pose(START)[:3]
OFFSETS = np.array([[150.0, 300.0, -80.0], [-100.0, 500.0, 100.0]])


@pytest.fixture(scope="module")
def path() -> cartesian.CartesianPath:
    return cartesian_path(START, TOOL + OFFSETS, UNIMATE)


def wrapped(angle: np.ndarray) -> np.ndarray:
    return (angle + 180.0) % 360.0 - 180.0


def test_gamma_and_beta_stay_constant_within_1e6_degrees(path: cartesian.CartesianPath) -> None:
    start = MODEL.pose(START)
    reached = MODEL.pose(path.q)  # the joints' forward kinematics, not the targets
    assert abs(start[4]) < 80.0  # away from β = ±90°, where γ and α are not separable
    assert np.max(np.abs(wrapped(reached[:, 3] - start[3]))) < 1e-6
    assert np.max(np.abs(wrapped(reached[:, 4] - start[4]))) < 1e-6


def test_alpha_turns_one_to_one_with_rotate(path: cartesian.CartesianPath) -> None:
    start = MODEL.pose(START)
    reached = MODEL.pose(path.q)
    turned = wrapped((reached[:, 5] - start[5]) - (path.q[:, 1] - START[1]))
    assert np.max(np.abs(turned)) < 1e-6
    assert np.ptp(path.q[:, 1]) > 10.0  # Rotate really turns on this path


def test_the_tool_attitude_relative_to_the_arm_is_constant(path: cartesian.CartesianPath) -> None:
    # Rz(−θ1)·R is constant, so Yaw and Swivel stay put and Bend makes up for Up/Down
    np.testing.assert_allclose(path.q[:, 4], START[4], atol=1e-9)
    np.testing.assert_allclose(path.q[:, 5], START[5], atol=1e-9)
    np.testing.assert_allclose(path.q[:, 2] + path.q[:, 3], START[2] + START[3], atol=1e-9)
    r = xyz_fixed.rotation(*np.radians(MODEL.pose(path.q)[:, 3:]).T)
    rz = xyz_fixed.rotation(0.0, 0.0, -np.radians(path.q[:, 1]))
    relative = rz @ r
    np.testing.assert_allclose(relative, np.broadcast_to(relative[0], relative.shape), atol=1e-12)


def test_the_tool_passes_through_the_via_points_on_a_cubic_spline(
        path: cartesian.CartesianPath) -> None:
    xyz = MODEL.pose(path.q)[:, :3]
    np.testing.assert_allclose(xyz[0], TOOL, atol=1e-9)
    np.testing.assert_allclose(xyz[path.via_index[1:]], TOOL + OFFSETS, atol=1e-6)
    np.testing.assert_allclose(xyz, path.poses[:, :3], atol=1e-6)
    np.testing.assert_allclose(path.q[0], START, atol=1e-9)
    # clamped spline: the tool starts and ends at rest (one sample moves it by a·dt²/2)
    speed = np.linalg.norm(np.diff(xyz, axis=0), axis=1) / DT
    assert speed[0] < 0.01 * speed.max() and speed[-1] < 0.01 * speed.max()


def test_the_joint_path_is_continuous_and_within_every_limit(
        path: cartesian.CartesianPath) -> None:
    speed = np.abs(np.diff(path.q, axis=0)).max(axis=0) / DT
    accel = np.abs(np.diff(path.q, n=2, axis=0)).max(axis=0) / DT**2
    assert np.all(speed <= VMAX * (1 + 1e-6))
    assert np.all(accel <= AMAX * (1 + 1e-6))
    assert np.max(speed / VMAX) > 0.95  # the fastest joint is at its limit: no time wasted
    assert np.all(path.q >= np.array(UNIMATE.lower)) and np.all(path.q <= np.array(UNIMATE.upper))


def test_every_sample_stays_on_the_start_branch(path: cartesian.CartesianPath) -> None:
    batch = MODEL.inverse_batch(path.poses, near=START)
    assert batch.valid[:, path.branch].all()
    np.testing.assert_allclose(batch.solutions[:, path.branch], path.q, atol=1e-9)
    # the branch is the one the start joints are on
    start_batch = MODEL.inverse_batch(MODEL.pose(START), near=START)
    nearest = np.argmin(np.where(start_batch.valid, unimate.distance(start_batch.solutions,
                                                                     START), np.inf))
    assert nearest == path.branch


def test_the_thesis_shortcut_alpha_from_phi_alone_is_only_right_in_the_arm_plane() -> None:
    frame = cartesian.arm_frame(START, MODEL)
    assert abs(frame.offset) > 100.0  # the tool point is far off the arm plane here
    end = TOOL + OFFSETS[-1]
    exact = math.degrees(frame.rotate_angle(np.vstack([TOOL, end]))[1])
    shortcut = START[1] + math.degrees(math.atan2(end[1], end[0]) - math.atan2(TOOL[1], TOOL[0]))
    final = cartesian_path(START, TOOL + OFFSETS, UNIMATE).q[-1, 1]
    assert final == pytest.approx(exact, abs=1e-9)
    assert abs(shortcut - exact) > 1.0


def test_given_times_are_kept_when_the_joints_can_make_them() -> None:
    slow = cartesian_path(START, TOOL + OFFSETS, UNIMATE, times=[3.0, 6.0])
    np.testing.assert_allclose(slow.via_t, [0.0, 3.0, 6.0])
    with pytest.raises(ValueError, match=r"given times are too fast for .* stretch the times"):
        cartesian_path(START, TOOL + OFFSETS, UNIMATE, times=[0.3, 0.6])


def test_speed_fraction_slows_the_path() -> None:
    full = cartesian_path(START, TOOL + OFFSETS, UNIMATE)
    half = cartesian_path(START, TOOL + OFFSETS, UNIMATE, speed_fraction=0.5)
    assert half.duration > 1.4 * full.duration


def test_a_point_beyond_the_joint_limits_is_refused_naming_where() -> None:
    high = TOOL + np.array([[150.0, 300.0, -80.0], [-100.0, 500.0, 800.0]])
    with pytest.raises(ValueError, match=r"path point at \d+% of the way from via point 1 to "
                                         r"via point 2 .*x y z = .*: outside the joint limits: "
                                         r"Up/Down"):
        cartesian_path(START, high, UNIMATE)


def test_a_point_out_of_reach_is_refused() -> None:
    far = TOOL + np.array([[150.0, 300.0, -80.0], [3000.0, 0.0, 0.0]])
    with pytest.raises(ValueError, match=r"path point at .*(out of reach|outside the joint "
                                         r"limits): In/Out"):
        cartesian_path(START, far, UNIMATE)


def test_a_branch_change_is_refused(monkeypatch: pytest.MonkeyPatch) -> None:
    real = Unimate2000B.inverse_batch

    def flipping(model: Unimate2000B, p: np.ndarray,
                 near: np.ndarray | None = None) -> unimate.InverseBatch:
        batch = real(model, p, near)
        valid = batch.valid.copy()
        half = len(valid) // 2
        slot = int(np.argmax(valid[0]))
        valid[half:, slot] = False
        valid[half:, (slot + 2) % 8] = True  # pretend the other wrist branch is there
        return unimate.InverseBatch(batch.solutions, valid, batch.best, batch.reachable)

    monkeypatch.setattr(Unimate2000B, "inverse_batch", flipping)
    with pytest.raises(ValueError, match=r"would have to change configuration here .*wrist "
                                         r"branch"):
        cartesian_path(START, TOOL + OFFSETS, UNIMATE)


def test_a_joint_jump_is_refused(monkeypatch: pytest.MonkeyPatch) -> None:
    real = Unimate2000B.inverse_batch

    def wrapping(model: Unimate2000B, p: np.ndarray,
                 near: np.ndarray | None = None) -> unimate.InverseBatch:
        batch = real(model, p, near)
        solutions = batch.solutions.copy()
        solutions[len(solutions) // 2:, :, 5] -= 360.0  # Swivel's other copy
        return unimate.InverseBatch(solutions, batch.valid, batch.best, batch.reachable)

    monkeypatch.setattr(Unimate2000B, "inverse_batch", wrapping)
    with pytest.raises(ValueError, match=r"Swivel would jump from 20\.00° to -340\.00°"):
        cartesian_path(START, TOOL + OFFSETS, UNIMATE)


def test_malformed_requests_are_refused() -> None:
    with pytest.raises(ValueError, match=r"at least one intermediate point|M ≥ 2"):
        cartesian_path(START, TOOL[None] + OFFSETS[:1], UNIMATE)
    with pytest.raises(ValueError, match="via point 1 is at the same position as the start"):
        cartesian_path(START, np.vstack([TOOL, TOOL + OFFSETS[0]]), UNIMATE)
    with pytest.raises(ValueError, match="start: Up/Down target 40"):
        cartesian_path(START + np.array([0, 0, 35, 0, 0, 0]), TOOL + OFFSETS, UNIMATE)
    with pytest.raises(ValueError, match="no unimate2000b kinematics"):
        cartesian_path([600.0], TOOL + OFFSETS, load_machine("rig"))


# -- pose files ---------------------------------------------------------------------------


def test_a_pose_csv_with_times_is_read_with_line_numbers() -> None:
    text = "# via points\nt,x [mm],y,z\n\n1.5, 10, 20, 30\n# a comment\n3.0,11,21,31\n"
    points = parse_poses(text)
    np.testing.assert_allclose(points.t, [1.5, 3.0])
    np.testing.assert_allclose(points.xyz, [[10, 20, 30], [11, 21, 31]])
    assert points.orientation is None and points.lines == (4, 6)


def test_a_pose_csv_without_times_and_with_greek_orientation_columns() -> None:
    points = parse_poses("x,y,z,γ,β,α\n1,2,3,4,5,6\n7,8,9,10,11,12\n")
    assert points.t is None
    np.testing.assert_allclose(points.orientation, [[4, 5, 6], [10, 11, 12]])


@pytest.mark.parametrize(("text", "message"), [
    ("", "empty file"),
    ("x,y\n1,2\n", "line 1: the header needs x, y and z"),
    ("x,y,z,speed\n1,2,3,4\n", "line 1: column 4 'speed' is not one of"),
    ("x,y,z,gamma\n1,2,3,4\n", "line 1: give gamma, beta and alpha together"),
    ("x,y,z,X\n1,2,3,4\n", "line 1: column 'X' appears twice"),
    ("x,y,z\n1,2,3\n4,5\n", "line 3: 2 field(s), the header has 3"),
    ("x,y,z\n1,2,three\n", "line 2: field 3 'three' is not a number"),
    ("x,y,z\n1,2,inf\n", "line 2: field 3 is inf, not a finite number"),
    ("t,x,y,z\n1,1,2,3\n1,4,5,6\n", "line 3: time 1 s must be after 1 s"),
    ("t,x,y,z\n0,1,2,3\n", "line 2: time 0 s must be after 0 s"),
    ("x,y,z\n# nothing\n", "no via points"),
])
def test_malformed_pose_files_are_reported_by_line(text: str, message: str) -> None:
    with pytest.raises(PoseFileError, match=rf"^<csv>: .*{_escape(message)}"):
        parse_poses(text)


def _escape(text: str) -> str:
    return "".join("\\" + c if c in "()[]." else c for c in text)


def test_a_pose_file_drives_the_same_path_as_the_points(tmp_path: Path) -> None:
    file = tmp_path / "pick.csv"
    rows = "\n".join(",".join(f"{v:.10f}" for v in p) for p in TOOL + OFFSETS)
    file.write_text(f"x,y,z\n{rows}\n", encoding="utf-8")
    from_file = path_from_poses(read_poses(file, UNIMATE), START, UNIMATE)
    direct = cartesian_path(START, TOOL + OFFSETS, UNIMATE)
    np.testing.assert_allclose(from_file.q, direct.q, atol=1e-6)


def test_orientation_columns_must_follow_the_one_to_one_rule() -> None:
    path = cartesian_path(START, TOOL + OFFSETS, UNIMATE)
    poses = path.poses[path.via_index[1:]]
    good = "x,y,z,gamma,beta,alpha\n" + "\n".join(",".join(f"{v:.12f}" for v in p)
                                                  for p in poses) + "\n"
    np.testing.assert_allclose(path_from_poses(parse_poses(good), START, UNIMATE).q, path.q,
                               atol=1e-6)
    bad = poses.copy()
    bad[1, 5] += 5.0
    text = "x,y,z,gamma,beta,alpha\n" + "\n".join(",".join(f"{v:.12f}" for v in p)
                                                  for p in bad) + "\n"
    with pytest.raises(PoseFileError, match=r"line 3: orientation .* is not the start "
                                            r"orientation turned with Rotate .*5° away"):
        path_from_poses(parse_poses(text), START, UNIMATE)


def test_a_pose_file_path_error_names_the_file(tmp_path: Path) -> None:
    file = tmp_path / "high.csv"
    rows = TOOL + np.array([[150.0, 300.0, -80.0], [-100.0, 500.0, 800.0]])
    file.write_text("x,y,z\n" + "\n".join(",".join(map(str, p)) for p in rows) + "\n",
                    encoding="utf-8")
    with pytest.raises(PoseFileError, match=rf"^{file}: path point .* Up/Down"):
        path_from_poses(read_poses(file, UNIMATE), START, UNIMATE)
    with pytest.raises(PoseFileError, match="1 via point"):
        path_from_poses(parse_poses("x,y,z\n1,2,3\n"), START, UNIMATE)
    with pytest.raises(PoseFileError, match="cannot read"):
        read_poses(tmp_path / "missing.csv", UNIMATE)


def test_a_pose_file_past_its_bound_is_refused_before_it_is_parsed(tmp_path: Path) -> None:
    """Each via point is a sample of the path: at most one per sample of the longest move
    allowed, and a header."""
    file = tmp_path / "many.csv"
    file.write_text("x,y,z\n" + "1,2,3\n" * 600_002)
    with pytest.raises(PoseFileError, match=r"many\.csv: at least 600,003 lines; a pose file may "
                                            r"hold at most 600,002 lines and 307\.2 MB \(one "
                                            r"point per 1 ms sample of the longest move allowed, "
                                            r"600 s, and a header.*\): use fewer via points"):
        read_poses(file, UNIMATE)


def test_a_pose_file_at_its_bound_is_read(tmp_path: Path) -> None:
    file = tmp_path / "most.csv"
    file.write_text("x,y,z\n" + "1,2,3\n" * 600_001)
    assert len(read_poses(file, UNIMATE).xyz) == 600_001
