"""What the arm's view (``app/widgets/arm_view.py``) costs while the arm moves, beside the
Scope's drawing as a peer. Prints figures, asserts nothing.

1. the drawing alone: a frame as the view makes it (the cached background copied, the ghost
   and the arm drawn, the changed rows turned into Strips) with the pose changing every
   frame as a jog does, full screen at 160 × 48 and 80 × 24; frames a second flat out, CPU
   ms a frame, and what 20 frames a second would take of one core. The peer: the Scope
   tab's twelve braille plots (six joints, position and duty, 2 × 2,000 points each), a frame;
2. headless Textual (the test driver): the view alone in an app, its source giving a new
   pose at every poll, for ``--seconds``; frames drawn a second and the process's CPU
   (Textual's compositor and driver included). The peer: a ScopePlot in the same app fed
   the Scope's data, shifted, at the view's poll rate;
3. the TUI headless (Textual's test driver, 160 × 48, a real-time controller): Up/Down
   position-jogged by a key every 30 ms as a terminal's repeat delivers it, for ``--seconds``
   with the Jog tab as it was and with the arm's view switched in (``p``): the view's frames
   a second and the UI process's CPU (the controller is another process);
4. live (``--tmux``): ``python -m app`` in a 160 × 48 tmux window (in reduced speed, as it
   starts), Up/Down jogged up and down in position mode (0.2° a press) by a key repeated every
   30 ms, the app's CPU (/proc) over the
   jogging with the Jog tab as it was and with the arm's view switched in (``p``), and the
   full screen (^A) while it jogs.

Run: ``python benchmarks/arm_view.py [--seconds 5] [--tmux]``
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import os
import shlex
import shutil
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np
from rich.style import Style
from rich.text import Text
from textual.app import App, ComposeResult

from app.plotting.arm_scene import ArmScene, Marker, Plan, tool_trace
from app.plotting.braille import Trace, render
from app.plotting.dot_canvas import DotCanvas
from app.plotting.projection import VIEWS, Projection
from app.widgets.arm_view import POLL_HZ, ArmView
from app.widgets.scope import ScopePlot
from control.motion.robot_model import builtin_unimate
from control.rt.layout import Flag, Mode, Status
from hw.machine import load_machine

ROOT = Path(__file__).resolve().parents[1]
MACHINE = load_machine("unimate2000b")
MODEL = builtin_unimate()
HOME = np.array(MACHINE.home)
SIZES = ((160, 48), (80, 24))
TARGET_FPS = 20.0
POINTS = 2_000
PANEL = (70, 8, 3)  # columns, position rows, duty rows of one Scope joint at 160 × 48
KEY_GAP_S = 0.03  # a terminal's key repeat
SWING_S = 1.5  # each way of the jog


def jog(k: int) -> np.ndarray:
    """The pose of frame ``k`` of a jog: In/Out and Rotate swinging, the wrist turning."""
    s = np.sin(k / 40.0)
    return HOME + np.array([300.0 * s, 40.0 * s, 5.0 * s, 20.0 * s, -30.0 * s, 90.0 * s])


def cpu_and_wall(fn: Callable[..., object], *args: object) -> tuple[float, float]:
    cpu, wall = time.process_time(), time.perf_counter()
    fn(*args)
    return time.process_time() - cpu, time.perf_counter() - wall


def frames_of(scene: ArmScene, projection: Projection, background: DotCanvas,
              frames: int) -> None:
    """``frames`` frames as the view draws them: the ghost and the arm over the background,
    the rows that changed made Strips."""
    drawn = None
    for k in range(frames):
        canvas = background.copy()
        scene.arm(canvas, projection, jog(k - 5), ghost=True)
        scene.arm(canvas, projection, jog(k))
        drawn = canvas.strips(drawn)


def drawing_alone(frames: int) -> None:
    print(f"1. drawing alone, the pose changing every frame ({frames} frames), isometric, "
          "the ghost, a previewed path and two markers")
    plan = Plan(tool_trace(MODEL, np.linspace(HOME, jog(60), 3000)), "joint",
                (Marker("home", (1500.0, 0.0, 747.0)), Marker("park", (1200.0, 0.0, 700.0))))
    scene = ArmScene(MODEL)
    for cols, rows in SIZES:
        rows -= 2  # the caption and the key bar
        projection = scene.projection(VIEWS["isometric"], cols, rows)
        background = scene.background(projection, cols, rows, plan, cols < 60 or rows < 16)
        cpu, wall = cpu_and_wall(frames_of, scene, projection, background, frames)
        ms = 1e3 * cpu / frames
        print(f"   {cols}×{rows + 2}: {frames / wall:6.0f} frames/s flat out, {ms:.2f} ms CPU "
              f"a frame: {ms * TARGET_FPS / 10:.1f} % of a core at {TARGET_FPS:g} frames/s")
    t = np.linspace(0.0, 10.0, POINTS)
    q = np.sin(t[:, None] + np.arange(6))
    red, cyan, yellow = Style(color="red"), Style(color="cyan"), Style(color="yellow")
    cols, rows, duty_rows = PANEL

    def scope() -> None:
        for k in range(frames // 10):
            for j in range(6):
                render([Trace(t, q[:, j] + k * 1e-3, red), Trace(t, q[:, j], cyan)],
                       (0, 10), (-2, 2), cols, rows)
                render([Trace(t, q[:, j], yellow)], (0, 10), (-2, 2), cols, duty_rows,
                       guide_y=0.0)

    cpu, wall = cpu_and_wall(scope)
    ms = 1e3 * cpu / (frames // 10)
    print(f"   peer, the Scope tab's 12 braille plots (6 × 3 × {POINTS} points): "
          f"{(frames // 10) / wall:6.0f} frames/s flat out, {ms:.2f} ms CPU a frame: "
          f"{ms * TARGET_FPS / 10:.1f} % of a core at {TARGET_FPS:g} frames/s")


def status_at(q: np.ndarray, desired: np.ndarray) -> Status:
    zeros = (0.0,) * 6
    return Status(tick=1, time_s=0.0, wall_ns=0, mode=Mode.HOLD, flags=Flag(0), move_id=0,
                  move_done=0, move_total=0, late_last_us=0.0, late_max_us=0.0, overruns=0,
                  compute_last_us=0.0, compute_max_us=0.0, compute_total_s=0.0,
                  io_total_s=0.0, feed_override=1.0, feed_rate=1.0, supply_mpa=float("nan"),
                  position=tuple(q), desired=tuple(desired), duty=zeros, valve=zeros,
                  settle_s=zeros, raw=(0,) * 6, glitches=(0,) * 6, link={}, fault="")


class Jogged:
    """A status source whose pose moves at every call, as a jog's does."""

    def __init__(self) -> None:
        self.k = 0

    def __call__(self) -> Status:
        self.k += 1
        return status_at(jog(self.k), jog(self.k + 5))


