"""The UI side frozen (SIGSTOP) or killed (SIGKILL) mid-move: the controller holds on the
next tick it notices, keeps ticking and publishing without a stall (it does no file I/O in
the loop), and the interrupted run is saved: by the client when it comes back, by the
controller itself after its loop has ended when the client is gone for good.

The "UI" is a small client script in its own process (as the TUI would be),
driven over its stdin. The test watches the controller from outside through
the control segment's seqlocked status, so it sees what an operator's second
screen would see while the client is gone.
"""

from __future__ import annotations

import contextlib
import ctypes
import json
import os
import signal
import subprocess
import sys
import textwrap
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from control import Flag, Mode
from control.recorder import list_runs, load_run
from control.rt import shm
from control.rt.layout import ControlLayout, LatencyHistogram, Status
from control.rt.seqlock import SeqlockReader

PR_SET_CHILD_SUBREAPER = 36
MISSED_AT_MOST = 100  # ticks around a client's death: a third of what saving 10 s in it cost
ROOT = Path(__file__).resolve().parents[2]

CLIENT_SCRIPT = textwrap.dedent("""
    import json, sys
    import numpy as np
    from control import ControlClient
    from control.motion import moves

    data_dir, orphan_s, path_file = sys.argv[1], float(sys.argv[2]), sys.argv[3]
    seconds, degrees = float(sys.argv[4]), float(sys.argv[5])
    client = ControlClient("unimate2000b", data_dir=data_dir, orphan_timeout_s=orphan_s)
    start = client.status().position
    path = moves.step(start, 1, start[1] + degrees, duration=seconds, machine=client.machine)
    np.save(path_file, path)
    handle = client.move(path, kind="step")
    print(json.dumps({"controller": client.pid, "segment": client.segment_name}), flush=True)
    for line in sys.stdin:
        command = line.strip()
        if command == "report":
            print(json.dumps({"dead": client.dead, "alive": client.alive,
                              "tick": client.status().tick}), flush=True)
        elif command == "welcome":
            back = client.wait_event("notice", 5.0, lambda e: "client is back" in e.message)
            print(json.dumps({"notice": back.message}), flush=True)
        elif command == "wait":
            result = client.wait(handle, timeout=10)
            print(json.dumps({"status": result.status, "samples": result.run.samples,
                              "files": str(result.files.json) if result.files else None}),
                  flush=True)
        elif command == "close":
            client.close()
            print(json.dumps({"controller_exit": client.link.process.returncode}), flush=True)
            break
""")


class ClientScript:
    """The client script as a child process, answering one JSON line per command; its move
    is a step of Rotate by ``degrees`` lasting ``seconds``."""

    def __init__(self, data_dir: Path, orphan_timeout_s: float, seconds: float = 8.0,
                 degrees: float = 40.0) -> None:
        self.path_file = data_dir.parent / "path.npy"
        env = {**os.environ, "PYTHONPATH": str(ROOT)}
        self.proc = subprocess.Popen(
            [sys.executable, "-c", CLIENT_SCRIPT, str(data_dir), str(orphan_timeout_s),
             str(self.path_file), str(seconds), str(degrees)],
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, env=env)
        first = self.answer()
        self.controller = int(first["controller"])
        self.segment = str(first["segment"])

    def answer(self) -> dict:
        assert self.proc.stdout is not None
        line = self.proc.stdout.readline()
        assert line, "the client script ended unexpectedly"
        return json.loads(line)

    def ask(self, command: str) -> dict:
        assert self.proc.stdin is not None
        self.proc.stdin.write(command + "\n")
        self.proc.stdin.flush()
        return self.answer()

    @property
    def path(self) -> np.ndarray:
        return np.load(self.path_file)

    def kill(self) -> None:
        with contextlib.suppress(ProcessLookupError):
            os.kill(self.proc.pid, signal.SIGCONT)
        self.proc.kill()
        self.proc.wait(timeout=10)


class StatusWatch:
    """Read the controller's status and histogram from the client's control segment."""

    def __init__(self, name: str) -> None:
        self.segment = shm.attach(name)
        self.layout = ControlLayout(6)
        self.reader = SeqlockReader(self.segment.buf, self.layout.status_offset,
                                    self.layout.status.struct)

    def status(self) -> Status:
        return self.layout.status.decode(self.reader.read())

    def histogram(self) -> LatencyHistogram:
        values = self.layout.histogram(self.segment.buf).copy()
        return LatencyHistogram.from_counters(values, self.status().overruns)

    def holding_without_client(self) -> bool:
        s = self.status()
        return s.mode == Mode.HOLD and bool(s.flags & Flag.UI_LOST) and not s.moving

    def close(self) -> None:
        self.reader.release()
        shm.release(self.segment, unlink=False)


