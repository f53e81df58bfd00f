"""Control quality per joint on both machines: the default controller beside the thesis P.I.

Run: ``PYTHONPATH=. python benchmarks/control_quality.py [--machines unimate2000b rig]
[--rest 5] [--svg docs/wrist_response.svg] [--sample-time-ms 0.5]`` (2-4 min on a busy
two-core machine: every move runs the real control subprocess on the lockstep simulator; each
rest is real time). ``--sample-time-ms`` runs copies of the machine files with that loop period
(0.5: 2 kHz; the gains' Δt terms scale with it, ``control/rt/law.py``).

Controllers: ``default`` is the machine file's hold and track sets; ``thesis P.I.`` is the
Unimate's ``thesis_pi`` (section 5.4.2) as both sets, and the rig's ``thesis_hold`` and
``thesis_track`` (function.c's hold, eq. 3.3's PID; the file's hold and track before issue 24).

Per joint, each joint alone from mid-range (the rig's ram from 600 mm), the other joints
holding; the wrist row moves Bend and Yaw together and reports the worse of the two:

* step: a ``STEP`` change at once; go_to at 0.25, 0.5 and 1.0 of max speed and acceleration
  (the minimum-jerk quintic of ``ControlClient.go_to``), each path followed by a dwell of
  ``DWELL_S`` on its end: ``over`` the overshoot past the target (units), ``settle`` the
  time after the path arrives until the joint stays within ±0.5° / ±1 mm (s; ``>`` the dwell
  when never), ``rms`` the tracking error while the path moves (units);
* ramp: ``STEP`` at a constant half of max speed (parabolic blends): ``rms`` while it moves;
* sine: one ``STEP`` swing at half of max speed peak, three periods: the amplitude ratio and
  the phase lag (deg) of the actual's fundamental (``moves.sine_summary``);
* rest: ``REST_S`` s of holding, from ``REST_AFTER_S`` after the last move, the status read
  about every millisecond: ``p-p`` the position's peak to peak (encoder counts) and ``rev/s``
  the controller output's sign changes a second (a valve reversal between its minimum PWMs).

``--svg`` writes the wrist's (Bend and Yaw together, go_to at full speed) desired and actual
positions and duty under both controllers as one figure (``app.plotting.svg``).
"""

from __future__ import annotations

import argparse
import math
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # ahead of benchmarks/hw.py

from loop import machine_at

from control import ControlClient
from control.motion import form_plans, moves
from hw.machine import Coefficients, Machine, load_machine

STEP = {"inout": 100.0, "rotate": 20.0, "updown": 10.0, "bend": 10.0, "yaw": 10.0,
        "swivel": 20.0, "ram": 100.0}
SPEEDS = (0.25, 0.5, 1.0)
DWELL_S = 2.0
REST_S = 5.0
REST_AFTER_S = 3.0  # the thesis's gains swing for seconds after a move: rest begins later
RIG_START = 600.0
BAND = {"deg": 0.5, "mm": 1.0}  # issue 24's settle band
WRIST = (3, 4)  # Bend and Yaw


@dataclass(frozen=True)
class Response:
    """One joint's figures for one move: overshoot, settle after arrival, tracking RMS."""

    over: float
    settle: float
    rms: float


def controllers(machine: Machine) -> dict[str, tuple[Coefficients, Coefficients]]:
    """The two controllers compared: (hold, track) sets by column."""
    c = machine.coefficients
    if "thesis_pi" in c:
        thesis = (c["thesis_pi"], c["thesis_pi"])
    else:  # the rig's: before issue 24 they were its hold and track sets
        thesis = (c.get("thesis_hold", machine.hold), c.get("thesis_track", machine.track))
    return {"default": (machine.hold, machine.track), "thesis P.I.": thesis}


def start_client(machine: Machine, sets: tuple[Coefficients, Coefficients],
                 data: str) -> tuple[ControlClient, np.ndarray]:
    robot = ControlClient(machine, lockstep=True, data_dir=data, heartbeat_timeout_s=5.0)
    robot.set_coefficients("hold", sets[0], override="benchmark")
    robot.set_coefficients("track", sets[1], override="benchmark")
    if machine.encoder_kind != "gray":
        robot.initialise()
        robot.wait_event("initialised", timeout=120)
        here = np.array(robot.status().position)
        here[0] = RIG_START
        go_to(robot, machine, here, 0.5)
    return robot, np.array(robot.status().position)


def follow(robot: ControlClient, path: np.ndarray, kind: str = "path",
           dwell_s: float = DWELL_S):
    """Run ``path`` then a dwell on its end; the recorded run."""
    dwell = np.repeat(path[-1:], round(dwell_s / robot.dt), axis=0)
    result = robot.wait(robot.move(np.vstack([path, dwell]), kind=kind), timeout=300)
    return result.run


