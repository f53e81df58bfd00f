"""``servodesk machine``: show (and so validate) a machine description: the file, its
kinematic model, and the simulator's plant when it describes one."""

from __future__ import annotations

import argparse
import json
import sys

from control.motion.robot_model import model_of
from hw.machine import Machine, MachineError, load_machine


def add_parsers(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("machine", help="show a machine description (built-in name or TOML path)",
                       description="Load a machine description, report any error with its file "
                                   "and key, and print its joints.")
    p.add_argument("spec", nargs="?", default=None,
                   help="built-in name (unimate2000b, rig) or path; default: --machine")
    p.add_argument("--json", action="store_true", help="machine-readable output")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from hw.sim import check_plant

    spec = args.spec or args.machine
    try:
        machine = load_machine(spec)
        model_of(machine)  # a DH table the closed-form model cannot take
        if machine.describes_plant:
            check_plant(machine)  # numbers the simulator cannot run, refused as it would
    except MachineError as exc:
        print(f"servodesk: {exc}", file=sys.stderr)
        return 2
    print(json.dumps(summary(machine), indent=2) if args.json else describe(machine))
    return 0


def summary(machine: Machine) -> dict:
    return {
        "name": machine.name,
        "title": machine.title,
        "file": str(machine.path),
        "sample_time_s": machine.sample_time_s,
        "encoder": machine.encoder_kind,
        "joints": [
            {"key": j.key, "name": j.name, "kind": j.kind, "unit": j.unit,
             "limits": [j.lower, j.upper], "min_pwm": [j.min_pwm_pos, j.min_pwm_neg],
             "polarity": j.polarity}
            for j in machine.joints
        ],
        "coefficient_sets": sorted(machine.coefficients),
        "home": list(machine.home) if machine.home is not None else None,
        "park": list(machine.park) if machine.park is not None else None,
    }


def describe(machine: Machine) -> str:
    lines = [f"{machine.title} ({machine.name}) from {machine.path}",
             f"sample time {machine.sample_time_s * 1e3:g} ms, {machine.encoder_kind} encoders, "
             f"coefficient sets: {', '.join(sorted(machine.coefficients))}",
             f"{'joint':<10}{'kind':<11}{'limits':>18}{'min PWM +/-':>14}{'polarity':>10}"]
    for j in machine.joints:
        lines.append(f"{j.name:<10}{j.kind:<11}{j.limit_text():>18}"
                     f"{f'{j.min_pwm_pos:g}/{j.min_pwm_neg:g}':>14}{j.polarity:>10d}")
    for name, q in (("home", machine.home), ("park", machine.park)):
        if q is not None:
            lines.append(f"{name}: " + ", ".join(f"{j.name} {v:g}{j.symbol}"
                                                  for j, v in zip(machine.joints, q, strict=True)))
    return "\n".join(lines)
