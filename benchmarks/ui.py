"""The TUI's figures: Scope frame time with six joints × 2,000 points, key response while
the Scope draws, the controller's lateness with and without it, and key-press to
duty-at-the-controller latency.

Run: ``python benchmarks/ui.py`` (``--quick`` for fewer repeats). The
app runs headless (Textual's test driver, 160 × 48) against a real-time simulated
Unimate 2000B. Parts:

1. renderers alone, the Scope tab's twelve plots (six joints, position and duty,
   2 × 2,000 points each): the braille raster the tab uses, plotext through
   textual-plotext (which needs plotext < 6) raw and decimated to ~2 points a column;
2. the Scope tab in the app: its frame (copy the window and raster it) and the
   screen update Textual makes of it, frames per second reached, and how long a
   key waits while it draws;
3. the controller's lateness over a few seconds with the Scope hidden and shown;
4. key to duty: a Jog key posted to the app as the terminal driver posts it, until
   the controller publishes the new valve duty (watched from another process);
5. startup: ``python -m app`` in a tmux window until the live screen shows (quiet, and
   beside a CPU burner with ``--tmux``);
6. UI pauses (``--pauses``; ``--no-burner`` without the burner): every tab opened for the
   first time (and End point in Moves) beside a CPU burner; the event loop's longest
   pause per tab (a task that wakes every 5 ms records how late it woke), the client's
   heartbeat's longest age as the controller sees it (read from shared memory by another
   process) and the controller's client-silent events;
7. soak (``--soak 300``, the five-minute soak; exits 1 if a check fails): ``python -m app``
   in tmux beside a CPU burner, a tab switch every second for that many seconds, then the
   app live at the end (the Jog tab, an E-stop, quit; tests/app/soak.py); the client-silent
   events of the session's events.jsonl counted, and none allowed;
8. browser (``--browser`` alone; also in the full run when Chromium is installed):
   ``servodesk serve`` started (its own controller), then three times a fresh headless
   Chromium opened on it (tests/app/browser.py): the time from asking for the page to the
   first bytes of the TUI's output, and to its first live frame (the header's tick count);
9. idle UI CPU (``--tmux``, ``--idle``): ``python -m app`` in tmux, its own process's CPU time
   (/proc), and its main thread's, over 10 s on each of Jog, Scope (drawing at its rate) and
   Status, nothing pressed;
10. key to the screen (``--tmux``): an increment key sent with ``tmux send-keys`` on the Jog
   tab until the screen shows the new increment, quiet and beside a CPU burner;
11. the arm's view (``--arm`` alone; also in the full run): a frame's drawing alone, and the
   view live in a headless app with a new pose every poll, its frames a second and CPU beside
   a Scope plot fed at the same rate (``benchmarks/arm_view.py``, which also has ``--tmux``).

``--tmux [ROOT ...]`` runs only 9, 5 and 10, for each ROOT given (a worktree of an older
commit: ``git worktree add /tmp/old HASH``) and then this tree, one after the other in one run;
``--idle [ROOT ...]`` only 9, for each ROOT and this tree by turns, ``--rounds`` times, and
prints each tab's median (the process and its main thread, the event loop that draws);
``--start [ROOT ...]`` only 5, one start of each ROOT and of this tree by turns, ``--rounds``
times (``--burner``: beside a CPU burner), and prints each one's median.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import multiprocessing as mp
import os
import shlex
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from multiprocessing import resource_tracker
from multiprocessing.connection import Connection
from pathlib import Path

import numpy as np
from rich.style import Style
from textual import events
from textual.screen import Screen
from textual.widgets import OptionList

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # ahead of benchmarks/hw.py

from app.plotting.braille import Trace, render
from app.plotting.figure import decimate
from app.tabs.latency import Lateness
from app.tabs.scope import ScopeTab
from app.tui import TABS, ServodeskApp
from control.rt import shm
from control.rt.layout import HEARTBEAT_WORD, ControlLayout
from control.rt.seqlock import SeqlockReader

ROOT = Path(__file__).resolve().parents[1]
POINTS = 2_000
WATCH_S = 0.0003  # the watcher polls the status this often (it is published every 1 ms)
JOINTS = 6
SIZE = (160, 48)
PAUSE_TICK_S = 0.005  # the pause clock's wake-ups
TAB_SETTLE_S = 1.5  # each tab's time to show and settle before the next
PANEL = (70, 8, 3)  # columns, position rows, duty rows of one joint on a 160 × 48 screen


def synthetic(points: int = POINTS, seconds: float = 10.0) -> tuple[np.ndarray, ...]:
    """``t``, and position, desired, duty ``(points, 6)`` that look like step responses."""
    t = np.linspace(0.0, seconds, points)
    k = np.arange(JOINTS)
    desired = np.where(t[:, None] > 2.0 + k * 0.5, 10.0 + k, 0.0)
    position = desired - 10.0 * np.exp(-3.0 * np.maximum(t[:, None] - 2.0 - k * 0.5, 0)) * (
        t[:, None] > 2.0 + k * 0.5) * np.cos(6 * t[:, None]) + 0.05 * np.sin(50 * t[:, None])
    duty = 40.0 * np.sin(2.0 * t[:, None] + k)
    return t, position, desired, duty


def best_ms(fn, repeats: int) -> tuple[float, float]:
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        times.append((time.perf_counter() - start) * 1e3)
    return min(times), statistics.median(times)


def renderers(repeats: int) -> None:
    from textual_plotext.plot import Plot

    t, q, d, u = synthetic()
    cols, rows, duty_rows = PANEL
    red, cyan, yellow = Style(color="red"), Style(color="cyan"), Style(color="yellow")

    def braille() -> None:
        for j in range(JOINTS):
            render([Trace(t, d[:, j], red), Trace(t, q[:, j], cyan)], (0, 10), (-2, 18),
                   cols, rows)
            render([Trace(t, u[:, j], yellow)], (0, 10), (-50, 50), cols, duty_rows,
                   guide_y=0.0)

    def plotext(points: int | None) -> None:
        plt = Plot()
        plt.plotsize(SIZE[0], SIZE[1] - 6)
        plt.subplots(JOINTS, 2)
        for j in range(JOINTS):
            for col, series in ((1, (d[:, j], q[:, j])), (2, (u[:, j],))):
                sub = plt.subplot(j + 1, col)
                for y in series:
                    tt, yy = (t, y) if points is None else decimate(t, y, points)
                    sub.plot(tt.tolist(), yy.tolist(), marker="braille")
        plt.build()

    print(f"1. renderers alone: {JOINTS} joints × ({POINTS} desired + {POINTS} actual + "
          f"{POINTS} duty points), ms per frame (best, median of {repeats})")
    for label, fn in (("braille raster (Scope tab)", braille),
                      ("plotext raw", lambda: plotext(None)),
                      ("plotext decimated, 2 points/column", lambda: plotext(2 * cols))):
        best, median = best_ms(fn, repeats)
        print(f"   {best:7.1f} {median:7.1f}  {label}")


class FrameClock:
    """Times ScopeTab.refresh_live (the frame) and Screen._compositor_refresh (the update)."""

    def __init__(self) -> None:
        self.frames: list[float] = []
        self.updates: list[float] = []
        self.frame_at: list[float] = []
        self._frame = ScopeTab.refresh_live
        self._update = Screen._compositor_refresh

    def install(self) -> None:
        clock = self

        def frame(tab: ScopeTab, force: bool = False) -> None:
            start = time.perf_counter()
            clock._frame(tab, force)
            clock.frames.append(time.perf_counter() - start)
            clock.frame_at.append(start)

        def update(screen: Screen) -> None:
            start = time.perf_counter()
            clock._update(screen)
            clock.updates.append(time.perf_counter() - start)

        ScopeTab.refresh_live = frame  # type: ignore[method-assign]
        Screen._compositor_refresh = update  # type: ignore[method-assign]

    def reset(self) -> None:
        self.frames.clear()
        self.updates.clear()
        self.frame_at.clear()


def post_key(app: ServodeskApp, key: str) -> None:
    """A key as the terminal driver delivers it (no Pilot idle waits)."""
    assert app._driver is not None
    app._driver.send_message(events.Key(key, key if len(key) == 1 else None))


async def ready(app: ServodeskApp, pilot: object) -> None:
    deadline = time.monotonic() + 30
    while (app.client is None or app.sampler is None or app.sampler.latest is None):
        if time.monotonic() > deadline:
            raise RuntimeError(f"controller did not start: {app.client_problem}")
        await asyncio.sleep(0.05)


def lateness(app: ServodeskApp, since: Lateness) -> str:
    assert app.client is not None
    now = Lateness.total(app.client.histogram()).since(since)
    return (f"mean {now.mean_us:6.1f} µs, max {now.max_text()}, overruns {now.overruns}, "
            f"{now.ticks} ticks")


async def scope_and_keys(seconds: float, presses: int) -> None:
    clock = FrameClock()
    clock.install()
    with tempfile.TemporaryDirectory() as data_dir:
        # automatic: part 4 times duty keys, and in T1 (the TUI's start) the pad steps
        # positions, whose valve changes on its own as the joint settles
        app = ServodeskApp("unimate2000b", data_dir=data_dir,
                           client_options={"speed_mode": "automatic"})
        async with app.run_test(size=SIZE) as pilot:
            await ready(app, pilot)
            assert app.client is not None
            await pilot.press("f4")
            await asyncio.sleep(1.0)
            before = Lateness.total(app.client.histogram())
            await asyncio.sleep(seconds)
            hidden = lateness(app, before)

            t, q, d, u = synthetic()
            app.history.clear()
            app.history.extend(t - t[-1] + app.history.latest_time, q, d, u)
            app.sampler.stop()  # hold the window at exactly POINTS samples per joint
            await pilot.press("f3")
            await asyncio.sleep(1.0)
            clock.reset()
            before = Lateness.total(app.client.histogram())
            key_waits = []
            tab = app.query_one(ScopeTab)
            original_zoom = ScopeTab.action_zoom
            answered: list[float] = []

            def zoom(self: ScopeTab, direction: int) -> None:
                answered.append(time.perf_counter())
                original_zoom(self, direction)

            ScopeTab.action_zoom = zoom  # type: ignore[method-assign]
            end = time.perf_counter() + seconds
            while time.perf_counter() < end:
                sent = time.perf_counter()
                post_key(app, "plus" if len(answered) % 2 else "minus")
                while len(answered) <= len(key_waits) and time.perf_counter() - sent < 1.0:
                    await asyncio.sleep(0.001)
                key_waits.append((answered[-1] - sent) * 1e3 if answered else 1e3)
                await asyncio.sleep(0.2)
            shown = lateness(app, before)
            ScopeTab.action_zoom = original_zoom  # type: ignore[method-assign]
            frames = [f * 1e3 for f in clock.frames]
            updates = [u * 1e3 for u in clock.updates]
            span = clock.frame_at[-1] - clock.frame_at[0] if len(clock.frame_at) > 1 else 1
            window = app.history.window(tab.window_s)
            print(f"\n2. Scope tab in the app ({SIZE[0]}×{SIZE[1]}, {JOINTS} joints × "
                  f"{len(window)} points, {seconds:g} s)")
            print(f"   frame (copy + raster)  median {statistics.median(frames):6.1f} ms, "
                  f"p95 {np.percentile(frames, 95):6.1f} ms")
            print(f"   screen update          median {statistics.median(updates):6.1f} ms, "
                  f"p95 {np.percentile(updates, 95):6.1f} ms")
            print(f"   frames per second      {(len(frames) - 1) / span:6.1f} "
                  f"(timer asks {ScopeTab.REFRESH_HZ:g})")
            print(f"   key answered after     median {statistics.median(key_waits):6.1f} ms, "
                  f"max {max(key_waits):6.1f} ms ({len(key_waits)} keys)")
            print(f"\n3. controller lateness, Status tab shown: {hidden}")
            print(f"   controller lateness, Scope tab drawing: {shown}")

            await pilot.press("f1")
            await asyncio.sleep(0.5)
            await key_to_duty(app, presses)


def watch_valve(segment: str, joints: int, joint: int, conn: Connection) -> None:
    """In its own process (no GIL shared with the UI): for each ``before`` value received,
    poll the controller's status until valve ``joint`` differs; answer the controller's
    publish time (monotonic ns) of the first snapshot seen with the new duty."""
    memory = shm.attach(segment)
    layout = ControlLayout(joints)
    reader = SeqlockReader(memory.buf, layout.status_offset, layout.status.struct)
    conn.send("ready")
    try:
        while (before := conn.recv()) is not None:
            deadline = time.monotonic_ns() + 1_000_000_000
            seen = 0
            while time.monotonic_ns() < deadline:
                status = layout.status.decode(reader.read())
                if status.valve[joint] != before:
                    seen = status.wall_ns
                    break
                time.sleep(WATCH_S)
            conn.send(seen)
    finally:
        reader.release()
        shm.release(memory, unlink=False)


async def key_to_duty(app: ServodeskApp, presses: int) -> None:
    client = app.client
    assert client is not None
    parent, child = mp.get_context("spawn").Pipe()
    # the client's control segment: read-only from the watcher (benchmark only)
    watcher = mp.get_context("spawn").Process(
        target=watch_valve, args=(client.segment_name, app.machine.n_joints, 0, child),
        daemon=True)
    watcher.start()
    if parent.recv() != "ready":
        raise RuntimeError("the valve watcher did not start")
    samples: list[float] = []
    try:
        for i in range(presses):
            parent.send(client.status().valve[0])
            await asyncio.sleep(0.02)  # the watcher is polling before the key goes
            sent = time.monotonic_ns()
            post_key(app, "a" if i % 2 == 0 else "z")
            while not parent.poll():
                await asyncio.sleep(0.0005)
            seen = parent.recv()
            if seen:
                samples.append((seen - sent) / 1e6)
            await asyncio.sleep(0.03)
    finally:
        parent.send(None)
        watcher.join(timeout=2)
    post_key(app, "space")
    print(f"\n4. key to duty at the controller ({len(samples)} of {presses} presses, Jog tab, "
          "duty mode: from posting the key to the controller publishing the new valve duty)")
    if samples:
        print(f"   median {statistics.median(samples):6.2f} ms, p95 "
              f"{np.percentile(samples, 95):6.2f} ms, max {max(samples):6.2f} ms")


def start_burner() -> subprocess.Popen:
    """A busy loop in its own process: one core's worth of someone else's work."""
    return subprocess.Popen([sys.executable, "-c", "while True: pass"])


def watch_heartbeat(segment: str, joints: int, conn: Connection) -> None:
    """In its own process (no GIL shared with the UI), as the controller reads it: poll the
    client's heartbeat word (its monotonic ns) every ``WATCH_S`` until told to stop; answer the
    longest age it reached, ms."""
    memory = shm.attach(segment)
    words = ControlLayout(joints).client_words(memory.buf)
    conn.send("ready")
    oldest = 0
    try:
        while not conn.poll():
            beat = words[HEARTBEAT_WORD]
            if beat:
                oldest = max(oldest, time.monotonic_ns() - beat)
            time.sleep(WATCH_S)
        conn.send(oldest / 1e6)
    finally:
        words.release()
        shm.release(memory, unlink=False)


class PauseClock:
    """The UI event loop's pauses: a task that asks to wake every ``PAUSE_TICK_S`` records how
    much later than that it woke, under the label of what the script is doing, and how much
    of that the UI thread spent working (its CPU time; the rest it waited for a CPU)."""

    def __init__(self) -> None:
        self.label = ""
        self.pauses: dict[str, list[float]] = {}
        self.worked: dict[str, list[float]] = {}
        self._task: asyncio.Task | None = None

    def start(self) -> None:
        self._task = asyncio.get_running_loop().create_task(self._tick())

    def stop(self) -> None:
        if self._task is not None:
            self._task.cancel()

    async def _tick(self) -> None:
        last, last_cpu = time.perf_counter(), time.thread_time()
        while True:
            await asyncio.sleep(PAUSE_TICK_S)
            now, cpu = time.perf_counter(), time.thread_time()
            if self.label:
                self.pauses.setdefault(self.label, []).append((now - last - PAUSE_TICK_S) * 1e3)
                self.worked.setdefault(self.label, []).append((cpu - last_cpu) * 1e3)
            last, last_cpu = now, cpu

    def longest(self, label: str) -> tuple[float, float]:
        """The longest pause under ``label`` and the UI thread's CPU time in it, ms."""
        k = int(np.argmax(self.pauses[label]))
        return self.pauses[label][k], self.worked[label][k]


