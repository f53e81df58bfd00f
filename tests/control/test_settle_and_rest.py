"""Issue 24 items 1 and 2 on the real control process (lockstep): with the machine files'
default sets every fast minimum-jerk joint move (0.5 and 1.0 of max speed and acceleration,
each joint alone, Bend with Yaw) overshoots by at most 10 % of its travel (or 1 unit) and is
within ±0.5° / ±1 mm 0.5 s after its path arrives; at rest every joint stays within 2 encoder
counts of its target and reverses its valve at most once a second (no limit cycle between
the minimum PWMs). The thesis's sets failed both: Bend and Yaw overshot 4-6° and settled
2.5-4 s late, and at rest the Unimate's valves reversed 1-11 times a second."""

from __future__ import annotations

import math
import os
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from control import ControlClient, Mode
from control.motion import form_plans
from control.rt import shm
from hw.machine import Machine, load_machine

UNIMATE = load_machine("unimate2000b")
RIG = load_machine("rig")
STEP = {"inout": 100.0, "rotate": 20.0, "updown": 10.0, "bend": 10.0, "yaw": 10.0,
        "swivel": 20.0, "ram": 100.0}
BAND = {"deg": 0.5, "mm": 1.0}
SETTLE_S = 0.5
DWELL_S = 1.0  # the path's end held this long after it arrives: the settle is judged on it
REST_S = 5.0
STEADY_S = 0.01  # a distance held this long is the joint's, not a wrong reading's
SEEN_READS = 5  # distinct readings a window needs to be judged: a starved test reads one
RIG_START = 600.0
CASES = [(m, joints) for m in (UNIMATE, RIG)
         for joints in [(j,) for j in range(m.n_joints)] + ([(3, 4)] if m is UNIMATE else [])]


def _start(machine: Machine, tmp: Path) -> ControlClient:
    client = ControlClient(machine.name, lockstep=True, data_dir=tmp, heartbeat_timeout_s=5.0)
    if machine.encoder_kind != "gray":
        client.initialise()
        client.wait_event("initialised", 120.0)
    return client


@pytest.fixture(scope="module")
def clients(tmp_path_factory: pytest.TempPathFactory) -> Iterator[dict[str, ControlClient]]:
    started: dict[str, ControlClient] = {}
    try:
        for machine in (UNIMATE, RIG):
            started[machine.name] = _start(machine, tmp_path_factory.mktemp(machine.name))
        yield started
    finally:
        for client in started.values():
            client.close()
    assert [n for n in shm.leftover_segments() if shm.owner_pid(n) == os.getpid()] == []


def _middle(machine: Machine) -> np.ndarray:
    return np.array([RIG_START] if machine is RIG else
                    [(j.lower + j.upper) / 2 for j in machine.joints])


def _go(client: ControlClient, machine: Machine, goal: np.ndarray, speed: float):
    here = np.array(client.status().position)
    path = form_plans.go_to(machine, here, goal, speed, dt=client.dt).path
    dwell = np.repeat(path[-1:], round(DWELL_S / client.dt), axis=0)
    result = client.wait(client.move(np.vstack([path, dwell])), timeout=120)
    assert result.run is not None, result.status
    return result.run, len(path) - 1


@pytest.mark.parametrize("speed", [0.5, 1.0])
@pytest.mark.parametrize(("machine", "joints"), CASES,
                         ids=[f"{m.name}-{'+'.join(m.joints[j].key for j in js)}"
                              for m, js in CASES])
def test_a_fast_minimum_jerk_move_arrives_and_settles(clients, machine: Machine,
                                                      joints: tuple[int, ...],
                                                      speed: float) -> None:
    client = clients[machine.name]
    start = _middle(machine)
    _go(client, machine, start, 0.5)
    goal = start.copy()
    for j in joints:
        goal[j] += STEP[machine.joints[j].key]
    run, arrive = _go(client, machine, goal, speed)
    t_arrive = run.t[arrive]
    for j in joints:
        joint = machine.joints[j]
        travel = goal[j] - start[j]
        actual = run.actual[:, j]
        overshoot = max(0.0, float(np.max(np.sign(travel) * (actual - goal[j]))))
        assert overshoot <= max(0.1 * abs(travel), 1.0), (joint.name, overshoot)
        outside = np.flatnonzero(np.abs(actual[arrive:] - goal[j]) > BAND[joint.unit])
        late = 0.0 if len(outside) == 0 else float(run.t[arrive + outside[-1]] - t_arrive)
        assert late <= SETTLE_S, (f"{joint.name} outside ±{BAND[joint.unit]:g} {joint.unit} "
                                  f"{late:.2f} s after its path arrived")
        assert math.isclose(run.desired[-1, j], goal[j])


@pytest.mark.parametrize("machine", [UNIMATE, RIG], ids=lambda m: m.name)
def test_at_rest_every_joint_is_still_and_its_valve_quiet(clients, machine: Machine) -> None:
    """After a go_to, 5 s of hold read from the status about every millisecond (the
    lockstep controller paces at real time once the arm has been still for 2 s). A joint's
    distance counts when every reading over ``STEADY_S`` shows it: a wrong reading (section
    6.2, the simulator's photocells make them, a few milliseconds long) is not the joint
    moving. A window the test was starved through (fewer than ``SEEN_READS`` readings) is
    not judged: at load 6 one reading filled it, a wrong one, "Rotate 10.8 counts"."""
    client = clients[machine.name]
    goal = _middle(machine)
    for j, joint in enumerate(machine.joints):
        goal[j] += STEP[joint.key] / 2
    _go(client, machine, goal, 0.5)
    counts = np.array([abs(j.encoder.gradient) for j in machine.joints])
    first = client.status()
    assert first.mode == Mode.HOLD
    target = np.array(first.desired)
    worst = np.zeros(machine.n_joints)
    recent: list[tuple[float, np.ndarray]] = []  # (time, distance in counts) over STEADY_S
    signs = np.sign(first.duty)
    reversals = np.zeros(machine.n_joints)
    judged = 0
    while (status := client.status()).time_s - first.time_s < REST_S:
        recent.append((status.time_s, np.abs(np.array(status.position) - target) / counts))
        while status.time_s - recent[0][0] > STEADY_S:
            recent.pop(0)
            if len({t for t, _ in recent}) >= SEEN_READS:  # a window the test saw, not a gap
                worst = np.maximum(worst, np.min([off for _, off in recent], axis=0))
                judged += 1
        now = np.sign(status.duty)
        reversals += (now != 0) & (signs != 0) & (now != signs)
        signs = np.where(now != 0, now, signs)
        time.sleep(0.0005)
    span = client.status().time_s - first.time_s
    assert judged >= 0.1 * REST_S / STEADY_S * SEEN_READS, f"only {judged} windows seen"
    for j, joint in enumerate(machine.joints):
        assert worst[j] <= 2.0 + 1e-6, f"{joint.name} {worst[j]:.1f} counts from its target"
        assert reversals[j] / span <= 1.0, (f"{joint.name}'s valve reversed "
                                            f"{reversals[j] / span:.1f} times a second")
