"""A move as planned, before it is sent: its path or duty profile, the approach in front of
it, and how its result is summarised afterwards, by its kind: a step's response, a smooth
path's tracking error, a sine's amplitude ratio and phase lag (``summaries``), for the
joints the move moved; the same metrics are saved with the run (``result_records``). A step's
response is judged with the settle after its path (where it came to rest), a path's
tracking on its own rows; the settle itself, when each joint came in position, is
``settle_rows``.

The thesis's ``move()`` first drove the robot to a move's start position; here a
path that begins away from where the joints are (beyond a joint's tolerance:
``acceptance.starts_here``) gets an approach ramp in front (``approached``),
at half of each joint's ``max_speed`` and ``max_accel``, which the result's
summary leaves out. The acceptance rules (``control.motion.acceptance.accept``,
which ``ControlClient.run`` applies to every plan) decide when one is needed
and hold it to the smooth rules, so a script and the TUI run, and summarise,
the same move.
"""

from __future__ import annotations

import contextlib
import itertools
import math
from collections.abc import Mapping
from dataclasses import asdict, dataclass, field, fields, replace
from typing import Any

import numpy as np

from control.motion import moves
from control.motion.acceptance import starts_here
from control.recorder import Run
from control.rt.commands import STEP_KINDS
from hw.machine import Machine

APPROACH_SPEED = 0.5  # approach ramps keep this fraction of each joint's max_speed, max_accel
APPROACH_MIN_S = 0.2
APPROACH_SETTLE_S = 0.5

Summary = moves.Summary


@dataclass(frozen=True)
class MovePlan:
    """What a run sends: a desired ``path (N, J)`` (follow_track) or a duty ``profile (N, J)``
    (tracking_actuate, open loop); neither for the rig's initialise."""

    kind: str
    title: str
    path: np.ndarray | None = None
    profile: np.ndarray | None = None
    meta: dict = field(default_factory=dict)
    approach: int = 0  # samples of the approach ramp at the start of ``path``
    moving: tuple[int, ...] = ()  # the joints the move means to move (summarised first)
    note: str = ""

    @classmethod
    def of_path(cls, path: np.ndarray, kind: str = "path", meta: dict | None = None
                ) -> MovePlan:
        """A plan for a bare path: titled by its kind, moving the joints whose desired moves."""
        return cls(kind, kind, path=path, meta=dict(meta or {}), moving=moving_joints(path))

    @property
    def samples(self) -> int:
        data = self.path if self.path is not None else self.profile
        return 0 if data is None else len(data)

    def approached(self, current: np.ndarray, machine: Machine, dt: float) -> MovePlan:
        """This plan with an approach ramp from ``current`` in front of its path, when its first
        row is farther than a joint's tolerance from where the joint is; else itself."""
        if self.path is None:
            return self
        ramp = approach_ramp(np.asarray(current, dtype=float), self.path[0], machine, dt)
        if not len(ramp):
            return self
        return replace(self, path=np.concatenate([ramp, self.path]),
                       approach=self.approach + len(ramp))


def approach_ramp(current: np.ndarray, start: np.ndarray, machine: Machine,
                  dt: float) -> np.ndarray:
    """``(M, J)`` from ``current`` to ``start`` within ``APPROACH_SPEED`` of every joint's
    max_speed and max_accel and a short settle, or ``(0, J)`` when every joint is already
    within its tolerance of the start. A joint resting just past a limit starts on it."""
    if starts_here(current, start, machine):
        return np.zeros((0, machine.n_joints))
    here = np.clip(current, machine.lower, machine.upper)
    ramp_time = max(APPROACH_MIN_S, moves.min_ramp_time(here, start, machine, APPROACH_SPEED))
    return moves.ramp(here, start, ramp_time, ramp_time + APPROACH_SETTLE_S, dt=dt,
                      machine=machine, fraction=APPROACH_SPEED)


def moving_joints(path: np.ndarray) -> tuple[int, ...]:
    """The joints whose desired position changes along ``path`` (none for an array that is
    not a path: the acceptance rules refuse it with the reason)."""
    if path.ndim != 2 or len(path) == 0:
        return ()
    with np.errstate(invalid="ignore"):  # inf − inf: a path the rules refuse
        return tuple(int(j) for j in np.flatnonzero(np.ptp(path, axis=0) > 0))


def summaries(plan: MovePlan, run: Run, machine: Machine) -> list[tuple[str, Summary]]:
    """``(label, summary)`` per joint the move moved, the approach left out, by the plan's
    kind: a step's response (step, multi-step), a sine's fundamentals (sine, at the period
    in its meta), else the tracking error of a smooth path. A joint moved when its desired
    position spans more than its ``tolerance`` (the settle band: a smaller step has no
    response to judge). A rig sequence (function.c MultiStep, ``steps`` in its meta) gets
    one row per step."""
    first = min(plan.approach, max(0, run.samples - 1))
    if run.samples - first < 2 or plan.path is None:
        return []
    joints = machine.joints
    t, desired, actual = run.t[first:], run.desired[first:], run.actual[first:]
    if "steps" in plan.meta:
        return _sequence(t, desired, actual, machine)
    if plan.kind in STEP_KINDS:  # the settle too: the response's end, where it came to rest
        rows: list[Summary] = list(moves.summary(t, desired, actual, joints))
    else:  # how the path was tracked: its own rows, not the hold of its end
        end = path_rows(run) - first
        t, desired, actual = t[:end], desired[:end], actual[:end]
        rows = (list(moves.sine_summary(t, desired, actual, joints, plan.meta.get("period")))
                if plan.kind == "sine" else list(moves.tracking_summary(t, desired, actual,
                                                                        joints)))
    return [(rows[j].joint, rows[j]) for j in moved(plan, desired, machine)]