async def open_end_point(app: ServodeskApp) -> None:
    """Moves tab: highlight End point in the menu, as the arrow keys would."""
    menu = app.query_one("#move-kinds", OptionList)
    menu.highlighted = next(i for i, option in enumerate(menu.options)
                            if option.id == "EndPointForm")


async def tab_pauses(burn: bool) -> None:
    """Every tab opened for the first time (and End point in Moves), each given
    ``TAB_SETTLE_S``, with a CPU burner beside the app: the UI's longest pause in each, the
    heartbeat's longest age as the controller would see it, and the controller's
    client-silent events."""
    burner = start_burner() if burn else None
    clock = PauseClock()
    try:
        with tempfile.TemporaryDirectory() as data_dir:
            app = ServodeskApp("unimate2000b", data_dir=data_dir)
            async with app.run_test(size=SIZE) as pilot:
                await ready(app, pilot)
                assert app.client is not None
                parent, child = mp.get_context("spawn").Pipe()
                watcher = mp.get_context("spawn").Process(
                    target=watch_heartbeat, args=(app.client.segment_name,
                                                  app.machine.n_joints, child), daemon=True)
                watcher.start()
                if parent.recv() != "ready":
                    raise RuntimeError("the heartbeat watcher did not start")
                clock.start()
                for i, (name, _) in enumerate(TABS):
                    clock.label = name
                    post_key(app, f"f{i + 1}")
                    await asyncio.sleep(TAB_SETTLE_S)
                    if name == "moves":
                        clock.label = "moves: End point"
                        await open_end_point(app)
                        await asyncio.sleep(TAB_SETTLE_S)
                clock.stop()
                parent.send(None)
                heartbeat_ms = parent.recv()
                watcher.join(timeout=2)
                silent = [e for e in app.desk.events.entries if e.kind == "UI lost"]
    finally:
        if burner is not None:
            burner.kill()
            burner.wait()
    every = [p for pauses in clock.pauses.values() for p in pauses]
    print(f"\n6. UI pauses opening every tab for the first time ({SIZE[0]}×{SIZE[1]}, "
          f"{'a CPU burner beside it' if burn else 'no burner'}; event-loop wake-ups "
          f"{PAUSE_TICK_S * 1e3:g} ms apart, lateness ms)")
    for label, pauses in clock.pauses.items():
        longest, worked = clock.longest(label)
        print(f"   {label:<18} median {statistics.median(pauses):6.1f}, max {longest:6.1f} "
              f"(the UI thread working {worked:5.1f} of it)")
    print(f"   all tabs           median {statistics.median(every):6.1f}, max {max(every):6.1f} "
          f"(target < 100); load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} CPUs")
    print(f"   heartbeat's longest age at the controller {heartbeat_ms:6.1f} ms (it holds at "
          f"250); client-silent events {len(silent)}")
    for entry in silent:
        print(f"   {entry.line()}")