@contextlib.contextmanager
def adopting_orphans() -> Iterator[None]:
    """Make this process the child subreaper, so an orphaned controller's exit code is ours."""
    libc = ctypes.CDLL(None, use_errno=True)
    if libc.prctl(PR_SET_CHILD_SUBREAPER, 1, 0, 0, 0) != 0:
        raise OSError(ctypes.get_errno(), "prctl(PR_SET_CHILD_SUBREAPER) failed")
    try:
        yield
    finally:
        libc.prctl(PR_SET_CHILD_SUBREAPER, 0, 0, 0, 0)


def the_interrupted_run(runs: Path, rows_before: int, path: np.ndarray) -> Path:
    """The saved run (by the saver the exiting controller started: wait for it):
    interrupted, every row up to the hold, readable."""
    deadline = time.monotonic() + 60.0
    while not list_runs(runs):
        assert time.monotonic() < deadline, "the controller's saver saved no run in 60 s"
        time.sleep(0.05)
    (info,) = list_runs(runs)
    run = load_run(info.files.json)
    assert run.status == "interrupted: client silent"
    assert rows_before <= run.samples < len(path)
    # desired as saved: to 10⁻⁶ mm and 10⁻⁷° (recorder: its max_accel's decimals)
    np.testing.assert_allclose(run.desired, path[:run.samples], atol=0.5e-6)
    return info.files.json


def ticks_keep_coming(watch: StatusWatch, seconds: float) -> tuple[int, int, float]:
    """Ticks and latency-histogram counts published during ``seconds`` without a client, and
    the latest wake-up among those ticks (µs, to the 5 µs bin; the last bin holds ≥ 2 ms)."""
    s0, h0 = watch.status(), watch.histogram()
    time.sleep(seconds)
    s1, h1 = watch.status(), watch.histogram()
    assert s1.mode == Mode.HOLD and s1.flags & Flag.UI_LOST
    grew = np.flatnonzero(h1.counts - h0.counts)
    latest = (grew[-1] + 1) * h1.bin_us if len(grew) else 0.0
    return s1.tick - s0.tick, h1.ticks - h0.ticks, latest


def test_a_frozen_client_makes_the_controller_hold_and_it_is_alive_on_resume(
        tmp_path: Path, until, leftovers, measured) -> None:
    """SIGSTOP of the client mid-move: the controller aborts into hold when the heartbeats
    stop (time from the freeze measured), keeps ticking and recording its latency (it never
    blocks on the channel, and saves nothing in the loop); on SIGCONT the client finds it
    alive, is told how the move ended and saves the interrupted run, and its close stops the
    controller with exit code 0 and no segment left."""
    runs = tmp_path / "runs"
    script = ClientScript(runs, orphan_timeout_s=30.0)
    watch = StatusWatch(script.segment)
    try:
        until(lambda: watch.status().move_done >= 300, 10.0, lambda: "the move to run "
              f"({watch.status().mode.name}, flags {watch.status().flags!r}, "
              f"{watch.status().move_done} samples)")
        rows_before = watch.status().move_done
        os.kill(script.proc.pid, signal.SIGSTOP)
        hold_s = until(watch.holding_without_client, 5.0, "the controller to hold")
        measured("hold_after_freeze_ms", hold_s * 1e3, "ms")
        assert hold_s < 2.0, "design: the controller holds 250 ms after the last heartbeat"
        ticks, counted, latest_us = ticks_keep_coming(watch, 0.5)
        measured("ticks_per_s_while_frozen", ticks / 0.5)
        measured("latest_wakeup_while_frozen_us", latest_us, "µs")
        assert ticks > 250 and counted > 250, "the loop must not block on a frozen client"
        assert list_runs(runs) == [], "the loop saved a run: file I/O in the tick"

        os.kill(script.proc.pid, signal.SIGCONT)
        report = script.ask("report")
        assert report["dead"] == "" and report["alive"] is True
        assert script.ask("welcome")["notice"] == "client is back; holding position"
        until(lambda: not watch.status().flags & Flag.UI_LOST, 5.0, "the client to be back")
        until(lambda: watch.status().tick > report["tick"] + 100, 2.0, "ticks after the resume")
        result = script.ask("wait")
        assert result["status"] == "interrupted: client silent"
        assert result["files"] == str(the_interrupted_run(runs, rows_before, script.path))
        assert script.ask("close")["controller_exit"] == 0
        script.proc.wait(timeout=10)
    finally:
        watch.close()
        script.kill()
    assert leftovers(script.proc.pid) == []