def go_to(robot: ControlClient, machine: Machine, goal: np.ndarray, speed: float):
    """A go_to from where the joints are, then the dwell; the recorded run (None: there)."""
    here = np.array(robot.status().position)
    if np.array_equal(here, goal):
        return None
    return follow(robot, form_plans.go_to(machine, here, goal, speed, dt=robot.dt).path)


def response(run, j: int, unit: str) -> Response:
    d, y, t = run.desired[:, j], run.actual[:, j], run.t
    changes = np.flatnonzero(np.diff(d) != 0)
    if len(changes) == 0:
        return Response(math.nan, math.nan, math.nan)
    first, arrive = int(changes[0]), int(changes[-1]) + 1
    target, travel = d[-1], d[-1] - d[0]
    over = max(0.0, float(np.max(np.sign(travel) * (y[first:] - target))))
    outside = np.flatnonzero(np.abs(y[arrive:] - target) > BAND[unit])
    settle = 0.0 if len(outside) == 0 else float(t[arrive + outside[-1] + 1] - t[arrive]) \
        if arrive + outside[-1] + 1 < len(t) else math.inf
    moving = slice(first, arrive + 1)
    rms = float(np.sqrt(np.mean((d[moving] - y[moving]) ** 2)))
    return Response(over, settle, rms)


def worse(a: Response, b: Response) -> Response:
    return Response(max(a.over, b.over), max(a.settle, b.settle), max(a.rms, b.rms))


def rest(robot: ControlClient, machine: Machine, seconds: float) -> tuple[np.ndarray, np.ndarray]:
    """Per joint: peak-to-peak position (counts) and output sign changes a second, holding,
    from ``REST_AFTER_S`` after the call."""
    counts = np.array([abs(j.encoder.gradient) for j in machine.joints])
    begin = robot.status().time_s
    while robot.status().time_s - begin < REST_AFTER_S:
        time.sleep(0.001)
    first = robot.status()
    low = high = np.array(first.position)
    signs = np.sign(first.duty)
    reversals = np.zeros(machine.n_joints)
    while (s := robot.status()).time_s - first.time_s < seconds:
        q = np.array(s.position)
        low, high = np.minimum(low, q), np.maximum(high, q)
        now = np.sign(s.duty)
        flipped = (now != 0) & (signs != 0) & (now != signs)
        reversals += flipped
        signs = np.where(now != 0, now, signs)
        time.sleep(0.0005)
    span = robot.status().time_s - first.time_s
    return (high - low) / counts, reversals / span


def measure(machine: Machine, sets: tuple[Coefficients, Coefficients], rest_s: float
            ) -> tuple[dict[str, dict[str, object]], object]:
    """Every figure of one controller on one machine, by row (joint or wrist); and the
    wrist's full-speed go_to run for the figure (None on a one-joint machine)."""
    rows: dict[str, dict[str, object]] = {}
    wrist_run = None
    with tempfile.TemporaryDirectory() as data:
        robot, home = start_client(machine, sets, data)
        with robot:
            groups = [(joint.name, (j,)) for j, joint in enumerate(machine.joints)]
            if machine.n_joints > max(WRIST):
                groups.append(("Bend+Yaw", WRIST))
            for label, joints in groups:
                row: dict[str, object] = {}
                unit = machine.joints[joints[0]].unit
                target = home.copy()
                for j in joints:
                    target[j] += STEP[machine.joints[j].key]
                step_path = moves.multi_step(home, target, DWELL_S, machine=machine,
                                             dt=robot.dt)
                run = follow(robot, step_path, kind="multi_step", dwell_s=0.0)
                row["step"] = _worst(run, joints, unit)
                go_to(robot, machine, home, 0.5)
                for speed in SPEEDS:
                    for goal, keep in ((target, True), (home, False)):
                        run = go_to(robot, machine, goal, speed)
                        if keep:
                            row[f"go_to {speed:g}"] = _worst(run, joints, unit)
                            if speed == 1.0 and joints == WRIST:
                                wrist_run = run
                if len(joints) == 1:
                    j = joints[0]
                    joint = machine.joints[j]
                    ramp_time = moves.min_ramp_time(home, target, machine, 0.5)
                    run = follow(robot, moves.ramp(home, target, ramp_time, ramp_time,
                                                   machine=machine, dt=robot.dt, fraction=0.5))
                    row["ramp"] = response(run, j, unit).rms
                    go_to(robot, machine, home, 0.5)
                    swing = STEP[joint.key]
                    period = max(2 * math.pi * swing / joint.max_speed,
                                 math.pi * math.sqrt(4 * swing / joint.max_accel))
                    sine_path = moves.sine(home, target, period, 3 * period, machine=machine,
                                           dt=robot.dt)
                    run = follow(robot, sine_path, kind="sine")
                    fit = moves.sine_summary(run.t, run.desired, run.actual, machine.joints,
                                             period)[j]
                    row["sine"] = (fit.amplitude_ratio, fit.phase_lag_deg)
                rows[label] = row
            go_to(robot, machine, home, 0.5)
            pp, rev = rest(robot, machine, rest_s)
            for j, joint in enumerate(machine.joints):
                rows[joint.name]["rest"] = (pp[j], rev[j])
    return rows, wrist_run


