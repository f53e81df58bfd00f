"""Joint-space paths from files: the thesis's time/position TSV and a CSV with joint names.

- **TSV** (``.tsv``, ``.txt``, ``.dat``): one point per line, ``time<TAB>position``
  on the rig (the layout of the thesis's data files), or time then one
  position per joint in joint order. Blank lines and ``#`` comments are skipped.
- **CSV** (``.csv``): a header naming the columns — a time column ``t``,
  ``time`` or ``t [s]``, and one column per joint by name or key (``In/Out``,
  ``inout``, ``Up/Down [deg]``). A joint not in the file stays where it is.
- **A saved run** (its ``.json``, either table, or its stem): its desired path plays
  again, one row per sample, as the move it was (``control/motion/replay.py``): a table
  beside its JSON is read through the JSON; one without (a CSV with ``<joint> desired
  [unit]`` columns, a TSV of sample then desired, actual and duty of each joint, as
  option.c SaveData wrote) plays as a path on the machine's sample grid.

Either may be gzipped (``.tsv.gz``, ``.csv.gz``: a saved run's files are). Times are
seconds, positions mm or degrees. Every malformed line is reported
with its line number. A file is bounded before it is parsed (``path_file_bound``):
at most one line per sample of the longest move allowed (``acceptance.MAX_MOVE_S``) and a
header, at ``file_fields.BYTES_PER_ROW`` bytes a line; reading stops at the bound. Only a
regular file is read: a named pipe or a device is refused at once, naming what it is.
A file is a ``path`` move, a smooth kind, so the points are held to the rules of
``control.motion.acceptance`` (``docs/motion.md``): every point inside the joint
limits, no joint faster than its ``max_speed`` from one point to the next.

``resample`` turns the points into a path at the sample time, as
``ControlClient.move`` expects: the points joined by straight lines, and each
change of speed at a point (leaving rest at the first, coming to rest at the
last) blended over a parabola at the joint's ``max_accel``, so the path keeps
``max_accel`` too. A blend takes ``|Δv|/max_accel`` seconds centred on its
point and passes within ``Δv²/(8·max_accel)`` of it (0.35 mm for the rig's
Ram turning from 100 to −50 mm/s); the path starts ``lead_s(dt)`` before the
file's time 0 (half the first blend, on whole samples) and ends at rest half
the last blend after its last point. Points closer together than their two
blends need are refused naming both lines. The thesis's files had one point per
sample (function.c FollowPath), where the blends are shorter than a sample.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from control.motion import replay
from control.motion.acceptance import (
    MAX_MOVE_S,
    MoveRefused,
    check_rows,
    check_smooth,
    check_speeds,
)
from control.motion.file_fields import (
    FileBound,
    csv_lines,
    field_number,
    format_suffix,
    move_file_bound,
    read_text_file,
)
from hw.machine import Machine

TIME_NAMES = ("t", "time", "t [s]", "time [s]")
CSV_SUFFIXES = (".csv",)


class PathFileError(ValueError):
    """A path file cannot be used; the message names the file and line."""


@dataclass(frozen=True)
class PathPoints:
    """Points of a path file: ``t (M,)`` s from 0, ``q (M, J)`` mm/deg, ``lines (M,)``,
    ``max_accel (J,)`` the changes of speed are blended at (none: straight corners, as a
    saved run's rows, one a sample), ``held``, the joints the file leaves out (they stay
    where they are: ``held_at``), the move ``kind`` they play as, and ``run``, what they
    replay (a saved run: ``replay.RunPath.title``; empty for a path file)."""

    source: str
    t: np.ndarray
    q: np.ndarray
    lines: tuple[int, ...]
    max_accel: tuple[float, ...] = ()
    held: tuple[int, ...] = ()
    kind: str = "path"
    run: str = ""

    @classmethod
    def of_run(cls, played: replay.RunPath) -> PathPoints:
        """A saved run's rows as points, one a sample: the path ``resample`` makes of them
        at their sample time is the rows themselves."""
        return cls(played.source, np.arange(len(played.q)) * played.dt, played.q,
                   played.lines(), kind=played.kind, run=played.title)

    def held_at(self, hold: np.ndarray) -> PathPoints:
        """These points with the joints the file leaves out at ``hold (J,)``: where they are
        when the path is played, not when the file was read."""
        if not self.held:
            return self
        q = self.q.copy()
        q[:, list(self.held)] = np.asarray(hold, dtype=np.float64)[list(self.held)]
        return replace(self, q=q)

    @property
    def duration(self) -> float:
        return float(self.t[-1]) if len(self.t) else 0.0

    def blends(self) -> np.ndarray:
        """``(M, J)`` s: how long each point's change of speed takes at ``max_accel``, from
        rest at the first point and to rest at the last (0 without ``max_accel``)."""
        if not self.max_accel or len(self.t) < 2:
            return np.zeros_like(self.q)
        return np.abs(speed_changes(self.t, self.q)) / np.array(self.max_accel)

    def lead_s(self, dt: float) -> float:
        """How long before the file's time 0 the resampled path starts: half the first
        blend, on whole samples of ``dt``."""
        return _whole(float(self.blends()[0].max(initial=0.0)) / 2, dt)


def path_file_bound(machine: Machine) -> FileBound:
    """The most a path file for ``machine`` may hold: one point per sample of a move of
    ``MAX_MOVE_S`` (600,002 lines and 307 MB at 1 ms)."""
    return move_file_bound("a path file", machine.sample_time_s, MAX_MOVE_S,
                           f"split it into moves of at most {MAX_MOVE_S:g} s, or thin its "
                           "points")


def read_path(path: str | Path, machine: Machine, hold: tuple[float, ...]) -> PathPoints:
    """Read a path file for ``machine``, within ``path_file_bound``; joints the file leaves
    out stay at ``hold``. A saved run (any of its files, its stem) is its desired path."""
    if (json := replay.saved_run(path)) is not None:
        return PathPoints.of_run(replay.read_run(json, machine, PathFileError,
                                                 named=str(path)))
    path, text = read_text_file(path, path_file_bound(machine), PathFileError)
    if format_suffix(path) in CSV_SUFFIXES:
        return parse_csv(text, machine, hold, str(path))
    return parse_tsv(text, machine, hold, str(path))


def parse_tsv(text: str, machine: Machine, hold: tuple[float, ...],
              source: str = "<tsv>") -> PathPoints:
    """``time<TAB>position…`` lines: 1 + J numbers each (or 2 on a one-joint machine); or a
    saved run's TSV, 1 + 3·J (sample, then desired, actual, duty of each joint), whose
    desired columns play on the sample grid (``replay.table_run``)."""
    n = machine.n_joints
    times, rows, lines = [], [], []
    width = 0
    for number, raw in enumerate(text.splitlines(), start=1):
        line = raw.split("#", 1)[0].strip()
        if not line:
            continue
        fields = line.split("\t") if "\t" in line else line.split()
        width = width or (len(fields) if len(fields) == 1 + 3 * n else 1 + n)
        if len(fields) != width:
            want = ("sample, then desired, actual and duty of each joint (a saved run)"
                    if width != 1 + n else
                    "time<TAB>position" if n == 1 else f"time then {n} positions")
            raise PathFileError(f"{source}: line {number}: {len(fields)} field(s), expected "
                                f"{width} ({want})")
        values = [_number(f, source, number, k) for k, f in enumerate(fields, start=1)]
        times.append(values[0])
        rows.append(values[1::3] if width != 1 + n else values[1:])
        lines.append(number)
    if width not in (0, 1 + n):
        return _saved_table(source, rows, lines, machine)
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
    saved = any(_joint_part(header[col])[1] == "desired" for col in joint_cols)
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
    held = tuple(j for j in range(machine.n_joints) if j not in joint_cols.values())
    if saved:  # a saved run's table: its times are when each sample was taken, jitter too
        return replace(_saved_table(source, rows, lines, machine), held=held)
    return replace(_points(source, times, rows, lines, machine), held=held)


def resample(points: PathPoints, dt: float) -> np.ndarray:
    """The path at sample time ``dt``, ``(N, J)``: straight lines between the points, each
    change of speed blended at ``max_accel`` (module docstring), from rest ``lead_s`` before
    the file's time 0 until rest after its last point."""
    blends = points.blends()
    lead = points.lead_s(dt)
    tail = _whole(float(blends[-1].max(initial=0.0)) / 2, dt)
    n_samples = max(1, math.ceil((points.duration + lead + tail) / dt - 1e-9) + 1)
    t = np.arange(n_samples) * dt - lead  # the file's time of each sample
    q = np.stack([np.interp(t, points.t, points.q[:, j]) for j in range(points.q.shape[1])],
                 axis=1)
    if len(points.t) < 2:
        return q
    change = speed_changes(points.t, points.q)
    last = len(points.t) - 1
    left = np.clip(np.searchsorted(points.t, t, side="right") - 1, 0, last)
    right = left + 1
    for k, here in ((left, True), (np.minimum(right, last), right <= last)):
        # a sample is in at most one blend: of the point before it or of the one after
        s = np.where(here, t - points.t[k], -np.inf)[:, None] + blends[k] / 2
        q += _blend(s, change[k], blends[k])
    return q