def test_a_client_killed_10_s_into_a_20_s_move_leaves_a_holding_controller_that_saves_and_exits(
        tmp_path: Path, until, leftovers, measured) -> None:
    """SIGKILL of the client 10 s into a 20 s move: the controller holds at once (measured),
    keeps ticking with no stall, exits with code 0 after its orphan timeout (measured), and
    only then, its loop ended, hands the interrupted run over to a saver of its own, which
    saves it with every row recorded; no shared-memory segment is left.

    10 s, because this is also the case that stalled the loop for a second when the controller
    saved the run inside its tick (a 30 s run: ~900 ticks): what a save in the tick costs grows
    with the run, and saving these 10 s there cost ~300 ticks, where fewer than
    ``MISSED_AT_MOST`` may be missed around the kill (the latest wake-up around it: 110 µs on
    a quiet machine, the target is under 2 ms). One scenario for both claims: a client killed
    300 rows into its move had a controller of its own to show the hold, the ticks and the
    exit, 2 s of the suite."""
    runs = tmp_path / "runs"
    orphan_s = 1.5
    with adopting_orphans():
        script = ClientScript(runs, orphan_timeout_s=orphan_s, seconds=20.0)
        watch = StatusWatch(script.segment)
        try:
            until(lambda: watch.status().move_done >= 10_000, 120.0, lambda: "10 s of the move "
                  f"({watch.status().mode.name}, flags {watch.status().flags!r}, "
                  f"{watch.status().move_done} samples)")
            rows_before = watch.status().move_done
            h0, s0 = watch.histogram(), watch.status()
            killed = time.monotonic()
            script.proc.kill()
            script.proc.wait(timeout=10)
            hold_s = until(watch.holding_without_client, 5.0, "the controller to hold")
            measured("hold_after_kill_ms", hold_s * 1e3, "ms")
            assert hold_s < 2.0, "design: the controller holds 250 ms after the last heartbeat"
            ticks, counted, latest_us = ticks_keep_coming(watch, 0.5)
            measured("latest_wakeup_after_kill_us", latest_us, "µs")
            assert ticks > 250 and counted > 250, "the loop must go on ticking without a client"
            h1, s1 = watch.histogram(), watch.status()
            grew = np.flatnonzero(h1.counts - h0.counts)
            measured("latest_wakeup_around_the_kill_us", (grew[-1] + 1) * h1.bin_us, "µs")
            missed = measured("ticks_missed_around_the_kill", s1.overruns - s0.overruns)
            # a save in the tick missed ~300; a CPU burner beside costs up to 24 (seen)
            assert missed < MISSED_AT_MOST, "the loop stalled when its client died"
            assert list_runs(runs) == [], "the loop saved a run: file I/O in the tick"
        finally:
            watch.close()
        _, code = os.waitpid(script.controller, 0)
        exited_s = measured("exit_after_kill_s", time.monotonic() - killed, "s")
    assert os.waitstatus_to_exitcode(code) == 0
    saved = the_interrupted_run(runs, rows_before, script.path)
    measured("run_saved_rows", load_run(saved).samples)
    assert orphan_s <= exited_s < orphan_s + 5.0
    # the saver unlinks the segment once the run is saved: just after its files appear
    until(lambda: leftovers(script.proc.pid) == [], 30.0, "the saver to unlink the segment")


def test_a_stall_of_the_whole_machine_is_not_the_clients_silence(tmp_path: Path, until,
                                                                 leftovers, measured) -> None:
    """The controller and its client both stopped for 0.6 s mid-move, as a stalled machine
    (or hypervisor) stops every process, and woken controller first: with the controller's
    real 250 ms timeout the client is not called silent for a stall it had no CPU in. The
    move completes and its run lists the stall. (A client frozen alone is lost: above.) The
    step is small and over before the stall: a valve left open through a stall moves the
    joint, and the supervisor's answer to that is not this test's subject. The move lasts 1 s:
    the stall begins 0.3 s into it, whatever the move's length."""
    script = ClientScript(tmp_path / "runs", orphan_timeout_s=30.0, seconds=1.0, degrees=2.0)
    watch = StatusWatch(script.segment)
    try:
        until(lambda: watch.status().move_done >= 300, 10.0, "the move to run")
        os.kill(script.controller, signal.SIGSTOP)
        os.kill(script.proc.pid, signal.SIGSTOP)
        stopped = watch.status()
        assert stopped.moving, f"the stall came after the move ({stopped.move_done} samples)"
        stopped_at = stopped.tick
        time.sleep(0.6)
        os.kill(script.controller, signal.SIGCONT)
        # the client wakes once the controller has surely looked for its heartbeat: 0.6 s
        # after its last beat by the wall clock, a few ms by the controller's own
        until(lambda: watch.status().tick > stopped_at + 20, 5.0, "ticks after the stall")
        os.kill(script.proc.pid, signal.SIGCONT)
        result = script.ask("wait")
        assert result["status"].startswith("complete, with a 0."), result["status"]
        measured("machine_stall_s", float(result["status"].split()[3]), "s")
        assert not watch.status().flags & Flag.UI_LOST
        assert script.ask("close")["controller_exit"] == 0
        script.proc.wait(timeout=10)
    finally:
        watch.close()
        script.kill()
    assert leftovers(script.proc.pid) == []
