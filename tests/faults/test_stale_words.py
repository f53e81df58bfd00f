"""Late answers from the I/O board, end to end: a word already judged is not judged again.

While the board's answers are late the serial backend returns the words it has, and the
same ``sample_ns``; the encoder input judges each sample once. So one wrong word read
through a late answer is one glitch, not one a tick until ``glitch_limit`` of them make a
feedback fault; and a resync (at the start, after a reset) confirms the words it believes
only with a new sample, which it asks the board for, never by reading them again.

The controller runs on ``--backend serial`` against ``servodesk emulate`` in another
process (at SCHED_FIFO 70, below the controller): ``--flip-word`` sends one wrong word every
``--fault-every`` seconds and ``--hold-replies`` then holds the board's answers back, the
reporter's case; ``--flip-first`` makes the first answer after every configuration wrong.
The encoders make no wrong readings of their own here (``--glitch-scale 0``).
"""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager

import numpy as np
import pytest

from control import ControlClient
from control.motion import moves
from control.rt.layout import Status
from hw.machine import load_machine

UNIMATE = load_machine("unimate2000b")
ROTATE = UNIMATE.joint_index("rotate")
BEND = UNIMATE.joint_index("bend")
TOLERANCE = np.array([j.tolerance for j in UNIMATE.joints])
WRONG_BIT = 11  # a Gray word's bit 11: tens of degrees away, far beyond a tick's reach
LINK_FAULTS = 3  # link faults a test resets and goes on from (see ``until_held``)


def free_tcp_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@contextmanager
def cpu_burner() -> Iterator[None]:
    """One busy loop at normal priority beside the test; killed on the way out."""
    burner = subprocess.Popen([sys.executable, "-c", "while True:\n    pass\n"])
    try:
        yield
    finally:
        burner.kill()
        burner.wait(timeout=10)


def held_for(client: ControlClient, seconds: float) -> Callable[[], bool]:
    """A condition: ``seconds`` of the controller's time have passed from now, or it latched."""
    since = client.status().time_s

    def done() -> bool:
        status = client.status()
        return status.estop or status.time_s > since + seconds

    return done


def feedback_faults(client: ControlClient) -> list[str]:
    """The feedback faults among the events not yet taken."""
    return [e.message for e in client.poll_events()
            if e.kind == "fault" and e.payload["kind"] == "feedback"]


def until_held(client: ControlClient, seconds: float, wait: Callable[..., float]) -> Status:
    """Hold ``seconds`` of the controller's time; the status then. A link fault on the way
    (the board silent for the 50 ms link timeout: this shared VM now and then stops its
    real-time tasks that long) is reset and the hold begun again, at most ``LINK_FAULTS``
    times: not what these tests are about, and said if it happens more often."""
    for _ in range(LINK_FAULTS + 1):
        wait(held_for(client, seconds), 10.0, f"{seconds:g} s of holding")
        status = client.status()
        if not status.fault.startswith("link fault"):
            return status
        client.reset()
        client.wait_event("estop", 5.0, lambda e: not e.payload["latched"])
    raise AssertionError(f"{LINK_FAULTS + 1} link faults: {status.fault}")


@pytest.mark.parametrize("hold_ms", [3, 6, 10])
def test_one_wrong_word_read_through_late_answers_is_one_glitch_not_a_fault(
        controller, emulator, until, measured, hold_ms: int) -> None:
    """Rotate holding still; every 0.1 s one wrong Rotate word, then the board's answers
    held back ``hold_ms``: the controller re-reads that word every tick of the hold. Each
    wrong word is rejected once (no more glitches than wrong words sent) and no feedback
    fault comes, however long the hold (it used to be five rejections in a row, a feedback
    fault, from 3-6 ms of hold on). The wrong words come 100 ms apart, ten times the longest
    hold, so each is judged alone, as when they came every 0.3 s; five come in 0.5 s."""
    board = emulator("--glitch-scale", "0", "--flip-word", f"{ROTATE}:{WRONG_BIT}",
                     "--hold-replies", str(hold_ms), "--fault-every", "0.1")
    client = controller(backend="serial", port=board.url)
    while not (status := until_held(client, 0.1, until)).estop:
        if status.glitches[ROTATE] >= 5:
            break
    assert not status.estop, status.fault
    summary = board.stop()
    assert feedback_faults(client) == []
    measured("wrong_words_sent", summary["flipped_words"])
    measured("glitches_counted", status.glitches[ROTATE])
    assert 0 < status.glitches[ROTATE] <= summary["flipped_words"], (
        f"{status.glitches[ROTATE]} glitches from {summary['flipped_words']} wrong words: "
        "a wrong word was judged more than once")
    assert summary["held_back"] >= 5
    assert sum(status.glitches) == status.glitches[ROTATE]


