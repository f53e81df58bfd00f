"""The docs name what exists: every module, file and dotted name they cite in backticks
(``control.rt.loop``, ``Controller.tick``, ``control/rt/loop.py``, ``ControlClient.go_to``) is in
the tree (issue 23: of eight claims checked, five named functions that did not exist)."""

from __future__ import annotations

import ast
import importlib
import re
import tomllib
from functools import cache
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = sorted([ROOT / "README.md", *(ROOT / "docs").glob("*.md")])
PACKAGES = ("app", "control", "hw", "kinematics", "benchmarks")
CODE = [p for package in PACKAGES for p in (ROOT / package).rglob("*.py")]
TICKED = re.compile(r"`([^`\n]+)`")
DOTTED = re.compile(r"^([A-Za-z_]\w*)((?:\.[A-Za-z_]\w*)+)(?:\(\))?$")
LISTINGS = (".h", ".c", ".o", ".m")  # the thesis's own files: RT.c, kinematics.h, plotsix.m
PATH = re.compile(r"^((?:app|control|hw|kinematics|benchmarks|tests|docs)/[\w/.-]*\w)(?::\d+)?$")


def cited(doc: Path) -> list[str]:
    text = re.sub(r"```.*?```", "", doc.read_text(), flags=re.S)  # code blocks show usage
    return [m.group(1).strip() for m in TICKED.finditer(text)]


@cache
def classes() -> dict[str, set[str]]:
    """Every class in the tree: the names its body defines (methods, fields, properties)."""
    found: dict[str, set[str]] = {}
    for path in CODE:
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ClassDef):
                names = found.setdefault(node.name, set())
                for item in node.body:
                    if isinstance(item, ast.FunctionDef | ast.AsyncFunctionDef | ast.ClassDef):
                        names.add(item.name)
                    elif isinstance(item, ast.AnnAssign) and isinstance(item.target, ast.Name):
                        names.add(item.target.id)
                    elif isinstance(item, ast.Assign):
                        names.update(t.id for t in item.targets if isinstance(t, ast.Name))
                for item in ast.walk(node):  # self.x = … in its methods
                    if (isinstance(item, ast.Attribute) and isinstance(item.value, ast.Name)
                            and item.value.id == "self" and isinstance(item.ctx, ast.Store)):
                        names.add(item.attr)
    return found


def exists(name: str) -> bool:
    """Whether the dotted ``name`` names a module, or something in one, or a class's member."""
    match = DOTTED.match(name)
    assert match is not None
    head, rest = match.group(1), match.group(2).lstrip(".").split(".")
    if head in PACKAGES:
        parts = [head, *rest]
        for cut in range(len(parts), 0, -1):
            try:
                thing: object = importlib.import_module(".".join(parts[:cut]))
            except ImportError:
                continue
            for attr in parts[cut:]:
                if not hasattr(thing, attr):
                    return False
                thing = getattr(thing, attr)
            return True
        return False
    members = classes().get(head)
    return members is not None and rest[0] in members


@cache
def machine_keys() -> set[str]:
    """Every dotted key of the built-in machine files (``kinematics.cartesian_jog_speed``)."""
    keys: set[str] = set()

    def walk(prefix: str, value: object) -> None:
        if isinstance(value, dict):
            for key, inner in value.items():
                keys.add(f"{prefix}{key}")
                walk(f"{prefix}{key}.", inner)
        elif isinstance(value, list):
            for inner in value:
                walk(prefix, inner)

    for path in (ROOT / "hw" / "machines").glob("*.toml"):
        walk("", tomllib.loads(path.read_text()))
    return keys


def checked(doc: Path) -> list[str]:
    """The citations of ``doc`` that name code: dotted names of the tree (not a thesis
    listing's file, ``kinematics.h``, nor a machine file's key) and repo paths."""
    out = []
    for token in cited(doc):
        m = DOTTED.match(token)
        code = m is not None and (m.group(1) in PACKAGES or m.group(1) in classes())
        if PATH.match(token) or (code and not token.endswith(LISTINGS)
                                 and token not in machine_keys()):
            out.append(token)
    return out


@pytest.mark.parametrize("doc", DOCS, ids=[str(d.relative_to(ROOT)) for d in DOCS])
def test_every_name_a_doc_cites_exists(doc: Path) -> None:
    missing = []
    for token in checked(doc):
        if path := PATH.match(token):
            if not (ROOT / path.group(1)).exists():
                missing.append(token)
        elif not exists(token):
            missing.append(token)
    assert missing == [], f"{doc.name} cites what is not in the tree: {missing}"


def test_the_check_finds_what_is_not_there() -> None:
    assert exists("control.client.ControlClient.go_to")
    assert exists("ControlClient.go_to")
    assert not exists("ControlClient.no_such_method")
    assert not exists("control.client.no_such_name")
    assert len(checked(ROOT / "docs" / "architecture.md")) > 50
