"""Joint-space paths from files: the thesis's time/position TSV and a CSV with joint names.

- **TSV** (``.tsv``, ``.txt``, ``.dat``): one point per line, ``time<TAB>position``
  on the rig (the layout of the thesis's data files), or time then one
  position per joint in joint order. Blank lines and ``#`` comments are skipped.
- **CSV** (``.csv``): a header naming the columns — a time column ``t``,
  ``time`` or ``t [s]``, and one column per joint by name or key (``In/Out``,
  ``inout``, ``Up/Down [deg]``). A joint not in the file stays where it is. A
  run saved by servodesk can be played back: its ``<joint> desired [unit]``
  columns are used and its actual and duty columns ignored.

Times are seconds, positions mm or degrees. Every malformed line is reported
with its line number, and the points are checked against the joint limits and
speeds of the machine. ``resample`` turns the points into a path at the sample
time, as ``ControlClient.move`` expects.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from control.motion.file_fields import csv_lines, field_number, read_text_file
from hw.machine import Machine

TIME_NAMES = ("t", "time", "t [s]", "time [s]")
MAX_MOVE_S = 600.0  # a move is sent and recorded whole: 600,000 samples at 1 ms is the most
CSV_SUFFIXES = (".csv",)


class PathFileError(ValueError):
    """A path file cannot be used; the message names the file and line."""


@dataclass(frozen=True)
class PathPoints:
    """Points of a path file: ``t (M,)`` s from 0, ``q (M, J)`` mm/deg, ``lines (M,)``."""

    source: str
    t: np.ndarray
    q: np.ndarray
    lines: tuple[int, ...]

    @property
    def duration(self) -> float:
        return float(self.t[-1]) if len(self.t) else 0.0


def read_path(path: str | Path, machine: Machine, hold: tuple[float, ...]) -> PathPoints:
    """Read a path file for ``machine``; joints the file leaves out stay at ``hold``."""
    path, text = read_text_file(path, PathFileError)
    if path.suffix.lower() in CSV_SUFFIXES:
        return parse_csv(text, machine, hold, str(path))
    return parse_tsv(text, machine, hold, str(path))


def parse_tsv(text: str, machine: Machine, hold: tuple[float, ...],
              source: str = "<tsv>") -> PathPoints:
    """``time<TAB>position…`` lines: 1 + J numbers each (or 2 on a one-joint machine)."""
    n = machine.n_joints
    times, rows, lines = [], [], []
    for number, raw in enumerate(text.splitlines(), start=1):
        line = raw.split("#", 1)[0].strip()
        if not line:
            continue
        fields = line.split("\t") if "\t" in line else line.split()
        if len(fields) != 1 + n:
            want = "time<TAB>position" if n == 1 else f"time then {n} positions"
            raise PathFileError(f"{source}: line {number}: {len(fields)} field(s), expected "
                                f"{1 + n} ({want})")
        values = [_number(f, source, number, k) for k, f in enumerate(fields, start=1)]
        times.append(values[0])
        rows.append(values[1:])
        lines.append(number)
    return _points(source, times, rows, lines, machine)


def parse_csv(text: str, machine: Machine, hold: tuple[float, ...],
              source: str = "<csv>") -> PathPoints:
    """A CSV with a header of joint names (and optionally a time column)."""
    reader = csv_lines(text, source, PathFileError)
    first = next(reader, None)
    if first is None:
        raise PathFileError(f"{source}: empty file: expected a header of joint names")
    header_line, header = first[0], [c.strip() for c in first[1]]
    time_col, joint_cols = _columns(header, machine, source, header_line)
    base = list(hold)
    times, rows, lines = [], [], []
    for number, row in reader:
        if len(row) != len(header):
            raise PathFileError(f"{source}: line {number}: {len(row)} field(s), the header has "
                                f"{len(header)}")
        q = list(base)
        for col, j in joint_cols.items():
            q[j] = _number(row[col], source, number, col + 1)
        t = (_number(row[time_col], source, number, time_col + 1) if time_col is not None
             else len(times) * machine.sample_time_s)
        times.append(t)
        rows.append(q)
        lines.append(number)
    return _points(source, times, rows, lines, machine)


def resample(points: PathPoints, dt: float) -> np.ndarray:
    """The path at sample time ``dt`` from t = 0 to the last point, ``(N, J)``."""
    n_samples = max(1, round(points.duration / dt) + 1)
    t = np.arange(n_samples) * dt
    return np.stack([np.interp(t, points.t, points.q[:, j]) for j in range(points.q.shape[1])],
                    axis=1)


def _columns(header: list[str], machine: Machine, source: str, line: int
             ) -> tuple[int | None, dict[int, int]]:
    time_col = None
    joint_cols: dict[int, int] = {}
    names = ", ".join(j.name for j in machine.joints)
    for col, name in enumerate(header):
        lowered = name.lower()
        if lowered in TIME_NAMES:
            time_col = col
            continue
        base, role = _joint_part(name)
        if role in ("actual", "duty"):
            continue  # a saved run: only its desired path is played
        try:
            j = machine.joint_index(base)
        except KeyError:
            raise PathFileError(f"{source}: line {line}: column {col + 1} {name!r} is not a "
                                f"joint of {machine.name} (joints: {names}; time: t)") from None
        if j in joint_cols.values():
            raise PathFileError(f"{source}: line {line}: joint {machine.joints[j].name} has "
                                "two columns")
        joint_cols[col] = j
    if not joint_cols:
        raise PathFileError(f"{source}: line {line}: no joint column in the header (joints: "
                            f"{names})")
    return time_col, joint_cols


def _joint_part(name: str) -> tuple[str, str]:
    """``'Up/Down desired [deg]'`` → ``('Up/Down', 'desired')``; ``'Ram [mm]'`` → ``('Ram', '')``.
    """
    base = name.split("[", 1)[0].strip()
    for role in ("desired", "actual", "duty"):
        if base.lower().endswith(" " + role):
            return base[: -len(role) - 1].strip(), role
    return base, ""


def _number(text: str, source: str, line: int, field: int) -> float:
    return field_number(text, source, line, field, PathFileError)


def _points(source: str, times: list[float], rows: list[list[float]], lines: list[int],
            machine: Machine) -> PathPoints:
    if not times:
        raise PathFileError(f"{source}: no points: expected lines of time and position")
    t = np.array(times)
    q = np.array(rows, dtype=np.float64).reshape(len(times), machine.n_joints)
    for k in range(1, len(t)):
        if t[k] <= t[k - 1]:
            raise PathFileError(f"{source}: line {lines[k]}: time {t[k]:g} s does not increase "
                                f"(previous {t[k - 1]:g} s)")
    if t[0] < 0:
        raise PathFileError(f"{source}: line {lines[0]}: time {t[0]:g} s is negative")
    t = t - t[0]
    if t[-1] > MAX_MOVE_S:
        raise PathFileError(f"{source}: line {lines[-1]}: the path lasts {t[-1]:g} s; a move "
                            f"lasts at most {MAX_MOVE_S:g} s: split the file into shorter ones")
    for k, row in enumerate(q):
        try:
            machine.check_targets(tuple(row))
        except ValueError as exc:
            raise PathFileError(f"{source}: line {lines[k]}: {exc}") from None
    if len(t) > 1:
        speed = np.abs(np.diff(q, axis=0)) / np.diff(t)[:, None]
        for j, joint in enumerate(machine.joints):
            fast = np.flatnonzero(speed[:, j] > joint.max_speed)
            if len(fast):
                k = int(fast[0]) + 1
                raise PathFileError(
                    f"{source}: line {lines[k]}: {joint.name} would move at "
                    f"{speed[k - 1, j]:.4g} {joint.unit}/s, above its max_speed "
                    f"{joint.max_speed:g} {joint.unit}/s: space the points further apart")
    return PathPoints(source, t, q, tuple(lines))
