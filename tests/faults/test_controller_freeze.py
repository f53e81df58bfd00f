"""A frozen controller (SIGSTOP): the client's heartbeats and E-stop go through shared
memory and its commands through a queue, so nothing the operator calls blocks. ``estop()``
returns at once and the E-stop latches on the first tick after SIGCONT; ``close()`` of a
controller that stays frozen returns within 2 s, killing it; a stall in a move is listed
in the run."""

from __future__ import annotations

import contextlib
import json
import os
import re
import signal
import time

import numpy as np

from control import ControllerError
from control.motion import moves


def test_estop_never_waits_on_a_frozen_controller_and_wins_when_it_wakes(
        controller, until, measured) -> None:
    client = controller()
    client.jog([20.0, 0.0, 0.0, 0.0, 0.0, 0.0])
    until(lambda: client.status().valve[0] != 0.0, 5.0, "the jog to reach the valve")
    os.kill(client.pid, signal.SIGSTOP)
    try:
        for _ in range(200):  # fill the command channel: jogs pile up behind the frozen loop
            try:
                client.jog([20.0, 0.0, 0.0, 0.0, 0.0, 0.0])
            except ControllerError:
                break
        started = time.perf_counter()
        client.estop()
        estop_ms = measured("estop_call_ms_frozen_controller",
                            (time.perf_counter() - started) * 1e3, "ms")
        assert estop_ms < 10.0
    finally:
        os.kill(client.pid, signal.SIGCONT)
    until(lambda: client.status().estop, 5.0, "the E-stop to latch after the thaw")
    status = client.status()
    assert status.valve == (0.0,) * 6 and status.fault == "operator E-stop"


def test_close_of_a_controller_that_stays_frozen_returns_within_2_s(controller,
                                                                  measured) -> None:
    client = controller()
    pid = client.pid
    os.kill(pid, signal.SIGSTOP)
    started = time.perf_counter()
    client.close()
    close_s = measured("close_s_frozen_controller", time.perf_counter() - started, "s")
    assert close_s < 2.0
    assert not client.alive
    with contextlib.suppress(ProcessLookupError):
        os.kill(pid, signal.SIGCONT)


def test_a_controller_stalled_mid_move_says_so_in_the_run(controller, until,
                                                         measured) -> None:
    """A 1 s SIGSTOP of the controller in the middle of a move: the move goes on after it,
    and the saved run says "complete, with a 1.0 s controller stall" and lists the gap in
    its JSON, instead of a silent hole in a run called complete. (A stall is any gap over the
    machine's 50 ms ``stall_ms``: one of a second shows it as one of three did, in a 2 s move
    instead of a 4 s one.)"""
    client = controller(heartbeat_timeout_s=30.0)  # this test is not about the client's
    start = np.array(client.status().position)
    end = start.copy()
    end[1] += 5.0
    handle = client.move(moves.sine(start, end, period=2.0, duration=2.0,
                                    machine=client.machine), kind="sine")
    until(lambda: client.status().move_done > 500, 10.0, "the move to run")
    os.kill(client.pid, signal.SIGSTOP)
    time.sleep(1.0)
    os.kill(client.pid, signal.SIGCONT)
    result = client.wait(handle, timeout=30)
    assert re.fullmatch(r"complete, with a 1\.\d s controller stall", result.status), \
        result.status
    saved = json.loads(result.files.json.read_text())
    ((at, length),) = saved["meta"]["gaps"]
    measured("stall_listed_s", length, "s")
    assert 0.9 <= length <= 2.0 and 0.4 < at < 1.5
    assert saved["status"] == result.status
