"""Throughput and success of the Unimate 2000B kinematics (``kinematics.unimate``).

Prints forward kinematics in poses/s (one batch), the closed-form inverse in
µs per pose (one pose at a time, median) and in poses/s (one batch), and how
often it solves poses made from random in-limit configurations. If the
Robotics Toolbox for Python is installed, the same robot is built as an
``rtb.DHRobot`` and its numerical ``ik_LM`` (Levenberg–Marquardt, in C++, on the
robot's ETS built once) is timed on the same poses. With ``--against REV`` the
``kinematics`` package of another commit (taken with ``git archive`` into a temporary
directory, imported beside this tree's and removed after) is timed on the same poses
in the same run, turn about with this tree's, and each figure is printed with its ratio
to that commit's and to ``ik_LM``'s. It prints figures and asserts nothing;
``measure()`` returns them::

    python benchmarks/kinematics.py [--n 100000] [--single 2000] [--rtb 200] [--against REV]
"""

from __future__ import annotations

import argparse
import contextlib
import importlib
import platform
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from types import ModuleType

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np

from control.motion.robot_model import builtin_unimate
from kinematics import Unreachable, unimate

ROOT = Path(__file__).resolve().parents[1]
ROUNDS = 3  # single-pose timings taken turn about: this tree's, the other commit's, ik_LM


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=100_000, help="poses in each batch figure")
    parser.add_argument("--single", type=int, default=2000, help="poses timed one at a time")
    parser.add_argument("--rtb", type=int, default=200,
                        help="poses for the Robotics Toolbox comparison")
    parser.add_argument("--seed", type=int, default=0, help="random seed of the configurations")
    parser.add_argument("--against", metavar="REV",
                        help="also time the kinematics of this git commit, side by side")
    args = parser.parse_args(argv)
    print(f"Unimate 2000B kinematics: {args.n:,} random in-limit configurations (seed "
          f"{args.seed}); Python {platform.python_version()}, numpy {np.__version__}")
    m = measure(args.n, args.single, args.rtb, args.seed, args.against)
    rtb, old = m["rtb"], m.get("against")
    print(f"FK batch      {m['fk_poses_s']:>12,.0f} poses/s"
          f"{versus(m['fk_poses_s'], old, 'fk_poses_s')}")
    print(f"IK batch      {m['ik_batch_poses_s']:>12,.0f} poses/s   (all 8 branches, nearest "
          f"chosen){versus(m['ik_batch_poses_s'], old, 'ik_batch_poses_s')}")
    print(f"IK single     {m['ik_single_us']:>12.1f} µs/pose  median (p99 "
          f"{m['ik_single_p99_us']:.1f} µs) over {m['single']:,} poses × {ROUNDS} rounds"
          f"{versus(1 / m['ik_single_us'], old, 'ik_single_us', invert=True)}")
    if isinstance(rtb, dict):
        print(f"              ik_LM's median is {rtb['median_us'] / m['ik_single_us']:.1f}× this"
              + ("" if old is None else
                 f" ({rtb['median_us'] / old['ik_single_us']:.1f}× {old['rev']}'s)")
              + f"; the batch solves {m['ik_batch_poses_s'] / rtb['poses_s']:.0f}× the poses a "
              "second of ik_LM one at a time")
    print(f"IK success    {m['success_batch_pct']:>11.3f} %  batch; "
          f"{m['success_single_pct']:.3f} % single; original configuration "
          f"first with near = itself: {m['recovered_pct']:.3f} %")
    print(f"IK accuracy   max |ΔP| {m['max_dp_mm']:.1e} mm, max |ΔR| {m['max_dr']:.1e}")
    if isinstance(rtb, str):
        print(f"rtb ik_LM     {rtb}")
    else:
        print(f"rtb ik_LM     {rtb['median_us']:>12.1f} µs/pose  median over {rtb['poses']:,} "
              f"poses × {ROUNDS} rounds, success {rtb['success_pct']:.1f} % (rtb "
              f"{rtb['version']}; one solution, where the closed form returns every branch)")
    return 0


def versus(value: float, old: dict | None, key: str, invert: bool = False) -> str:
    """``value`` (larger is better) as a ratio to the other commit's figure ``old[key]``."""
    if old is None:
        return ""
    theirs = 1 / old[key] if invert else old[key]
    shown = f"{old[key]:.1f} µs" if invert else f"{old[key]:,.0f}"
    return f"; {old['rev']}: {shown}, this is {value / theirs:.2f}× as fast"


