"""Simulator speed: a 10 s six-axis Unimate move and a 10 s rig run, in lockstep.

Run from the repository root: ``python benchmarks/hw.py``. Each run is the
control loop's shape (read, control, write, sleep to the next 1 ms deadline)
with a small stand-in controller, so the figure is what the control subprocess
will see from the simulator. Ends with the serial round-trip benchmark when
``benchmarks/serial_rtt.py`` is there.
"""

from __future__ import annotations

import importlib.util
import math
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # ahead of benchmarks/, where this file would shadow the hw package

from hw.machine import Machine, load_machine  # noqa: E402
from hw.sim.backend import SimBackend  # noqa: E402
from hw.transmission import Transmission, valve_duty  # noqa: E402

TICK_NS = 1_000_000
MOVE_S = 10.0


def simulator_only(machine: Machine) -> float:
    """Wall seconds for 10 s of read + write alone, every joint swinging at +-40 % duty."""
    sim = SimBackend(machine, seed=1, lockstep=True)
    n = machine.n_joints
    raw = [0] * n
    pattern = [[40.0 * math.sin(2e-3 * k + j) for j in range(n)] for k in range(1000)]
    sim.open()
    t0 = time.perf_counter()
    for k in range(round(MOVE_S * 1e9 / TICK_NS)):
        sim.read(raw)
        sim.write(pattern[k % 1000])
        sim.clock.sleep_until(sim.clock.now_ns() + TICK_NS)
    return time.perf_counter() - t0


def unimate_move(machine: Machine) -> tuple[float, list[float], list[int]]:
    """10 s move of all six joints under the thesis P.I. gains (section 5.4.2).

    Returns wall seconds, largest |error| per joint over the last second, wrong readings.
    """
    sim = SimBackend(machine, seed=1, lockstep=True, initial=[1500.0, 0, 0, 0, 0, 0])
    n = machine.n_joints
    start = [1500.0, 0.0, 0.0, 0.0, 0.0, 0.0]
    goal = [1800.0, 60.0, 20.0, -60.0, 45.0, 90.0]
    pi = machine.coefficients["thesis_pi"]
    raw, duty, q, integral = [0] * n, [0.0] * n, list(start), [0.0] * n
    transmission = Transmission(machine)
    zero, actuator, reading, output = [0] * n, [0.0] * n, [0.0] * n, [0.0] * n
    late_error = [0.0] * n
    ticks = round(MOVE_S * 1e9 / TICK_NS)
    sim.open()
    t0 = time.perf_counter()
    for k in range(ticks):
        sim.read(raw)
        blend = 0.5 - 0.5 * math.cos(math.pi * min(k / (0.8 * ticks), 1.0))
        transmission.actuators_from_words(raw, zero, actuator)
        transmission.joints_from_actuators(actuator, reading)
        for j, joint in enumerate(machine.joints):
            if abs(reading[j] - q[j]) < 5.0 * joint.tolerance + joint.max_speed * 2e-3:
                q[j] = reading[j]  # a jump no joint can make is a glitch: keep the last one
            error = start[j] + blend * (goal[j] - start[j]) - q[j]
            if k >= ticks - 1000:
                late_error[j] = max(late_error[j], abs(error))
            integral[j] = min(max(integral[j] + pi.ki[j] * error * 1e-3, -50.0), 50.0)
            u = pi.kp[j][0] * error + integral[j]
            if u > 0.0:  # errata #5
                u = (1.0 - joint.min_pwm_pos / 100.0) * u + joint.min_pwm_pos
            elif u < 0.0:
                u = (1.0 - joint.min_pwm_neg / 100.0) * u - joint.min_pwm_neg
            output[j] = u
        transmission.valve_duties(output, duty)
        sim.write(duty)
        sim.clock.sleep_until(sim.clock.now_ns() + TICK_NS)
    return time.perf_counter() - t0, late_error, sim.wrong_readings()