def soak(seconds: float) -> bool:
    """``python -m app`` in tmux beside a CPU burner, switching every tab (F1…F10, a key a
    second) for ``seconds``, then live at the end (tests/app/soak.py): what it saw, the
    session's client-silent events and stalls, and whether every check passed."""
    from tests.app import soak as tmux_soak

    if shutil.which("tmux") is None:
        print("\n7. soak skipped: tmux is not installed")
        return True
    with tempfile.TemporaryDirectory() as directory:
        result = tmux_soak.soak(Path(directory), seconds)
        events = tmux_soak.logged(Path(directory))
    failed = tmux_soak.failures(result, events)
    silent = [e for e in events if e["kind"] == "UI lost"]
    stalls = [e for e in events if e["kind"] == "stall"]
    print(f"\n7. soak: {seconds:g} s in tmux {SIZE[0]}×{SIZE[1]} beside a CPU burner, "
          f"{result['switches']} tab switches ({tmux_soak.KEY_S:g} s apart, "
          f"F1…F{tmux_soak.TABS}): client-silent events {len(silent)}, loop stalls logged "
          f"{len(stalls)}, {len(events)} events in all, load average {result['load']:.1f}")
    for entry in silent + stalls:
        print(f"   {entry['time']} {entry['kind']}: {entry['what']}")
    print("   passed: live to the end, a switch a second, the E-stop logged, never silent"
          if not failed else "   FAILED:\n" + "\n".join(f"   - {f}" for f in failed))
    return not failed


