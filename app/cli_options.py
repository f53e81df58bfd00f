"""The command line's global options, declared once: ``--machine``, ``--backend``, ``--port``,
``--data-dir``, ``--seed``, ``--timing``, ``--interrupt-ms``, ``--slip``.

``servodesk`` takes every one of them before a command, with its default; a command takes
those it uses after its name too (``global_options`` as an argparse parent). There they have
no default (``argparse.SUPPRESS``), so one not given after the command leaves the value given
before it, or the default, in place: ``servodesk --machine rig move step …`` and
``servodesk move step --machine rig …`` are one command.
"""

from __future__ import annotations

import argparse
import copy
from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType

from control.rt.law import SLIPS
from control.timing import TIMINGS
from hw.factory import BACKENDS
from hw.machine import Machine, load_machine

DEFAULT_MACHINE = "unimate2000b"


@dataclass(frozen=True)
class GlobalOption:
    """One global option: its flags, its value when not given, its help, and the rest of
    ``add_argument``'s keywords (type, choices, metavar, action)."""

    flags: tuple[str, ...]
    default: object
    help: str
    keywords: Mapping[str, object] = field(default_factory=lambda: MappingProxyType({}))


GLOBAL_OPTIONS: Mapping[str, GlobalOption] = MappingProxyType({
    "machine": GlobalOption(("--machine",), DEFAULT_MACHINE,
                            f"built-in machine (unimate2000b, rig) or a machine TOML path "
                            f"(default {DEFAULT_MACHINE})"),
    "backend": GlobalOption(("--backend",), "sim",
                            "sim (default) or serial (an I/O board, with --port)",
                            MappingProxyType({"choices": BACKENDS})),
    "port": GlobalOption(("--port",), None, "pyserial URL of the I/O board for --backend serial"),
    "data_dir": GlobalOption(("--data-dir", "--data"), None,
                             "where runs are saved (default: the user's data directory, "
                             "servodesk/runs)", MappingProxyType({"metavar": "DIR"})),
    "seed": GlobalOption(("--seed",), 0, "simulator seed (default 0)",
                         MappingProxyType({"type": int})),
    "timing": GlobalOption(("--timing",), "servodesk",
                           "servodesk (every joint every tick, default) or thesis (one joint "
                           "per interrupt, as RT.o: docs/thesis_timing.md)",
                           MappingProxyType({"choices": TIMINGS})),
    "interrupt_ms": GlobalOption(("--interrupt-ms",), 1.0,
                                 "thesis timing: the interrupt period, one joint each (1 or 6 "
                                 "as the thesis; default 1)",
                                 MappingProxyType({"type": float, "metavar": "MS"})),
    "slip": GlobalOption(("--slip",), [],
                         "thesis timing: run the listing's law with this slip (errata); "
                         "repeat for several",
                         MappingProxyType({"action": "append", "choices": sorted(SLIPS)})),
})
ALL = tuple(GLOBAL_OPTIONS)


def global_options(*names: str, defaults: bool = False, scope: str = ""
                   ) -> argparse.ArgumentParser:
    """A parent parser (``parents=[…]``) holding the global options ``names``: with their
    defaults for ``servodesk`` itself, without (SUPPRESS) for a command. ``scope`` says what
    they are for in that command's help (``servodesk serve``: a controller started there)."""
    parent = argparse.ArgumentParser(add_help=False)
    for name in names:
        option = GLOBAL_OPTIONS[name]
        parent.add_argument(*option.flags, dest=name,
                            default=copy.copy(option.default) if defaults else argparse.SUPPRESS,
                            help=f"{scope}: {option.help}" if scope else option.help,
                            **option.keywords)
    return parent


def machine_for(args: argparse.Namespace) -> Machine:
    """``--machine``, loaded; on the simulator its plant checked too, as the simulator will
    (``hw.sim.check_plant``), so a file it cannot run is refused here, before a controller
    starts. MachineError naming the file and the key."""
    machine = load_machine(args.machine)
    if args.backend == "sim":
        from hw.sim import check_plant  # the simulator's modules, for a simulated run only

        check_plant(machine)
    return machine
