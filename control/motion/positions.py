"""Taught positions, home and park: named joint vectors the operator returns to.

Home and park come from the machine file (``[machine] home``, ``park``;
``docs/machines.md``). Taught positions are kept per machine in the data
directory, ``positions/<machine>.toml``, a file a person may read and edit
(``docs/motion.md``, "Taught positions")::

    machine = "unimate2000b"

    [[position]]
    name = "above the fixture"
    joints = [1300.0, 0.0, 0.0, 0.0, 90.0, 0.0]  # mm and degrees, joint order

Reading it checks everything: TOML, the keys, names (non-empty, printable, at
most ``MAX_NAME`` characters, unique, not ``home`` or ``park``), one finite
number per joint inside its limits; an error names the file, the line and the
fix. Writing is atomic (``control.recorder.replace_file``): a reader, or a
writer killed half-way, sees the old file or the new one, never a part.
"""

from __future__ import annotations

import json
import math
import re
import unicodedata
from collections.abc import Mapping
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from control.recorder import remove_stale_temps, replace_file
from control.rt.shm import pid_alive
from hw.machine import UNPRINTABLE, Joint, Machine, MachineError, parse_toml, read_text

HOME, PARK = "home", "park"  # the machine file's positions; no taught one takes these names
MAX_NAME = 40  # characters: a name fits the Positions table's column
MAX_POSITIONS = 1000  # taught positions a file may hold
DECIMALS = 3  # a reading is taught to 0.001 mm or degree, finer than any encoder's count
SUFFIX = ".toml"
_HEADER = re.compile(r"^\s*\[\[\s*position\s*\]\]")  # an entry of the file
_TABLE = re.compile(r"^\s*\[\[?\s*([\w.\"' -]+)\s*\]\]?\s*(#.*)?$")  # any table header
_KEY = re.compile(r"^\s*([\w-]+|\"[^\"]*\")\s*=")
_TOML_AT = re.compile(r"\s*\(at line (\d+), column (\d+)\)")


class PositionsError(ValueError):
    """A positions file cannot be read or written, or a change to it is refused; the message
    names the file (and the line) and says how to fix it."""


@dataclass(frozen=True)
class Position:
    """A named position: ``joints (J,)`` in joint order, mm and degrees. ``source`` is
    ``taught`` or ``machine file`` (home and park)."""

    name: str
    joints: tuple[float, ...]
    source: str = "taught"

    @property
    def taught(self) -> bool:
        return self.source == "taught"


@dataclass(frozen=True)
class PositionBook:
    """The positions of one machine: its home and park, then the taught ones in file order.

    The editing methods return a new book and raise ValueError (nothing changed) with the
    fix when a name is unusable or taken, or a reading is outside the limits.
    """

    machine: Machine
    taught: tuple[Position, ...] = ()

    @property
    def positions(self) -> tuple[Position, ...]:
        """Home and park (those the machine file has), then the taught positions."""
        fixed = [Position(name, q, "machine file")
                 for name, q in ((HOME, self.machine.home), (PARK, self.machine.park))
                 if q is not None]
        return (*fixed, *self.taught)

    def find(self, name: str) -> Position:
        for p in self.positions:
            if p.name == name:
                return p
        raise ValueError(f"no position named {name!r}")

    def check_name(self, name: str, renaming: str | None = None) -> str:
        """``name`` stripped, if a taught position may take it (``renaming``'s own name
        may be kept); ValueError saying what to type otherwise."""
        name = name.strip()
        if not name:
            raise ValueError("type a name for the position")
        if len(name) > MAX_NAME:
            raise ValueError(f"a name has at most {MAX_NAME} characters, this one "
                             f"{len(name)}: shorten it")
        bad = next((i for i, c in enumerate(name) if unicodedata.category(c) in UNPRINTABLE),
                   None)
        if bad is not None:
            raise ValueError(f"character {bad + 1} of the name ({name[bad]!r}) does not print: "
                             f"remove it")
        if name.lower() in (HOME, PARK):
            raise ValueError(f"{name!r} is the machine file's {name.lower()} position "
                             f"({self.machine.path.name}): choose another name")
        if name != renaming and any(p.name == name for p in self.taught):
            raise ValueError(f"a position named {name!r} exists: choose another name, or "
                             f"delete that one first")
        return name

    def teach(self, name: str, q: tuple[float, ...] | list[float]) -> PositionBook:
        """Add the reading ``q (J,)`` (mm, deg; kept to ``DECIMALS`` places) as ``name``. A
        joint resting within its tolerance past a limit (the rig on its bottom stop) is
        taught on the limit."""
        name = self.check_name(name)
        if len(self.taught) >= MAX_POSITIONS:
            raise ValueError(f"{MAX_POSITIONS} positions are taught already: delete some first")
        reading = tuple(float(v) for v in q)
        if len(reading) == self.machine.n_joints:  # else _check_joints names the count
            reading = tuple(_onto_limits(v, j)
                            for v, j in zip(reading, self.machine.joints, strict=True))
        joints = tuple(round(v, DECIMALS) for v in reading)
        try:
            _check_joints(joints, self.machine)
        except ValueError as exc:
            raise ValueError(f"{exc}: jog it inside and teach again") from None
        return replace(self, taught=(*self.taught, Position(name, joints)))

    def rename(self, old: str, new: str) -> PositionBook:
        self._taught_one(old, "renamed")
        new = self.check_name(new, renaming=old)
        return replace(self, taught=tuple(replace(p, name=new) if p.name == old else p
                                          for p in self.taught))

    def delete(self, name: str) -> PositionBook:
        self._taught_one(name, "deleted")
        return replace(self, taught=tuple(p for p in self.taught if p.name != name))

    def _taught_one(self, name: str, what: str) -> None:
        if name in (HOME, PARK):
            raise ValueError(f"{name} comes from the machine file ({self.machine.path.name}): "
                             f"it is {what} there, not here")
        if not any(p.name == name for p in self.taught):
            raise ValueError(f"no taught position named {name!r}")


