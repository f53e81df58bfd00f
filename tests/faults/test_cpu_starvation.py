"""CPU starvation: one busy-looping process per core while the controller runs a move.

The controller asks for SCHED_FIFO and a core of its own (granted to root);
the burners run at normal priority, one pinned to each core, so they take
everything the controller does not. The claim is not "no overrun" but that
overruns are counted honestly (every period is either a tick or a counted
overrun), shown in the status, and that the controller stays safe: the move
keeps tracking and an E-stop still closes every valve at once.
"""

from __future__ import annotations

import contextlib
import math
import os
import subprocess
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import replace

import numpy as np

from control import ControlClient
from control.motion import moves
from control.recorder import load_run
from control.rt.layout import LatencyHistogram, Status
from hw.machine import load_machine

UNIMATE = load_machine("unimate2000b")
ROTATE, BEND = UNIMATE.joint_index("rotate"), UNIMATE.joint_index("bend")
INOUT = UNIMATE.joint_index("inout")
BURN = "import os, sys\nos.sched_setaffinity(0, {int(sys.argv[1])})\nwhile True:\n    pass\n"
# read before any controller runs: a client's threads keep off its controller's core meanwhile
# (control/off_core.py), and every core is to burn, the controller's too
CORES = sorted(os.sched_getaffinity(0))
STARVED_NICE = 5  # the starved controller's nice value (see the overrun-hold test)


@contextmanager
def burning_every_core(per_core: int = 1) -> Iterator[int]:
    """``per_core`` busy loops pinned to each core; killed on the way out."""
    burners = [subprocess.Popen([sys.executable, "-c", BURN, str(cpu)])
               for cpu in CORES for _ in range(per_core)]
    try:
        yield len(burners)
    finally:
        for burner in burners:
            burner.kill()
        for burner in burners:
            burner.wait(timeout=10)


def status_and_histogram(client: ControlClient) -> tuple[Status, LatencyHistogram]:
    """The status and the latency histogram of one tick: read until no tick came between
    (a starved reader preempted between the two reads saw the histogram ticks ahead)."""
    deadline = time.monotonic() + 10.0
    while True:
        status, histogram = client.status(), client.histogram()
        if client.status().tick == status.tick or time.monotonic() > deadline:
            return status, histogram


def grid_time(status: Status) -> float:
    """The deadline of the tick that published ``status``: its publish time less the tick's
    lateness and compute (a stall inside a tick shows in its compute, and its missed periods
    are counted as overruns only after it published)."""
    return status.time_s - (status.late_last_us + status.compute_last_us) / 1e6


def test_a_starved_machine_counts_its_overruns_and_the_controller_stays_safe(
        controller, until, measured) -> None:
    """With every core burning for 1 s during a move: the move keeps tracking within its
    following error, every period is accounted for as a tick or a counted overrun, the
    latency histogram counts every tick, and an E-stop still latches with every valve at 0
    (time measured); the run up to the E-stop is on disk. The client's heartbeat timeout
    is 2 s here: this test starves the client too, and is about the controller. (A second
    is a thousand periods to account for; each is accounted for alone, so a longer burn
    would show nothing more.)"""
    client: ControlClient = controller(heartbeat_timeout_s=2.0)
    start = client.status().position
    end = np.array(start)
    end[ROTATE] += 20.0
    end[BEND] += 20.0
    handle = client.move(moves.sine(start, end, period=3.0, duration=8.0, machine=UNIMATE),
                         kind="sine")
    until(lambda: client.status().move_done >= 200, 10.0, "the move to run")
    s0, h0 = status_and_histogram(client)
    with burning_every_core() as burners:
        time.sleep(1.0)
        s1 = client.status()
        assert s1.moving and not s1.estop, s1.fault
        client.estop()
        latched_s = until(lambda: client.status().estop, 5.0, "the E-stop under load")
        s2, h2 = status_and_histogram(client)
    measured("burners", burners)
    measured("estop_latched_under_load_ms", latched_s * 1e3, "ms")
    assert s2.valve == (0.0,) * 6 and s2.duty == (0.0,) * 6

    ticks, overruns = s2.tick - s0.tick, s2.overruns - s0.overruns
    periods = (grid_time(s2) - grid_time(s0)) / client.dt
    measured("overruns", overruns)
    measured("ticks", ticks)
    measured("late_max_us", s2.late_max_us, "µs")
    measured("compute_max_us", s2.compute_max_us, "µs")
    measured("realtime", int(client.realtime))
    assert overruns >= 0 and s2.overruns == h2.overruns
    assert abs(ticks + overruns - periods) <= 1, "a period neither ticked nor counted"
    assert abs((h2.ticks - h0.ticks) - ticks) <= 2, "the histogram missed ticks"

    result = client.wait(handle, timeout=5.0)
    assert result.status == "estop: operator E-stop"
    run = load_run(result.files.json)
    error = np.abs(run.desired - run.actual).max(axis=0)
    assert np.all(error < [j.following_error for j in UNIMATE.joints]), error


