"""Feedback that lies, on real processes: a board answering on time with frozen encoder words
or a stuck bit (``servodesk emulate --frozen-after``/``--stuck-bit``, over a pty), a valve
jammed shut, a board flooding the link with valid reports. Every one is a fault naming the
joint, with the valves closed, in well under a second (measured), and the joint is never
driven to its stop."""

from __future__ import annotations

import numpy as np

from control import Mode
from control.motion import moves
from hw.machine import load_machine

UNIMATE = load_machine("unimate2000b")
ROTATE, UPDOWN = UNIMATE.joint_index("rotate"), UNIMATE.joint_index("updown")


def first_fault(client, kind: str, timeout: float = 10.0):
    return client.wait_event("fault", timeout, lambda e: e.payload["kind"] == kind)


def test_frozen_words_on_time_are_a_feedback_fault_not_a_drive_into_the_stop(
        controller, emulator, until, measured) -> None:
    """The board's multiplexer stalls 1 s after it is configured: its REPORTs keep coming,
    on time and valid, with the same words. A 10° Rotate step then opens the valve and the
    reading never moves: feedback fault naming Rotate, E-stop latched, valves closed, the
    move ended, and Rotate (really) stopped far from its 110° stop."""
    board = emulator("--frozen-after", "1", "--glitch-scale", "0")
    client = controller(backend="serial", port=board.url)
    until(lambda: client.status().time_s > 1.5, 10.0, "the words to freeze")
    start = np.array(client.status().position)
    handle = client.move(moves.step(start, ROTATE, start[ROTATE] + 10.0, duration=3.0,
                                    machine=UNIMATE), kind="step")
    result = client.wait(handle, timeout=10)
    assert result.status.startswith("estop: feedback fault: Rotate's valve"), (
        f"the move ended {result.status!r}; the controller's log:\n{client.controller_log()}")
    fault = first_fault(client, "feedback")
    assert fault.payload["joint"] == ROTATE and "has not moved" in fault.message
    status = client.status()
    assert status.estop and status.valve == (0.0,) * 6
    moving = np.flatnonzero(result.run.desired[:, ROTATE] != start[ROTATE])[0]
    measured("frozen_words_to_fault_ms", (result.run.samples - moving) * client.dt * 1e3, "ms")
    assert (result.run.samples - moving) * client.dt < 1.0


def test_a_stuck_bit_is_a_feedback_fault_never_a_believed_jump(controller, emulator,
                                                               measured) -> None:
    """Bit 8 of Up/Down's word reads 1 always (3.67° of counts). Up/Down at home has that bit
    set, so it reads true until a step carries it past count 2048, where the word jumps: the
    glitch filter rejects the jump, and five rejections in a row are a feedback fault naming
    Up/Down, never a believed position (which would drive the joint to its stop)."""
    board = emulator("--stuck-bit", f"{UPDOWN}:8:1", "--glitch-scale", "0")
    client = controller(backend="serial", port=board.url)
    start = np.array(client.status().position)
    handle = client.move(moves.step(start, UPDOWN, start[UPDOWN] + 5.0, duration=3.0,
                                    machine=UNIMATE), kind="step")
    result = client.wait(handle, timeout=10)
    fault = first_fault(client, "feedback")
    assert fault.payload["joint"] == UPDOWN and "jumps in a row" in fault.message
    status = client.status()
    assert status.estop and status.valve == (0.0,) * 6
    assert np.abs(np.diff(result.run.actual[:, UPDOWN])).max() < 0.5, "a jump was believed"
    moving = np.flatnonzero(result.run.desired[:, UPDOWN] != start[UPDOWN])[0]
    measured("stuck_bit_to_fault_ms", (result.run.samples - moving) * client.dt * 1e3, "ms")


def test_a_valve_jammed_shut_is_a_feedback_fault_within_250_ms(controller, measured) -> None:
    client = controller(lockstep=True)
    client.inject("jam_valve", ROTATE, 1.0)
    start = np.array(client.status().position)
    result = client.wait(client.move(moves.step(start, ROTATE, start[ROTATE] + 20.0,
                                                duration=3.0, machine=UNIMATE), kind="step"),
                         timeout=30)
    assert result.status.startswith("estop: feedback fault: Rotate's valve"), result.status
    moving = np.flatnonzero(result.run.desired[:, ROTATE] != start[ROTATE])[0]
    trip_ms = measured("jammed_shut_to_fault_ms",
                       (result.run.samples - moving) * client.dt * 1e3, "ms")
    assert trip_ms <= 250


def test_a_board_flooding_the_link_with_valid_reports_stops_the_motion(
        controller, emulator, measured) -> None:
    """Each REPORT followed by 100 more, all valid: the loop spends its ticks reading them.
    Motion stops with the reason said: either more than a fifth of a second's ticks overran
    (an overrun fault, and the controller holds) or the late commands let the board's 50 ms
    watchdog close the valves (a link fault, E-stop latched); which comes first depends on
    the machine's load, and both are safe. The overrun rule alone is pinned down in
    tests/control/rt/test_loop.py."""
    board = emulator("--flood", "100", "--glitch-scale", "0")
    client = controller(backend="serial", port=board.url)
    start = np.array(client.status().position)
    end = start.copy()
    end[ROTATE] += 10.0
    handle = client.move(moves.sine(start, end, period=4.0, duration=20.0, machine=UNIMATE),
                         kind="sine")
    result = client.wait(handle, timeout=30)
    assert result.status.startswith(("fault: overrun", "estop: link fault")), result.status
    measured("flood_to_stop_s", result.run.samples * client.dt, "s of the move")
    status = client.status()
    assert status.mode == Mode.HOLD and not status.moving