class ViewApp(App[None]):
    def __init__(self, scope: bool) -> None:
        super().__init__()
        self.scope = scope

    def compose(self) -> ComposeResult:
        if self.scope:
            yield ScopePlot()
        else:
            yield ArmView(MACHINE, MODEL, Jogged(), id="view")


async def headless(seconds: float, size: tuple[int, int], scope: bool) -> tuple[float, float]:
    """Frames a second and % of a core of the view (or the Scope plot) in a headless app."""
    app = ViewApp(scope)
    t = np.linspace(0.0, 10.0, POINTS)
    style = Style(color="cyan")
    async with app.run_test(size=size) as pilot:
        await pilot.pause(0.5)
        if scope:
            plot = app.query_one(ScopePlot)
            frames = 0

            def feed() -> None:
                nonlocal frames
                frames += 1
                plot.plot([Trace(t, np.sin(t * (j + 1) + frames * 0.05) + j, style)
                           for j in range(6)], (0.0, 10.0), (-1.0, 7.0), Text("scope"))

            app.set_interval(1.0 / POLL_HZ, feed)
            count: Callable[[], int] = lambda: frames  # noqa: E731
        else:
            view = app.query_one(ArmView)
            count = lambda: view.draws  # noqa: E731
        start, cpu, wall = count(), time.process_time(), time.perf_counter()
        await asyncio.sleep(seconds)
        drawn = count() - start
        return drawn / (time.perf_counter() - wall), 100 * (time.process_time() - cpu) / (
            time.perf_counter() - wall)