def test_overrun_holds_under_starvation_keep_the_commanded_target(controller, until,
                                                                   measured) -> None:
    """Issue 24 item 4: starved (the controller at nice 5, two burners a core), the loop
    overruns and holds, again and again; each hold is where the arm was commanded
    (the hold target), never where it had got to, so starvation never moves the target (the
    operator's In/Out crept 1309.9 → 1330.2 mm over ten holds). The hold gains are zeroed
    and Rotate's target jogged 1.5° on: the arm stays where it is, 1.5° (50 counts) from its
    target and inside its 2.5° standstill following error, so a hold taken where the arm is
    would move the target by 50 counts."""
    client: ControlClient = controller(realtime=False, heartbeat_timeout_s=60.0)
    # every term zero, the velocity feed-forward too: a jog's target moving at its speed
    # opened Rotate's valve by kv, and a loaded loop's jog kept it open for longer (one
    # suite run: the arm ended 6.85° past its target before the starvation began)
    zero = replace(UNIMATE.hold, name="zero", kp=((0.0,),) * 6, ki=(0.0,) * 6,
                   kd=(0.0,) * 6, w=((),) * 6, kv=(0.0,) * 6)
    client.set_coefficients("hold", zero, override="test: the arm stays where it is left")
    before = client.status()
    start = np.array(before.position)
    client.jog_position("rotate", 1.5)  # the hold target moves on by 1.5°

    def jog_state() -> str:
        now = client.status()
        moved = now.desired[ROTATE] - before.desired[ROTATE]
        return (f"Rotate's target jogged on: it is {moved:+.6f}° from where it was, mode "
                f"{now.mode!r}, estop {now.estop}, fault "
                f"{now.fault!r}; events {[(e.kind, e.payload) for e in client.poll_events()]}")
    until(lambda: abs(client.status().desired[ROTATE] - before.desired[ROTATE] - 1.5) < 1e-9,
          10.0, jog_state)
    commanded = np.array(client.status().desired)
    left = client.status().position[ROTATE]
    assert abs(left - start[ROTATE]) < 0.1, f"Rotate moved {left - start[ROTATE]:.2f}° on the jog"
    client.poll_events()  # a fault from a loaded start is not one of these
    targets, away = [], []
    # at nice 0 beside them a waking loop was served first often enough to keep up (it
    # never overran in one suite run); at nice 19 beside three a core it was served hardly
    # at all (Linux 6.18's EEVDF: 0-1 ticks a second, so no second of the overrun watch
    # ended, one hold or none in 30 s). At nice 5 it ticks 10-250 times a second, most of
    # them late, and holds every second, beside one to five burners a core (probed): the two
    # here, and whatever else the machine runs
    for thread in os.listdir(f"/proc/{client.pid}/task"):
        os.setpriority(os.PRIO_PROCESS, int(thread), STARVED_NICE)
    with burning_every_core(per_core=2):
        deadline = time.monotonic() + 30.0
        while len(targets) < 2 and time.monotonic() < deadline:
            with contextlib.suppress(TimeoutError):
                client.wait_event("fault", 1.0, lambda e: e.payload["kind"] == "overrun")
                status = client.status()
                targets.append(np.array(status.desired))
                away.append(commanded[ROTATE] - status.position[ROTATE])
    measured("overrun_holds", len(targets))
    measured("rotate_from_target_deg", min(away, default=math.nan), "°")
    # one hold shows it: a hold where the arm is moves the target 1.5° at the first (b552302);
    # a second shows a hold is no one-off (they come a second or two apart)
    assert targets, "starved, the loop never overran a fifth of a second's ticks"
    assert not client.status().estop, client.status().fault
    count = np.array([abs(j.encoder.gradient) for j in UNIMATE.joints])
    for target, off in zip(targets, away, strict=True):
        assert off > 1.4, f"Rotate followed its target ({off:.2f}° away): nothing to tell"
        assert np.all(np.abs(target - commanded) <= count + 1e-9), target - commanded
    assert np.all(np.abs(np.array(client.status().desired) - commanded) <= count + 1e-9)
