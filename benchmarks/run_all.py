"""Run every benchmark and the fault-injection suite; write the README's Performance and
Reliability sections, and docs/reliability.md, from what they measured.

    python benchmarks/run_all.py              # about 5 minutes on the two-core VM
    python benchmarks/run_all.py --quick      # shorter runs, fewer repeats
    python benchmarks/run_all.py --no-faults  # benchmarks only; Reliability left as it is

Calls the ``measure``-style functions of ``loop.py``, ``kinematics.py``,
``law.py``, ``hw.py`` and ``serial_rtt.py``; runs ``ui.py``, ``tracking.py`` and
``cartesian_jog.py``
(``python -m benchmarks.NAME``) and reads their printed figures; runs ``pytest tests/faults`` with
``SERVODESK_FAULT_REPORT`` set, so every fault case reports what it proved
(its docstring), its outcome and the latencies it measured. A benchmark that
fails is reported as not measured, with its last words, and the rest go on.
Only the text between the README's ``performance`` and ``reliability``
markers is rewritten.
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import os
import platform
import re
import subprocess
import sys
import tempfile
import time
import traceback
from collections.abc import Callable
from datetime import UTC, datetime
from pathlib import Path
from types import ModuleType

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # ahead of benchmarks/, whose hw.py would hide the hw package

import numpy as np  # noqa: E402

from control import ControlClient  # noqa: E402
from control.motion import moves  # noqa: E402

README = ROOT / "README.md"
RELIABILITY_DOC = ROOT / "docs" / "reliability.md"
MARKERS = {"performance": ("<!-- performance:begin -->", "<!-- performance:end -->"),
           "reliability": ("<!-- reliability:begin -->", "<!-- reliability:end -->")}
TABLE_2_1 = "thesis Table 2.1 (486-66, RT-Linux 1.0, 100,290 interrupts)"
FAMILIES = {  # test file → what is injected, in the order the issue lists them
    "test_controller_death": "`kill -9` of the control process",
    "test_client_loss": "The UI side frozen or killed",
    "test_serial_link": "Serial link: corruption, dropped frames, the port vanishing",
    "test_encoder_glitches": "Encoder glitches (thesis section 6.2)",
    "test_limits": "A joint at its limit, a following error",
    "test_estop_modes": "E-stop during every mode",
    "test_cpu_starvation": "CPU starvation",
    "test_disk_full": "Disk full, unusable data directory",
    "test_bad_input": "Bad input (hypothesis)",
}
FIGURES = {  # figure key → (how the README says it, number format, scale)
    "client_told_ms": ("client told after {} ms", ".0f", 1.0),
    "board_watchdog_ms": ("board's watchdog closed the valves {} ms after the last command",
                          ".0f", 1.0),
    "hold_after_freeze_ms": ("held {} ms after the freeze", ".0f", 1.0),
    "hold_after_kill_ms": ("held {} ms after the kill", ".0f", 1.0),
    "ticks_per_s_while_frozen": ("{} ticks/s while the client was frozen", ".0f", 1.0),
    "exit_after_kill_s": ("exited {} s after the kill (orphan timeout 1.5 s)", ".2f", 1.0),
    "host_damaged_frames": ("{} damaged reports counted by the host", ".0f", 1.0),
    "board_damaged_frames": ("{} damaged commands counted by the board", ".0f", 1.0),
    "frames_each_way": ("of {} frames each way", ",.0f", 1.0),
    "reports_missing": ("{} reports missing", ".0f", 1.0),
    "motion_stopped_ms": ("E-stop latched {} ms after the port vanished", ".0f", 1.0),
    "silence_before_link_lost_ms": ("link declared lost after {} ms of silence", ".0f", 1.0),
    "overruns_during_loss": ("{} deadlines missed during the loss", ".0f", 1.0),
    "false_glitches": ("{} real readings rejected as glitches", ".0f", 1.0),
    "rejected_readings": ("{} wrong readings rejected", ".0f", 1.0),
    "peak_duty_clean_pct": ("peak duty {} % clean", ".1f", 1.0),
    "peak_duty_glitchy_pct": ("{} % with glitches", ".1f", 1.0),
    "latched_after_ms": ("latched {} ms after the command", ".1f", 1.0),
    "ticks_from_last_seen_to_latch": ("{} tick(s) after the last status seen", ".0f", 1.0),
    "estop_latched_under_load_ms": ("E-stop latched {} ms after the command under load",
                                    ".0f", 1.0),
    "overruns": ("{} overruns", ".0f", 1.0),
    "ticks": ("in {} ticks", ",.0f", 1.0),
    "late_max_us": ("worst lateness {} µs", ".0f", 1.0),
    "compute_max_us": ("worst tick compute {} µs", ".0f", 1.0),
    "run_bytes": ("a {} MB run", ".1f", 1e-6),
}
HIDDEN_FIGURES = {"burners", "realtime"}


# -- the benchmarks ---------------------------------------------------------------------------


def load(name: str) -> ModuleType:
    """``benchmarks/NAME.py`` as a module (by path: ``hw.py`` must not shadow ``hw``)."""
    spec = importlib.util.spec_from_file_location(f"bench_{name}", ROOT / "benchmarks" /
                                                  f"{name}.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # dataclasses look their module up while it executes
    spec.loader.exec_module(module)
    return module


def attempt(label: str, run: Callable[[], object]) -> object:
    """Run one benchmark; on failure print why and return the reason as a string."""
    print(f"-- {label}", flush=True)
    started = time.monotonic()
    try:
        result = run()
    except Exception as exc:  # a broken benchmark must not stop the others
        traceback.print_exc()
        return f"not measured: {type(exc).__name__}: {exc}"
    print(f"   done in {time.monotonic() - started:.1f} s", flush=True)
    return result


def lockstep_move(seconds: float) -> dict:
    """Wall time of a ``seconds`` six-joint move in a lockstep control process (run saved)."""
    with tempfile.TemporaryDirectory() as runs, ControlClient(
            "unimate2000b", lockstep=True, data_dir=runs, heartbeat_timeout_s=3.0) as robot:
        start = robot.status().position
        end = np.array(start) + np.array([60.0, 20.0, 5.0, 20.0, 20.0, 30.0])
        path = moves.sine(start, end, period=4.0, duration=seconds, machine=robot.machine)
        began = time.perf_counter()
        result = robot.wait(robot.move(path, kind="sine"), timeout=300)
        wall = time.perf_counter() - began
    return {"seconds": seconds, "wall": wall, "status": result.status}


def script(name: str, *args: str, timeout: float = 900) -> str:
    """Run ``python -m benchmarks.NAME ARGS`` from the repository root and return what it
    printed; raise with its last words. As a module, the script's own folder is not first
    on ``sys.path``, where ``benchmarks/hw.py`` would hide the ``hw`` package."""
    done = subprocess.run([sys.executable, "-m", f"benchmarks.{name}", *args], cwd=ROOT,
                          capture_output=True, text=True, timeout=timeout, check=False)
    print(done.stdout, end="")
    if done.returncode != 0:
        last = (done.stderr.strip().splitlines() or ["no output"])[-1]
        raise RuntimeError(f"{name}.py exited {done.returncode}: {last}")
    return done.stdout


def number(pattern: str, text: str) -> float | None:
    match = re.search(pattern, text)
    return float(match.group(1)) if match else None


def parse_ui(text: str) -> dict:
    """The figures ``ui.py`` prints (ms unless said), None where a line is missing."""
    return {
        "braille_ms": number(r"([\d.]+)\s+[\d.]+\s+braille raster", text),
        "plotext_raw_ms": number(r"([\d.]+)\s+[\d.]+\s+plotext raw", text),
        "plotext_decimated_ms": number(r"([\d.]+)\s+[\d.]+\s+plotext decimated", text),
        "frame_median_ms": number(r"frame \(copy \+ raster\)\s+median\s+([\d.]+)", text),
        "frame_p95_ms": number(r"frame \(copy \+ raster\).*p95\s+([\d.]+)", text),
        "update_median_ms": number(r"screen update\s+median\s+([\d.]+)", text),
        "update_p95_ms": number(r"screen update.*p95\s+([\d.]+)", text),
        "fps": number(r"frames per second\s+([\d.]+)", text),
        "key_answer_median_ms": number(r"key answered after\s+median\s+([\d.]+)", text),
        "late_hidden_mean_us": number(r"Status tab shown: mean\s+([\d.]+)", text),
        "late_scope_mean_us": number(r"Scope tab drawing: mean\s+([\d.]+)", text),
        "overruns_hidden": number(r"Status tab shown:.*overruns (\d+)", text),
        "overruns_scope": number(r"Scope tab drawing:.*overruns (\d+)", text),
        "key_to_duty_median_ms": number(r"4\. key to duty[^\n]*\n\s+median\s+([\d.]+)", text),
        "key_to_duty_p95_ms": number(r"4\. key to duty[^\n]*\n.*p95\s+([\d.]+)", text),
        "key_to_duty_max_ms": number(r"4\. key to duty[^\n]*\n.*max\s+([\d.]+)", text),
        "pause_max_ms": number(r"all tabs\s+median\s+[\d.]+, max\s+([\d.]+)", text),
        "pause_load": number(r"load average ([\d.]+) on", text),
        "heartbeat_age_ms": number(r"heartbeat's longest age at the controller\s+([\d.]+)", text),
        "client_silent": number(r"client-silent events (\d+)", text),
    }


def parse_cartesian_jog(text: str) -> dict:
    """The figures ``cartesian_jog.py`` prints: (median, p95, max) per line, None if missing."""
    labels = {"ik_single_us": "IK per jog point, one pose",
              "ik_batch_us": "IK per jog sample, in a plan", "plan_ms": "plan of a",
              "api_ms": "API call → first motion", "key_ms": "key → first motion"}
    out: dict[str, tuple[float, float, float] | None] = {}
    for key, label in labels.items():
        match = re.search(re.escape(label) + r".*?median\s+([\d.]+).*?p95\s+([\d.]+).*?max\s+"
                          r"([\d.]+)", text)
        out[key] = tuple(float(v) for v in match.groups()) if match else None  # type: ignore
    return out


def parse_tracking(text: str) -> dict:
    """``tracking.py``'s error table: column names and rows of (joint, cells)."""
    lines = text.splitlines()
    start = next(i for i, line in enumerate(lines) if line.startswith("tracking error"))
    columns = re.split(r"\s{2,}", lines[start + 1].strip())
    rows = []
    for line in lines[start + 2:]:
        if not line.strip():
            break
        joint, *cells = re.split(r"\s{2,}", line.strip())
        rows.append((joint, cells))
    return {"title": lines[start].strip(), "columns": columns, "rows": rows}


