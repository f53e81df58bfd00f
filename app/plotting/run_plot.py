"""Figures of runs and paths: the thesis's ``plotsix.m`` and ``plotdata.m``, and the preview
of a desired path, as ``Figure`` records (``app.plotting.figure``) that the terminal draws
(``app.plotting.strips``) and ``export`` writes as an SVG drawn from the same data
(``app.plotting.svg``).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from app.plotting.figure import (
    ACTUAL,
    APPROACH,
    DESIRED,
    DUTY,
    ERROR,
    ESTOP,
    FAULT,
    STALL,
    VELOCITY,
    Figure,
    Line,
    Mark,
    Panel,
)
from app.plotting.strips import figure_text
from app.plotting.svg import figure_svg
from control.recorder import Run

# The velocity: a running median outvotes a wrong reading (section 6.2) held up to one
# 6-joint scan without moving a step's edge; then the slope of a line fitted over SLOPE_S
# (Savitzky-Golay). Both are centred, so a step is not delayed, as a causal filter would.
MEDIAN_S = 0.015
SLOPE_S = 0.021
FLAT_COUNTS = 10  # a joint that holds still is drawn on at least this many encoder counts
DUTY_SPAN = 2.0  # % , the least span of a duty panel
STATUS_MARKS = {"estop": ("E-stop", ESTOP), "fault": ("fault", FAULT)}
JOINT_COLORS = ("#e8453c", "#3d8bfd", "#2fae5f", "#e0a526", "#c94fd6", "#16b3c9")


def velocity(t: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Estimated velocity (units/s) of ``q (N,)`` at ``t``: its running median over
    ``MEDIAN_S``, then at each sample the slope of the line fitted over ``SLOPE_S`` around
    it (the Savitzky-Golay first derivative)."""
    if len(t) < 3:
        return np.zeros_like(q)
    dt = float(np.median(np.diff(t)))
    return _slope(_running_median(q, _half(MEDIAN_S, dt, len(q))), dt,
                  _half(SLOPE_S, dt, len(q)))