class TmuxApp:
    """``python -m app`` (from ``root``) in a 160 × 48 tmux window of its own tmux server; or
    ``python PEER`` (the bare Textual app beside it)."""

    def __init__(self, root: Path, data_dir: str, name: str, peer: bool = False) -> None:
        self.tmux = [shutil.which("tmux") or "tmux", "-L", f"servodesk-bench-{os.getpid()}",
                     "-f", os.devnull]
        self.name = name
        what = shlex.quote(str(PEER)) if peer else f"-m app --data-dir {data_dir}"
        # exec: the pane's process is the app itself, whose CPU time /proc gives
        command = (f"cd {shlex.quote(str(root))} && PYTHONPATH={shlex.quote(str(root))} exec "
                   f"{shlex.quote(sys.executable)} {what}")
        self.started = time.monotonic()
        subprocess.run([*self.tmux, "new-session", "-d", "-s", name, "-x", str(SIZE[0]),
                        "-y", str(SIZE[1]), command], check=True)
        self.pid = int(subprocess.run([*self.tmux, "display", "-p", "-t", name, "#{pane_pid}"],
                                      capture_output=True, text=True, check=True).stdout)

    def screen(self) -> str:
        return subprocess.run([*self.tmux, "capture-pane", "-p", "-t", self.name],
                              capture_output=True, text=True).stdout

    def wait_for(self, *texts: str, timeout: float = 30.0) -> float:
        """Seconds since start until every one of ``texts`` is on the screen."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            screen = self.screen()
            if all(text in screen for text in texts):
                return time.monotonic() - self.started
            time.sleep(0.005)
        raise RuntimeError(f"{texts} not on the screen after {timeout:g} s:\n{self.screen()}")

    def line(self, marker: str) -> str:
        """The first line of the screen holding ``marker`` ("" if none does)."""
        return next((line for line in self.screen().splitlines() if marker in line), "")

    def wait_change(self, marker: str, before: str, timeout: float = 30.0) -> None:
        """Until the line holding ``marker`` is no longer ``before``."""
        deadline = time.monotonic() + timeout
        while self.line(marker) == before:
            if time.monotonic() > deadline:
                raise RuntimeError(f"the line of {marker!r} still shows {before!r} after "
                                   f"{timeout:g} s:\n{self.screen()}")
            time.sleep(0.005)

    def keys(self, *keys: str) -> None:
        subprocess.run([*self.tmux, "send-keys", "-t", self.name, *keys], check=True)

    def cpu_s(self, main_thread: bool = False) -> float:
        """The app's CPU time so far (user + system), its own process only (or its main
        thread's alone: the event loop's, without the sampler's and the client's threads)."""
        stat = Path(f"/proc/{self.pid}/task/{self.pid}/stat" if main_thread
                    else f"/proc/{self.pid}/stat")
        fields = stat.read_text().rsplit(")", 1)[1].split()
        return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")

    def close(self) -> None:
        self.keys("C-q")
        with contextlib.suppress(RuntimeError):
            deadline = time.monotonic() + 5
            while Path(f"/proc/{self.pid}").exists() and time.monotonic() < deadline:
                time.sleep(0.05)
        subprocess.run([*self.tmux, "kill-server"], capture_output=True)


# A live screen: the header once the controller's status is shown (RUN on the lamp, the mode
# read from the status), not merely the first frame (the lamp says STARTING before the status)
LIVE = (" RUN", "mode HOLD")
PEER = Path(__file__).resolve().with_name("textual_peer.py")  # its first frame shows both too
IDLE_TABS = (("jog", "F1"), ("scope", "F3"), ("status", "F4"))
IDLE_S = 10.0  # each tab's idle CPU is measured over this long, after IDLE_SETTLE_S
IDLE_SETTLE_S = 2.0
# once the screen is live the other tabs are built behind the first, which on a loaded
# machine can outlast IDLE_SETTLE_S: their building would count as the Jog tab's idle CPU
IDLE_BUILT_S = 6.0


@contextlib.contextmanager
def burning(burn: bool):
    burner = start_burner() if burn else None
    try:
        yield
    finally:
        if burner is not None:
            burner.kill()
            burner.wait()


def load() -> str:
    return f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} CPUs"


def startup(repeats: int, root: Path = ROOT, burn: bool = False, peer: bool = False
            ) -> list[float]:
    """Seconds from starting ``python -m app`` (or the bare peer) in a 160 × 48 tmux window to
    a live screen."""
    if shutil.which("tmux") is None:
        print("\n5. startup: skipped (no tmux)")
        return []
    times = []
    with tempfile.TemporaryDirectory() as data_dir, burning(burn):
        for k in range(repeats):
            app = TmuxApp(root, data_dir, f"s{k}", peer)
            try:
                times.append(app.wait_for(*LIVE))
            finally:
                app.close()
    what = "the bare Textual peer's first frame" if peer else "a live screen"
    print(f"\n5. startup to {what} (tmux 160×48, {len(times)} starts, "
          f"{'beside a CPU burner' if burn else 'no burner'}, {root}): median "
          f"{statistics.median(times):.2f} s, max {max(times):.2f} s; {load()}")
    return times


def start_rounds(roots: list[Path], rounds: int, burn: bool) -> None:
    """Part 5 by turns: one start of each of ``roots``, ``rounds`` times (the machine's load
    drifts: by turns, each root sees the same), then each one's median and spread."""
    seen: dict[Path, list[float]] = {root: [] for root in roots}
    with tempfile.TemporaryDirectory() as data_dir, burning(burn):
        for k in range(rounds):
            for root in roots:
                app = TmuxApp(root, data_dir, f"s{k}")
                try:
                    seen[root].append(app.wait_for(*LIVE))
                finally:
                    app.close()
    print(f"\n5. startup to a live screen, median of {rounds} starts by turns (tmux "
          f"{SIZE[0]}×{SIZE[1]}, {'beside a CPU burner' if burn else 'no burner'}; {load()})")
    for root, times in seen.items():
        print(f"   {root!s:<28}  median {statistics.median(times):.2f} s  min {min(times):.2f}"
              f"  max {max(times):.2f}  ({' '.join(f'{t:.2f}' for t in times)})")