def headless_figures(seconds: float) -> None:
    print(f"\n2. headless Textual app, {seconds:g} s each, a new pose at every poll "
          f"({POLL_HZ:g} a second)")
    for size in SIZES:
        fps, core = asyncio.run(headless(seconds, size, scope=False))
        print(f"   arm view {size[0]}×{size[1]}: {fps:.1f} frames/s, {core:.1f} % of a core "
              "(the whole app process)")
    fps, core = asyncio.run(headless(seconds, SIZES[0], scope=True))
    print(f"   peer, a ScopePlot of six 2,000-point traces {SIZES[0][0]}×{SIZES[0][1]} fed "
          f"at the same rate: {fps:.1f} frames/s, {core:.1f} % of a core")


class Tmux:
    """``python -m app`` in a 160 × 48 window of its own tmux server."""

    def __init__(self, data_dir: str) -> None:
        self.tmux = [shutil.which("tmux") or "tmux", "-L", f"arm-bench-{os.getpid()}",
                     "-f", os.devnull]
        command = (f"cd {shlex.quote(str(ROOT))} && exec {shlex.quote(sys.executable)} -m app "
                   f"--data-dir {shlex.quote(data_dir)}")
        subprocess.run([*self.tmux, "new-session", "-d", "-s", "arm", "-x", "160", "-y", "48",
                        command], check=True)
        self.pid = int(subprocess.run([*self.tmux, "display", "-p", "-t", "arm",
                                       "#{pane_pid}"], capture_output=True, text=True,
                                      check=True).stdout)

    def screen(self) -> str:
        return subprocess.run([*self.tmux, "capture-pane", "-p", "-t", "arm"],
                              capture_output=True, text=True).stdout

    def wait_for(self, text: str, timeout: float = 30.0) -> None:
        deadline = time.monotonic() + timeout
        while text not in self.screen():
            if time.monotonic() > deadline:
                raise RuntimeError(f"{text!r} not on the screen:\n{self.screen()}")
            time.sleep(0.05)

    def keys(self, *keys: str) -> None:
        subprocess.run([*self.tmux, "send-keys", "-t", "arm", *keys], check=True)

    def cpu_s(self) -> float:
        fields = Path(f"/proc/{self.pid}/stat").read_text().rsplit(")", 1)[1].split()
        return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")

    def jogging_cpu(self, seconds: float) -> float:
        """% of a core the app used while Up/Down was jogged up and down."""
        stop = threading.Event()

        def hold() -> None:
            key, turned = "d", time.monotonic()
            while not stop.is_set():
                self.keys(key)
                if time.monotonic() - turned > SWING_S:
                    key, turned = ("c" if key == "d" else "d"), time.monotonic()
                time.sleep(KEY_GAP_S)

        holder = threading.Thread(target=hold, daemon=True)
        holder.start()
        time.sleep(1.0)  # under way
        cpu, wall = self.cpu_s(), time.monotonic()
        time.sleep(seconds)
        used = 100 * (self.cpu_s() - cpu) / (time.monotonic() - wall)
        stop.set()
        holder.join()
        time.sleep(0.5)
        return used

    def close(self) -> None:
        self.keys("C-q")
        deadline = time.monotonic() + 5
        while Path(f"/proc/{self.pid}").exists() and time.monotonic() < deadline:
            time.sleep(0.05)
        subprocess.run([*self.tmux, "kill-server"], capture_output=True)