def run_faults(report: Path) -> dict:
    """``pytest tests/faults``: its closing line, wall time, and the per-case report."""
    began = time.monotonic()
    done = subprocess.run([sys.executable, "-m", "pytest", "tests/faults", "-q", "-rxX",
                           "-p", "no:cacheprovider"], cwd=ROOT,
                          env={**os.environ, "SERVODESK_FAULT_REPORT": str(report)},
                          capture_output=True, text=True, timeout=1800, check=False)
    print(done.stdout[-3000:], end="")
    closing = [line.strip("= ") for line in done.stdout.splitlines()
               if re.search(r"\d+ (passed|failed)", line)]
    return {"closing": closing[-1] if closing else f"pytest exited {done.returncode}",
            "wall_s": time.monotonic() - began, "returncode": done.returncode,
            "cases": json.loads(report.read_text()) if report.is_file() else {}}


# -- the machine --------------------------------------------------------------------------------


def machine_description() -> str:
    cpu = "unknown CPU"
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return (f"{cpu}, {os.cpu_count()} cores, {platform.system()} {platform.release()}, "
            f"Python {platform.python_version()}, numpy {np.__version__}")


# -- rendering ----------------------------------------------------------------------------


def fmt(value: float | None, spec: str = ".0f") -> str:
    if value is None:
        return "–"
    if isinstance(value, float) and not np.isfinite(value):
        return "≥ 2000"
    return format(value, spec)


