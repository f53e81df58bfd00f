"""Tracking a standard section 6.4 Cartesian path: thesis P.I. vs identified P.I. vs feed-forward.

Run: ``PYTHONPATH=. python benchmarks/tracking.py [--speed 0.8] [--seed 0]``
(10–20 s on a busy two-core machine; everything runs on the lockstep
simulator).

1. Drive to the standard start joints with a via-point trajectory.
2. Identify every joint from one ``tracking_actuate`` run of six simultaneous
   PRBS profiles (``excitation.prbs``, sized to the limits) and check the
   models on a second, fresh run.
3. Propose P.I. gains (max ki with Ms ≤ 2) and velocity feed-forward.
4. Follow the standard path (from the start through two via points, γ and β
   held, α turning with Rotate; timed to ``--speed`` of the joints' speed and
   acceleration limits, default 80 %) with each track set. Before each run
   the robot returns to the start and settles there with the proposed gains
   as track and hold set, so every run starts on target from the same stiff
   hold (the thesis's Bend gains, Kp 3 and Ki 3, and option.c's hold set take
   seconds to settle, and a lockstep hold lasts as long as the script takes to
   send the next move).

Feed-forward: the third column adds ``kv·v_desired`` in the loop, with kv
from the identified models (``tuning.with_feed_forward``).
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # ahead of benchmarks/hw.py

from control import ControlClient
from control.identify import excitation, sysid, tuning
from control.motion import trajectory
from control.motion.cartesian import CartesianPath, cartesian_path
from control.motion.robot_model import builtin_unimate
from control.recorder import Run
from hw.machine import Coefficients, Machine, load_machine

START = (1400.0, -20.0, 5.0, -10.0, 30.0, 20.0)  # mm, deg: Yaw off 0, so β is not ±90°
VIA_OFFSETS = ((150.0, 300.0, -80.0), (-100.0, 500.0, 100.0))  # mm from the start's tool point
SPEED_FRACTION = 0.8  # at 50 % the identified P.I. alone is at the encoders' floor already
PRBS_S = 4.0
SETTLE_S = 0.5


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seed", type=int, default=0, help="simulator seed")
    parser.add_argument("--speed", type=float, default=SPEED_FRACTION,
                        help="fraction of the joints' speed and acceleration limits (0, 1]")
    args = parser.parse_args()
    machine = load_machine("unimate2000b")
    with tempfile.TemporaryDirectory() as runs, ControlClient(
            machine, lockstep=True, seed=args.seed, data_dir=runs,
            heartbeat_timeout_s=3.0) as robot:
        go_to(robot, machine, np.array(START))
        identified = identify(robot, machine)
        models = [i.deadband for i in identified]
        proposal = tuning.propose(models, machine, machine.track)
        ffs = [tuning.feed_forward(m, joint) for m, joint in zip(models, machine.joints,
                                                                   strict=True)]
        path = standard_path(machine, args.speed)
        print_path(path, args.speed)
        print_gains(machine, models, proposal)
        print_feed_forward(ffs)
        desired = np.vstack([path.q, np.repeat(path.q[-1:], round(SETTLE_S / machine.sample_time_s),
                                               axis=0)])
        # the gain check judges every set below on these models, not the machine file's
        robot.set_coefficients("hold", machine.hold, models)
        feed_forward = tuning.with_feed_forward(proposal.coefficients, ffs)
        columns = {
            "thesis P.I. (5.4.2)": follow(robot, machine, machine.coefficients["thesis_pi"],
                                          desired, proposal.coefficients),
            "identified P.I.": follow(robot, machine, proposal.coefficients, desired,
                                      proposal.coefficients),
            "identified + feed-forward": follow(robot, machine, feed_forward, desired,
                                                proposal.coefficients),
        }
    print_errors(machine, desired, columns)


def go_to(robot: ControlClient, machine: Machine, target: np.ndarray) -> None:
    """Move from wherever the robot is to ``target`` on a via-point trajectory and settle."""
    here = np.array(robot.status().position)
    move = trajectory.via_path(np.vstack([here, target]), machine, speed_fraction=0.5)
    hold = np.repeat(target[None], round(SETTLE_S / machine.sample_time_s), axis=0)
    result = robot.wait(robot.move(np.vstack([move.q, hold]), kind="go_to"))
    if not result.complete:
        raise SystemExit(f"could not reach {target.tolist()}: {result.status}")


def actuate(robot: ControlClient, machine: Machine, seed: int) -> Run:
    """Six simultaneous PRBS profiles from where the robot stands; the recorded run."""
    start = np.array(robot.status().position)
    profile = excitation.combine(
        *(excitation.prbs(machine, j, start, duration=PRBS_S, seed=seed * 10 + j)
          for j in range(machine.n_joints)), machine=machine)
    result = robot.wait(robot.actuate(profile.duty, meta=dict(profile.meta)))
    if not result.complete:
        raise SystemExit(f"identification run failed: {result.status}")
    return result.run


def identify(robot: ControlClient, machine: Machine) -> tuple[sysid.Identification, ...]:
    """Identify every joint on one run, validate on a fresh one, print the table."""
    training = actuate(robot, machine, seed=1)
    go_to(robot, machine, np.array(START))
    fresh = actuate(robot, machine, seed=2)
    go_to(robot, machine, np.array(START))
    identified = sysid.identify_all(training, machine)
    print(f"identification: {PRBS_S:g} s of PRBS on all joints at once; fit (NRMSE %) on a "
          "fresh run")
    print(f"  {'joint':8s} {'k+':>7s} {'d+ %':>6s} {'k-':>7s} {'d- %':>6s} {'fn Hz':>6s} "
          f"{'zeta':>5s} | {'velocity':>8s} {'position':>8s} | {'ARX v':>6s} {'ARX q':>6s}")
    for j, ident in enumerate(identified):
        m = ident.deadband
        data = sysid.joint_series(fresh, machine, j)
        fit, arx = sysid.validate(m, data), sysid.validate(ident.arx, data)
        print(f"  {m.name:8s} {m.k_pos:7.3f} {m.d_pos:6.1f} {m.k_neg:7.3f} {m.d_neg:6.1f} "
              f"{m.wn / (2 * np.pi):6.1f} {m.zeta:5.2f} | {fit.velocity_pct:8.1f} "
              f"{fit.position_pct:8.1f} | {arx.velocity_pct:6.1f} {arx.position_pct:6.1f}")
    print("  (k in units/s per % of controller output; ARX(2,3,1) at 10 ms on the deadband "
          "line)\n")
    return identified


def standard_path(machine: Machine, speed: float = SPEED_FRACTION) -> CartesianPath:
    tool = builtin_unimate().pose(np.array(START))[:3]
    return cartesian_path(START, tool + np.array(VIA_OFFSETS), machine, speed_fraction=speed)


def follow(robot: ControlClient, machine: Machine, track: Coefficients, sent: np.ndarray,
           positioning: Coefficients) -> Run:
    """Follow ``sent (N, 6)`` with ``track`` as the track set, after returning to the standard
    start with ``positioning`` as the track and hold set."""
    robot.set_coefficients("hold", positioning)
    robot.set_coefficients("track", positioning)
    go_to(robot, machine, np.array(START))
    robot.set_coefficients("track", track)
    result = robot.wait(robot.move(sent, kind="cartesian"))
    if not result.complete:
        raise SystemExit(f"path with {track.name} failed: {result.status}")
    return result.run


def print_path(path: CartesianPath, speed: float) -> None:
    p = path.poses
    print(f"standard path (section 6.4): start q = {START}, via points +{VIA_OFFSETS[0]} and "
          f"+{VIA_OFFSETS[1]} mm from the start's tool point,\n  γ β = {p[0, 3]:.2f} "
          f"{p[0, 4]:.2f}° held, α {p[0, 5]:.2f} → {p[-1, 5]:.2f}° with Rotate; "
          f"{speed:.0%} of the joint limits: {path.duration:.2f} s\n")


def print_gains(machine: Machine, models: list[sysid.DeadbandModel],
                proposal: tuning.Proposal) -> None:
    thesis = machine.coefficients["thesis_pi"]
    dt = machine.sample_time_s
    print("P.I. gains: thesis (section 5.4.2) vs proposed (max ki with Ms ≤ 2), and each "
          "set's Ms and phase margin on the identified model")
    for j, design in enumerate(proposal.designs):
        assert design is not None
        plant = tuning.loop_plant(models[j], machine.joints[j], dt)
        old = tuning.margins(plant, tuning.controller(thesis, j, dt), dt)
        new = design.margins
        print(f"  {design.joint:8s} thesis Kp {thesis.kp[j][0]:6.3g} Ki {thesis.ki[j]:6.3g} "
              f"(Ms {old.ms:4.2f}, PM {old.phase_margin_deg:3.0f}°)   proposed Kp "
              f"{design.kp:6.3g} Ki {design.ki:6.3g} (Ms {new.ms:4.2f}, PM "
              f"{new.phase_margin_deg:3.0f}°, {new.crossover_hz:4.1f} Hz)")
    print()


def print_feed_forward(ffs: list[tuning.FeedForward]) -> None:
    print("feed-forward, added to the law's output before min-PWM compensation: "
          "u_ff = kv±·v + offset±")
    for ff in ffs:
        print(f"  {ff.joint:8s} kv+ {ff.kv_pos:6.3f} kv- {ff.kv_neg:6.3f} %/({ff.unit}/s)   "
              f"offset+ {ff.offset_pos:6.1f} offset- {ff.offset_neg:6.1f} %")
    print()


def print_errors(machine: Machine, desired: np.ndarray, columns: dict[str, Run]) -> None:
    print("tracking error, desired − actual over the path and 0.5 s after it: RMS / max")
    print("  " + " " * 11 + "".join(f"{name:>28s}" for name in columns))
    for j, joint in enumerate(machine.joints):
        cells = []
        for run in columns.values():  # a run goes on past its path until the arm is in
            e = desired[:, j] - run.actual[:len(desired), j]  # position: the same span each
            cells.append(f"{np.sqrt(np.mean(e ** 2)):.3f} / {np.max(np.abs(e)):.3f}")
        print(f"  {joint.name + ' ' + joint.unit:11s}" + "".join(f"{c:>28s}" for c in cells))
    print()


if __name__ == "__main__":
    main()
