"""A frozen controller (SIGSTOP): the client's heartbeats and E-stop go through shared
memory and its commands through a queue, so nothing the operator calls blocks. ``estop()``
returns at once and the E-stop latches on the first tick after SIGCONT; ``close()`` of a
controller that stays frozen returns within 2 s, killing it."""

from __future__ import annotations

import contextlib
import os
import signal
import time

from control import ControllerError


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