def table(header: list[str], rows: list[list[str]]) -> list[str]:
    out = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    out += ["| " + " | ".join(row) + " |" for row in rows]
    return out


def performance_section(r: dict, when: str, machine: str, quick: bool) -> str:
    out = [f"Generated by `python benchmarks/run_all.py{' --quick' if quick else ''}` on "
           f"{when}, on {machine} (a shared virtual machine: other work runs beside it, so "
           "figures move from run to run; each is one run, not a best case).", ""]
    out += loop_part(r["loop"]) + kinematics_part(r["kinematics"]) + speed_part(r)
    out += latency_part(r) + scope_part(r["ui"]) + law_part(r["law"])
    out += tracking_part(r["tracking"])
    out += ["### Reproduce", "", "From the repository root:", "", "```sh",
            "python benchmarks/run_all.py               # all of these, then rewrites this "
            "section",
            "python -m benchmarks.loop --seconds 10     # lateness beside cyclictest (apt-get "
            "install rt-tests)",
            "python -m benchmarks.kinematics            # pip install roboticstoolbox-python "
            "to compare",
            "python -m benchmarks.hw                    # simulator speed, then the serial "
            "round trip",
            "python -m benchmarks.serial_rtt            # --port /dev/ttyACM0 for a real board",
            "python -m benchmarks.law",
            f"python -m benchmarks.ui{' --quick' if quick else ''}"
            "                      # Scope frame time, key to valve, UI pauses",
            "python -m benchmarks.ui --pauses             # UI pauses opening every tab beside "
            "a CPU burner",
            "python -m benchmarks.ui --soak 300           # every tab in tmux beside a burner "
            "for 5 min: client-silent events",
            "python -m benchmarks.tracking",
            "python -m benchmarks.cartesian_jog       # IK per jog step, key → first motion",
            "```"]
    return "\n".join(out)


