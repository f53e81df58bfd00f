"""Measure the control loop: compute per tick, wake-up lateness, overruns, CPU use.

Runs the real control subprocess on the simulator for ``--seconds`` and, when
Debian's ``cyclictest`` (rt-tests) is installed, runs it at the same period in
the same window on the other core, then prints both side by side with the
thesis's Table 2.1 (486-66, RTL 1.0). Beside it, the same ticks in a tight loop
(``tight_compute``: the controller's ``tick`` on a lockstep simulator, back to back
on the controller's core): live ÷ tight says what the wake-up costs the work. The control
process ticks a shadow, a piece at a time, in the window before each deadline to warm that
work (the machine file's ``warm_up_pct``, control/rt/warmup.py): the live part runs again
without it (``SERVODESK_WARM_UP=0``), and both by turns in one real-time child, with the
warm-up's counters. Prints figures; asserts nothing.

    python benchmarks/loop.py --seconds 20
    python benchmarks/loop.py --sample-time-ms 0.5 --spin-us 0   # 2 kHz, no spin

``--sample-time-ms`` runs a copy of the machine file with its ``sample_time_ms`` changed.
The code measured is the first of ``PYTHONPATH``'s entries (another checkout: ``git worktree
add /tmp/old <rev>``, then ``PYTHONPATH=/tmp/old``), else this file's repository.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import platform
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

# ahead of benchmarks/, whose hw.py would shadow the hw package: PYTHONPATH's checkout, or ours
sys.path.insert(0, os.environ.get("PYTHONPATH", "").split(os.pathsep)[0]
                or str(Path(__file__).resolve().parents[1]))

from app.priority import UI_NICE
from control import ControlClient
from control.client import SPIN_US
from control.rt.layout import HIST_BIN_NS
from hw.machine import load_machine
from hw.transmission import valve_duty

if TYPE_CHECKING:
    from control.rt.loop import Controller
    from hw.backend import Backend
    from hw.machine import Machine

WARM_UP_ENV = "SERVODESK_WARM_UP"  # control/rt/process.py: "0" starts it with no warm-up
TABLE_2_1 = {"min_us": 11.5, "mean_us": 13.97, "max_us": 54.0, "ticks": 100_290}
JOG_S = 2.0  # how long commands are timed, cyclictest beside them


@dataclass(frozen=True)
class Lateness:
    """Percentiles (µs) of a latency histogram given as bin upper edges and counts."""

    ticks: int
    p50: float
    p99: float
    p999: float
    max_us: float
    over_1ms: int
    min_us: float | None = None
    mean_us: float | None = None
    over_20us: int = 0  # ticks late by 20 µs or more (a window a warm-up piece overran, say)

    @classmethod
    def from_histogram(cls, edges_us: np.ndarray, counts: np.ndarray, max_us: float,
                       min_us: float | None = None, mean_us: float | None = None) -> Lateness:
        total = int(counts.sum())
        cumulative = np.cumsum(counts)

        def pct(p: float) -> float:
            return float(edges_us[min(np.searchsorted(cumulative, p / 100 * total),
                                      len(edges_us) - 1)])

        over = int(counts[edges_us > 1000].sum())
        return cls(total, pct(50), pct(99), pct(99.9), max_us, over, min_us, mean_us,
                   int(counts[edges_us > 20].sum()))


def cpu_seconds(pid: int) -> float:
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def start_cyclictest(period_us: int, seconds: float, cpu: int) -> subprocess.Popen | None:
    if shutil.which("cyclictest") is None:
        return None
    loops = int(seconds * 1e6 / period_us)
    return subprocess.Popen(
        ["cyclictest", "-m", "-p", "80", "--policy=fifo", "-i", str(period_us), "-l", str(loops),
         "-q", "-h", "2000", "-a", str(cpu)], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
        text=True)


def parse_cyclictest(output: str) -> Lateness:
    counts = np.zeros(2001, np.int64)
    for line in output.splitlines():
        if re.match(r"^\d+\s+\d+", line):
            us, count = (int(v) for v in line.split()[:2])
            counts[min(us, 2000)] += count
    overflow = re.search(r"# Histogram Overflows:\s+(\d+)", output)
    if overflow:
        counts[2000] += int(overflow.group(1))
    edges = np.arange(2001, dtype=float) + 1.0  # a count at n µs lies in [n, n+1)
    summary = {name: float(m.group(1)) if (m := re.search(rf"# {name} Latencies:\s+(\d+)",
                                                          output)) else None
               for name in ("Min", "Avg", "Max")}
    return Lateness.from_histogram(edges, counts, summary["Max"] or 0.0, summary["Min"],
                                   summary["Avg"])


def machine_at(name: str, sample_time_ms: float | None, directory: str) -> str:
    """The machine file ``name``, or a copy in ``directory`` whose ``sample_time_ms`` is
    ``sample_time_ms`` (the loop's period: 0.5 runs it at 2 kHz)."""
    if sample_time_ms is None:
        return name
    path = load_machine(name).path
    text, count = re.subn(r"(?m)^sample_time_ms\s*=\s*[0-9.]+",
                          f"sample_time_ms = {sample_time_ms!r}", path.read_text())
    if count != 1:
        raise SystemExit(f"{path}: no sample_time_ms line to change")
    copy = Path(directory) / path.name
    copy.write_text(text)
    return str(copy)


def tight_compute(machine: str, batches: int = 7, ticks: int = 1000) -> tuple[float, float]:
    """Compute and backend read/write per tick (µs) of the controller's own ``tick`` back to
    back on a lockstep simulator, holding as the live loop does in ``measure``: in a child
    made real-time as the control process is (``enter_realtime``), timed by the wall clock
    over the span the live loop times (wake-up to the valves written); the median of
    ``batches`` means of ``ticks`` ticks, as a busy machine's other work lands in some."""
    code = (f"import json, sys; sys.path.insert(0, {sys.path[0]!r}); "
            f"import loop; print(json.dumps(loop.tight_child({machine!r}, {batches}, {ticks})))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         cwd=Path(__file__).parent, check=True).stdout
    compute, io = json.loads(out.splitlines()[-1])
    return compute, io


def windows_text(counters: dict, late_max_us: float) -> str:
    """The warm-up's counters (``WarmUp.report``'s) as a line's end."""
    windows = max(counters["windows"], 1)
    return (f"{counters['ran'] / windows:.2f} shadow ticks ({counters['pieces'] / windows:.1f} "
            f"pieces) a window, {100 * counters['skipped'] / windows:.1f} % of windows skipped "
            f"(no room), {counters['late']} ended late of {counters['windows']} (at most "
            f"{late_max_us:.0f} µs)")


@contextlib.contextmanager
def bare_controller(machine: Machine, backend: Backend, name: str) -> Iterator[Controller]:
    """A controller of ``machine`` on ``backend`` with a status segment of its own and no
    client (nothing ever missed), released on the way out: the children's tight and warm
    loops."""
    import socket

    from control.rt import shm
    from control.rt.channel import controller_end
    from control.rt.layout import ControlLayout
    from control.rt.loop import Controller, LoopConfig

    period = round(machine.sample_time_s * 1e9)
    ours, theirs = socket.socketpair()
    layout = ControlLayout(machine.n_joints)
    segment = shm.create(name, layout.size)
    layout.write_header(segment.buf)
    controller = Controller(machine, backend, controller_end(theirs), segment.buf,
                            LoopConfig(period_ns=period, heartbeat_timeout_ns=10**15,
                                       orphan_timeout_ns=10**15))
    try:
        yield controller
    finally:
        controller.release()
        shm.release(segment, unlink=True)
        ours.close()


def tight_child(machine_name: str, batches: int, ticks: int) -> tuple[float, float]:
    """``tight_compute``'s child: a batch to warm up, the batches, their median means (µs)."""
    from control.rt.realtime import enter_realtime
    from hw.backend import RealClock
    from hw.sim.backend import SimBackend

    machine = load_machine(machine_name)
    backend = SimBackend(machine, lockstep=True)
    period = round(machine.sample_time_s * 1e9)
    with bare_controller(machine, backend, "tight") as controller:
        backend.open()
        controller.start()
        controller.clock = RealClock()  # the controller times itself; the plant steps lockstep
        enter_realtime()
        step, latency = backend.clock, controller.latency
        means = []
        for _ in range(batches + 1):
            compute0, io0 = latency.compute_total_ns, latency.io_total_ns
            for _ in range(ticks):
                step.sleep_until(step.now_ns() + period)
                controller.deadline = woke = time.monotonic_ns()
                controller.tick(woke)
            means.append(((latency.compute_total_ns - compute0) / ticks / 1e3,
                          (latency.io_total_ns - io0) / ticks / 1e3))
        return sorted(means[1:])[batches // 2]


def warm_compute(machine: str, spin_us: float, turns: int = 8, ticks: int = 1000) -> dict | None:
    """``warm_child`` in a child made real-time as the control process is; None when the
    code measured has no warm-up (an older commit)."""
    code = (f"import json, sys; sys.path.insert(0, {sys.path[0]!r}); import loop; "
            f"print(json.dumps(loop.warm_child({machine!r}, {spin_us!r}, {turns}, {ticks})))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         cwd=Path(__file__).parent, check=True).stdout
    return json.loads(out.splitlines()[-1])


def warm_child(machine_name: str, spin_us: float, turns: int, ticks: int) -> dict | None:
    """The controller on a real-time simulator, paced as the control process paces it
    (``Controller.cycle``), ``ticks`` ticks without its warm-up (control/rt/warmup.py), then
    as many with it, by turns: the median of each's means of compute per tick (µs), each's
    wake-up lateness p99 (µs, the live tick's start after its deadline), and the warm-up's
    counters over its turns."""
    from control.rt.realtime import enter_realtime
    from hw.sim.backend import SimBackend
    try:
        from control.rt.warmup import WarmUp
    except ImportError:
        return None

    machine = load_machine(machine_name)
    backend = SimBackend(machine)
    backend.clock.spin_ns = round(spin_us * 1e3)
    period = round(machine.sample_time_s * 1e9)
    with bare_controller(machine, backend, "warm") as controller:
        warm_up = WarmUp.beside(controller)
        try:
            backend.open()
            controller.start()
            enter_realtime()
            latency = controller.latency
            means: dict[bool, list[float]] = {False: [], True: []}
            late: dict[bool, list[int]] = {False: [], True: []}
            controller.deadline = backend.clock.now_ns() + period
            for turn in range(2 * turns + 2):
                on = turn % 2 == 1
                controller.warm_up = warm_up if on else None
                compute0 = latency.compute_total_ns
                for _ in range(ticks):
                    controller.cycle()
                    late[on].append(latency.late_ns)
                if turn >= 2:  # the first two: a warm-up
                    means[on].append((latency.compute_total_ns - compute0) / ticks / 1e3)
            return {"off_us": float(np.median(means[False])),
                    "on_us": float(np.median(means[True])),
                    "off_p99_us": float(np.percentile(late[False], 99)) / 1e3,
                    "on_p99_us": float(np.percentile(late[True], 99)) / 1e3,
                    "windows": warm_up.windows, "ran": warm_up.ran, "skipped": warm_up.skipped,
                    "pieces": warm_up.pieces_run, "late": warm_up.late,
                    "late_max_us": warm_up.late_max_ns / 1e3,
                    "error": warm_up.error}
        finally:
            controller.warm_up = None
            warm_up.close()


@dataclass(frozen=True)
class CommandLatency:
    """Milliseconds from the call of ``client.jog_joint`` to its duty, one entry a command:
    ``backend`` to the status of the tick that wrote it to the backend (stamped by the
    controller as it published it, ``Status.wall_ns``), ``seen`` until the client read it.
    ``exact``: the client read the tick before too; where it did not (it was not scheduled),
    ``backend`` is the stamp of the first tick it read with the duty, an upper bound."""

    backend: np.ndarray
    seen: np.ndarray
    exact: np.ndarray

    @staticmethod
    def figures(ms: np.ndarray) -> tuple[float, float, float, int]:
        """Median, p99, max (ms) and how many commands."""
        return float(np.median(ms)), float(np.percentile(ms, 99)), float(ms.max()), len(ms)


def command_latency(client: ControlClient, seconds: float = JOG_S, nice: int | None = None,
                    seed: int = 29) -> CommandLatency:
    """Jog joint 0 between two small duties for ``seconds`` (the joint barely moves), each
    command a random fraction of a tick more than 2 ms after the last was seen, so that
    commands arrive at every phase of the loop's tick, as an operator's do. The caller spins
    on the status meanwhile, keeping the GIL as a busy UI does. ``nice``: the priority of
    every thread of this process meanwhile (the TUI's, ``UI_NICE``, which its threads
    inherit: the one that calls alone would wait for the others to hand the GIL back)."""
    joint = client.machine.joints[0]
    rng = np.random.default_rng(seed)
    backend, seen, exact = [], [], []
    priorities = {t.native_id: os.getpriority(os.PRIO_PROCESS, t.native_id)
                  for t in threading.enumerate() if nice is not None and t.native_id is not None}
    for thread in priorities:
        os.setpriority(os.PRIO_PROCESS, thread, nice)
    end = time.monotonic() + seconds
    try:
        while time.monotonic() < end:
            duty = 5.0 + len(seen) % 2
            target = valve_duty(joint, duty)
            t0 = time.monotonic_ns()
            client.jog_joint(0, duty)
            last = client.status().tick  # the last tick read without the duty
            while (status := client.status()).valve[0] != target:
                last = status.tick
                if time.monotonic_ns() - t0 > 1e9:
                    break
            t1 = time.monotonic_ns()
            backend.append(status.wall_ns - t0 if status.valve[0] == target else t1 - t0)
            seen.append(t1 - t0)
            exact.append(status.tick == last + 1)
            time.sleep(0.002 + rng.random() * client.dt)
    finally:
        for thread, priority in priorities.items():
            os.setpriority(os.PRIO_PROCESS, thread, priority)
    client.hold()
    return CommandLatency(np.array(backend) / 1e6, np.array(seen) / 1e6, np.array(exact))


def measure(seconds: float = 10.0, machine: str = "unimate2000b", spin_us: float = SPIN_US,
            warmup: float = 1.0, sample_time_ms: float | None = None) -> dict:
    """Run the controller for ``seconds`` (cyclictest alongside) and return the figures.

    Keys: ``realtime``, ``notice``, ``period_us``, ``ticks``, ``compute_mean_us``,
    ``compute_max_us``, ``cpu_pct``, ``overruns``, ``jog_ms`` (median, p99, max and count of
    ``client.jog`` → duty at the backend, ms, timed for ``JOG_S`` after the window;
    ``jog_seen_ms`` the same until the client saw it, ``jog_exact`` the share of exact
    ones, ``jog_ui_ms`` … ``jog_ui_exact`` the same at the TUI's priority, ``jog_cyclictest``
    cyclictest's ``Lateness`` beside them, None when not installed), ``servodesk`` and
    ``cyclictest``
    (``Lateness`` in µs; servodesk's mean and percentiles cover the window, its min and
    max the whole run, as the histogram keeps them; ``cyclictest`` None when not installed),
    ``whole_run`` (min, mean, max µs and ticks since the controller started), ``tight_us``
    and ``tight_io_us`` (``tight_compute``'s compute and backend read/write per tick), ``warm``
    (``warm_child``'s figures; None without a spin, or for code with no warm-up), ``cold``
    (``measure_live``'s figures without the warm-up, when there is one).
    """
    with tempfile.TemporaryDirectory() as data:
        path = machine_at(machine, sample_time_ms, data)
        tight, tight_io = tight_compute(path)
        home = os.getcwd()
        os.chdir(data)  # ``python -m`` puts its cwd first: a checkout there would be measured
        try:
            live = measure_live(seconds, path, spin_us, warmup, data)
            warm = warm_compute(path, spin_us) if spin_us > 0 else None
            cold = (measure_live(seconds, path, spin_us, warmup, data, warm_up=False)
                    if warm is not None else None)
        finally:
            os.chdir(home)
    return {**live, "machine": machine, "tight_us": tight, "tight_io_us": tight_io,
            "warm": warm, "cold": cold}


def measure_live(seconds: float, machine: str, spin_us: float, warmup: float, data: str,
                 warm_up: bool = True) -> dict:
    """``measure``'s live part: the control subprocess for ``seconds``, cyclictest beside it;
    ``warm_up`` False starts it with ``SERVODESK_WARM_UP=0`` (no shadow ticks)."""
    os.environ[WARM_UP_ENV] = "report" if warm_up else "0"
    try:
        client = ControlClient(machine, data_dir=data, spin_us=spin_us)
    finally:
        os.environ.pop(WARM_UP_ENV, None)
    with client:
        realtime, notice, pid = client.realtime, client.notice, client.pid
        period_us = round(client.dt * 1e6)
        time.sleep(warmup)
        others = sorted(os.sched_getaffinity(0))
        cyclic = start_cyclictest(period_us, seconds, others[0])
        before, status0, cpu0, wall0 = client.histogram(), client.status(), cpu_seconds(
            client.pid), time.monotonic()
        time.sleep(seconds)
        after, status1, cpu1, wall1 = client.histogram(), client.status(), cpu_seconds(
            client.pid), time.monotonic()
        cyclic_out = cyclic.communicate(timeout=seconds + 30)[0] if cyclic else ""
        cyclic_jog = start_cyclictest(period_us, 2 * JOG_S, others[0])
        latency = command_latency(client)
        ui = command_latency(client, nice=UI_NICE)
        cyclic_jog_out = (cyclic_jog.communicate(timeout=2 * JOG_S + 30)[0] if cyclic_jog
                          else "")
        warm_report = stopped_report(client)
    ticks = status1.tick - status0.tick
    counts = after.counts - before.counts
    edges = (np.arange(len(counts)) + 1) * HIST_BIN_NS / 1e3
    edges[-1] = np.inf
    return {
        "machine": machine, "pid": pid, "realtime": realtime, "notice": notice,
        "spin_us": spin_us, "seconds": seconds, "period_us": period_us, "ticks": ticks,
        "compute_mean_us": (status1.compute_total_s - status0.compute_total_s)
        / max(ticks, 1) * 1e6,
        "compute_max_us": status1.compute_max_us,
        "io_mean_us": (status1.io_total_s - status0.io_total_s) / max(ticks, 1) * 1e6,
        "cpu_pct": 100 * (cpu1 - cpu0) / (wall1 - wall0),
        "overruns": status1.overruns - status0.overruns,
        "jog_ms": CommandLatency.figures(latency.backend),
        "jog_seen_ms": CommandLatency.figures(latency.seen),
        "jog_exact": float(latency.exact.mean()),
        "jog_ui_ms": CommandLatency.figures(ui.backend),
        "jog_ui_seen_ms": CommandLatency.figures(ui.seen),
        "jog_ui_exact": float(ui.exact.mean()),
        "jog_cyclictest": parse_cyclictest(cyclic_jog_out) if cyclic_jog_out else None,
        "servodesk": Lateness.from_histogram(
            edges, counts, after.max_us, after.min_us,
            (after.mean_us * after.ticks - before.mean_us * before.ticks)
            / max(after.ticks - before.ticks, 1)),
        "cyclictest": parse_cyclictest(cyclic_out) if cyclic_out else None,
        "whole_run": (after.min_us, after.mean_us, after.max_us, after.ticks),
        "warm_report": warm_report,
    }


def stopped_report(client: ControlClient) -> dict[str, int] | None:
    """Stop the control process (SIGTERM ends its loop) and read the warm-up counters it
    wrote to stderr on the way out (``SERVODESK_WARM_UP=report``); None if it wrote none."""
    os.kill(client.pid, signal.SIGTERM)
    end = time.monotonic() + 5.0
    while client.alive and time.monotonic() < end:
        time.sleep(0.01)
    found = re.search(r"warm-up: windows (\d+), ran (\d+), pieces (\d+), skipped (\d+), "
                      r"late (\d+), max (\d+) ns", client.controller_log())
    if found is None:
        return None
    return dict(zip(("windows", "ran", "pieces", "skipped", "late", "late_max_ns"),
                    map(int, found.groups()), strict=True))


def run(seconds: float, machine: str, spin_us: float, warmup: float,
        sample_time_ms: float | None) -> None:
    print(f"machine: {platform.node()} {platform.machine()}, {os.cpu_count()} CPUs, "
          f"{platform.system()} {platform.release()}, Python {platform.python_version()}")
    print(f"code measured: {Path(sys.modules['control'].__file__).parents[1]}")
    m = measure(seconds, machine, spin_us, warmup, sample_time_ms)
    fifo = "granted" if m["realtime"] else "refused"
    print(f"control process pid {m['pid']}: SCHED_FIFO {fifo}"
          f"{' - ' + m['notice'] if m['notice'] else ''}; spin {spin_us:g} µs")
    median, p99, worst, n = m["jog_ms"]
    print(f"\nservodesk loop, {machine}, period {m['period_us']} µs, {seconds:g} s, "
          f"{m['ticks']} ticks")
    control_us = m["compute_mean_us"] - m["io_mean_us"]
    print(f"  compute per six-joint tick: mean {m['compute_mean_us']:.1f} µs (controller "
          f"{control_us:.1f} µs + backend read/write {m['io_mean_us']:.1f} µs), "
          f"max {m['compute_max_us']:.0f} µs; {100 * m['compute_mean_us'] / m['period_us']:.0f} % "
          f"of the period (target <= 25 %)")
    print(f"  the same ticks in a tight loop: {m['tight_us']:.1f} µs (backend read/write "
          f"{m['tight_io_us']:.1f} µs); live / tight {m['compute_mean_us'] / m['tight_us']:.2f} "
          f"(target <= 1.5), backend {m['io_mean_us'] / m['tight_io_us']:.2f}, controller "
          f"{control_us / (m['tight_us'] - m['tight_io_us']):.2f}")
    warm = m["warm"]
    if warm is not None:
        print(f"  warm-up (shadow pieces in the window before each deadline), by turns in one "
              f"real-time child: compute {warm['on_us']:.1f} µs with it, {warm['off_us']:.1f} µs "
              f"without ({warm['on_us'] / warm['off_us'] - 1:+.0%}); wake-up p99 "
              f"{warm['on_p99_us']:.0f} µs with it, {warm['off_p99_us']:.0f} without; "
              f"{windows_text(warm, warm['late_max_us'])}"
              + (f"; error: {warm['error']}" if warm["error"] else ""))
    counted = m["warm_report"]
    if counted is not None:
        print(f"  warm-up in this control process: "
              f"{windows_text(counted, counted['late_max_ns'] / 1e3)}")
    cold = m["cold"]
    if cold is not None:
        ct = cold["cyclictest"]
        ratio = f"{cold['servodesk'].p99 / max(ct.p99, 1):.2f}" if ct is not None else "-"
        print(f"  without the warm-up ({WARM_UP_ENV}=0; the same code, next in this run): "
              f"compute {cold['compute_mean_us']:.1f} µs, live / tight "
              f"{cold['compute_mean_us'] / m['tight_us']:.2f}, wake-up p99 "
              f"{cold['servodesk'].p99:.0f} µs (ratio to cyclictest {ratio}), "
              f"{cold['servodesk'].over_20us} ticks woke >= 20 µs late, "
              f"{cold['cpu_pct']:.1f} % of a core, {cold['overruns']} overruns")
    print(f"  CPU use of the control process: {m['cpu_pct']:.1f} % of a core")
    print(f"  overruns: {m['overruns']}")
    print(f"  client.jog -> duty at the backend: median {median:.2f} ms, p99 {p99:.2f} ms, "
          f"max {worst:.2f} ms over {n} commands (target: median <= 1, p99 <= 2)")
    for label, key in (("", "jog"), (f"  at the TUI's priority (nice {UI_NICE}): ", "jog_ui")):
        if label:
            ui_median, ui_p99, ui_worst, ui_n = m[f"{key}_ms"]
            print(f"   {label}median {ui_median:.2f} ms, p99 {ui_p99:.2f} ms, max "
                  f"{ui_worst:.2f} ms over {ui_n} commands")
        seen_median, seen_p99, seen_worst, _ = m[f"{key}_seen_ms"]
        print(f"      seen by the client polling the status: median {seen_median:.2f} ms, p99 "
              f"{seen_p99:.2f} ms, max {seen_worst:.2f} ms; {100 * m[f'{key}_exact']:.0f} % "
              "exact (the rest: the client missed the tick before, an upper bound)")
    jog_ct = m["jog_cyclictest"]
    print("    cyclictest beside them: " + (f"p99 {jog_ct.p99:.0f} µs, max {jog_ct.max_us:.0f} µs"
                                          if jog_ct is not None else "not installed"))
    ours, ct = m["servodesk"], m["cyclictest"]
    header = f"  {'':<22}{'p50':>8}{'p99':>8}{'p99.9':>8}{'max':>9}{'>1 ms':>8}{'>=20 µs':>9}"
    print("\nwake-up lateness (µs; servodesk in 5 µs bins, upper edges)")
    print(header)
    print(f"  {'servodesk':<22}{ours.p50:>8.0f}{ours.p99:>8.0f}{ours.p999:>8.0f}"
          f"{ours.max_us:>9.0f}{ours.over_1ms:>8d}{ours.over_20us:>9d}")
    if ct is not None:
        print(f"  {'cyclictest (C)':<22}{ct.p50:>8.0f}{ct.p99:>8.0f}{ct.p999:>8.0f}"
              f"{ct.max_us:>9.0f}{ct.over_1ms:>8d}{ct.over_20us:>9d}")
        print(f"  ratio p99 servodesk/cyclictest: {ours.p99 / max(ct.p99, 1):.2f} "
              f"(target <= 1.5); ticks > 1 ms: {ours.over_1ms} vs {ct.over_1ms}")
    else:
        print("  cyclictest: not installed (apt-get install rt-tests) - no comparison")
    print(f"  thesis Table 2.1 (486-66, RTL): min {TABLE_2_1['min_us']} mean "
          f"{TABLE_2_1['mean_us']} max {TABLE_2_1['max_us']} over {TABLE_2_1['ticks']} interrupts")
    low, mean, high, total = m["whole_run"]
    print(f"  servodesk over the whole run: min {low:.1f} mean {mean:.1f} "
          f"max {high:.1f} over {total} ticks")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=10.0)
    parser.add_argument("--machine", default="unimate2000b")
    parser.add_argument("--spin-us", type=float, default=SPIN_US,
                        help=f"spin this long before each deadline (default {SPIN_US:g})")
    parser.add_argument("--warmup", type=float, default=1.0)
    parser.add_argument("--sample-time-ms", type=float, default=None,
                        help="run the machine file with this sample_time_ms (0.5: 2 kHz)")
    args = parser.parse_args()
    run(args.seconds, args.machine, args.spin_us, args.warmup, args.sample_time_ms)


if __name__ == "__main__":
    main()