def speed_changes(t: np.ndarray, q: np.ndarray) -> np.ndarray:
    """``(M, J)`` units/s: the change of speed at each point of straight lines through the
    points, from rest before the first and to rest after the last."""
    speed = np.diff(q, axis=0) / np.diff(t)[:, None]
    rest = np.zeros((1, q.shape[1]))
    return np.diff(np.concatenate([rest, speed, rest]), axis=0)


def _blend(s: np.ndarray, change: np.ndarray, blend: np.ndarray) -> np.ndarray:
    """What a parabolic blend adds to the straight lines at ``s`` s into the blend (0 outside):
    ``Δv·s²/(2·tb) − Δv·max(0, s − tb/2)``, for changes ``Δv`` taking ``tb`` s."""
    active = (s >= 0.0) & (s <= blend) & (blend > 0.0)
    tb = np.where(active, blend, 1.0)
    s = np.where(active, s, 0.0)
    add = change * s**2 / (2 * tb) - change * np.maximum(0.0, s - tb / 2)
    return np.where(active, add, 0.0)


def _whole(seconds: float, dt: float) -> float:
    return math.ceil(seconds / dt - 1e-9) * dt


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


def _saved_table(source: str, rows: list[list[float]], lines: list[int], machine: Machine
                 ) -> PathPoints:
    """A saved run's table without its JSON: its desired rows, one a sample."""
    if not rows:
        raise PathFileError(f"{source}: no rows: a saved run's table holds one per sample")
    q = np.array(rows, dtype=np.float64).reshape(len(rows), machine.n_joints)
    return PathPoints.of_run(replay.table_run(source, q, machine, tuple(lines), PathFileError))


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
    def at(k: int) -> str:
        return f"t = {t[k]:g} s"

    try:
        check_rows(q, machine, at)
        check_speeds(t, q, machine, at, "space the points further apart")
    except MoveRefused as exc:
        raise PathFileError(f"{source}: line {lines[exc.index or 0]}: {exc}") from None
    points = PathPoints(source, t, q, tuple(lines),
                        tuple(j.max_accel for j in machine.joints))
    _check_blends(points, machine)
    _check_resampled(points, machine)
    return points