def test_a_stuck_bit_read_through_late_answers_is_still_a_feedback_fault(
        controller, emulator, measured) -> None:
    """Bit 8 of Up/Down's word stuck at 1 (as in test_feedback.py) while the board holds its
    answers back 5 ms every 10 ms: the readings judged are fewer, but a word that stays
    wrong is still a feedback fault naming Up/Down, never a believed jump."""
    updown = UNIMATE.joint_index("updown")
    board = emulator("--stuck-bit", f"{updown}:8:1", "--glitch-scale", "0",
                     "--hold-replies", "5", "--fault-every", "0.01")
    client = controller(backend="serial", port=board.url)
    start = np.array(client.status().position)
    handle = client.move(moves.step(start, updown, start[updown] + 5.0, duration=3.0,
                                    machine=UNIMATE), kind="step")
    result = client.wait(handle, timeout=10)
    fault = client.wait_event("fault", 10.0, lambda e: e.payload["kind"] == "feedback")
    assert fault.payload["joint"] == updown and "5 jumps in a row" in fault.message
    assert client.status().estop
    assert np.abs(np.diff(result.run.actual[:, updown])).max() < 0.5, "a jump was believed"
    moving = np.flatnonzero(result.run.desired[:, updown] != start[updown])[0]
    measured("stuck_bit_to_fault_ms", (result.run.samples - moving) * client.dt * 1e3, "ms")


def test_a_step_read_through_late_answers_is_no_frozen_encoder(controller, emulator,
                                                                measured) -> None:
    """A 30° Rotate step with the board's answers held back 10 ms every 25 ms: the valve is
    wide open for longer than the supervisor's 200 ms window while the words the controller
    reads are up to 10 ms old, as often as not. The supervisor judges motion over its whole
    window, so stale words for a few ms are no frozen encoder: the step completes."""
    board = emulator("--glitch-scale", "0", "--hold-replies", "10", "--fault-every", "0.025")
    client = controller(backend="serial", port=board.url)
    start = np.array(client.status().position)
    result = client.wait(client.move(moves.step(start, ROTATE, start[ROTATE] + 30.0,
                                                duration=2.0, machine=UNIMATE), kind="step"),
                         timeout=30)
    summary = board.stop()
    measured("answers_held_back", summary["held_back"])
    assert result.complete, result.status
    assert feedback_faults(client) == []
    open_s = measured("rotate_valve_open_s",
                      float((np.abs(result.run.duty[:, ROTATE]) >= 50.0).sum()) * client.dt, "s")
    assert open_s > 0.2, "the valve must be open for longer than the supervisor's window"


def test_resets_after_watchdog_trips_hold_where_the_arm_is_beside_a_cpu_burner(
        controller, emulator, until, measured) -> None:
    """Ten times, beside a CPU burner: the controller frozen 150 ms trips the board's
    watchdog; the operator's reset reconnects, and the board's first answer after each
    configuration has a wrong Bend word. The resync asks the board for new samples and
    believes the true words over the wrong one, so each reset is released and the arm then
    holds where it was, without a fault, for 0.1 s of the controller's time. (A resync that
    re-read the first answer confirmed its wrong word, and the true ones after it were a
    feedback fault: ``glitch_limit``, five, rejections in a row, 5 ms after the release; a
    hold toward a wrong Bend word, tens of degrees off, moves the arm within ms.)"""
    board = emulator("--tcp", str(free_tcp_port()), "--glitch-scale", "0",
                     "--flip-first", f"{BEND}:{WRONG_BIT}")
    client = controller(backend="serial", port=board.url)
    until(lambda: client.status().link["frames_rx"] > 50, 5.0, "the board to run (unheld)")
    assert not client.status().estop, client.status().fault
    where = np.array(client.status().position)
    held = 0
    with cpu_burner():
        for attempt in range(10):
            os.kill(client.pid, signal.SIGSTOP)
            time.sleep(0.15)  # past the board's 50 ms watchdog
            os.kill(client.pid, signal.SIGCONT)
            until(lambda: client.status().estop, 5.0, f"the link fault, attempt {attempt + 1}")
            client.reset()
            released = client.wait_event("estop", 5.0, lambda e: not e.payload["latched"])
            assert released.payload["reason"] == "reset by operator", attempt
            status = until_held(client, 0.1, until)
            assert not status.estop, f"attempt {attempt + 1}: {status.fault}"
            moved = np.abs(np.array(status.position) - where)
            assert np.all(moved <= 3 * TOLERANCE), (attempt, moved.round(2).tolist())
            held += 1
    measured("resets_held", held)
    summary = board.stop()
    assert summary["flipped_words"] >= 11  # the start's first answer and each reset's
    events = client.poll_events()
    assert [e.message for e in events if e.kind == "refused"] == []
    assert [e.message for e in events if e.kind == "fault" and e.payload["kind"] == "feedback"
            ] == []