def path_rows(run: Run) -> int:
    """The rows of ``run`` that followed its path (its ``path_samples``, as its move
    segment said), the settle's after them; all of them for a run saved without it."""
    rows = run.meta.get("path_samples")
    return min(rows, run.samples) if isinstance(rows, int) else run.samples


def moved(plan: MovePlan, desired: np.ndarray, machine: Machine) -> list[int]:
    """The joints whose ``desired (N, J)`` spans more than their tolerance, the plan's
    ``moving`` first."""
    span = np.ptp(desired, axis=0)  # NaN (no desired) is not a move
    order = [*plan.moving, *(j for j in range(machine.n_joints) if j not in plan.moving)]
    return [j for j in order if span[j] > machine.joints[j].tolerance]


def _sequence(t: np.ndarray, desired: np.ndarray, actual: np.ndarray, machine: Machine
              ) -> list[tuple[str, Summary]]:
    """Each step of a rig sequence as a step response of its own."""
    d = desired[:, 0]
    starts = [0, *(np.flatnonzero(np.diff(d) != 0) + 1).tolist(), len(d)]
    rows: list[tuple[str, Summary]] = []
    tolerance = machine.joints[0].tolerance
    for a, b in itertools.pairwise(starts):
        a0 = max(0, a - 1)  # one sample before the change: the step's start
        s = moves.summary(t[a0:b], desired[a0:b], actual[a0:b], machine.joints)[0]
        if abs(s.step) > tolerance:
            rows.append((f"{s.joint} step {len(rows) + 1}", s))
    return rows


SETTLE_COLUMNS = ("joint", "in position", "error at end")


def settle_rows(settle: Mapping[str, Any], machine: Machine) -> list[tuple[str, str, str]]:
    """A move's settle after its path (``MoveResult.settle``, the run's ``settle``) per joint:
    when it came in position, s after the path's end ("not in position" when it never did
    within goal_time), and its error from the goal when the move ended; none for a move
    that had no settle (open loop, or ended on its path)."""
    times, errors = settle.get("settle_s") or (), settle.get("goal_error") or ()
    if len(times) != machine.n_joints or len(errors) != machine.n_joints:
        return []
    return [(j.name, "not in position" if t is None else f"{t:.3f} s",
             f"{e:+.3f}{j.symbol}") for j, t, e in zip(machine.joints, times, errors,
                                                        strict=True)]


def settle_cell(label: str, settle: Mapping[str, Any], machine: Machine) -> str:
    """The "in position" cell of a result row (labelled by its joint's name)."""
    for name, when, _ in settle_rows(settle, machine):
        if label == name or label.startswith(name + " "):
            return when
    return "–"


def result_records(rows: list[tuple[str, Summary]]) -> list[dict[str, Any]]:
    """The summaries as JSON records, for a run's metadata: ``label``, ``metric`` (step,
    tracking or sine) and every field of the summary; a number that is not finite is null."""
    return [{"label": label, "metric": s.METRIC,
             **{k: _finite(v) for k, v in asdict(s).items()}} for label, s in rows]


def _finite(value: object) -> object:
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, tuple):
        return list(value)
    return value


def from_records(records: list[dict[str, Any]]) -> list[tuple[str, Summary]]:
    """``result_records`` read back (a null is NaN, or None where the field may be None);
    KeyError, TypeError or ValueError for a record that is not one."""
    rows: list[tuple[str, Summary]] = []
    for record in records:
        kind = _SUMMARY_KINDS[record["metric"]]
        values = {f.name: _read(record[f.name], str(f.type)) for f in fields(kind)}
        rows.append((str(record["label"]), kind(**values)))
    return rows


_SUMMARY_KINDS: dict[str, type[Summary]] = {
    k.METRIC: k for k in (moves.StepSummary, moves.TrackingSummary, moves.SineSummary)}


def _read(value: object, annotation: str) -> object:
    if value is None and annotation == "float":
        return math.nan
    return tuple(value) if isinstance(value, list) else value


def run_summaries(run: Run, machine: Machine) -> list[tuple[str, Summary]]:
    """The results of a saved run: those saved with it when the move ended (``results`` in
    its metadata, from the samples before they were rounded to be written), else
    ``summaries`` from its samples and what its metadata says of its plan (the approach in
    front, the joints it meant to move; ``ControlClient`` records them); none for an
    open-loop run, which follows no path."""
    meta = run.meta
    if meta.get("open_loop"):
        return []
    if "results" in meta:
        with contextlib.suppress(KeyError, TypeError, ValueError):  # damaged: from the samples
            return from_records(meta["results"])
    moving = meta.get("moving")
    plan = MovePlan(run.kind, run.kind, path=run.desired, meta=dict(meta),
                    approach=int(meta.get("approach_samples", 0)),
                    moving=tuple(moving) if moving is not None else moving_joints(run.desired))
    return summaries(plan, run, machine)