def not_measured(section: str, reason: object) -> list[str]:
    return [f"### {section}", "", f"{reason}", ""]


def loop_part(m: object) -> list[str]:
    title = "Control loop: wake-up lateness"
    if isinstance(m, str):
        return not_measured(title, m)
    ours, ct = m["servodesk"], m["cyclictest"]
    fifo = "SCHED_FIFO granted" if m["realtime"] else f"no SCHED_FIFO ({m['notice']})"
    rows = [["servodesk (Python, " + ("SCHED_FIFO" if m["realtime"] else "normal priority")
             + ", 5 µs bins)", fmt(ours.min_us, ".1f"), fmt(ours.mean_us, ".1f"),
             fmt(ours.p50), fmt(ours.p99), fmt(ours.p999), fmt(ours.max_us),
             str(ours.over_1ms)]]
    if ct is not None:
        rows.append(["cyclictest (C, same run, other core)", fmt(ct.min_us, ".0f"),
                     fmt(ct.mean_us, ".0f"), fmt(ct.p50), fmt(ct.p99), fmt(ct.p999),
                     fmt(ct.max_us), str(ct.over_1ms)])
    rows.append([TABLE_2_1, "11.5", "13.97", "–", "–", "–", "54", "–"])
    median, p99, worst, n = m["jog_ms"]
    return [f"### {title} (µs), {m['period_us']} µs period, {m['seconds']:g} s",
            "", *table(["", "min", "mean", "p50", "p99", "p99.9", "max", "ticks > 1 ms"], rows),
            "", f"Compute per six-joint tick: mean {m['compute_mean_us']:.1f} µs (the controller "
            f"{m['compute_mean_us'] - m['io_mean_us']:.1f} µs, the simulator's read and write "
            f"{m['io_mean_us']:.1f} µs), worst {m['compute_max_us']:.0f} µs; spinning the last "
            f"{m['spin_us']:g} µs before each deadline; the control "
            f"process used {m['cpu_pct']:.1f} % of a core; {m['overruns']} overruns in "
            f"{m['ticks']:,} ticks; {fifo}. servodesk's min and max are over its whole run "
            f"(the histogram keeps only those), the rest over the window; cyclictest's max is "
            f"its own. `client.jog` → duty at the backend: median {median:.2f} ms, p99 "
            f"{p99:.2f} ms, max {worst:.2f} ms over {n} commands.", ""]


