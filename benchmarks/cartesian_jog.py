"""Cartesian jog: the inverse kinematics per jog step, key → first motion, and the
figures of issue 25 (a tool turn by the wrist singularity, a held jog).

Prints figures and asserts nothing; ``measure()`` returns them::

    python -m benchmarks.cartesian_jog [--jogs 40] [--steps 2000]
    python -m benchmarks.cartesian_jog --issue25 [--before REV]

``--issue25`` measures, on a real control process (real time, the simulator):

4. a 5° tool turn at the start pose: ``jog_cartesian([0, 0, 0, 5, 0, 0], frame="tool")``
   from the simulator's start (Yaw 2.5°): each joint's travel, commanded and measured, or
   the refusal;
5. a held Cartesian jog: the Jog tab in the world frame, hold-to-move at 100 % (25 mm/s),
   ``a`` (x +) posted every 33 ms for 5 s as a terminal's auto-repeat does, then silence:
   how far the commanded tool went along x, its largest sideways drift (y, z), how far it
   went after the last key, and the runs it left.

``--before REV`` runs the same figures on the tree of git revision ``REV`` (extracted
with ``git archive`` into a temporary folder, this script copied in) and prints both.

1. IK per jog step: the closed-form inverse of one point of a jog on the arm's
   branch (``Unimate2000B.inverse``, one pose, as a jog that solved each step
   as it went would call it), and per sample inside a planned jog
   (``inverse_batch`` over the jog's samples, the way ``plan_jog`` solves them);
   and the whole plan of a 1 mm step (line, timing, every sample solved twice,
   limits and singularities checked).
2. API → first motion: ``robot.jog_cartesian`` of 1 mm on a real-time (1 kHz)
   controller on the simulator, from the call until the first published status
   whose desired position differs from the one before the call: the first tick
   of the jog.
3. Key → first motion: the same through the TUI: the Jog tab in the world
   frame, position mode, 1 mm a press, a key posted as the terminal driver posts
   it, until that first tick.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
from textual import events

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # ahead of benchmarks/hw.py

from app.tui import ServodeskApp
from control import ControlClient
from control.motion.cartesian_jog import plan_jog
from control.motion.robot_model import unimate_model
from control.recorder import list_runs
from hw.machine import load_machine

START = np.array([1500.0, 10.0, 5.0, 20.0, 30.0, 10.0])  # away from limits and singularities
STEP_MM = 1.0
SIZE = (160, 48)
POLL_S = 0.0002


def spread(values: list[float]) -> dict[str, float]:
    return {"median": statistics.median(values), "p95": float(np.percentile(values, 95)),
            "max": max(values), "n": len(values)}


def ik_per_step(steps: int, seed: int) -> dict[str, dict[str, float]]:
    """Microseconds per IK of a jog point, one pose and in a planned jog; ms per 1 mm plan."""
    machine = load_machine("unimate2000b")
    model = unimate_model(machine)
    rng = np.random.default_rng(seed)
    jog = plan_jog(START, [40.0, -20.0, 10.0, 0.0, 0.0, 0.0], machine)
    picks = rng.integers(1, len(jog.q), steps)
    single = []
    for k in picks:
        began = time.perf_counter()
        model.inverse(jog.poses[k], near=jog.q[k - 1])
        single.append((time.perf_counter() - began) * 1e6)
    batch = []
    for _ in range(20):
        began = time.perf_counter()
        model.inverse_batch(jog.poses, near=START)
        batch.append((time.perf_counter() - began) * 1e6 / len(jog.poses))
    plans = []
    for k in range(200):
        axis = k % 6
        d = np.zeros(6)
        d[axis] = (STEP_MM if axis < 3 else 0.2) * (1 if k % 12 < 6 else -1)
        began = time.perf_counter()
        plan_jog(START, d, machine, frame="world" if k % 2 else "tool")
        plans.append((time.perf_counter() - began) * 1e3)
    return {"single_us": spread(single), "batch_us": spread(batch), "plan_ms": spread(plans)}


def first_motion(robot: ControlClient, start: Callable[[], object]) -> float:
    """Milliseconds from ``start()`` to the first status whose desired position changed."""
    before = robot.status().desired
    began = time.perf_counter()
    start()
    while robot.status().desired == before:
        time.sleep(POLL_S)
    return (time.perf_counter() - began) * 1e3


def settle(robot: ControlClient) -> None:
    """Wait until the last jog has ended, in position: a step waits for the one before it to
    come in position (steps add up exactly), and that wait is not the latency measured here
    (waiting for HOLD alone put the last step's 160 ms settle into every figure)."""
    while robot.status().moving:
        time.sleep(0.001)
    time.sleep(0.05)


def api_first_motion(jogs: int) -> dict[str, float]:
    with tempfile.TemporaryDirectory() as runs, ControlClient(
            "unimate2000b", data_dir=runs, heartbeat_timeout_s=2.0) as robot:
        robot.wait(robot.go_to(START, speed=1.0), timeout=60)
        times = []
        for k in range(jogs):
            d = [STEP_MM if k % 2 == 0 else -STEP_MM, 0, 0, 0, 0, 0]
            times.append(first_motion(robot, lambda d=d: robot.jog_cartesian(d)))
            settle(robot)
    return spread(times)


def key_first_motion(jogs: int) -> dict[str, float]:
    async def scenario(data_dir: str) -> list[float]:
        app = ServodeskApp("unimate2000b", "sim", None, Path(data_dir), lockstep=False,
                           client_options={"heartbeat_timeout_s": 2.0})
        times: list[float] = []
        async with app.run_test(size=SIZE) as pilot:
            while app.client is None or app.focused is None:
                await pilot.pause(0.05)
            robot = app.client
            await asyncio.to_thread(lambda: robot.wait(robot.go_to(START, speed=1.0), 60))
            await pilot.press("w", "5")  # world frame, position mode, 1 mm a press
            for k in range(jogs):
                before = robot.status().desired
                began = time.perf_counter()
                assert app._driver is not None
                key = "a" if k % 2 == 0 else "z"
                app._driver.send_message(events.Key(key, key))
                while robot.status().desired == before:
                    await asyncio.sleep(POLL_S)
                times.append((time.perf_counter() - began) * 1e3)
                while robot.status().moving:  # in position, as settle() waits
                    await asyncio.sleep(0.001)
                await asyncio.sleep(0.05)
        return times

    with tempfile.TemporaryDirectory() as data_dir:
        return spread(asyncio.run(scenario(data_dir)))


def tool_turn() -> dict[str, object]:
    """Figure 4: the 5° tool turn at the simulator's start pose."""
    with tempfile.TemporaryDirectory() as runs, ControlClient(
            "unimate2000b", data_dir=runs, heartbeat_timeout_s=2.0) as robot:
        home = np.array(unimate_model(robot.machine).mid_range)
        robot.wait(robot.go_to(home, speed=1.0), timeout=60)
        try:
            result = robot.wait(robot.jog_cartesian([0, 0, 0, 5.0, 0, 0], frame="tool"), 60)
        except ValueError as exc:
            return {"refused": str(exc), "desired": [0.0] * 6, "actual": [0.0] * 6}
        run = result.run
        return {"refused": "", "desired": np.ptp(run.desired, axis=0).tolist(),
                "actual": np.ptp(run.actual, axis=0).tolist()}


HELD_S = 5.0
REPEAT_S = 0.033  # a terminal's auto-repeat, about 30 Hz


def held_jog(seconds: float = HELD_S) -> dict[str, object]:
    """Figure 5: ``a`` held ``seconds`` in the Jog tab's world frame at 100 %."""
    model = unimate_model(load_machine("unimate2000b"))

    async def scenario(data_dir: str) -> dict[str, object]:
        app = ServodeskApp("unimate2000b", "sim", None, Path(data_dir), lockstep=False,
                           client_options={"heartbeat_timeout_s": 2.0})
        async with app.run_test(size=SIZE) as pilot:
            while app.client is None or app.focused is None:
                await pilot.pause(0.05)
            robot = app.client
            await asyncio.to_thread(lambda: robot.wait(robot.go_to(START, speed=1.0), 60))
            await asyncio.sleep(0.5)
            await pilot.press("w", "m", "9")  # world frame, hold-to-move, 100 %
            start = model.pose(np.array(robot.status().desired))
            drift = 0.0

            def moved() -> np.ndarray:
                nonlocal drift
                d = model.pose(np.array(robot.status().desired)) - start
                drift = max(drift, float(np.hypot(d[1], d[2])))
                return d

            assert app._driver is not None
            end = time.monotonic() + seconds
            while time.monotonic() < end:
                app._driver.send_message(events.Key("a", "a"))
                moved()
                await asyncio.sleep(REPEAT_S)
            at_release = float(moved()[0])
            still = time.monotonic()
            last = moved()
            while time.monotonic() - still < 1.0:  # until the commanded tool stands for 1 s
                await asyncio.sleep(0.02)
                now = moved()
                if np.abs(now - last).max() > 1e-6:
                    still, last = time.monotonic(), now
            await asyncio.sleep(1.0)  # the runs of the moves it made are saved meanwhile
            runs = [info.kind for info in list_runs(Path(data_dir))]
            holds = [e for e in app.desk.events.entries if e.kind == "jog"]
            return {"distance": float(last[0]), "drift": drift,
                    "after_release": float(last[0]) - at_release,
                    "runs": len([k for k in runs if k == "cartesian_jog"]),
                    "holds": [e.what for e in holds]}

    with tempfile.TemporaryDirectory() as data_dir:
        return asyncio.run(scenario(data_dir))


def issue25() -> dict[str, object]:
    return {"tool_turn": tool_turn(), "held": held_jog()}


def issue25_before(rev: str) -> dict[str, object]:
    """``issue25()`` on the tree of git revision ``rev``, in a process of its own."""
    root = Path(__file__).resolve().parents[1]
    with tempfile.TemporaryDirectory() as tree:
        archive = subprocess.run(["git", "-C", str(root), "archive", rev], check=True,
                                 capture_output=True).stdout
        subprocess.run(["tar", "-x", "-C", tree], input=archive, check=True)
        shutil.copy(__file__, Path(tree) / "benchmarks" / "cartesian_jog.py")
        out = subprocess.run([sys.executable, "-m", "benchmarks.cartesian_jog", "--issue25",
                              "--json"], cwd=tree, check=True, capture_output=True, text=True)
    return json.loads(out.stdout)


def print_issue25(label: str, m: dict) -> None:
    turn, held = m["tool_turn"], m["held"]
    names = [j.name for j in load_machine("unimate2000b").joints]
    units = [" mm" if j.unit == "mm" else "°" for j in load_machine("unimate2000b").joints]
    print(f"{label}:")
    if turn["refused"]:
        print(f"  5° tool turn at the start pose: refused: {turn['refused']}")
    else:
        for what in ("desired", "actual"):
            travel = ", ".join(f"{n} {v:.1f}{u}" for n, v, u in zip(names, turn[what], units,
                                                                   strict=True))
            print(f"  5° tool turn at the start pose, joint travel ({what}): {travel}")
    print(f"  held a {HELD_S:g} s at 25 mm/s: x {held['distance']:.1f} mm (asked "
          f"{25 * HELD_S:g}), sideways drift {held['drift']:.2f} mm, "
          f"{held['after_release']:.1f} mm after the last key, {held['runs']} cartesian_jog "
          "runs")
    for what in held.get("holds", []):
        print(f"  logged: {what}")


def measure(jogs: int = 40, steps: int = 2000, seed: int = 0) -> dict[str, object]:
    return {"ik": ik_per_step(steps, seed), "api": api_first_motion(jogs),
            "key": key_first_motion(jogs)}


def line(label: str, s: dict[str, float], unit: str, digits: int = 2) -> str:
    return (f"{label:<34} median {s['median']:8.{digits}f} {unit}  p95 {s['p95']:8.{digits}f} "
            f"{unit}  max {s['max']:8.{digits}f} {unit}  (n = {s['n']})")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--jogs", type=int, default=40, help="jogs timed on the controller")
    parser.add_argument("--steps", type=int, default=2000, help="jog points solved one by one")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--issue25", action="store_true",
                        help="the figures of issue 25 only (a tool turn, a held jog)")
    parser.add_argument("--before", metavar="REV",
                        help="with --issue25: the same figures on git revision REV too")
    parser.add_argument("--json", action="store_true", help="with --issue25: print JSON")
    args = parser.parse_args(argv)
    if args.issue25:
        now = issue25()
        if args.json:
            print(json.dumps(now))
            return 0
        if args.before:
            print_issue25(f"before ({args.before})", issue25_before(args.before))
        print_issue25("now", now)
        return 0
    m = measure(args.jogs, args.steps, args.seed)
    ik = m["ik"]
    assert isinstance(ik, dict)
    print("Cartesian jog (unimate2000b, simulator)")
    print(line("IK per jog point, one pose", ik["single_us"], "µs", 1))
    print(line("IK per jog sample, in a plan", ik["batch_us"], "µs", 1))
    print(line(f"plan of a {STEP_MM:g} mm / 0.2° step", ik["plan_ms"], "ms"))
    print(line("API call → first motion", m["api"], "ms"))  # type: ignore[arg-type]
    print(line("key → first motion (Jog tab)", m["key"], "ms"))  # type: ignore[arg-type]
    return 0


if __name__ == "__main__":
    sys.exit(main())
