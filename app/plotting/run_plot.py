"""Plotext drawings of runs and paths: the thesis's ``plotsix.m`` and ``plotdata.m`` in a
terminal, and the preview of a desired path. Every series is decimated to a min/max
envelope of about two points per column first, which keeps plotext fast (it costs
120–160 ms a frame for six joints × 2,000 raw points, 45–65 ms decimated).

The functions draw on a ``textual_plotext`` ``Plot`` (a plotext figure), so the
same drawing appears in a widget and is exported to a file.
"""

from __future__ import annotations

import io
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np
from rich.console import Console
from rich.text import Text
from textual_plotext.plot import Plot

from control.recorder import Run

DESIRED_COLOR = "red"  # plotsix.m: desired 'r-'
ACTUAL_COLOR = "blue+"  # plotsix.m: actual 'b'
DUTY_COLOR = "green+"
ERROR_COLOR = "magenta+"
VELOCITY_COLOR = "cyan+"
SMOOTH_S = 0.02  # velocity estimate: moving average over 20 ms before differencing


def decimate(t: np.ndarray, y: np.ndarray, points: int) -> tuple[np.ndarray, np.ndarray]:
    """At most ``points`` samples of ``y(t)`` keeping each bucket's min and max (peaks stay)."""
    n = len(t)
    buckets = max(1, points // 2)
    if n <= points:
        return t, y
    size = n // buckets
    cut = size * buckets
    tb = t[:cut].reshape(buckets, size)
    yb = y[:cut].reshape(buckets, size)
    finite = np.isfinite(yb)
    lo_i = np.argmin(np.where(finite, yb, np.inf), axis=1)
    hi_i = np.argmax(np.where(finite, yb, -np.inf), axis=1)
    first = np.minimum(lo_i, hi_i)
    second = np.maximum(lo_i, hi_i)
    rows = np.arange(buckets)
    tt = np.stack([tb[rows, first], tb[rows, second]], axis=1).ravel()
    yy = np.stack([yb[rows, first], yb[rows, second]], axis=1).ravel()
    return tt, yy


def velocity(t: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Estimated velocity (units/s): ``q`` smoothed over ``SMOOTH_S``, then differentiated."""
    if len(t) < 3:
        return np.zeros_like(q)
    dt = float(np.median(np.diff(t)))
    width = max(1, round(SMOOTH_S / dt))
    kernel = np.ones(width) / width
    padded = np.pad(q, (width // 2, width - 1 - width // 2), mode="edge")
    smooth = np.convolve(padded, kernel, mode="valid")
    return np.gradient(smooth, t)


def steady_velocity(t: np.ndarray, q: np.ndarray) -> float:
    """plotdata.m: (actual(end) − actual(mid)) / (time(end) − time(mid)), over the second half."""
    if len(t) < 2:
        return 0.0
    mid = int(np.ceil(len(t) / 2)) - 1
    span = t[-1] - t[mid]
    return float((q[-1] - q[mid]) / span) if span > 0 else 0.0


def _line(sub: object, t: np.ndarray, y: np.ndarray, points: int, **style: object) -> None:
    tt, yy = decimate(t, y, points)
    keep = np.isfinite(yy)
    if keep.any():
        sub.plot(tt[keep].tolist(), yy[keep].tolist(), marker="braille", **style)  # type: ignore[attr-defined]


def draw_overview(plt: Plot, run: Run, joints: Sequence[int], width: int) -> None:
    """plotsix.m: for each joint, desired and actual position beside its duty."""
    plt.clear_figure()
    rows = max(1, len(joints))
    plt.subplots(rows, 2)
    points = max(40, width)  # about two points per column of a half-width subplot
    for r, j in enumerate(joints, start=1):
        name, unit = run.joint_names[j], run.joint_units[j]
        left = plt.subplot(r, 1)
        _line(left, run.t, run.desired[:, j], points, color=DESIRED_COLOR, label="desired")
        _line(left, run.t, run.actual[:, j], points, color=ACTUAL_COLOR, label="actual")
        left.title(f"{name} ({unit})")
        right = plt.subplot(r, 2)
        _line(right, run.t, run.duty[:, j], points, color=DUTY_COLOR)
        right.title(f"{name} duty (%)")
        if r == rows:
            left.xlabel("time (s)")
            right.xlabel("time (s)")


def draw_joint(plt: Plot, run: Run, j: int, width: int) -> None:
    """plotdata.m for one joint: error, desired vs actual, duty, and the estimated velocity."""
    plt.clear_figure()
    plt.subplots(2, 2)
    points = max(40, width)
    name, unit = run.joint_names[j], run.joint_units[j]
    t, d, q, u = run.t, run.desired[:, j], run.actual[:, j], run.duty[:, j]
    position = plt.subplot(1, 1)
    _line(position, t, d, points, color=DESIRED_COLOR, label="desired")
    _line(position, t, q, points, color=ACTUAL_COLOR, label="actual")
    position.title(f"{name}: output/response ({unit})")
    error = plt.subplot(1, 2)
    _line(error, t, d - q, points, color=ERROR_COLOR)
    error.hline(0.0, "red")
    error.title(f"{name}: error, desired − actual ({unit})")
    duty = plt.subplot(2, 1)
    _line(duty, t, u, points, color=DUTY_COLOR)
    duty.title(f"{name}: duty (%)")
    duty.xlabel("time (s)")
    speed = plt.subplot(2, 2)
    _line(speed, t, velocity(t, q), points, color=VELOCITY_COLOR)
    speed.title(f"{name}: velocity ({unit}/s), second half {steady_velocity(t, q):+.4g}")
    speed.xlabel("time (s)")


def draw_path(plt: Plot, t: np.ndarray, path: np.ndarray, names: Sequence[str],
              units: Sequence[str], joints: Sequence[int], width: int, title: str) -> None:
    """The desired path of the joints that move, one subplot each."""
    plt.clear_figure()
    shown = list(joints) or [0]
    plt.subplots(len(shown), 1)
    for r, j in enumerate(shown, start=1):
        sub = plt.subplot(r, 1)
        _line(sub, t, path[:, j], 2 * width, color=DESIRED_COLOR)
        sub.title(f"{title} · {names[j]} ({units[j]})" if r == 1 else f"{names[j]} ({units[j]})")
        if r == len(shown):
            sub.xlabel("time (s)")


def views(run: Run) -> list[str]:
    """The plots of ``run`` the Runs tab cycles through: ``plotsix`` of each group of three
    joints (none on a one-joint machine), then ``plotdata`` of each joint."""
    n = len(run.joint_names)
    groups = [f"plotsix {a + 1}–{min(n, a + 3)}" for a in range(0, n, 3)] if n > 1 else []
    return groups + [f"plotdata {name}" for name in run.joint_names]


def view_slug(view: str) -> str:
    """``view`` as a part of a file name: ``plotsix-1-3``, ``plotdata-UpDown``."""
    return view.replace(" ", "-").replace("–", "-").replace("/", "")


def draw_view(plt: Plot, run: Run, view: str, width: int) -> None:
    """Draw one of ``views(run)`` at ``width`` columns."""
    if view.startswith("plotsix"):
        first = int(view.split(" ")[1].split("–")[0]) - 1
        draw_overview(plt, run, list(range(first, min(len(run.joint_names), first + 3))),
                      max(20, width // 2))
    else:
        draw_joint(plt, run, run.joint_names.index(view.split(" ", 1)[1]), max(20, width // 2))


def export(path: Path, draw: Callable[[Plot, int], None], width: int = 160,
           height: int = 48, formats: Sequence[str] = ("txt", "svg")) -> list[Path]:
    """Draw at ``width × height`` and write ``path.txt`` (plain) and ``path.svg`` (colour),
    or those of ``formats``."""
    plt = Plot()
    draw(plt, width)
    plt.plotsize(width, height)
    plt.theme("pro")
    built = plt.build()
    path.parent.mkdir(parents=True, exist_ok=True)
    written = []
    if "txt" in formats:
        written.append(path.with_suffix(".txt"))
        written[-1].write_text(plt.uncolorize(built) + "\n", encoding="utf-8")
    if "svg" in formats:
        console = Console(record=True, width=width, file=io.StringIO())
        console.print(Text.from_ansi(built))
        written.append(path.with_suffix(".svg"))
        written[-1].write_text(console.export_svg(title=path.stem), encoding="utf-8")
    return written
