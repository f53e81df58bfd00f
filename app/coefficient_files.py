"""Coefficient files: controller sets saved and loaded as TOML, in the machine file's schema.

A coefficient file holds only ``[coefficients.NAME]`` tables, exactly as in a
machine description (``docs/machines.md``), so a set tuned in the TUI can be
pasted into a machine file and a machine file's sets can be loaded here. It is
read with the machine loader's own reader, so every error names the file, the
line and the key, and checked against the shared-memory layout (at most ``MAX_TAPS``
taps).
"""

from __future__ import annotations

import math
import os
import re
import tempfile
from collections.abc import Mapping
from pathlib import Path

from control.rt.layout import MAX_TAPS
from hw.machine import (
    Coefficients,
    Machine,
    MachineError,
    parse_coefficient_tables,
    parse_toml,
    read_text,
)

SUFFIX = ".toml"
# the machine loader's "FILE: coefficients.SET[.KEY]: what", to name the line it is on
_AT_KEY = re.compile(r"coefficients\.(?P<set>[\w-]+)(?:\.(?P<key>[\w-]+)(?:\[\d+\])*)?: "
                     r"(?P<what>.*)", re.S)
_UNKNOWN = re.compile(r"unknown key\(s\) (?P<key>[\w-]+)")


class CoefficientFileError(ValueError):
    """A coefficient file cannot be read or written; the message names file and key."""


def parse_coefficients(text: str, machine: Machine, filename: str = "<text>"
                       ) -> dict[str, Coefficients]:
    """Every ``[coefficients.NAME]`` set in ``text`` for ``machine``'s joints, in file order."""
    try:
        doc = parse_toml(text, filename)
    except MachineError as exc:
        raise CoefficientFileError(str(exc)) from None
    try:
        return dict(parse_coefficient_tables(doc, filename, machine.n_joints))
    except MachineError as exc:
        raise CoefficientFileError(_with_line(str(exc), text, filename)) from None


def _with_line(message: str, text: str, filename: str) -> str:
    """The loader's message naming a set's key, with the line that key is on, as tomllib
    says it ("FILE: coefficients.hold.ki: … (at line 12)"); as it was when the key is not
    found on a line of its own."""
    found = _AT_KEY.match(message.removeprefix(f"{filename}: "))
    if found is None:
        return message
    unknown = _UNKNOWN.match(found["what"])
    key = found["key"] or (unknown["key"] if unknown else None)
    line = _line_of(text, found["set"], key)
    return message if line is None else f"{message} (at line {line})"


def _line_of(text: str, name: str, key: str | None) -> int | None:
    """The line of ``key`` in the ``[coefficients.NAME]`` table (of the table, without a key)."""
    header = re.compile(rf"^\s*\[\s*coefficients\s*\.\s*\"?{re.escape(name)}\"?\s*\]")
    at_key = re.compile(rf"^\s*\"?{re.escape(key or '')}\"?\s*=")
    inside = None
    for n, line in enumerate(text.splitlines(), 1):
        if header.match(line):
            if key is None:
                return n
            inside = n
        elif inside is not None and line.lstrip().startswith("["):
            inside = None
        elif inside is not None and at_key.match(line):
            return n
    return None


def load_coefficients(path: str | Path, machine: Machine) -> dict[str, Coefficients]:
    """Read a coefficient file; CoefficientFileError names the file and key on any problem
    (missing, not a file, unreadable, too large, not UTF-8, not TOML, nested too deep)."""
    path = Path(path).expanduser()
    try:
        text = read_text(path, "coefficient file")
    except MachineError as exc:
        raise CoefficientFileError(str(exc)) from None
    return parse_coefficients(text, machine, str(path))