async def tui_jogging(seconds: float, view: bool) -> tuple[float, float, float]:
    """Frames a second of the Jog tab's arm view and its polls a second (0 without it), and
    % of a core of the UI process, while Up/Down is position-jogged up and down."""
    from textual import events

    from app.tui import ServodeskApp

    with tempfile.TemporaryDirectory() as data_dir:
        app = ServodeskApp("unimate2000b", data_dir=data_dir)
        async with app.run_test(size=SIZES[0]) as pilot:
            deadline = time.monotonic() + 60
            while app.sampler is None or app.sampler.latest is None or app.focused is None:
                if time.monotonic() > deadline:
                    raise RuntimeError(f"the controller did not start: {app.client_problem}")
                await asyncio.sleep(0.05)
            await pilot.press("m", "m", "5", *(["p"] if view else []))
            await pilot.pause(1.0)
            views = app.query("#jog-arm")
            draws: Callable[[], tuple[int, int]] = (
                (lambda: (views.first(ArmView).draws, views.first(ArmView).polls)) if view
                else (lambda: (0, 0)))
            assert app._driver is not None
            start, cpu, wall = draws(), time.process_time(), time.perf_counter()
            key, turned = "d", wall
            while time.perf_counter() - wall < seconds:
                app._driver.send_message(events.Key(key, key))  # as a terminal's repeat comes
                if time.perf_counter() - turned > SWING_S:
                    key, turned = ("c" if key == "d" else "d"), time.perf_counter()
                await asyncio.sleep(KEY_GAP_S)
            elapsed = time.perf_counter() - wall
            end = draws()
            return ((end[0] - start[0]) / elapsed, (end[1] - start[1]) / elapsed,
                    100 * (time.process_time() - cpu) / elapsed)


def tui_figures(seconds: float) -> None:
    plain = asyncio.run(tui_jogging(seconds, view=False))[2]
    fps, polls, beside = asyncio.run(tui_jogging(seconds, view=True))
    print(f"\n3. the TUI headless 160×48, Up/Down position-jogged (a key every "
          f"{KEY_GAP_S * 1e3:.0f} ms) for {seconds:g} s: the arm's view drew {fps:.1f} "
          f"frames/s (it looked {polls:.1f} times a second; a look at an unmoved pose draws "
          f"nothing); the UI process used {plain:.1f} % of a core without the view, "
          f"{beside:.1f} % with it (the view's share {beside - plain:+.1f} %); load average "
          f"{os.getloadavg()[0]:.1f} on {os.cpu_count()} CPUs")


def tmux_figures(seconds: float) -> None:
    if shutil.which("tmux") is None:
        print("\n4. live in tmux: skipped (no tmux)")
        return
    with tempfile.TemporaryDirectory() as data_dir:
        app = Tmux(data_dir)
        try:
            app.wait_for("mode HOLD")
            app.wait_for("frame joint")
            app.keys("m", "m", "5")  # position jog, 0.2° a press (T1 refuses open-loop duty)
            app.wait_for("mode position")
            plain = app.jogging_cpu(seconds)
            app.keys("p")
            app.wait_for("isometric")
            before = app.screen()
            beside = app.jogging_cpu(seconds)
            moved = sum(a != b for a, b in zip(before.splitlines(), app.screen().splitlines(),
                                               strict=False))
            app.keys("C-a")
            app.wait_for("back to the tabs")
            app.keys("C-a")  # and straight back: the jog keys are the Jog tab's
            app.wait_for("frame joint")
        finally:
            with contextlib.suppress(Exception):
                app.close()
    print(f"\n4. live in tmux 160×48, Up/Down jogged (position jog, a key every "
          f"{KEY_GAP_S * 1e3:.0f} ms) for {seconds:g} s: the app used {plain:.1f} % of a core "
          f"on the Jog tab as it was, {beside:.1f} % with the arm's view switched in "
          f"(the view's share {beside - plain:+.1f} %; {moved} rows of the screen changed "
          f"over the jog); load average "
          f"{os.getloadavg()[0]:.1f} on {os.cpu_count()} CPUs")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=500)
    parser.add_argument("--seconds", type=float, default=5.0)
    parser.add_argument("--tmux", action="store_true", help="also the live app in tmux")
    args = parser.parse_args()
    drawing_alone(args.frames)
    headless_figures(args.seconds)
    tui_figures(args.seconds)
    if args.tmux:
        tmux_figures(args.seconds)


if __name__ == "__main__":
    main()