def _onto_limits(v: float, joint: Joint) -> float:
    """``v`` moved onto the nearer limit if it is past it by no more than the tolerance."""
    if joint.lower - joint.tolerance <= v < joint.lower:
        return joint.lower
    if joint.upper < v <= joint.upper + joint.tolerance:
        return joint.upper
    return v


def _check_joints(joints: tuple[float, ...], machine: Machine) -> None:
    """ValueError naming the joint if ``joints`` is not one finite in-limit value per joint."""
    if len(joints) != machine.n_joints:
        names = ", ".join(j.name for j in machine.joints)
        raise ValueError(f"{len(joints)} joint values, {machine.name} has {machine.n_joints} "
                         f"({names})")
    for joint, v in zip(machine.joints, joints, strict=True):
        if not math.isfinite(v):
            raise ValueError(f"{joint.name} is {v}, not a number")
        if not joint.lower <= v <= joint.upper:
            raise ValueError(f"{joint.name} at {v:g}{joint.symbol} is outside its limits "
                             f"{joint.limit_text()}")


# -- the file ----------------------------------------------------------------------------------


def positions_file(data_dir: Path, machine: Machine) -> Path:
    """Where ``machine``'s taught positions are kept: ``<data_dir>/positions/<name>.toml``."""
    return Path(data_dir) / "positions" / f"{machine.name}{SUFFIX}"


def dump_positions(book: PositionBook) -> str:
    """The TOML text of ``book``'s taught positions, with a header saying what it holds."""
    m = book.machine
    units = ", ".join(f"{j.name} [{j.unit}]" for j in m.joints)
    lines = ["# Taught positions, written by servodesk, of the",
             f"#   {m.title} ({m.name}).",
             "# You may edit this file: one [[position]] per position, a unique name and one",
             "# number per joint, in this order and these units:",
             f"#   {units}.",
             "# Home and park are in the machine file. Format: docs/motion.md.",
             "", f"machine = {_string(m.name)}"]
    for p in book.taught:
        lines += ["", "[[position]]", f"name = {_string(p.name)}",
                  "joints = [" + ", ".join(repr(float(v)) for v in p.joints) + "]"]
    return "\n".join(lines) + "\n"


def parse_positions(text: str, machine: Machine, filename: str = "<text>") -> PositionBook:
    """The positions in ``text`` (a positions file of ``machine``); PositionsError naming
    ``filename``, the line and the fix for anything wrong."""
    try:
        doc = parse_toml(text, filename)
    except MachineError as exc:
        raise PositionsError(_toml_line(str(exc), filename)) from None
    where = _Lines(text, filename)
    unknown = sorted(set(doc) - {"machine", "position"})
    if unknown:
        raise where.fail(None, unknown[0], f"unknown key {unknown[0]!r}; a positions file holds "
                                           f"`machine = \"…\"` and [[position]] tables")
    written_for = doc.get("machine", machine.name)
    if written_for != machine.name:
        raise where.fail(None, "machine", f"the positions of machine {written_for!r}, not "
                                          f"{machine.name!r}: use that machine, or move the file")
    entries = doc.get("position", [])
    if not isinstance(entries, list) or not all(isinstance(e, dict) for e in entries):
        raise where.fail(None, "position", "`position` must be [[position]] tables")
    if len(entries) > MAX_POSITIONS:
        raise where.fail(None, "position", f"{len(entries)} positions; a file holds at most "
                                           f"{MAX_POSITIONS}")
    if len(where.entries) != len(entries):  # tables spelt otherwise: name entries, not lines
        where.entries = []
    book = PositionBook(machine)
    for i, entry in enumerate(entries):
        book = _entry(book, entry, i, where)
    return book


