"""Dependencies point one way (docs/architecture.md): ``app → control → hw``, ``app`` may use
``kinematics`` for display, ``hw`` never imports ``control``, ``app`` or ``kinematics``, and
``kinematics`` imports nothing of the project and reads no file.

Every import statement of every module is read from its source, those inside functions and
under ``TYPE_CHECKING`` too: a late import is still an arrow (``hw.machine`` once imported
the simulator inside ``parse_machine``, which importing ``hw`` in a fresh interpreter would
not have shown). ``control.rt``, the code the control process runs, imports nothing of
``control`` outside itself. The process's own imports, as it runs, are tests/control/rt/
test_process.py's.
"""

from __future__ import annotations

import ast
from collections.abc import Iterator, Sequence
from functools import cache
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
# What pure numpy kinematics may import: numpy and the stdlib's plain computation, nothing
# that reads a file or finds a package (tomllib, pathlib, importlib, io, os…).
KINEMATICS_MAY_IMPORT = ("__future__", "collections", "dataclasses", "functools", "itertools",
                         "math", "typing", "numpy", "kinematics")
# hw's modules that build a backend, and so may import one.
BUILDS_BACKENDS = ("hw.factory",)
BACKENDS = ("hw.sim", "hw.serial")


def module_name(path: Path) -> str:
    parts = path.relative_to(ROOT).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def imports_in(source: str, package: str) -> Iterator[tuple[int, str]]:
    """``(line, name)`` of every import in ``source``, a module of ``package``: each name
    imported from a module as ``module.name``, so ``from hw import sim`` is ``hw.sim``;
    relative ones resolved."""
    parts = package.split(".")
    for node in statements(ast.parse(source).body):
        if isinstance(node, ast.Import):
            for alias in node.names:
                yield node.lineno, alias.name
        elif isinstance(node, ast.ImportFrom):
            base = parts[:len(parts) - node.level + 1] if node.level else []
            module = ".".join([*base, *filter(None, [node.module])])
            for alias in node.names:
                yield node.lineno, f"{module}.{alias.name}"


def statements(body: Sequence[ast.AST]) -> Iterator[ast.AST]:
    """Every statement in ``body`` and in the bodies nested in it (of functions, classes,
    ifs, trys, their handlers, match cases): an import is a statement, and no expression
    holds one, so the expressions (most of a module) are not walked (ast.walk: 0.18 s)."""
    for node in body:
        yield node
        for field in ("body", "orelse", "finalbody", "handlers", "cases"):
            nested = getattr(node, field, None)
            if isinstance(nested, list):
                yield from statements(nested)


def imports_of(path: Path) -> Iterator[tuple[int, str]]:
    name = module_name(path)
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    return imports_in(path.read_text(encoding="utf-8"), package)


def under(module: str, *packages: str) -> bool:
    return any(module == p or module.startswith(f"{p}.") for p in packages)


@cache  # read when a test asks, not at collection (0.6 s: every xdist worker collects)
def arrows(package: str) -> list[tuple[str, int, str]]:
    """``(module, line, imported)`` for every import of every module of ``package``."""
    return [(module_name(path), line, imported)
            for path in sorted((ROOT / package).rglob("*.py"))
            for line, imported in imports_of(path)]


def shown(found: list[tuple[str, int, str]]) -> str:
    return "; ".join(f"{module} (line {line}) imports {imported}"
                     for module, line, imported in found)


def test_the_import_reader_sees_late_relative_and_from_imports() -> None:
    source = ("import numpy as np\n"
              "def f():\n    from .sim import backend\n"
              "if TYPE_CHECKING:\n    from .. import app\n"
              "from hw import sim\n")
    assert sorted(imports_in(source, "hw.serial")) == [
        (1, "numpy"), (3, "hw.serial.sim.backend"), (5, "hw.app"), (6, "hw.sim")]
    assert {"hw.sim.backend.SimBackend", "hw.serial.backend.SerialBackend"} <= {
        name for _, name in imports_of(ROOT / "hw" / "factory.py")}  # inside a function


def test_kinematics_is_pure_numpy_and_imports_nothing_of_the_project() -> None:
    found = [a for a in arrows("kinematics") if not under(a[2], *KINEMATICS_MAY_IMPORT)]
    assert found == [], (f"{shown(found)}: kinematics takes its numbers from the caller "
                         "(control.motion.robot_model builds models from machine files)")


def test_hw_imports_neither_control_nor_app_nor_kinematics() -> None:
    found = [a for a in arrows("hw") if under(a[2], "control", "app", "kinematics")]
    assert found == [], f"{shown(found)}: hw is the core the others stand on"


def test_the_machine_description_knows_no_backend() -> None:
    """Only the factory builds a backend; the machine description, transmission and the
    Backend interface know neither the simulator nor the I/O board."""
    found = [a for a in arrows("hw")
             if under(a[2], *BACKENDS) and not under(a[0], *BACKENDS, *BUILDS_BACKENDS)]
    assert found == [], (f"{shown(found)}: a backend checks what it needs of a machine as it "
                         "is built (hw.sim.check_plant)")


def test_control_imports_nothing_of_the_app() -> None:
    found = [a for a in arrows("control") if under(a[2], "app")]
    assert found == [], shown(found)


def test_the_1_khz_code_imports_nothing_of_control_outside_it() -> None:
    """``control/rt/`` is what runs at 1 kHz and in the control process: the client, planning,
    identification and run files stand on it, never the other way round."""
    found = [a for a in arrows("control")
             if under(a[0], "control.rt") and under(a[2], "control")
             and not under(a[2], "control.rt")]
    assert found == [], shown(found)


@pytest.mark.parametrize("ui", ["app.widgets", "app.tabs", "app.tui", "app.desk"])
def test_plotting_imports_nothing_of_the_ui(ui: str) -> None:
    """Plots are drawn as strips and exported without a screen (``servodesk runs export``);
    the widgets show them, never the other way round."""
    found = [a for a in arrows("app") if under(a[0], "app.plotting") and under(a[2], ui)]
    assert found == [], shown(found)
