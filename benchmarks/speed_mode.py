"""Reduced speed (T1) against automatic: the largest tool and joint speeds of manual motions.

Run: ``PYTHONPATH=. python benchmarks/speed_mode.py`` (about 40 s; the simulated Unimate 2000B,
in lockstep but for the loop's cost).

Each manual motion runs once in each mode, from home: a go-to at full speed fraction (In/Out to
1700 mm, Rotate to 40°, the Positions tab's "go"), a Cartesian line of 600 mm sideways as fast
as the joints allow (a Moves Cartesian path), a position jog of Rotate by 20° and a streamed
velocity jog of Rotate at its jog speed for 1.5 s back (the Jog tab). For each the script prints,
reduced and automatic side by side, the largest speed of the tool point from forward
kinematics of the desired rows (what the controller commands) and of the actual ones over
50 ms and 0.2 s (the arm's own; over one tick an encoder count reads as a spike), and the
largest joint speed as a fraction of that joint's jog speed (desired). Jogs are measured
from the status, sampled as often as it can be read. Then the loop's compute per tick during
a go-to in each mode (in real time), and what a batch forward kinematics of a 60 s path costs
(why the controller bounds the tool's speed instead, control/rt/speed_cap.py).
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # ahead of benchmarks/hw.py

from control import ControlClient
from control.motion.cartesian import cartesian_path
from control.motion.robot_model import builtin_unimate
from hw.machine import load_machine

UNIMATE = load_machine("unimate2000b")
MODEL = builtin_unimate()
JOG_SPEED = np.array([j.jog_speed for j in UNIMATE.joints])
INOUT, ROTATE = UNIMATE.joint_index("inout"), UNIMATE.joint_index("rotate")


def tool_speed(t: np.ndarray, q: np.ndarray, window_s: float = 0.0) -> float:
    """The largest tool-point speed (mm/s) along joint rows ``q (N, 6)`` at times ``t``."""
    p = MODEL.pose(q)[:, :3]
    later = (np.searchsorted(t, t + window_s, side="right") if window_s
             else np.arange(1, len(t) + 1))
    ok = later < len(t)
    return float((np.linalg.norm(p[later[ok]] - p[ok], axis=1) / (t[later[ok]] - t[ok])).max())


def joint_fraction(t: np.ndarray, q: np.ndarray) -> float:
    return float((np.abs(np.diff(q, axis=0)) / np.diff(t)[:, None] / JOG_SPEED).max())


def sampled(robot: ControlClient, start: object,
            stream: tuple[list[float], float] | None = None) -> tuple[np.ndarray, ...]:
    """Status rows from ``start()`` until the hold target has stood still 0.3 s; ``stream``:
    a velocity jog ``(velocity, seconds)`` renewed from this loop every 20 ms of controller
    time (a lockstep controller's time runs fast: a thread could miss the 150 ms deadman)."""
    rows: list[tuple[float, tuple[float, ...], tuple[float, ...]]] = []
    start()
    began = sent = robot.status().time_s
    still = None
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline:
        s = robot.status()
        if stream and s.time_s - began < stream[1] and s.time_s - sent >= 0.02:
            robot.jog_velocity(stream[0])
            sent = s.time_s
        if rows and s.time_s == rows[-1][0]:
            continue
        if rows and s.desired == rows[-1][1] and s.time_s > rows[0][0] + 0.2:
            still = still or s.time_s
            if s.time_s - still > 0.3:
                break
        else:
            still = None
        rows.append((s.time_s, s.desired, s.position))
    return tuple(np.array([r[i] for r in rows]) for i in range(3))


def motions(robot: ControlClient) -> dict[str, tuple[np.ndarray, ...]]:
    """Each manual motion's ``(t, desired, actual)``, each from home."""
    home = np.array(UNIMATE.home)
    far = home.copy()
    far[INOUT], far[ROTATE] = 1700.0, 40.0
    out = {}
    run = robot.wait(robot.go_to(far, speed=1.0), 120).run
    out["go-to"] = (run.t, run.desired, run.actual)
    robot.wait(robot.go_to(home, speed=1.0), 120)
    side = np.array([0.0, 300.0, 0.0])
    start = MODEL.pose(home)[:3]
    line = cartesian_path(home, [start + side, start + 2 * side], UNIMATE,
                          dt=UNIMATE.sample_time_s).q
    run = robot.wait(robot.move(line, kind="cartesian"), 120).run
    out["Cartesian line"] = (run.t, run.desired, run.actual)
    robot.wait(robot.go_to(home, speed=1.0), 120)
    out["position jog"] = sampled(robot, lambda: robot.jog_position(ROTATE, 20.0))
    velocity = [0.0] * UNIMATE.n_joints
    velocity[ROTATE] = -JOG_SPEED[ROTATE]
    out["velocity jog"] = sampled(robot, lambda: robot.jog_velocity(velocity), (velocity, 1.5))
    return out


def loop_cost() -> str:
    """The loop's mean compute per tick over the go-to in each mode, in real time (lockstep's
    clock does not count compute)."""
    far = np.array(UNIMATE.home)
    far[INOUT], far[ROTATE] = 1700.0, 40.0
    cost = {}
    with tempfile.TemporaryDirectory() as data, \
            ControlClient("unimate2000b", data_dir=data) as robot:
        robot.wait(robot.go_to(UNIMATE.home, speed=1.0), 60)
        for mode, target in (("automatic", far), ("reduced", UNIMATE.home)):
            robot.set_speed_mode(mode)
            before = robot.status()
            robot.wait(robot.go_to(target, speed=1.0), 120)
            after = robot.status()
            cost[mode] = (after.compute_total_s - before.compute_total_s) / (after.tick
                                                                            - before.tick)
    return (f"loop compute per tick during a go-to, real time: reduced "
            f"{cost['reduced'] * 1e6:.0f} µs | automatic {cost['automatic'] * 1e6:.0f} µs")


def main() -> None:
    figures: dict[str, dict[str, tuple[np.ndarray, ...]]] = {}
    with tempfile.TemporaryDirectory() as data, \
            ControlClient("unimate2000b", lockstep=True, data_dir=data,
                          heartbeat_timeout_s=3.0, speed_mode="reduced") as robot:
        for mode in ("reduced", "automatic"):
            robot.set_speed_mode(mode)
            robot.wait(robot.go_to(UNIMATE.home, speed=1.0), 60)
            figures[mode] = motions(robot)
    print("largest speeds of manual motions, reduced (T1) | automatic; tool in mm/s, joints as a "
          "fraction of their jog speed")
    print(f"{'motion':16}{'tool desired':>22}{'actual 50 ms':>22}{'actual 0.2 s':>22}"
          f"{'joint/jog':>18}")
    for name in figures["reduced"]:
        cells = []
        for measure in (lambda t, d, a: tool_speed(t, d), lambda t, d, a: tool_speed(t, a, 0.05),
                        lambda t, d, a: tool_speed(t, a, 0.2)):
            cells.append(" | ".join(f"{measure(*figures[m][name]):7.0f}"
                                    for m in ("reduced", "automatic")))
        joints = " | ".join(f"{joint_fraction(*figures[m][name][:2]):6.2f}"
                            for m in ("reduced", "automatic"))
        print(f"{name:16}{cells[0]:>22}{cells[1]:>22}{cells[2]:>22}{joints:>18}")
    print(loop_cost())
    q = np.tile(np.array(UNIMATE.home), (60_000, 1)) + np.random.default_rng(0).random((60_000, 6))
    MODEL.pose(q[:10])
    took = []
    for _ in range(3):
        begun = time.perf_counter()
        MODEL.pose(q)
        took.append(time.perf_counter() - begun)
    print(f"batch forward kinematics of a 60 s path (60000 rows): {min(took) * 1e3:.0f} ms "
          f"(best of 3): a controller tick is 1 ms")


if __name__ == "__main__":
    main()