def measure(n: int = 100_000, single: int = 2000, rtb_poses: int = 200, seed: int = 0,
            against: str | None = None) -> dict:
    """The figures ``main`` prints, as a dict (µs, poses/s, %); ``rtb`` is a dict of the
    Robotics Toolbox's ``ik_LM`` figures, or the reason it was not timed; ``against``
    (when given a commit) that commit's FK and IK figures on the same poses."""
    model = builtin_unimate()  # the built-in machine file's Table 4.1 and limits
    q = np.random.default_rng(seed).uniform(model.lower, model.upper, (n, 6))
    pose = model.pose(q)
    with contextlib.ExitStack() as stack:
        old = None if against is None else stack.enter_context(checkout(against))
        other = None if old is None else old.Unimate2000B(
            d1=model.d1, a2=model.a2, lb=model.lb, ly=model.ly, lower=model.lower,
            upper=model.upper)
        fk_s, old_fk_s = best_pair(lambda: model.forward(q),
                                   None if other is None else lambda: other.forward(q))
        ik_s, old_ik_s = best_pair(lambda: model.inverse_batch(pose),
                                   None if other is None else lambda: other.inverse_batch(pose))
        times_us, unreachable, old_us = [], 0, []
        rtb: dict | str = {}
        for _ in range(ROUNDS):
            got, missed = time_single(model, pose[:single], Unreachable)
            times_us += got
            unreachable += missed
            if other is not None:
                old_us += time_single(other, pose[:single], old.Unreachable)[0]
            toolbox = rtb_ik(model, q[:rtb_poses])
            rtb = toolbox if not rtb or isinstance(toolbox, str) else {
                **rtb, "times_us": rtb["times_us"] + toolbox["times_us"]}
    result = model.inverse_batch(pose, near=q)
    recovered = np.abs(result.best - q).max(axis=-1) < 1e-6
    t = model.forward(np.where(result.reachable[:, None], result.best, q))
    want = model.forward(q)
    if isinstance(rtb, dict):
        median_us = statistics.median(rtb["times_us"])
        rtb = {**rtb, "median_us": median_us, "poses_s": 1e6 / median_us}
    out = {
        "n": n, "single": min(single, n), "seed": seed,
        "fk_poses_s": n / fk_s, "ik_batch_poses_s": n / ik_s,
        "ik_single_us": statistics.median(times_us),
        "ik_single_p99_us": float(np.percentile(times_us, 99)),
        "success_batch_pct": 100 * float(result.reachable.mean()),
        "success_single_pct": 100 * (1 - unreachable / len(times_us)),
        "recovered_pct": 100 * float(recovered.mean()),
        "max_dp_mm": float(np.abs(t[:, :3, 3] - want[:, :3, 3]).max()),
        "max_dr": float(np.abs(t[:, :3, :3] - want[:, :3, :3]).max()),
        "rtb": rtb,
    }
    if against is not None:
        out["against"] = {"rev": against, "fk_poses_s": n / old_fk_s,
                          "ik_batch_poses_s": n / old_ik_s,
                          "ik_single_us": statistics.median(old_us)}
    return out


@contextlib.contextmanager
def checkout(rev: str) -> Iterator[ModuleType]:
    """``kinematics.unimate`` of commit ``rev``, imported beside this tree's package (which
    keeps its name): the commit's ``kinematics/`` is taken with ``git archive`` into a
    temporary directory, removed after."""
    with tempfile.TemporaryDirectory(prefix="kinematics-") as tmp:
        archive = subprocess.run(["git", "-C", str(ROOT), "archive", rev, "kinematics"],
                                 capture_output=True, check=False)
        if archive.returncode:
            raise SystemExit(f"--against {rev}: git archive failed: "
                             f"{archive.stderr.decode().strip()}")
        subprocess.run(["tar", "-x", "-C", tmp], input=archive.stdout, check=True)
        ours = own_modules(pop=True)
        sys.path.insert(0, tmp)
        try:
            module = importlib.import_module("kinematics.unimate")
        finally:
            sys.path.remove(tmp)
            own_modules(pop=True)
            sys.modules.update(ours)
        yield module


def own_modules(pop: bool) -> dict[str, ModuleType]:
    """The imported ``kinematics`` modules, taken out of ``sys.modules`` if ``pop``."""
    names = [k for k in sys.modules if k == "kinematics" or k.startswith("kinematics.")]
    return {k: sys.modules.pop(k) if pop else sys.modules[k] for k in names}


def best_pair(run: Callable[[], object], other: Callable[[], object] | None,
              repeats: int = 5) -> tuple[float, float]:
    """Shortest of ``repeats`` wall-clock runs (s) of ``run`` and of ``other`` (inf if None),
    taken turn about."""
    best, best_other = float("inf"), float("inf")
    for _ in range(repeats):
        best = min(best, best_of(run, 1))
        if other is not None:
            best_other = min(best_other, best_of(other, 1))
    return best, best_other


def best_of(run: Callable[[], object], repeats: int = 3) -> float:
    """Shortest of ``repeats`` wall-clock runs (s)."""
    best = float("inf")
    for _ in range(repeats):
        start = time.perf_counter()
        run()
        best = min(best, time.perf_counter() - start)
    return best


def time_single(model: unimate.Unimate2000B, poses: np.ndarray,
                unreachable_error: type[Exception]) -> tuple[list[float], int]:
    """µs of each ``model.inverse`` call, and how many poses raised ``unreachable_error``
    (the model's module's Unreachable)."""
    times_us, unreachable = [], 0
    for p in poses:
        start = time.perf_counter_ns()
        try:
            model.inverse(p)
        except unreachable_error:
            unreachable += 1
        times_us.append((time.perf_counter_ns() - start) / 1e3)
    return times_us, unreachable


def rtb_ik(model: unimate.Unimate2000B, q: np.ndarray) -> dict | str:
    """Time the Robotics Toolbox's numerical ``ik_LM`` on the poses of ``q``, if installed:
    its µs per pose, median, poses/s, success % and version; else why not."""
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
    return {"times_us": times_us, "median_us": median_us, "poses_s": 1e6 / median_us,
            "poses": len(targets), "success_pct": 100 * solved / len(targets),
            "version": rtb.__version__}


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
