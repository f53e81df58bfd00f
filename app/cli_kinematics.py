"""``servodesk fk`` and ``servodesk ik``: the Unimate 2000B's kinematics from the command line.

``fk Q1..Q6`` prints the pose of a joint vector; ``ik X Y Z GAMMA BETA ALPHA``
prints every in-limit joint solution, nearest ``--near`` first. Joints are in
the thesis's actuator order, In/Out in mm, then Rotate, Up/Down, Bend, Yaw,
Swivel in degrees; a pose is x, y, z in mm and X-Y-Z fixed angles γ, β, α in
degrees (eq. 4.04). Both solve the ``--machine``'s model (``control.motion.robot_model``:
its DH lengths and joint limits), the built-in Unimate 2000B by default.

A number too large for the arithmetic (a finite input whose pose, solution or
distance is not a finite number at the printed 0.001) is an error naming it,
exit 2, never an ``inf`` or a numpy warning.
"""

from __future__ import annotations

import argparse
import json
import math
import re
import sys
from collections.abc import Callable

import numpy as np

from app.cli_options import global_options
from control.motion.robot_model import unimate_model
from hw.machine import load_machine
from kinematics import Unreachable, unimate

JOINT_ARGS = ("IN_OUT", "ROTATE", "UPDOWN", "BEND", "YAW", "SWIVEL")
POSE_ARGS = ("X", "Y", "Z", "GAMMA", "BETA", "ALPHA")
POSE_NAMES = ("x", "y", "z", "gamma", "beta", "alpha")
POSE_LABELS = ("x", "y", "z", "γ", "β", "α")
POSE_UNITS = ("mm", "mm", "mm", "°", "°", "°")
POSE_HELP = ("x (mm)", "y (mm)", "z (mm)", "gamma (deg), about the fixed x axis",
             "beta (deg), about the fixed y axis", "alpha (deg), about the fixed z axis")
# A value starting like a negative number (or -inf/-nan) is a value, not an option;
# argparse's own pattern misses "-1e3", "-inf" and "-nan".
NEGATIVE_NUMBER = re.compile(r"^-(\d|\.\d|inf|nan)", re.IGNORECASE)
RESOLUTION = 1e-3  # mm and degrees: the tables print three decimals


def add_parsers(sub: argparse._SubParsersAction) -> None:
    """Add the ``fk`` and ``ik`` subcommands; each sets ``func`` to its runner."""
    fk = sub.add_parser(
        "fk", parents=[global_options("machine")],
        help="pose of a joint vector (forward kinematics)",
        description="Print the end-effector pose of a Unimate 2000B joint vector: x, y, z (mm) "
                    "and X-Y-Z fixed angles gamma, beta, alpha (deg), on --machine's "
                    "[kinematics] model.")
    for metavar, name, unit in zip(JOINT_ARGS, unimate.JOINTS, unimate.UNITS, strict=True):
        fk.add_argument(metavar.lower(), metavar=metavar, help=f"{name} ({unit})")
    fk.add_argument("--json", action="store_true", help="machine-readable output")
    fk.set_defaults(func=run_fk)

    ik = sub.add_parser(
        "ik", parents=[global_options("machine")],
        help="joint solutions of a pose (inverse kinematics)",
        description="Print every joint solution of a pose inside the Unimate 2000B's limits, "
                    "nearest --near first; the first is the one chosen. --machine's "
                    "[kinematics] model and limits are solved.")
    for metavar, text in zip(POSE_ARGS, POSE_HELP, strict=True):
        ik.add_argument(metavar.lower(), metavar=metavar, help=text)
    ik.add_argument("--near", nargs=6, metavar=JOINT_ARGS,
                    help="joint vector to rank by, e.g. the current reading; also the Swivel/Bend "
                         "kept at a wrist singularity (default: the middle of the limits)")
    ik.add_argument("--json", action="store_true", help="machine-readable output")
    ik.set_defaults(func=run_ik)

    for parser in (fk, ik):
        # private argparse attribute (3.11–3.13): the only hook for what counts as a number
        parser._negative_number_matcher = NEGATIVE_NUMBER


def run_fk(args: argparse.Namespace) -> int:
    """``servodesk fk``: exit 0, or 2 with a one-line reason on stderr."""
    try:
        model = machine_model(args)
        q = parse_numbers([getattr(args, m.lower()) for m in JOINT_ARGS], unimate.JOINTS)
        pose = finite_results(model.pose, q, model, "the pose")
    except ValueError as exc:
        return fail("fk", exc)
    outside = [name for name, v, lo, hi in zip(unimate.JOINTS, q, model.lower, model.upper,
                                               strict=True)
               if not lo <= v <= hi]
    if args.json:
        print(json.dumps({"q": named(unimate.JOINTS, q), "pose": named(POSE_NAMES, pose),
                          "units": {"length": "mm", "angle": "deg"},
                          "outside_limits": outside}, indent=2))
        return 0
    print(f"pose of {describe_joints(q)}:")
    for label, value, unit in zip(POSE_LABELS, pose, POSE_UNITS, strict=True):
        print(f"  {label} {round(value, 3) + 0.0:10.3f} {unit}")
    if outside:
        print(f"note: {', '.join(outside)} outside the joint limits; the robot cannot go there")
    return 0


