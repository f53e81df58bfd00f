"""E-stop during every mode: every valve is closed in the tick that latches it.

The loop publishes its status after writing the valves in the same tick, so
the first published status that shows the latch shows what the valves got
that tick. A tap thread reads the status as fast as it can and keeps every
tick it sees; the test then looks at the last tick before the E-stop and the
first tick after it. Both E-stop sources are driven: the operator's command
and the E-stop input (the simulator's button; on the serial backend, the
emulated board's button, which closes the valves on the board itself).
"""

from __future__ import annotations

import signal
import threading
import time
from collections.abc import Callable

import numpy as np
import pytest

from control import ControlClient, Flag, Mode, MoveHandle, Status
from control.motion import moves
from control.recorder import load_run
from hw.machine import load_machine

UNIMATE = load_machine("unimate2000b")
ROTATE = UNIMATE.joint_index("rotate")


class StatusTap:
    """Every distinct tick's status, read in a thread as fast as the seqlock allows."""

    def __init__(self, client: ControlClient) -> None:
        self.client = client
        self.seen: list[tuple[float, Status]] = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)

    def __enter__(self) -> StatusTap:
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self._thread.join(timeout=5)

    def _run(self) -> None:
        last = -1
        while not self._stop.is_set():
            status = self.client.status()
            if status.tick != last:
                self.seen.append((time.monotonic(), status))
                last = status.tick
            time.sleep(0.0001)

    def latest(self) -> Status | None:
        return self.seen[-1][1] if self.seen else None

    def ticks_latched(self) -> int:
        """Ticks seen since the first latched one (0: none latched yet)."""
        first = next((s.tick for _, s in self.seen if s.estop), None)
        return 0 if first is None else self.seen[-1][1].tick - first

    def around(self, sent: float) -> tuple[Status, list[tuple[float, Status]]]:
        """The last status read before ``sent`` and every latched one read after it."""
        before = [s for t, s in self.seen if t < sent]
        latched = [(t, s) for t, s in self.seen if t >= sent and s.estop]
        assert before and latched, "the tap saw no status before, or no latch after"
        return before[-1], latched


def start_hold(client: ControlClient) -> None:
    client.jog_position(ROTATE, 20.0)


def start_follow_track(client: ControlClient) -> MoveHandle:
    start = client.status().position
    return client.move(moves.step(start, ROTATE, start[ROTATE] + 30.0, duration=4.0,
                                  machine=UNIMATE), kind="step")


def start_manual(client: ControlClient) -> None:
    client.jog([30.0] * 6)


def start_tracking_actuate(client: ControlClient) -> MoveHandle:
    profile = np.zeros((4000, 6))
    profile[:, ROTATE] = 40.0
    return client.actuate(profile)


def start_initialise(client: ControlClient) -> None:
    client.initialise()


MODES: dict[str, tuple[Mode, Callable[[ControlClient], MoveHandle | None]]] = {
    "hold": (Mode.HOLD, start_hold),
    "follow_track": (Mode.FOLLOW_TRACK, start_follow_track),
    "manual_actuate": (Mode.MANUAL_ACTUATE, start_manual),
    "tracking_actuate": (Mode.TRACKING_ACTUATE, start_tracking_actuate),
    "initialise": (Mode.INITIALISE, start_initialise),
}
REASONS = {"operator": "operator E-stop", "button": "E-stop input pressed"}
AFTER_TICKS = 50  # latched ticks watched after the latching one: a valve reopened shows at once
MOVE_ROWS = 100  # rows a move has recorded when the E-stop comes


def press(client: ControlClient, source: str) -> None:
    if source == "operator":
        client.estop()
    else:
        client.inject("press_estop", True)


def release(client: ControlClient, source: str) -> None:
    if source == "button":
        client.inject("press_estop", False)
    client.reset()