def kinematics_part(m: object) -> list[str]:
    title = "Kinematics: the closed-form inverse beside the Robotics Toolbox"
    if isinstance(m, str):
        return not_measured(title, m)
    rows = [["servodesk closed form, one pose at a time", fmt(m["ik_single_us"], ".1f"),
             f"{1e6 / m['ik_single_us']:,.0f}", fmt(m["success_single_pct"], ".1f") + " %",
             "every in-limit branch, nearest first"],
            [f"servodesk closed form, batch of {m['n']:,}",
             fmt(1e6 / m["ik_batch_poses_s"], ".2f"), f"{m['ik_batch_poses_s']:,.0f}",
             fmt(m["success_batch_pct"], ".1f") + " %", "all 8 branches"]]
    rtb = m["rtb"]
    note = ""
    if isinstance(rtb, dict):
        rows.append([f"Robotics Toolbox {rtb['version']} `ik_LM` (numerical, C++), one pose",
                     fmt(rtb["median_us"], ".1f"), f"{rtb['poses_s']:,.0f}",
                     fmt(rtb["success_pct"], ".1f") + " %", "one solution"])
    else:
        note = f" Robotics Toolbox: {rtb}."
    return [f"### {title}", "",
            *table(["inverse kinematics", "µs per pose (median)", "poses/s", "solved",
                    "returns"], rows),
            "", f"Forward kinematics: {m['fk_poses_s']:,.0f} poses/s in a batch. Poses from "
            f"{m['n']:,} random in-limit configurations (seed {m['seed']}); single-pose "
            f"figures over {m['single']:,} of them, the toolbox over "
            f"{rtb['poses'] if isinstance(rtb, dict) else 0} (its ETS built once). "
            f"Worst error of the chosen solution: {m['max_dp_mm']:.0e} mm.{note}", ""]


def speed_part(r: dict) -> list[str]:
    title = "Simulator speed (× real time)"
    hw, lock = r["hw"], r["lockstep"]
    if isinstance(hw, str):
        return not_measured(title, hw)
    s = hw["seconds"]
    rows = [["Unimate simulator alone (read + write, 1 ms ticks)", f"{hw['unimate_io_wall']:.3f}",
             f"{s / hw['unimate_io_wall']:.0f}×"],
            ["Unimate six-axis move, simulator + a P.I. loop in Python",
             f"{hw['unimate_move_wall']:.3f}", f"{s / hw['unimate_move_wall']:.0f}×"],
            ["Rig simulator alone", f"{hw['rig_io_wall']:.3f}", f"{s / hw['rig_io_wall']:.0f}×"],
            ["Rig PID steps 200 → 600 → 200 mm", f"{hw['rig_steps_wall']:.3f}",
             f"{s / hw['rig_steps_wall']:.0f}×"]]
    if isinstance(lock, dict):
        rows.append([f"the control process in lockstep: a {lock['seconds']:g} s six-joint move "
                     "through `ControlClient`, run saved", f"{lock['wall']:.3f}",
                     f"{lock['seconds'] / lock['wall']:.0f}×"])
    return [f"### {title}", "", *table([f"{s:g} s of simulated time", "wall s", "× real time"],
                                       rows), ""]


def latency_part(r: dict) -> list[str]:
    rows = []
    ui, loop, serial = r["ui"], r["loop"], r["serial"]
    if isinstance(ui, dict) and ui["key_to_duty_median_ms"] is not None:
        rows.append(["key press in the TUI (Jog tab) → duty published by the controller",
                     fmt(ui["key_to_duty_median_ms"], ".2f") + " ms",
                     "p95 " + fmt(ui["key_to_duty_p95_ms"], ".2f") + " ms",
                     fmt(ui["key_to_duty_max_ms"], ".2f") + " ms"])
    if isinstance(loop, dict):
        median, p99, worst, _ = loop["jog_ms"]
        rows.append(["`client.jog` → duty at the backend", f"{median:.2f} ms",
                     f"p99 {p99:.2f} ms", f"{worst:.2f} ms"])
    if isinstance(serial, dict):
        rtts = serial["rtts_us"]
        late = sum(v > 1000 for v in rtts)
        rows.append(["serial DUTY → REPORT, emulated board on a pty (1 kHz)",
                     f"{rtts[len(rtts) // 2]:.0f} µs",
                     f"p99 {rtts[min(len(rtts) - 1, int(0.99 * len(rtts)))]:.0f} µs",
                     f"{rtts[-1]:.0f} µs ({late} of {len(rtts):,} later than a tick)"])
    jog = r.get("cartesian_jog")
    if isinstance(jog, dict):
        for key, path in (("key_ms", "Cartesian jog key (Jog tab, world frame, 1 mm) → first "
                                     "tick of the jog"),
                          ("api_ms", "`robot.jog_cartesian` (1 mm) → first tick of the jog")):
            if jog[key] is not None:
                median, p95, worst = jog[key]
                rows.append([path, f"{median:.2f} ms", f"p95 {p95:.2f} ms", f"{worst:.2f} ms"])
    problems = [v for v in (ui, loop, serial, jog) if isinstance(v, str)]
    ik = []
    if isinstance(jog, dict) and None not in (jog["ik_single_us"], jog["ik_batch_us"],
                                              jog["plan_ms"]):
        ik = ["", f"Inverse kinematics per Cartesian jog step (`benchmarks/cartesian_jog.py`): "
              f"{jog['ik_single_us'][0]:.1f} µs one pose (median, p95 "
              f"{jog['ik_single_us'][1]:.1f} µs), {jog['ik_batch_us'][0]:.1f} µs a sample in "
              f"a planned jog (median, p95 {jog['ik_batch_us'][1]:.1f} µs); a whole 1 mm step "
              f"planned in {jog['plan_ms'][0]:.2f} ms (median, p95 {jog['plan_ms'][1]:.2f} ms)."]
    return ["### Key to valve", "", *table(["path", "median", "tail", "max"], rows), *ik,
            *(["", "Not measured: " + "; ".join(problems)] if problems else []), ""]


