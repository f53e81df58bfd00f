"""Throughput and success of the Unimate 2000B kinematics (``kinematics.unimate``).

Prints forward kinematics in poses/s (one batch), the closed-form inverse in
µs per pose (one pose at a time, median) and in poses/s (one batch), and how
often it solves poses made from random in-limit configurations. If the
Robotics Toolbox for Python is installed, the same robot is built as an
``rtb.DHRobot`` and its numerical ``ik_LM`` (Levenberg–Marquardt, in C++, on the
robot's ETS built once) is timed on the same poses. It prints figures and
asserts nothing; ``measure()`` returns them::

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

from control.motion.robot_model import builtin_unimate
from kinematics import Unreachable, unimate


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=100_000, help="poses in each batch figure")
    parser.add_argument("--single", type=int, default=2000, help="poses timed one at a time")
    parser.add_argument("--rtb", type=int, default=200,
                        help="poses for the Robotics Toolbox comparison")
    parser.add_argument("--seed", type=int, default=0, help="random seed of the configurations")
    args = parser.parse_args(argv)
    print(f"Unimate 2000B kinematics: {args.n:,} random in-limit configurations (seed "
          f"{args.seed}); Python {platform.python_version()}, numpy {np.__version__}")
    m = measure(args.n, args.single, args.rtb, args.seed)
    print(f"FK batch      {m['fk_poses_s']:>12,.0f} poses/s")
    print(f"IK batch      {m['ik_batch_poses_s']:>12,.0f} poses/s   "
          "(all 8 branches, nearest chosen)")
    print(f"IK single     {m['ik_single_us']:>12.1f} µs/pose  median (p99 "
          f"{m['ik_single_p99_us']:.1f} µs) over {m['single']:,} poses")
    print(f"IK success    {m['success_batch_pct']:>11.3f} %  batch; "
          f"{m['success_single_pct']:.3f} % single; original configuration "
          f"first with near = itself: {m['recovered_pct']:.3f} %")
    print(f"IK accuracy   max |ΔP| {m['max_dp_mm']:.1e} mm, max |ΔR| {m['max_dr']:.1e}")
    rtb = m["rtb"]
    if isinstance(rtb, str):
        print(f"rtb ik_LM     {rtb}")
    else:
        print(f"rtb ik_LM     {rtb['median_us']:>12.1f} µs/pose  median over {rtb['poses']:,} "
              f"poses, success {rtb['success_pct']:.1f} %: "
              f"{rtb['median_us'] / m['ik_single_us']:.0f}× the closed form (which also "
              "returns every branch)")
    return 0


def measure(n: int = 100_000, single: int = 2000, rtb_poses: int = 200, seed: int = 0) -> dict:
    """The figures ``main`` prints, as a dict (µs, poses/s, %); ``rtb`` is a dict of the
    Robotics Toolbox's ``ik_LM`` figures, or the reason it was not timed."""
    model = builtin_unimate()  # the built-in machine file's Table 4.1 and limits
    q = np.random.default_rng(seed).uniform(model.lower, model.upper, (n, 6))
    pose = model.pose(q)
    fk_s = best_of(lambda: model.forward(q))
    ik_s = best_of(lambda: model.inverse_batch(pose))
    times_us, unreachable = time_single(model, pose[:single])
    result = model.inverse_batch(pose, near=q)
    recovered = np.abs(result.best - q).max(axis=-1) < 1e-6
    t = model.forward(np.where(result.reachable[:, None], result.best, q))
    want = model.forward(q)
    return {
        "n": n, "single": len(times_us), "seed": seed,
        "fk_poses_s": n / fk_s, "ik_batch_poses_s": n / ik_s,
        "ik_single_us": statistics.median(times_us),
        "ik_single_p99_us": float(np.percentile(times_us, 99)),
        "success_batch_pct": 100 * float(result.reachable.mean()),
        "success_single_pct": 100 * (1 - unreachable / len(times_us)),
        "recovered_pct": 100 * float(recovered.mean()),
        "max_dp_mm": float(np.abs(t[:, :3, 3] - want[:, :3, 3]).max()),
        "max_dr": float(np.abs(t[:, :3, :3] - want[:, :3, :3]).max()),
        "rtb": rtb_ik(model, q[:rtb_poses]),
    }


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


def rtb_ik(model: unimate.Unimate2000B, q: np.ndarray) -> dict | str:
    """Time the Robotics Toolbox's numerical ``ik_LM`` on the poses of ``q``, if installed:
    its median µs per pose, poses/s, success % and version; else why not."""
    try:
        import roboticstoolbox as rtb
    except ImportError:
        return ("Robotics Toolbox for Python not installed "
                "(pip install roboticstoolbox-python to compare)")
    robot = rtb_robot(rtb, model)
    q_dh = np.radians(q[:, list(unimate.DH_ORDER)])
    q_dh[:, 2] = q[:, 0] / 1000  # In/Out in metres
    targets = model.forward(q)
    targets[:, :3, 3] /= 1000
    mismatch = np.abs(robot.fkine(q_dh[0]).A - targets[0]).max()
    if mismatch > 1e-9:
        return f"skipped: the rtb model's FK differs from ours by {mismatch:.1e}"
    ets = robot.ets()  # built once: Robot.ik_LM rebuilds it on every call (~10x slower)
    times_us, solved = [], 0
    for t in targets:
        start = time.perf_counter_ns()
        solution = ets.ik_LM(t)
        times_us.append((time.perf_counter_ns() - start) / 1e3)
        # rtb >= 1.2 returns an IKSolution, older versions a tuple
        solved += bool(solution.success if hasattr(solution, "success") else solution[1])
    median_us = statistics.median(times_us)
    return {"median_us": median_us, "poses_s": 1e6 / median_us, "poses": len(targets),
            "success_pct": 100 * solved / len(targets), "version": rtb.__version__}


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