def _half(window_s: float, dt: float, n: int) -> int:
    """Half a centred window of ``window_s`` in samples, within a record of ``n``."""
    return max(1, min(round(window_s / dt) // 2, (n - 1) // 2))


def _running_median(q: np.ndarray, half: int, chunk: int = 65_536) -> np.ndarray:
    """The median of each sample's ``2·half + 1`` neighbours (the ends repeated), in chunks
    so a 600 s run needs no more than a few MB."""
    padded = np.pad(q, half, mode="edge")
    windows = np.lib.stride_tricks.sliding_window_view(padded, 2 * half + 1)
    return np.concatenate([np.median(windows[a:a + chunk], axis=1)
                           for a in range(0, len(q), chunk)])


def _slope(q: np.ndarray, dt: float, half: int) -> np.ndarray:
    """Least-squares slope over ``2·half + 1`` samples centred on each; the first and last
    ``half`` take their nearest whole window's."""
    k = np.arange(-half, half + 1, dtype=float)
    return np.pad(np.correlate(q, k, mode="valid") / (dt * float(k @ k)), half, mode="edge")


def steady_velocity(t: np.ndarray, q: np.ndarray) -> float:
    """plotdata.m: (actual(end) − actual(mid)) / (time(end) − time(mid)), over the second half."""
    if len(t) < 2:
        return 0.0
    mid = int(np.ceil(len(t) / 2)) - 1
    span = t[-1] - t[mid]
    return float((q[-1] - q[mid]) / span) if span > 0 else 0.0


def marks(run: Run) -> tuple[Mark, ...]:
    """The moments to mark on a run's plots: the controller's stalls (its ``gaps``), and how
    it ended when that was the E-stop or a fault, at its last sample (nothing is recorded
    after either)."""
    found = [Mark(float(at), f"stall {length:.2f} s", STALL, "stall")
             for at, length in run.meta.get("gaps", ())]
    kind, _, why = run.status.partition(":")
    if kind in STATUS_MARKS and run.samples:
        name, color = STATUS_MARKS[kind]
        why = why.split(", with a ")[0].strip()  # the stall the status adds is marked above
        found.append(Mark(float(run.t[-1]), f"{name}: {why}" if why else name, color, kind))
    return tuple(found)


def least_span(run: Run, j: int) -> float:
    """The least y span of joint ``j``'s position: ``FLAT_COUNTS`` encoder counts (0: the
    panel's own, for a run that does not say its encoder)."""
    return FLAT_COUNTS * run.joint_resolution[j] if run.joint_resolution else 0.0


def overview(run: Run, joints: Sequence[int], title: str = "") -> Figure:
    """plotsix.m: for each joint, desired and actual position beside its duty."""
    panels = []
    moments = marks(run)
    for j in joints:
        name, unit = run.joint_names[j], run.joint_units[j]
        panels.append(Panel(name, (Line(run.t, run.desired[:, j], DESIRED, "desired"),
                                   Line(run.t, run.actual[:, j], ACTUAL, "actual")), unit,
                            floor=least_span(run, j), marks=moments))
        panels.append(Panel(f"{name} duty", (Line(run.t, run.duty[:, j], DUTY),), "%",
                            zero_line=True, floor=DUTY_SPAN, marks=moments))
    return Figure(title or f"{run.kind} run: position and duty", tuple(panels), columns=2)


def joint_figure(run: Run, j: int, title: str = "") -> Figure:
    """plotdata.m for one joint: response, error, duty and the estimated velocity."""
    name, unit = run.joint_names[j], run.joint_units[j]
    t, d, q, u = run.t, run.desired[:, j], run.actual[:, j], run.duty[:, j]
    least, moments = least_span(run, j), marks(run)
    panels = (
        Panel(f"{name} output/response", (Line(t, d, DESIRED, "desired"),
                                          Line(t, q, ACTUAL, "actual")), unit,
              floor=least, marks=moments),
        Panel(f"{name} error, desired − actual", (Line(t, d - q, ERROR),), unit,
              zero_line=True, floor=least, marks=moments),
        Panel(f"{name} duty", (Line(t, u, DUTY),), "%", zero_line=True, floor=DUTY_SPAN,
              marks=moments),
        Panel(f"{name} velocity, second half {steady_velocity(t, q):+.4g}",
              (Line(t, velocity(t, q), VELOCITY),), f"{unit}/s", zero_line=True,
              floor=least / 0.1, marks=moments),  # ten counts in 0.1 s
    )
    return Figure(title or f"{run.kind} run: {name}", panels, columns=2)


def path_figure(t: np.ndarray, path: np.ndarray, names: Sequence[str], units: Sequence[str],
                joints: Sequence[int], approach: int, title: str) -> Figure:
    """The desired path of the joints that move, one panel each; the approach ramp in front
    (its first ``approach`` samples) in grey."""
    panels = []
    for j in list(joints) or [0]:
        lines = [Line(t[approach:], path[approach:, j], DESIRED, "move" if approach else "")]
        if approach:
            lines.insert(0, Line(t[:approach + 1], path[:approach + 1, j], APPROACH,
                                 "approach"))
        panels.append(Panel(names[j], tuple(lines), units[j]))
    return Figure(title, tuple(panels))


def path_compact(t: np.ndarray, path: np.ndarray, names: Sequence[str],
                 joints: Sequence[int], approach: int, title: str) -> Figure:
    """Every moving joint in one panel, as % of its largest move from where it starts: the
    shape and timing of a path with more joints than the panels can hold."""
    lines = []
    for k, j in enumerate(list(joints) or [0]):
        change = path[:, j] - path[0, j]
        largest = float(np.max(np.abs(change)))
        share = 100.0 * change / largest if largest > 0 else change
        lines.append(Line(t, share, JOINT_COLORS[k % len(JOINT_COLORS)], names[j]))
    after = f", the approach the first {t[approach]:.2f} s" if approach else ""
    panel = Panel(f"% of each joint's largest move{after}", tuple(lines))
    return Figure(title, (panel,))


def views(run: Run, group: int = 3) -> list[str]:
    """The plots of ``run`` the Runs tab cycles through: ``plotsix`` of each ``group`` of
    joints (the thesis's three; none on a one-joint machine), then ``plotdata`` of each
    joint."""
    n = len(run.joint_names)
    groups = ([f"plotsix {a + 1}" + (f"–{min(n, a + group)}" if group > 1 else "")
               for a in range(0, n, group)] if n > 1 else [])
    return groups + [f"plotdata {name}" for name in run.joint_names]


def view_slug(view: str) -> str:
    """``view`` as a part of a file name: ``plotsix-1-3``, ``plotdata-UpDown``."""
    return view.replace(" ", "-").replace("–", "-").replace("/", "")


def view_figure(run: Run, view: str, title: str = "") -> Figure:
    """The figure of one of ``views(run)``, titled ``title · view`` (or by the run)."""
    heading = f"{title} · {view}" if title else ""
    if view.startswith("plotsix"):
        joints = [int(k) for k in view.split(" ")[1].split("–")]
        return overview(run, range(joints[0] - 1, joints[-1]), heading)
    return joint_figure(run, run.joint_names.index(view.split(" ", 1)[1]), heading)


def export(path: Path, figure: Figure, formats: Sequence[str] = ("svg",)) -> list[Path]:
    """Write the figure drawn from its data as ``path.svg`` and, if asked, ``path.txt`` (the
    terminal's braille drawing at 160 × 48, plain text); the files written."""
    path.parent.mkdir(parents=True, exist_ok=True)
    written = []
    if "txt" in formats:
        written.append(path.with_suffix(".txt"))
        written[-1].write_text(figure_text(figure), encoding="utf-8")
    if "svg" in formats:
        written.append(path.with_suffix(".svg"))
        written[-1].write_text(figure_svg(figure), encoding="utf-8")
    return written
