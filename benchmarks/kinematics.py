"""Throughput and success of the Unimate 2000B kinematics (``kinematics.unimate``).

Prints forward kinematics in poses/s (one batch), the closed-form inverse in
µs per pose (one pose at a time, median) and in poses/s (one batch), and how
often it solves poses made from random in-limit configurations. If the
Robotics Toolbox for Python is installed, the same robot is built as an
``rtb.DHRobot`` and its numerical ``ik_LM`` is timed on the same poses. It
prints figures and asserts nothing::

    python benchmarks/kinematics.py [--n 100000] [--single 2000] [--rtb 200]
"""

from __future__ import annotations

import argparse
import platform
import statistics
import sys
import time
from collections.abc import Callable
from pathlib import Path
from types import ModuleType

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np

from kinematics import Unreachable, unimate


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=100_000, help="poses in each batch figure")
    parser.add_argument("--single", type=int, default=2000, help="poses timed one at a time")
    parser.add_argument("--rtb", type=int, default=200,
                        help="poses for the Robotics Toolbox comparison")
    parser.add_argument("--seed", type=int, default=0, help="random seed of the configurations")
    args = parser.parse_args(argv)

    model = unimate.MODEL
    q = np.random.default_rng(args.seed).uniform(model.lower, model.upper, (args.n, 6))
    pose = model.pose(q)
    print(f"Unimate 2000B kinematics: {args.n:,} random in-limit configurations (seed "
          f"{args.seed}); Python {platform.python_version()}, numpy {np.__version__}")

    fk_s = best_of(lambda: model.forward(q))
    print(f"FK batch      {args.n / fk_s:>12,.0f} poses/s")
    ik_s = best_of(lambda: model.inverse_batch(pose))
    print(f"IK batch      {args.n / ik_s:>12,.0f} poses/s   (all 8 branches, nearest chosen)")

    single = pose[: args.single]
    times_us, unreachable = time_single(model, single)
    median_us = statistics.median(times_us)
    print(f"IK single     {median_us:>12.1f} µs/pose  median (p99 "
          f"{np.percentile(times_us, 99):.1f} µs) over {len(single):,} poses")

    result = model.inverse_batch(pose, near=q)
    recovered = np.abs(result.best - q).max(axis=-1) < 1e-6
    t = model.forward(np.where(result.reachable[:, None], result.best, q))
    want = model.forward(q)
    print(f"IK success    {100 * result.reachable.mean():>11.3f} %  batch; "
          f"{100 * (1 - unreachable / len(single)):.3f} % single; original configuration "
          f"first with near = itself: {100 * recovered.mean():.3f} %")
    print(f"IK accuracy   max |ΔP| {np.abs(t[:, :3, 3] - want[:, :3, 3]).max():.1e} mm, "
          f"max |ΔR| {np.abs(t[:, :3, :3] - want[:, :3, :3]).max():.1e}")

    compare_rtb(model, q[: args.rtb], median_us)
    return 0


def best_of(run: Callable[[], object], repeats: int = 3) -> float:
    """Shortest of ``repeats`` wall-clock runs (s)."""
    best = float("inf")
    for _ in range(repeats):
        start = time.perf_counter()
        run()
        best = min(best, time.perf_counter() - start)
    return best


def time_single(model: unimate.Unimate2000B, poses: np.ndarray) -> tuple[list[float], int]:
    """µs of each ``model.inverse`` call, and how many poses raised Unreachable."""
    times_us, unreachable = [], 0
    for p in poses:
        start = time.perf_counter_ns()
        try:
            model.inverse(p)
        except Unreachable:
            unreachable += 1
        times_us.append((time.perf_counter_ns() - start) / 1e3)
    return times_us, unreachable


def compare_rtb(model: unimate.Unimate2000B, q: np.ndarray, ours_us: float) -> None:
    """Time the Robotics Toolbox's numerical ``ik_LM`` on the poses of ``q``, if installed."""
    try:
        import roboticstoolbox as rtb
    except ImportError:
        print("rtb ik_LM     Robotics Toolbox for Python not installed "
              "(pip install roboticstoolbox-python to compare)")
        return
    robot = rtb_robot(rtb, model)
    q_dh = np.radians(q[:, list(unimate.DH_ORDER)])
    q_dh[:, 2] = q[:, 0] / 1000  # In/Out in metres
    targets = model.forward(q)
    targets[:, :3, 3] /= 1000
    mismatch = np.abs(robot.fkine(q_dh[0]).A - targets[0]).max()
    if mismatch > 1e-9:
        print(f"rtb ik_LM     skipped: the rtb model's FK differs from ours by {mismatch:.1e}")
        return
    times_us, solved = [], 0
    for t in targets:
        start = time.perf_counter_ns()
        solution = robot.ik_LM(t)
        times_us.append((time.perf_counter_ns() - start) / 1e3)
        # rtb >= 1.2 returns an IKSolution, older versions a tuple
        solved += bool(solution.success if hasattr(solution, "success") else solution[1])
    median_us = statistics.median(times_us)
    print(f"rtb ik_LM     {median_us:>12.1f} µs/pose  median over {len(targets):,} poses, "
          f"success {100 * solved / len(targets):.1f} %: {median_us / ours_us:.0f}× the "
          f"closed form (which also returns every branch)")


def rtb_robot(rtb: ModuleType, model: unimate.Unimate2000B) -> object:
    """The model as an ``rtb.DHRobot`` in rtb's units (m, rad), joints in DH order."""
    lower = np.array(model.lower)[list(unimate.DH_ORDER)]
    upper = np.array(model.upper)[list(unimate.DH_ORDER)]
    links = []
    for link, lo, hi in zip(model.links(), lower, upper, strict=True):
        alpha = np.radians(link.alpha_deg)
        if link.prismatic:
            links.append(rtb.PrismaticDH(theta=np.radians(link.theta_deg), a=link.a / 1000,
                                         alpha=alpha, offset=link.d / 1000,
                                         qlim=[lo / 1000, hi / 1000]))
        else:
            links.append(rtb.RevoluteDH(d=link.d / 1000, a=link.a / 1000, alpha=alpha,
                                        offset=np.radians(link.theta_deg),
                                        qlim=np.radians([lo, hi])))
    return rtb.DHRobot(links, name="Unimate 2000B")


if __name__ == "__main__":
    sys.exit(main())
