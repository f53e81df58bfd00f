"""The TUI's stylesheets: every .tcss under app/ is one the app loads, every tab has one, and
the package data ships exactly them (pyproject's globs each match files that exist)."""

from __future__ import annotations

import tomllib
from fnmatch import fnmatch
from pathlib import Path

from app.tui import TABS, ServodeskApp

ROOT = Path(__file__).resolve().parents[2]
APP = ROOT / "app"


def test_the_app_loads_every_stylesheet_and_each_tab_has_one() -> None:
    loaded = {(APP / path).resolve() for path in ServodeskApp.CSS_PATH}
    assert loaded == {path.resolve() for path in APP.rglob("*.tcss")}
    assert {APP / "tabs" / f"{name}.tcss" for name, _ in TABS} <= loaded


def test_package_data_ships_exactly_the_stylesheets() -> None:
    package_data = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"][
        "package-data"]
    shipped = set()
    for package, globs in package_data.items():
        folder = ROOT / package.replace(".", "/")
        for glob in globs:
            if not glob.endswith(".tcss"):
                continue
            matched = {p for p in folder.iterdir() if fnmatch(p.name, glob)}
            assert matched, f"{package}: {glob} matches no file"
            shipped |= matched
    assert shipped == set(APP.rglob("*.tcss"))