def _worst(run, joints: tuple[int, ...], unit: str) -> Response:
    figures = [response(run, j, unit) for j in joints]
    out = figures[0]
    for f in figures[1:]:
        out = worse(out, f)
    return out


def print_table(machine: Machine, results: dict[str, dict[str, dict[str, object]]]) -> None:
    names = list(results)
    print(f"\n{machine.title} ({machine.name}) at {1e-3 / machine.sample_time_s:g} kHz: "
          f"{' | '.join(names)} per cell; over and rms in "
          f"the joint's unit, settle in s after the path arrives (±0.5° / ±1 mm)")
    head = ["joint", "move", *names]
    lines = [head]
    for label in results[names[0]]:
        for key in ("step", *(f"go_to {s:g}" for s in SPEEDS), "ramp", "sine", "rest"):
            if key not in results[names[0]][label]:
                continue
            cells = [_cell(key, results[n][label][key]) for n in names]
            lines.append([label, key, *cells])
    widths = [max(len(r[i]) for r in lines) for i in range(len(head))]
    print("| " + " | ".join(h.ljust(w) for h, w in zip(head, widths, strict=True)) + " |")
    print("|" + "|".join("-" * (w + 2) for w in widths) + "|")
    for r in lines[1:]:
        print("| " + " | ".join(c.ljust(w) for c, w in zip(r, widths, strict=True)) + " |")


def _cell(key: str, value: object) -> str:
    if isinstance(value, Response):
        settle = "never" if math.isinf(value.settle) else f"{value.settle:.2f}"
        rms = "–" if key == "step" else f"{value.rms:.2f}"
        return f"over {value.over:.2f}, settle {settle}, rms {rms}"
    if key == "ramp":
        return f"rms {value:.3f}"
    if key == "sine":
        ratio, lag = value
        return "–" if ratio is None else f"ratio {ratio:.3f}, lag {lag:.1f}°"
    pp, rev = value
    return f"p-p {pp:.0f} counts, {rev:.1f} rev/s"


def write_svg(path: Path, runs: dict[str, object], machine: Machine) -> None:
    from app.plotting.figure import Figure, Line, Panel
    from app.plotting.svg import figure_svg

    colours = {"desired": "#444444", "default": "#1f77b4", "thesis P.I.": "#d62728"}
    panels = []
    for j in WRIST:
        joint = machine.joints[j]
        first = next(iter(runs.values()))
        lines = [Line(first.t, first.desired[:, j], colours["desired"], "desired")]
        lines += [Line(run.t, run.actual[:, j], colours[name], name) for name, run in runs.items()]
        panels.append(Panel(f"{joint.name}: position", tuple(lines), joint.unit))
    for j in WRIST:
        joint = machine.joints[j]
        lines = [Line(run.t, run.duty[:, j], colours[name], name) for name, run in runs.items()]
        panels.append(Panel(f"{joint.name}: controller output", tuple(lines), "%",
                            zero_line=True))
    figure = Figure("Wrist, Bend and Yaw 10° together, go_to at full speed, then 2 s held",
                    tuple(panels), columns=2)
    path.write_text(figure_svg(figure))
    print(f"\nwrote {path}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--machines", nargs="+", default=["unimate2000b", "rig"])
    parser.add_argument("--rest", type=float, default=REST_S, help="seconds of rest measured")
    parser.add_argument("--svg", type=Path, default=None, help="write the wrist figure here")
    parser.add_argument("--sample-time-ms", type=float, default=None,
                        help="run the machine files with this sample_time_ms (0.5: 2 kHz)")
    args = parser.parse_args()
    started = time.monotonic()
    for name in args.machines:
        with tempfile.TemporaryDirectory() as copies:
            machine = load_machine(machine_at(name, args.sample_time_ms, copies))
            results, wrist = {}, {}
            for label, sets in controllers(machine).items():
                results[label], run = measure(machine, sets, args.rest)
                if run is not None:
                    wrist[label] = run
        print_table(machine, results)
        if args.svg is not None and wrist:
            write_svg(args.svg, wrist, machine)
    print(f"\n{time.monotonic() - started:.0f} s")


if __name__ == "__main__":
    main()