def run_ik(args: argparse.Namespace) -> int:
    """``servodesk ik``: exit 0, or 2 with a one-line reason on stderr."""
    try:
        model = machine_model(args)
        pose = parse_numbers([getattr(args, m.lower()) for m in POSE_ARGS], POSE_LABELS)
        near = None if args.near is None else parse_numbers(args.near, unimate.JOINTS)
        solutions = model.inverse(pose, near=near)
        ref = list(model.mid_range) if near is None else near
        travel = finite_results(lambda r: unimate.distance(solutions, r), ref, model,
                                "the distance to it", "--near ")
    except (ValueError, Unreachable) as exc:
        return fail("ik", exc)
    singular = abs(math.sin(math.radians(solutions[0, 4]))) <= unimate.WRIST_TOL
    if args.json:
        print(json.dumps({"pose": named(POSE_NAMES, pose), "near": named(unimate.JOINTS, ref),
                          "solutions": [named(unimate.JOINTS, s) for s in solutions],
                          "distance": travel.tolist(), "chosen": 0, "wrist_singular": singular,
                          "units": {"length": "mm", "angle": "deg"}}, indent=2))
        return 0
    print(f"{len(solutions)} solution{'s' if len(solutions) > 1 else ''} for "
          f"{describe_pose(pose)}")
    print(f"ranked by distance to {describe_joints(ref)}:")
    print("   " + "".join(f"{name:>10}" for name in unimate.JOINTS) + f"{'distance':>10}")
    print("   " + "".join(f"{unit:>10}" for unit in unimate.UNITS))
    for i, (q, d) in enumerate(zip(solutions, travel, strict=True)):
        mark = "*" if i == 0 else " "
        print(f"{mark}  " + "".join(f"{round(v, 3) + 0.0:10.3f}" for v in q) + f"{d:10.3f}")
    print(f"* chosen; distance = Σ|Δangle| (deg) + |ΔIn/Out| / {unimate.MM_PER_DEGREE:g} (mm)")
    if singular:
        print("note: wrist singular (Yaw 0°): Swivel or Bend is kept at its --near value")
    return 0


def machine_model(args: argparse.Namespace) -> unimate.Unimate2000B:
    """The model of ``--machine`` (given before or after the subcommand); ValueError (a
    MachineError naming file and key for a bad file) when it has none."""
    return unimate_model(load_machine(args.machine))


def parse_numbers(texts: list[str], names: tuple[str, ...]) -> list[float]:
    """Finite floats from command-line strings; ValueError naming the bad one."""
    values = []
    for name, text in zip(names, texts, strict=True):
        try:
            value = float(text)
        except ValueError:
            raise ValueError(f"{name} {text!r} is not a number") from None
        if not math.isfinite(value):
            raise ValueError(f"{name} {text!r} must be a finite number")
        values.append(value)
    return values


def finite_results(compute: Callable[[list[float]], np.ndarray], q: list[float],
                   model: unimate.Unimate2000B, what: str, option: str = "") -> np.ndarray:
    """``compute(q)`` of joint values ``q``; ValueError naming the joint that overflows it
    when a result is not a finite number at the printed ``RESOLUTION`` (numpy rounds by
    scaling, so a result past float's largest / 1000 would print as inf)."""
    with np.errstate(all="ignore"):  # an overflow is the error below, never a numpy warning
        results = compute(q)
        if printable(results):
            return results
        k = overflowing(compute, q)
    name, unit, gap = unimate.JOINTS[k], unimate.UNITS[k], "" if unimate.UNITS[k] == "°" else " "
    raise ValueError(f"{option}{name} {q[k]:g}{gap}{unit} is too large: {what} overflows (is "
                     f"not a finite number to {RESOLUTION:g}); give a value near its limits "
                     f"{model.lower[k]:g}…{model.upper[k]:g}{gap}{unit}")


def overflowing(compute: Callable[[list[float]], np.ndarray], q: list[float]) -> int:
    """The joint that overflows ``compute`` on its own, the others at 0 (the largest such),
    else the largest: only together do they overflow it."""
    order = sorted(range(len(q)), key=lambda k: -abs(q[k]))
    alone = (k for k in order
             if not printable(compute([v if i == k else 0.0 for i, v in enumerate(q)])))
    return next(alone, order[0])


def printable(results: np.ndarray) -> bool:
    """Whether every result is a finite number at ``RESOLUTION``."""
    with np.errstate(all="ignore"):
        return bool(np.isfinite(np.asarray(results, dtype=float) / RESOLUTION).all())


def named(names: tuple[str, ...], values: np.ndarray | list[float]) -> dict[str, float]:
    return {name: float(v) for name, v in zip(names, values, strict=True)}


def describe_joints(q: np.ndarray | list[float]) -> str:
    return ", ".join(f"{name} {v:g}{'' if unit == '°' else ' '}{unit}"
                     for name, v, unit in zip(unimate.JOINTS, q, unimate.UNITS, strict=True))


def describe_pose(p: np.ndarray | list[float]) -> str:
    return ", ".join(f"{label} {v:g}{'' if unit == '°' else ' '}{unit}"
                     for label, v, unit in zip(POSE_LABELS, p, POSE_UNITS, strict=True))


def fail(command: str, exc: Exception) -> int:
    print(f"servodesk {command}: {exc}", file=sys.stderr)
    return 2