def _entry(book: PositionBook, entry: Mapping[str, Any], i: int, where: _Lines) -> PositionBook:
    unknown = sorted(set(entry) - {"name", "joints"})
    if unknown:
        raise where.fail(i, unknown[0], f"unknown key {unknown[0]!r}; a position has a name "
                                        f"and joints")
    name = entry.get("name")
    if not isinstance(name, str):
        raise where.fail(i, "name", "needs a name: name = \"…\"")
    try:
        name = book.check_name(name)
    except ValueError as exc:
        raise where.fail(i, "name", str(exc)) from None
    joints = entry.get("joints")
    if (not isinstance(joints, list)
            or not all(isinstance(v, int | float) and not isinstance(v, bool) for v in joints)):
        raise where.fail(i, "joints", f"{name!r}: joints must be a list of numbers, one per "
                                      f"joint (mm, deg)")
    try:
        q = tuple(float(v) for v in joints)
        _check_joints(q, book.machine)
    except (ValueError, OverflowError) as exc:
        raise where.fail(i, "joints", f"{name!r}: {exc}") from None
    return replace(book, taught=(*book.taught, Position(name, q)))


def load_positions(path: Path, machine: Machine) -> PositionBook:
    """The positions kept in ``path``; none taught when it does not exist yet."""
    path = Path(path)
    if not path.exists() and not path.is_symlink():
        return PositionBook(machine)
    try:
        text = read_text(path, "positions file")
    except MachineError as exc:
        raise PositionsError(str(exc)) from None
    return parse_positions(text, machine, str(path))


def save_positions(book: PositionBook, path: Path) -> Path:
    """Write ``book``'s taught positions to ``path`` atomically; PositionsError (the file as
    it was) if it cannot be written."""
    path = Path(path)
    text = dump_positions(book)
    parse_positions(text, book.machine, str(path))  # what we write must load back
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        remove_stale_temps(path.parent, pid_alive)
        replace_file(text.encode("utf-8"), path)
    except OSError as exc:
        raise PositionsError(f"{path}: cannot write it: {exc.strerror or exc}; the file is "
                             f"as it was") from None
    return path


class _Lines:
    """Where the keys of a positions file are, to name the line of an error (best effort: the
    entry's number when the file spells its tables some other way)."""

    def __init__(self, text: str, filename: str) -> None:
        self.filename = filename
        self.top: dict[str, int] = {}
        self.entries: list[dict[str, int]] = []
        section: dict[str, int] | None = self.top
        for n, line in enumerate(text.splitlines(), 1):
            if _HEADER.match(line):
                self.entries.append({"": n})
                section = self.entries[-1]
            elif table := _TABLE.match(line):  # a table of its own: its name's line is this
                self.top.setdefault(table.group(1).strip('"\' ').split(".")[0].strip(), n)
                section = None
            elif section is not None and (key := _KEY.match(line)):
                section.setdefault(key.group(1).strip('"'), n)

    def fail(self, entry: int | None, key: str, what: str) -> PositionsError:
        if entry is None:
            line = self.top.get(key)
            label = ""
        else:
            keys = self.entries[entry] if entry < len(self.entries) else {}
            line = keys.get(key, keys.get(""))
            label = f"position {entry + 1}: "
        at = f"line {line}: " if line is not None else ""
        return PositionsError(f"{self.filename}: {at}{label}{what}")


def _toml_line(message: str, filename: str) -> str:
    """tomllib's "… (at line 3, column 9)" as "FILE: line 3: not valid TOML: … (column 9)"."""
    at = _TOML_AT.search(message)
    if at is None:
        return message
    what = _TOML_AT.sub("", message).removeprefix(f"{filename}: ")
    return f"{filename}: line {at.group(1)}: {what} (column {at.group(2)})"


def _string(text: str) -> str:
    """A TOML basic string: JSON's escapes are TOML's for text that prints."""
    return json.dumps(text, ensure_ascii=False)