def assert_closed_on_the_latching_tick(tap: StatusTap, sent: float, mode: Mode,
                                       measured: Callable[..., float]) -> Status:
    before, latched = tap.around(sent)
    assert before.mode == mode and not before.estop
    assert any(before.valve), f"nothing was moving before the E-stop: {before.valve}"
    first = latched[0][1]
    assert first.valve == (0.0,) * len(first.valve), f"valves open when latched: {first.valve}"
    assert first.duty == (0.0,) * len(first.duty) and first.mode == Mode.HOLD
    assert all(s.valve == (0.0,) * len(s.valve) for _, s in latched)
    measured("latched_after_ms", (latched[0][0] - sent) * 1e3, "ms")
    measured("ticks_from_last_seen_to_latch", first.tick - before.tick)
    return first


@pytest.mark.parametrize("source", list(REASONS))
@pytest.mark.parametrize("mode", list(MODES))
def test_estop_closes_every_valve_on_the_latching_tick(controller, until, measured,
                                                       mode: str, source: str) -> None:
    """In each mode (hold moving to a new target, follow_track, manual_actuate,
    tracking_actuate, the rig's initialise), with motion under way, an E-stop from the
    operator or from the E-stop input latches, and the first status that shows the latch
    already has every valve and every controller output at 0, as have the fifty ticks after
    it (``AFTER_TICKS``); a move in progress (a hundred samples of it) ends as "estop: …"
    with its run on disk; a reset returns to hold."""
    expected, start = MODES[mode]
    rig = mode == "initialise"
    client = controller("rig" if rig else "unimate2000b",
                        sim_options={"initial": [400.0]} if rig else {})
    with StatusTap(client) as tap:
        handle = start(client)
        until(lambda: (seen := tap.latest()) is not None and seen.mode == expected
              and any(seen.valve) and (handle is None or seen.move_done > MOVE_ROWS), 5.0,
              f"the tap to see {mode} move a joint")
        sent = time.monotonic()
        press(client, source)
        event = client.wait_event("estop", 5.0, lambda e: e.payload["latched"])
        until(lambda: tap.ticks_latched() >= AFTER_TICKS, 5.0, "the tap to see ticks latched")
    assert event.payload["reason"] == REASONS[source]
    first = assert_closed_on_the_latching_tick(tap, sent, expected, measured)
    assert first.fault == REASONS[source]
    if handle is not None:
        result = client.wait(handle, timeout=5.0)
        assert result.status == f"estop: {REASONS[source]}"
        assert load_run(result.files.json).samples > MOVE_ROWS
    release(client, source)
    until(lambda: not client.status().estop, 2.0, "the reset")
    assert client.status().mode == Mode.HOLD


def test_the_boards_estop_button_closes_the_valves_over_the_serial_link(
        controller, emulator, until, measured) -> None:
    """On the serial backend, the emulated board's E-stop button (SIGUSR1) during a
    follow_track move: the board holds its valves closed itself, the controller latches,
    and the first latched status has every valve at 0; released (SIGUSR2) and reset, the
    robot holds again."""
    board = emulator("--glitch-scale", "0")
    client = controller(backend="serial", port=board.url)
    with StatusTap(client) as tap:
        start_follow_track(client)
        until(lambda: client.status().move_done > 200, 5.0, "the move to run")
        sent = time.monotonic()
        board.send(signal.SIGUSR1)
        event = client.wait_event("estop", 5.0, lambda e: e.payload["latched"])
        until(lambda: tap.ticks_latched() >= AFTER_TICKS, 5.0, "the tap to see ticks latched")
    assert event.payload["reason"] == REASONS["button"]
    assert_closed_on_the_latching_tick(tap, sent, Mode.FOLLOW_TRACK, measured)
    board.send(signal.SIGUSR2)
    until(lambda: not client.status().flags & Flag.ESTOP_INPUT, 5.0, "the button released")
    client.reset()
    until(lambda: not client.status().estop, 2.0, "the reset")
    assert client.status().mode == Mode.HOLD and client.status().fault == ""