def scope_part(ui: object) -> list[str]:
    title = "Scope frame time (six joints × 2,000 points, 160 × 48 terminal)"
    if isinstance(ui, str):
        return not_measured(title, ui)
    rows = [["Scope frame in the app (copy the window, braille raster)",
             fmt(ui["frame_median_ms"], ".1f"), fmt(ui["frame_p95_ms"], ".1f")],
            ["Textual screen update of that frame", fmt(ui["update_median_ms"], ".1f"),
             fmt(ui["update_p95_ms"], ".1f")],
            ["renderer alone: braille raster (best)", fmt(ui["braille_ms"], ".1f"), "–"],
            ["renderer alone: plotext, raw points (best)", fmt(ui["plotext_raw_ms"], ".1f"), "–"],
            ["renderer alone: plotext, decimated (best)", fmt(ui["plotext_decimated_ms"], ".1f"),
             "–"]]
    return [f"### {title}", "", *table(["ms", "median", "p95"], rows), "",
            f"{fmt(ui['fps'], '.1f')} frames/s reached; a key waits "
            f"{fmt(ui['key_answer_median_ms'], '.1f')} ms (median) while the Scope draws. "
            f"Controller lateness with the Status tab shown: mean "
            f"{fmt(ui['late_hidden_mean_us'], '.1f')} µs, {fmt(ui['overruns_hidden'])} overruns; "
            f"with the Scope drawing: mean {fmt(ui['late_scope_mean_us'], '.1f')} µs, "
            f"{fmt(ui['overruns_scope'])} overruns.", "",
            f"Opening every tab for the first time beside a CPU burner: the UI's longest pause "
            f"{fmt(ui['pause_max_ms'], '.0f')} ms (target < 100; load average "
            f"{fmt(ui['pause_load'], '.1f')}), the heartbeat's longest age at the controller "
            f"{fmt(ui['heartbeat_age_ms'], '.0f')} ms (it holds at 250), "
            f"{fmt(ui['client_silent'])} client-silent events.", ""]


def law_part(law: object) -> list[str]:
    title = "Controller law (eq. 5.1): µs per six-joint update"
    if isinstance(law, str):
        return not_measured(title, law)
    return [f"### {title}", "", *table(["case", "µs"], [[label, f"{us:.2f}"]
                                                         for label, us in law]), ""]


def tracking_part(tracking: object) -> list[str]:
    title = "Tracking a section 6.4 Cartesian path (lockstep simulator)"
    if isinstance(tracking, str):
        return not_measured(title, tracking)
    return [f"### {title}", "", f"{tracking['title']} (from `benchmarks/tracking.py`):", "",
            *table(["joint", *tracking["columns"]], [[j, *cells] for j, cells in
                                                     tracking["rows"]]), ""]


# -- reliability ----------------------------------------------------------------------------