def idle_cpu(root: Path = ROOT) -> dict[str, tuple[float, float]]:
    """The app's CPU, % of one core, idle on each of Jog, Scope (drawing at its rate) and
    Status, in tmux; nothing else pressed: the process's and its main thread's (the event
    loop: drawing), by tab."""
    cost = {}
    with tempfile.TemporaryDirectory() as data_dir:
        app = TmuxApp(root, data_dir, "idle")
        try:
            app.wait_for(*LIVE)
            time.sleep(IDLE_BUILT_S)
            for name, key in IDLE_TABS:
                app.keys(key)
                time.sleep(IDLE_SETTLE_S)
                cpu, main, wall = app.cpu_s(), app.cpu_s(main_thread=True), time.monotonic()
                time.sleep(IDLE_S)
                elapsed = time.monotonic() - wall
                cost[name] = (100 * (app.cpu_s() - cpu) / elapsed,
                              100 * (app.cpu_s(main_thread=True) - main) / elapsed)
        finally:
            app.close()
    print(f"\n9. idle UI CPU (tmux 160×48, {IDLE_S:g} s a tab, {root}): "
          + ", ".join(f"{name} {pct:.1f} % (main thread {main:.1f})"
                      for name, (pct, main) in cost.items())
          + f" of a core; {load()}")
    return cost


