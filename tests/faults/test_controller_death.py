"""``kill -9`` of the control process mid-move: the client is told, the run is on disk,
and with the serial backend the I/O board's own watchdog closes the valves.

The client learns of the death from its channel (EOF) and the process table;
the board learns of it from the DUTY frames that stop arriving. Both latencies
are measured and recorded; the assertions allow a loaded machine's stalls.
"""

from __future__ import annotations

import os
import signal
import statistics
import time
from pathlib import Path

import numpy as np
import pytest

from control import ControllerError
from control.motion import moves
from control.recorder import as_written, load_run
from hw.backend import LinkCounters
from hw.gray import gray_to_binary
from hw.machine import load_machine
from hw.serial.messages import BOARD_TO_HOST, Event, Flag, MessageReader, Report, Status

UNIMATE = load_machine("unimate2000b")
ROTATE = UNIMATE.joint_index("rotate")


def test_kill_9_of_the_controller_is_reported_and_the_run_is_on_disk(
        controller, until, measured) -> None:
    """SIGKILL mid-move on the simulator: the client reports the death (time measured), the
    move ends as "interrupted: controller died", every row recorded before the kill is saved
    on disk and reads back, and further commands raise ControllerError."""
    client = controller()
    start = client.status().position
    path = moves.step(start, ROTATE, start[ROTATE] + 30.0, duration=5.0, machine=UNIMATE)
    handle = client.move(path, kind="step")
    until(lambda: client.status().move_done >= 300, 10.0, "the move to run")
    rows_before = client.status().move_done
    killed = time.monotonic()
    os.kill(client.pid, signal.SIGKILL)
    died = client.wait_event("died", timeout=5.0)
    told_ms = measured("client_told_ms", (died.wall - killed) * 1e3, "ms")
    assert told_ms < 2000, "the death must be reported promptly (design: 250 ms)"
    assert "controller died" in died.message and "restart servodesk" in died.message

    result = client.wait(handle, timeout=5.0)
    assert result.status == "interrupted: controller died"
    assert result.files is not None and result.save_error == ""
    saved = load_run(result.files.json)
    assert saved == as_written(result.run)
    assert saved.status == "interrupted: controller died"
    assert rows_before - 2 <= saved.samples < len(path)  # the status lags the record by a tick
    np.testing.assert_allclose(result.run.desired, path[:saved.samples], atol=1e-9)
    with pytest.raises(ControllerError, match="controller died"):
        client.jog([10.0] * 6)


def test_a_killed_controller_is_not_left_a_zombie(controller, until, measured) -> None:
    """SIGKILL of an idle controller: the client's monitor thread reaps the process as soon as
    it notices the death, so the process table holds no zombie while the client stays open
    (until ``close``, which a TUI only calls on the way out)."""
    client = controller()
    pid = client.pid
    killed = time.monotonic()
    os.kill(pid, signal.SIGKILL)
    client.wait_event("died", timeout=5.0)
    until(lambda: not is_zombie(pid), 5.0,
          lambda: f"the killed controller {pid} to be reaped (/proc/{pid}/stat: {stat(pid)!r})")
    measured("reaped_ms", (time.monotonic() - killed) * 1e3, "ms")
    assert client.dead


def stat(pid: int) -> str:
    """``/proc/PID/stat``, or "" once the process is gone (reaped while its stat is opened:
    ESRCH, ProcessLookupError)."""
    try:
        return Path(f"/proc/{pid}/stat").read_text()
    except (FileNotFoundError, ProcessLookupError):
        return ""


def is_zombie(pid: int) -> bool:
    """Whether ``pid`` is a zombie: exited, its status not yet collected (state ``Z``; the
    field after the command name in parentheses, which may itself hold spaces)."""
    text = stat(pid)
    return bool(text) and text.rsplit(")", 1)[1].split()[0] == "Z"


def read_board(url: str, seconds: float) -> list[Report | Status]:
    """What the board sent on its pty while nobody read it, then for ``seconds`` more."""
    fd = os.open(url, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
    reader = MessageReader(LinkCounters(), BOARD_TO_HOST)
    out: list[Report | Status] = []
    try:
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            try:
                data = os.read(fd, 4096)
            except BlockingIOError:
                time.sleep(0.005)
                continue
            out += [m for _, m in reader.feed(data) if isinstance(m, Report | Status)]
    finally:
        os.close(fd)
    return out


def rotate_deg(report: Report) -> float:
    cal = UNIMATE.joints[ROTATE].encoder
    return cal.gradient * gray_to_binary(report.words[ROTATE]) + cal.constant


def test_kill_9_with_the_serial_backend_the_board_watchdog_closes_the_valves(
        controller, emulator, until, measured) -> None:
    """SIGKILL of a controller driving the emulated I/O board over a pty: the board's own
    watchdog closes every valve (its WATCHDOG_TRIP says how long after the last command,
    recorded), Rotate, which was moving, comes to rest, the client reports the death and
    the open-loop run recorded before the kill is on disk."""
    board = emulator("--glitch-scale", "0")
    client = controller(backend="serial", port=board.url)
    profile = np.zeros((4000, 6))
    profile[:, ROTATE] = 45.0
    handle = client.actuate(profile, kind="tracking_actuate")
    until(lambda: client.status().move_done >= 300, 10.0, "the actuation to run")
    before = client.status().position[ROTATE]
    time.sleep(0.1)
    assert abs(client.status().position[ROTATE] - before) > 0.5, "Rotate should be moving"
    rows_before = client.status().move_done
    killed = time.monotonic()
    os.kill(client.pid, signal.SIGKILL)

    frames = read_board(board.url, 0.6)
    died = client.wait_event("died", timeout=5.0)
    measured("client_told_ms", (died.wall - killed) * 1e3, "ms")
    trips = [m for m in frames if isinstance(m, Status) and m.event == Event.WATCHDOG_TRIP]
    assert len(trips) == 1, f"expected one watchdog trip, the board sent {frames[:5]}…"
    trip = trips[0]
    watchdog_ms = measured("board_watchdog_ms", trip.detail, "ms")
    assert 50 <= watchdog_ms <= 250, "the board must trip at its 50 ms watchdog"
    assert trip.flags & (Flag.HELD | Flag.WATCHDOG) == Flag.HELD | Flag.WATCHDOG

    after = [m for m in frames if isinstance(m, Report) and m.t_us > trip.t_us + 100_000]
    assert len(after) >= 5, "the board keeps reporting (heartbeats) after the trip"
    assert all(m.flags & Flag.HELD for m in after)
    resting = [rotate_deg(m) for m in after]
    assert max(resting) - statistics.median(resting) < 0.2, "Rotate must be at rest"

    summary = board.stop()
    assert summary["watchdog"] is True and summary["held"] is True
    assert summary["watchdog_trips"] == 1

    result = client.wait(handle, timeout=5.0)
    assert result.status == "interrupted: controller died" and result.files is not None
    saved = load_run(result.files.json)
    assert saved.samples >= rows_before - 2
    assert np.all(saved.duty[:, ROTATE] == 45.0)