def dump_coefficients(sets: Mapping[str, Coefficients], machine: Machine) -> str:
    """TOML text of ``sets`` in the machine file's ``[coefficients.NAME]`` schema."""
    lines = [f"# Coefficient sets for {machine.title} ({machine.name}), one entry per joint:",
             f"# {', '.join(j.name for j in machine.joints)}. Schema: docs/machines.md.", ""]
    for name, c in sets.items():
        _check_taps(c, f"coefficients.{name}")
        lines += [
            f"[coefficients.{_key(name)}]",
            f"note = {_string(c.note)}",
            f"kp = {_taps(c.kp)}",
            f"ki = {_numbers(c.ki)}",
            f"kd = {_numbers(c.kd)}",
            f"w = {_taps(c.w)}",
            f"filter = {_numbers(c.filter)}",
            f"filter_divisor = {_number(c.filter_divisor)}",
            f"integral_limit = {_number(c.integral_limit)}",
            f"duty_limit = {_number(c.duty_limit)}",
            *([f"kv = {_numbers(c.kv)}"] if c.kv else []),
            *([f"deadband = {_numbers(c.deadband)}"] if c.deadband else []),
            *([f"integral_separation = {_number(c.integral_separation)}"]
              if c.integral_separation else []),
            "",
        ]
    return "\n".join(lines)


def coefficient_path(path: str | Path) -> Path:
    """Where ``save_coefficients`` writes ``path``: ``~`` expanded, ``.toml`` added if missing."""
    path = Path(path).expanduser()
    return path if path.suffix == SUFFIX else path.with_name(path.name + SUFFIX)


def save_coefficients(path: str | Path, sets: Mapping[str, Coefficients],
                      machine: Machine) -> Path:
    """Write ``sets`` to ``path`` atomically (temporary file, then rename); return the path."""
    path = coefficient_path(path)
    text = dump_coefficients(sets, machine)
    parse_coefficients(text, machine, str(path))  # what we write must load back
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", dir=path.parent)
        with os.fdopen(fd, "w", encoding="utf-8") as f:
            f.write(text)
        os.replace(tmp, path)
    except OSError as exc:
        raise CoefficientFileError(f"{path}: cannot write: {exc.strerror or exc}") from None
    return path


def coefficient_changes(before: Coefficients, after: Coefficients, machine: Machine
                        ) -> list[tuple[str, str, str, str]]:
    """What replacing ``before`` with ``after`` changes, as ``(joint or "all joints", key,
    before, after)`` rows in the machine file's keys (taps newest first, ``–`` for none)."""
    rows = []
    for j, joint in enumerate(machine.joints):
        for key in ("kp", "ki", "kd", "w", "kv", "deadband"):
            old, new = _entry(before, key, j), _entry(after, key, j)
            if old != new:
                rows.append((joint.name, key, old, new))
    for key in ("filter", "filter_divisor", "integral_limit", "duty_limit",
                "integral_separation"):
        old, new = _shown(getattr(before, key)), _shown(getattr(after, key))
        if old != new:
            rows.append(("all joints", key, old, new))
    return rows


def _entry(c: Coefficients, key: str, j: int) -> str:
    values = getattr(c, key)
    if key in ("kv", "deadband") and not values:
        return "0"  # a set without feed-forward or deadband has none: 0
    return _shown(values[j])


def _shown(value: float | tuple[float, ...]) -> str:
    if isinstance(value, tuple):
        return ", ".join(f"{v:g}" for v in value) or "–"
    return f"{value:g}"


def _check_taps(c: Coefficients, where: str) -> None:
    for label, taps in (("kp", c.kp), ("w", c.w)):
        for j, t in enumerate(taps):
            if len(t) > MAX_TAPS:
                raise CoefficientFileError(f"{where}.{label}[{j}]: {len(t)} taps; the controller "
                                           f"takes at most {MAX_TAPS}")
    if len(c.filter) > MAX_TAPS:
        raise CoefficientFileError(f"{where}.filter: {len(c.filter)} taps; the controller takes "
                                   f"at most {MAX_TAPS}")


def _key(name: str) -> str:
    bare = name.replace("_", "").replace("-", "").isalnum() and name.isascii()
    return name if bare else _string(name)


def _string(text: str) -> str:
    escaped = text.replace("\\", "\\\\").replace('"', '\\"').replace("\n", "\\n")
    return f'"{escaped}"'


def _number(v: float) -> str:
    if not math.isfinite(v):
        raise CoefficientFileError(f"coefficient {v} is not a finite number")
    return repr(float(v))


def _numbers(values: tuple[float, ...]) -> str:
    return "[" + ", ".join(_number(v) for v in values) + "]"


def _taps(taps: tuple[tuple[float, ...], ...]) -> str:
    return "[" + ", ".join(_numbers(t) for t in taps) + "]"