def idle_rounds(roots: list[Path], rounds: int) -> None:
    """Part 9 for each of ``roots`` by turns, ``rounds`` times (the machine's load drifts: by
    turns, each root sees the same), then each tab's median per root."""
    seen: dict[Path, list[dict[str, tuple[float, float]]]] = {root: [] for root in roots}
    for _ in range(rounds):
        for root in roots:
            seen[root].append(idle_cpu(root))
    print(f"\n9. idle UI CPU, median of {rounds} rounds by turns, % of a core (process / "
          "main thread)")
    for root, runs in seen.items():
        print(f"   {root!s:<28}" + "".join(
            f"  {name} {statistics.median(r[name][0] for r in runs):5.1f} / "
            f"{statistics.median(r[name][1] for r in runs):4.1f}" for name, _ in IDLE_TABS))


def peer_idle_cpu() -> float:
    """The bare Textual peer's CPU (``benchmarks/textual_peer.py``: the Jog screen's widget
    count, one line changing ten times a second), % of one core, as ``idle_cpu`` measures."""
    with tempfile.TemporaryDirectory() as data_dir:
        app = TmuxApp(ROOT, data_dir, "peer", peer=True)
        try:
            app.wait_for(*LIVE)
            time.sleep(IDLE_SETTLE_S)
            cpu, wall = app.cpu_s(), time.monotonic()
            time.sleep(IDLE_S)
            cost = 100 * (app.cpu_s() - cpu) / (time.monotonic() - wall)
        finally:
            app.close()
    print(f"\n9. bare Textual peer idle (tmux 160×48, {IDLE_S:g} s, {PEER.name}): {cost:.1f} % "
          f"of a core; {load()}")
    return cost