def _check_blends(points: PathPoints, machine: Machine) -> None:
    """Refuse two points closer together than their changes of speed take at max_accel."""
    blends = points.blends()
    if len(points.t) < 2:
        return
    room = np.diff(points.t)[:, None]
    need = (blends[:-1] + blends[1:]) / 2
    over = np.argwhere(need > room * (1 + 1e-9))
    if not len(over):
        return
    k, j = (int(i) for i in over[0])
    joint = machine.joints[j]
    change = speed_changes(points.t, points.q)[:, j]
    u = joint.unit
    raise PathFileError(
        f"{points.source}: lines {points.lines[k]} and {points.lines[k + 1]}: {joint.name} "
        f"changes speed by {change[k]:+.4g} {u}/s at the first (t = {points.t[k]:g} s) and by "
        f"{change[k + 1]:+.4g} {u}/s at the second (t = {points.t[k + 1]:g} s), "
        f"{room[k, 0]:.4g} s apart; at its max_accel {joint.max_accel:g} {u}/s² those changes "
        f"need {need[k, j]:.3g} s (machine {machine.name}): space the points further apart or "
        "change speed in smaller steps (the path leaves rest at the first point and comes to "
        "rest at the last)")


def _check_resampled(points: PathPoints, machine: Machine) -> None:
    """The path ``resample`` makes at the machine's sample time, under the smooth rules, its
    samples named by the file's lines (it keeps them by construction: this is the guard)."""
    dt = machine.sample_time_s
    path = resample(points, dt)
    lead = points.lead_s(dt)

    def line(k: int) -> str:
        when = k * dt - lead
        i = int(np.clip(np.searchsorted(points.t, when, side="right") - 1, 0,
                        len(points.t) - 1))
        near = (f"line {points.lines[i]}" if i == len(points.t) - 1 or when <= points.t[0]
                else f"lines {points.lines[i]}–{points.lines[i + 1]}")
        return f"{near} (t = {when:.3f} s in the file)"

    try:
        check_smooth(path, machine, dt, line)
    except MoveRefused as exc:
        raise PathFileError(f"{points.source}: {exc}") from None