def grouped(cases: dict) -> dict[str, dict[str, list[tuple[str, dict]]]]:
    """family file → test function → [(parameters, case)], in file order."""
    out: dict[str, dict[str, list[tuple[str, dict]]]] = {}
    for nodeid, case in cases.items():
        path, _, name = nodeid.partition("::")
        function, _, params = name.partition("[")
        out.setdefault(Path(path).stem, {}).setdefault(function, []).append(
            (params.rstrip("]"), case))
    order = list(FAMILIES)
    return dict(sorted(out.items(), key=lambda item: order.index(item[0])
                       if item[0] in order else len(order)))


OUTCOMES = {"passed": "passed", "xfailed": "xfail: known bug", "failed": "FAILED",
            "skipped": "skipped"}


def outcome(runs: list[tuple[str, dict]]) -> str:
    results = [case["outcome"] for _, case in runs]
    if len(set(results)) == 1:
        label = OUTCOMES.get(results[0], results[0] or "not run")
        return label if len(results) == 1 else f"{len(results)}/{len(results)} {label}"
    return ", ".join(f"{results.count(r)} {OUTCOMES.get(r, r)}" for r in sorted(set(results)))


def measured_text(runs: list[tuple[str, dict]]) -> str:
    """The figures of a test's runs in words; a range where parameter sets differ."""
    values: dict[str, list[float]] = {}
    for _, case in runs:
        for key, (value, _unit) in case["figures"].items():
            values.setdefault(key, []).append(value)
    parts = []
    for key, seen in values.items():
        if key in HIDDEN_FIGURES:
            continue
        template, spec, scale = FIGURES.get(key, (key.replace("_", " ") + " {}", ".3g", 1.0))
        low, high = (format(v * scale, spec) for v in (min(seen), max(seen)))
        parts.append(template.format(low if low == high else f"{low}–{high}"))
    return "; ".join(parts)


def title_of(function: str) -> str:
    return function.removeprefix("test_").replace("_", " ").capitalize()


def reliability_section(faults: dict, when: str, machine: str) -> str:
    cases = faults["cases"]
    out = [f"Generated by `python benchmarks/run_all.py`, which runs `python -m pytest "
           f"tests/faults` ({faults['closing']}) on {when}, on "
           f"{machine}. Each case runs the real control subprocess (the simulator, and for the "
           "serial cases `servodesk emulate` in another process over a pty or TCP), injects the "
           "fault mid-move and checks the safe outcome and that the run up to the fault is on "
           "disk. Latencies are measured, not asserted tightly: the bounds in the tests are "
           "generous, so a noisy machine cannot make them flaky.", ""]
    families = grouped(cases)
    rows = [[FAMILIES.get(family, family), runs[0][1]["doc"].replace("|", "\\|"),
             measured_text(runs) or "–", outcome(runs)]
            for family, functions in families.items() if family != "test_bad_input"
            for runs in functions.values()]
    out += [*table(["fault", "what the test proved", "measured", "result"], rows), ""]
    bad = families.get("test_bad_input", {})
    tried = {f: sum(c["examples"] for _, c in runs) for f, runs in bad.items()}
    properties = sum(1 for n in tried.values() if n)
    out += [f"**Bad input**: {sum(tried.values()):,} generated cases across {properties} "
            "properties, each ending in a clear one-line error of the parser's own type that "
            "names its source, or in a value that keeps the parser's promises; nothing "
            "started.", ""]
    out += [*table(["property", "cases tried", "result"],
                   [[title_of(f), f"{tried[f]:,}" if tried[f] else "example-based",
                     outcome(runs)] for f, runs in bad.items()]), ""]
    known = sorted({case["reason"] for functions in families.values()
                    for runs in functions.values() for _, case in runs
                    if case["outcome"] == "xfailed"})
    if known:
        out += ["**Known bugs.** Each is shown by a strict `xfail` test (in the tables above as "
                "\"xfail: known bug\"), which turns the suite red the day the bug is fixed so "
                "that its marker goes. Details per case: "
                "[docs/reliability.md](docs/reliability.md).", ""]
        out += [*(f"- {reason.removeprefix('bug: ')}" for reason in known), ""]
    out += [f"Reproduce: `python -m pytest tests/faults` ({faults['wall_s']:.0f} s here; "
            "`SERVODESK_FAULT_REPORT=report.json` also writes what each case measured)."]
    return "\n".join(out)