JOG_LINE = "  ·  mode "  # the Jog tab's line of frame, mode and increment (duty) or step


def key_to_screen(presses: int, root: Path = ROOT, burn: bool = False) -> list[float]:
    """Jog tab in tmux: an increment key (3 or 7, by turns) sent with ``tmux send-keys`` until
    the Jog line shows the new increment (duty mode, the older tabs' first) or step (position
    mode), ms (the capture polled every ~5 ms: its own cost is in the figure)."""
    samples = []
    with tempfile.TemporaryDirectory() as data_dir, burning(burn):
        app = TmuxApp(root, data_dir, "keys")
        try:
            app.wait_for(*LIVE)
            time.sleep(1.0)
            first = app.line(JOG_LINE)
            app.keys("7")  # then each key below changes the line (3 and 7 by turns)
            app.wait_change(JOG_LINE, first, timeout=5)
            time.sleep(0.2)
            for i in range(presses):
                k = "3" if i % 2 == 0 else "7"
                before = app.line(JOG_LINE)
                sent = time.monotonic()
                app.keys(k)
                app.wait_change(JOG_LINE, before, timeout=5)
                samples.append((time.monotonic() - sent) * 1e3)
                time.sleep(0.1)
        finally:
            app.close()
    print(f"\n10. key to the screen (Jog tab, tmux 160×48, {presses} keys, "
          f"{'beside a CPU burner' if burn else 'no burner'}, {root}): median "
          f"{statistics.median(samples):.0f} ms, p95 {np.percentile(samples, 95):.0f} ms, "
          f"max {max(samples):.0f} ms; {load()}")
    return samples


def tmux_figures(roots: list[Path], repeats: int, presses: int) -> None:
    """Items 2 and 3 of issue 26 for each of ``roots`` (a worktree of an older commit beside
    this one), one after the other in one run: idle CPU, start quiet and beside a burner,
    key to the screen quiet and beside a burner; then the bare Textual peer's idle CPU and
    start, the base these are to be read against."""
    for root in roots:
        idle_cpu(root)
        for burn in (False, True):
            startup(repeats, root, burn)
            key_to_screen(presses, root, burn)
    peer_idle_cpu()
    for burn in (False, True):
        startup(repeats, ROOT, burn, peer=True)