def rig_steps(machine: Machine) -> tuple[float, float, float]:
    """10 s of eq. 3.3's PID stepping 200 -> 600 -> 200 mm (Figures 3.7, 3.9).

    Returns wall seconds, the bounce (peak to peak in the 0.3 s after first
    reaching 200 mm again) and the final offset from 200 mm.
    """
    joint = machine.joints[0]
    pid = machine.track
    sim = SimBackend(machine, lockstep=True, initial=[200.0])
    raw = [0]
    sim.open()
    sim.read(raw)
    zero = raw[0] - round(200.0 / joint.encoder.gradient)  # as if Initialise had run
    errors = [0.0] * len(pid.filter)
    integral, arrived, window = 0.0, None, []
    ticks = round(MOVE_S * 1e9 / TICK_NS)
    t0 = time.perf_counter()
    for k in range(ticks):
        sim.read(raw)
        target = 600.0 if k < ticks // 2 else 200.0
        position = joint.encoder.gradient * (raw[0] - zero)
        errors = [(target - position) / joint.gain_unit, *errors[:-1]]
        derivative = sum(f * e for f, e in zip(pid.filter, errors, strict=True))
        integral = min(max(integral + pid.ki[0] * errors[0] * 1e-3, -50.0), 50.0)
        u = pid.kp[0][0] * errors[0] + pid.kd[0] * derivative / (pid.filter_divisor * 1e-3)
        u = min(max(u + integral, -100.0), 100.0)
        sim.write([valve_duty(joint, u)])
        sim.clock.sleep_until(sim.clock.now_ns() + TICK_NS)
        if k >= ticks // 2 and arrived is None and position <= 200.5:
            arrived = k
        if arrived is not None and k < arrived + 300:
            window.append(position)
    final = sim.joint_positions()[0] - 200.0
    return time.perf_counter() - t0, max(window) - min(window), final


def serial_round_trip() -> None:
    """Run ``benchmarks/serial_rtt.py``'s ``main()`` if that benchmark exists."""
    path = Path(__file__).with_name("serial_rtt.py")
    if not path.is_file():
        print("serial round trip: not available (benchmarks/serial_rtt.py is missing)")
        return
    spec = importlib.util.spec_from_file_location("serial_rtt", path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    module.main([])


def measure() -> dict:
    """Wall seconds of each 10 s run, and what the moves achieved (``main`` prints them)."""
    unimate, rig = load_machine("unimate2000b"), load_machine("rig")
    move_wall, late_error, wrong = unimate_move(unimate)
    steps_wall, bounce, final = rig_steps(rig)
    return {
        "seconds": MOVE_S,
        "unimate_io_wall": simulator_only(unimate),
        "unimate_move_wall": move_wall,
        "unimate_late_error": dict(zip([j.key for j in unimate.joints], late_error,
                                       strict=True)),
        "unimate_wrong_readings": wrong,
        "rig_io_wall": simulator_only(rig),
        "rig_steps_wall": steps_wall,
        "rig_bounce_mm": bounce,
        "rig_final_mm": final,
    }


def main() -> None:
    m = measure()
    unimate = load_machine("unimate2000b")
    wall = m["unimate_io_wall"]
    print(f"unimate2000b: {MOVE_S:g} s of read + write alone: {wall:.3f} s wall, "
          f"{MOVE_S / wall:.0f}x real time, {wall / MOVE_S * 1e3:.1f} us per 1 ms tick")
    wall = m["unimate_move_wall"]
    print(f"unimate2000b: {MOVE_S:g} s six-axis move under P.I. control: {wall:.3f} s wall, "
          f"{MOVE_S / wall:.0f}x real time, {wall / MOVE_S * 1e3:.1f} us per 1 ms tick")
    units = ", ".join(f"{j.key} {m['unimate_late_error'][j.key]:.2f}{j.symbol}"
                      for j in unimate.joints)
    print(f"  largest error in the last second: {units}")
    print(f"  wrong encoder readings (Figure 6.1): {m['unimate_wrong_readings']}")
    wall = m["rig_io_wall"]
    print(f"rig: {MOVE_S:g} s of read + write alone: {wall:.3f} s wall, "
          f"{MOVE_S / wall:.0f}x real time")
    wall = m["rig_steps_wall"]
    print(f"rig: {MOVE_S:g} s of PID steps 200->600->200 mm: {wall:.3f} s wall, "
          f"{MOVE_S / wall:.0f}x real time")
    print(f"  bounce on arrival {m['rig_bounce_mm']:.2f} mm peak to peak, final offset "
          f"{m['rig_final_mm']:+.2f} mm")
    serial_round_trip()


if __name__ == "__main__":
    main()