def reliability_doc(faults: dict, when: str, machine: str) -> str:
    """docs/reliability.md: every case, every parameter set, its figures and duration."""
    out = ["# Reliability: the fault-injection suite", "",
           f"Generated by `python benchmarks/run_all.py` on {when}, on {machine}: "
           f"{faults['closing']}.", "",
           "Every case below is a test in `tests/faults/`; its text is the test's docstring. "
           "\"xfail\" marks a strict expected failure: the test shows a bug that is not fixed "
           "yet (its reason names the bug and where it is), and it fails the suite once the "
           "bug is fixed, so that the marker is removed.", ""]
    for family, functions in grouped(faults["cases"]).items():
        out += [f"## {FAMILIES.get(family, family)}", "", f"`tests/faults/{family}.py`", ""]
        for function, runs in functions.items():
            out += [f"### {title_of(function)}", "", runs[0][1]["doc"], ""]
            reasons = {case["reason"] for _, case in runs if case["reason"]}
            out += [f"Known bug: {reason.removeprefix('bug: ')}" for reason in reasons]
            out += [""] if reasons else []
            for params, case in runs:
                figures = ", ".join(f"{k} {v:g}{(' ' + u) if u else ''}"
                                    for k, (v, u) in case["figures"].items())
                examples = f", {case['examples']:,} examples" if case["examples"] else ""
                label = f"`[{params}]` " if params else ""
                out.append(f"- {label}{case['outcome'] or 'not run'} in "
                           f"{case['duration_s']:.1f} s{examples}"
                           + (f": {figures}" if figures else ""))
            out.append("")
    return "\n".join(out) + "\n"


def rewrite(path: Path, which: str, body: str) -> None:
    begin, end = MARKERS[which]
    text = path.read_text()
    head, rest = text.split(begin, 1)
    _, tail = rest.split(end, 1)
    path.write_text(f"{head}{begin}\n{body}\n{end}{tail}")


# -- main -------------------------------------------------------------------------------------


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="shorter runs, fewer repeats")
    parser.add_argument("--no-faults", action="store_true",
                        help="skip the fault suite and leave the Reliability section")
    parser.add_argument("--readme", type=Path, default=README, help="the README to rewrite")
    args = parser.parse_args(argv)
    when = datetime.now(UTC).strftime("%Y-%m-%d %H:%M UTC")
    machine = machine_description()
    print(f"machine: {machine}")
    quick = args.quick
    r = {
        "loop": attempt("loop.py", lambda: load("loop").measure(5.0 if quick else 10.0)),
        "kinematics": attempt("kinematics.py", lambda: load("kinematics").measure(
            20_000 if quick else 100_000, 500 if quick else 2000, 50 if quick else 200)),
        "law": attempt("law.py", lambda: load("law").measure()),
        "hw": attempt("hw.py", lambda: load("hw").measure()),
        "lockstep": attempt("lockstep move", lambda: lockstep_move(10.0)),
        "serial": attempt("serial_rtt.py", lambda: load("serial_rtt").run(
            3.0 if quick else 10.0)),
        "ui": attempt("ui.py", lambda: parse_ui(script("ui", *(["--quick"] if quick else [])))),
        "tracking": attempt("tracking.py", lambda: parse_tracking(script("tracking"))),
        "cartesian_jog": attempt("cartesian_jog.py", lambda: parse_cartesian_jog(script(
            "cartesian_jog", *(["--jogs", "20"] if quick else [])))),
    }
    rewrite(args.readme, "performance", performance_section(r, when, machine, quick))
    print(f"rewrote the Performance section of {args.readme}")
    if not args.no_faults:
        print("-- tests/faults", flush=True)
        with tempfile.TemporaryDirectory() as tmp:
            faults = run_faults(Path(tmp) / "faults.json")
        rewrite(args.readme, "reliability", reliability_section(faults, when, machine))
        RELIABILITY_DOC.write_text(reliability_doc(faults, when, machine))
        print(f"rewrote the Reliability section and {RELIABILITY_DOC.relative_to(ROOT)}: "
              f"{faults['closing']}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
