"""A machine file's ``[kinematics]`` as the model the kinematics package solves.

The machine file names its model and gives its DH table (joint order there is the
actuator order; each row names the joint whose variable it carries). A file with
``model = "unimate2000b"`` gets the closed-form Unimate 2000B model with its own
lengths and joint limits, so a re-measured or modified Unimate is a TOML file away;
``hw`` stays free of kinematics, and every user of a pose (the Status tab, the
end-point and Cartesian moves, ``servodesk fk/ik``) goes through here.
``builtin_unimate()`` is the built-in file's model, loaded once: the kinematics package
reads no file, so this is where the benchmarks and the tests get the thesis's Unimate.
"""

from __future__ import annotations

import functools

from hw.machine import Machine, MachineError, load_machine
from kinematics.dh import DHLink
from kinematics.unimate import Unimate2000B

UNIMATE = "unimate2000b"


def dh_links(machine: Machine) -> tuple[tuple[DHLink, ...], tuple[int, ...]]:
    """The machine's DH rows as links in DH order, and the actuator index of each."""
    links = tuple(DHLink(r.alpha, r.a, r.d, r.theta, machine.joints[r.joint].kind == "prismatic")
                  for r in machine.dh)
    return links, tuple(r.joint for r in machine.dh)


def has_unimate_model(machine: Machine) -> bool:
    return machine.kinematics_model == UNIMATE


def model_of(machine: Machine) -> Unimate2000B | None:
    """``unimate_model(machine)``, or None for a machine without one (the rig)."""
    return unimate_model(machine) if has_unimate_model(machine) else None


def unimate_model(machine: Machine) -> Unimate2000B:
    """The closed-form model of ``machine``: ValueError when it has none, MachineError
    (naming the file and key) when its DH table is not of the Unimate 2000B's form."""
    if not has_unimate_model(machine):
        raise ValueError(f"machine {machine.name} has no {UNIMATE} kinematics (its file's "
                         "[kinematics] model): poses, end points and Cartesian paths need it")
    links, order = dh_links(machine)
    try:
        return Unimate2000B.from_table(links, order, machine.lower, machine.upper,
                                       [j.name for j in machine.joints])
    except ValueError as exc:
        raise MachineError(f"{machine.path.name}: kinematics.dh: {exc}") from None


@functools.cache
def builtin_unimate() -> Unimate2000B:
    """The built-in Unimate 2000B's model (``hw/machines/unimate2000b.toml``), loaded once."""
    return unimate_model(load_machine(UNIMATE))
