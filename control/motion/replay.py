"""A saved run played again: its desired path, at its own timing, as the move it was.

A run (``control/recorder.py``) recorded one desired row per sample, so it plays on its
sample grid: row k at k·Δt, Δt its JSON's sample time (the machine's). Its CSV's time
column is when each sample was taken, jitter and all; followed as a path file's times its
second differences read as accelerations far past max_accel, so the replay never uses it.
Only the rows of its path are played (``path_samples``: the settle after them is the
controller's own); the first gets the approach any path gets when the arm is elsewhere
(``MovePlan.approached``), and the rows are held to the rules of the move's kind
(``control.motion.acceptance``), so the replay plays what the run was:

- a **smooth** kind (ramp, sine, go to, end point, via points, Cartesian paths and jogs,
  path) plays as a ``path``: every max_speed and max_accel kept. Its desired positions
  are saved to the decimals at which rounding adds at most 0.2 % of max_accel to a
  second difference, well inside the rules' 1 %;
- a **step** kind (step, multi-step, the rig's sequence) plays as that kind: it jumps as
  it did;
- a **duty** kind (the identification's PRBS, ``tracking_actuate``; a pulse,
  ``set_pulse``) and the rig's initialise are refused: they drove the valves open loop and
  have no desired path (their desired column is empty), and their duty played from where
  the arm is now would be another experiment, not this one again.

A saved run is named by any of its files or its stem (``RunFiles.from_json``); its JSON
says its machine, kind, sample time and path rows. A table copied without its JSON still
plays, as a ``path`` on the machine's sample grid: its CSV by its ``desired`` columns
(``path_files.parse_csv``), its TSV by the thesis's SaveData layout, sample then desired,
actual and duty of each joint (``parse_tsv``).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from control.motion.acceptance import MAX_MOVE_S, MoveRefused, check_path
from control.recorder import RecorderError, Run, RunFiles, load_run
from control.rt.commands import SMOOTH_KINDS, STEP_KINDS
from hw.machine import Machine

TABLE_SUFFIXES = (".csv", ".csv.gz", ".tsv", ".tsv.gz")


@dataclass(frozen=True)
class RunPath:
    """A saved run's desired path to play: ``q (N, J)`` mm/deg, one row per sample of
    ``dt`` s, the move ``kind`` it plays as, ``title`` what it is ("the ramp run
    20261125-…"), and each row's line in its table (none for rows read through a JSON)."""

    source: str
    q: np.ndarray
    dt: float
    kind: str
    title: str
    table_lines: tuple[int, ...] = ()

    def lines(self) -> tuple[int, ...]:
        """Each row's line in its table, or its sample number (through a JSON)."""
        return self.table_lines or tuple(range(len(self.q)))


def saved_run(path: str | Path) -> Path | None:
    """The JSON of the saved run ``path`` names: the JSON itself, the stem (no file of that
    name, its JSON beside), or one of its tables with its JSON beside; None for any other
    file, which is read as a path file."""
    path = Path(path).expanduser()
    name = path.name.lower()
    if name.endswith(".json"):
        return path
    json = RunFiles.from_json(path).json
    if name.endswith(TABLE_SUFFIXES) or not path.exists():
        return json if json.is_file() else None
    return None


def read_run(json: Path, machine: Machine, error: type[ValueError], *,
             named: str | None = None) -> RunPath:
    """The desired path of the run saved as ``json``, to play on ``machine``; ``error`` (a
    message naming the run and the fix) if it is not a run of this machine or has no
    desired path to play. ``named`` is how the operator named it (a table, the stem)."""
    source = named or str(json)
    try:
        run = load_run(json)
    except RecorderError as exc:  # it names the run's file
        raise error(str(exc) if source == str(json) else f"{source}: {exc}") from None
    _check_machine(run, machine, source, error)
    title = f"the {run.kind} run {RunFiles.from_json(json).stem}"
    if run.kind in STEP_KINDS:
        kind = run.kind
    elif run.kind in SMOOTH_KINDS:
        kind = "path"
    else:
        raise error(f"{source}: {title} has no desired path to play: a {run.kind} move drives "
                    f"the valves open loop, and its duty played from where the arm is now "
                    f"would be another experiment, not this one again; {_again(run.kind)}")
    rows = _path_rows(run)
    if not rows:
        raise error(f"{source}: {title} recorded no sample of its path ({run.status}): "
                    "nothing to play")
    played = RunPath(source, run.desired[:rows], run.sample_time_s, kind, title)
    status = "" if run.status in ("complete", "unsettled") else f" (it ended {run.status})"
    check(played, machine, error, f"{source}: {title}{status}: ")
    return played


def table_run(source: str, q: np.ndarray, machine: Machine, lines: tuple[int, ...],
              error: type[ValueError]) -> RunPath:
    """A saved run's table without its JSON: its desired columns ``q (N, J)`` played as a
    ``path`` on ``machine``'s sample grid, row k from line ``lines[k]``."""
    played = RunPath(source, q, machine.sample_time_s, "path", "a saved run's table",
                     tuple(lines))
    check(played, machine, error, f"{source}: a saved run's table, played as a path on the "
                                  f"{machine.sample_time_s * 1e3:g} ms sample grid: ")
    return played


def check(played: RunPath, machine: Machine, error: type[ValueError], prefix: str) -> None:
    """The rules of ``played.kind`` on its rows at its sample time; ``error`` with
    ``prefix``, the row at fault (its line or its sample) and the fix if they refuse."""
    dt = played.dt
    if len(played.q) and (len(played.q) - 1) * dt > MAX_MOVE_S:
        raise error(f"{prefix}its path lasts {(len(played.q) - 1) * dt:g} s; a move lasts at "
                    f"most {MAX_MOVE_S:g} s")
    try:
        check_path(np.asarray(played.q, dtype=np.float64), played.kind, machine, dt,
                   where=_row_names(played))
    except MoveRefused as exc:
        hint = ("" if not played.table_lines or played.kind != "path" else
                "; a step run's table plays as its kind beside its JSON: give the run's .json")
        raise error(f"{prefix}{exc}{hint}") from None


def _row_names(played: RunPath) -> Callable[[int], str]:
    def name(k: int) -> str:
        at = f"t = {k * played.dt:.3f} s of the run"
        return (f"line {played.table_lines[k]} ({at})" if played.table_lines
                else f"sample {k} ({at})")
    return name


def _check_machine(run: Run, machine: Machine, source: str, error: type[ValueError]) -> None:
    if run.machine != machine.name:
        raise error(f"{source}: a run of {run.machine}, not of {machine.name}: play it on "
                    f"its machine (--machine {run.machine})")
    names = tuple(j.name for j in machine.joints)
    if run.joint_names != names:
        raise error(f"{source}: its joints {', '.join(run.joint_names)} are not "
                    f"{machine.name}'s ({', '.join(names)}): the machine file changed since it "
                    "was saved")
    if not np.isclose(run.sample_time_s, machine.sample_time_s, rtol=1e-9, atol=0.0):
        raise error(f"{source}: recorded at {run.sample_time_s * 1e3:g} ms a sample; "
                    f"{machine.name} samples every {machine.sample_time_s * 1e3:g} ms: a run "
                    "plays at its own timing, on a machine file with its sample time")


def _path_rows(run: Run) -> int:
    """The rows of ``run`` that followed its path (its settle's follow them)."""
    rows = run.meta.get("path_samples")
    return min(int(rows), run.samples) if isinstance(rows, int) and rows > 0 else run.samples


def _again(kind: str) -> str:
    if kind == "tracking_actuate":
        return "run the identification again (Identify tab)"
    if kind == "set_pulse":
        return "run the pulse again (servodesk move pulse, or the Moves tab)"
    return f"run the {kind} again from its own form"