def browser_first_render(repeats: int = 3) -> None:
    """Seconds from a headless Chromium asking for ``servodesk serve``'s page to the TUI's
    first output and to its first live frame, each in a fresh browser (Chromium's own start
    not counted)."""
    from tests.app.browser import CHROMIUM, WINDOW, Served, browser

    if not Path(CHROMIUM).exists():
        print("\n8. browser: skipped (no chromium)")
        return
    first_bytes, live = [], []
    with tempfile.TemporaryDirectory() as tmp:
        started = time.monotonic()
        served = Served(Path(tmp) / "serve.log", "--data-dir", str(Path(tmp) / "runs"))
        up_s = time.monotonic() - started
        try:
            for _ in range(repeats):
                with browser() as page:
                    asked = time.monotonic()
                    page.open(served.url)  # returns once the page has loaded
                    while not page.text().strip():
                        time.sleep(0.005)
                    first_bytes.append(time.monotonic() - asked)
                    while "tick " not in page.text():
                        time.sleep(0.005)
                    live.append(time.monotonic() - asked)
        finally:
            served.stop()
    print(f"\n8. browser (servodesk serve, headless Chromium {WINDOW[0]}×{WINDOW[1]} px, "
          f"{repeats} fresh browsers; serve and its controller up in {up_s:.2f} s): page asked "
          f"→ first TUI output median {statistics.median(first_bytes):.2f} s "
          f"(max {max(first_bytes):.2f}), "
          f"→ first live frame median {statistics.median(live):.2f} s (max {max(live):.2f})")


def main() -> None:
    # The key-to-valve watcher is a spawned process, and spawn starts multiprocessing's
    # resource tracker with sys.stderr's descriptor: start it now, before Textual takes stderr.
    resource_tracker.ensure_running()
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer repeats, shorter runs")
    parser.add_argument("--pauses", action="store_true",
                        help="only part 6: the UI's pauses opening every tab beside a burner")
    parser.add_argument("--no-burner", action="store_true", help="part 6 without the burner")
    parser.add_argument("--soak", type=float, metavar="SECONDS",
                        help="only part 7: switch every tab in tmux beside a burner this long")
    parser.add_argument("--tmux", nargs="*", type=Path, metavar="ROOT",
                        help="only parts 5, 9 and 10 (idle CPU, start and key to screen, "
                        "quiet and beside a burner) for this tree and each ROOT given")
    parser.add_argument("--idle", nargs="*", type=Path, metavar="ROOT",
                        help="only part 9 (idle CPU on Jog, Scope and Status) for each ROOT "
                        "given and this tree, by turns, --rounds times")
    parser.add_argument("--start", nargs="*", type=Path, metavar="ROOT",
                        help="only part 5 (start to a live screen) for each ROOT given and this "
                        "tree, by turns, --rounds times")
    parser.add_argument("--burner", action="store_true", help="--start beside a CPU burner")
    parser.add_argument("--rounds", type=int, default=3, help="rounds of --idle and --start (3)")
    parser.add_argument("--browser", action="store_true",
                        help="only part 8: servodesk serve's first render in headless Chromium")
    parser.add_argument("--arm", action="store_true",
                        help="only part 11: the arm's view, its frames a second and CPU beside "
                             "the Scope's (benchmarks/arm_view.py)")
    args = parser.parse_args()
    if args.arm:
        arm_view_figures(3.0 if args.quick else 5.0)
        return
    if args.idle is not None:
        idle_rounds([*args.idle, ROOT], args.rounds)
        return
    if args.start is not None:
        start_rounds([*args.start, ROOT], args.rounds, args.burner)
        return
    if args.tmux is not None:
        tmux_figures([*args.tmux, ROOT], 5, 10 if args.quick else 40)
        return
    if args.browser:
        browser_first_render()
        return
    if args.soak:
        sys.exit(0 if soak(args.soak) else 1)
    if args.pauses:
        asyncio.run(tab_pauses(not args.no_burner))
        return
    repeats, seconds, presses = (5, 3.0, 20) if args.quick else (20, 8.0, 60)
    renderers(repeats)
    asyncio.run(scope_and_keys(seconds, presses))
    startup(3 if args.quick else 5)
    asyncio.run(tab_pauses(not args.no_burner))
    browser_first_render()
    arm_view_figures(3.0 if args.quick else 5.0)


def arm_view_figures(seconds: float) -> None:
    """Part 11: the arm's view (issue 28), drawn alone and live in a headless app, its frames a
    second and CPU beside the Scope's in the same run."""
    from benchmarks import arm_view

    print("\n11. the arm's view (python benchmarks/arm_view.py, which also has --tmux)")
    arm_view.drawing_alone(200 if seconds < 5.0 else 500)
    arm_view.headless_figures(seconds)


if __name__ == "__main__":
    main()
