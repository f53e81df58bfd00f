"""A run is never lost to a killed saver: the client killed at every point of saving a
finished run (before each file, inside the write of one, after the last before its segment
is unlinked) leaves the run either complete and listed, or whole in its move segment,
where the next start saves it, marked recovered, once; a controller killed with its client
leaves the run recorded so far to the next start too. Real processes, SIGKILL."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from control.motion.plan import path_rows
from control.recorder import RunFiles, list_runs, load_run
from control.recovery import recover_runs
from control.rt import shm

ROOT = Path(__file__).resolve().parents[2]

SAVER = textwrap.dedent("""
    import os, signal, sys
    from control import ControlClient, recorder
    from control.motion import moves

    data_dir, where, count, after = sys.argv[1], sys.argv[2], int(sys.argv[3]), sys.argv[4]
    calls = [0]

    def dying(original):
        def call(*args):
            if calls[0] == count and after == "before":
                os.kill(os.getpid(), signal.SIGKILL)
            result = original(*args)
            if calls[0] == count and after == "after":
                os.kill(os.getpid(), signal.SIGKILL)
            calls[0] += 1
            return result
        return call

    setattr(recorder, where, dying(getattr(recorder, where)))
    client = ControlClient("unimate2000b", lockstep=True, data_dir=data_dir,
                           heartbeat_timeout_s=3.0, orphan_timeout_s=0.3)
    print(client.pid, flush=True)
    start = client.status().position
    path = moves.step(start, 1, start[1] + 10.0, duration=2.0, machine=client.machine)
    client.wait(client.move(path, kind="step"), timeout=60)
    print("saved", flush=True)
""")

# (recorder function, its call, killed before or after it): before placing the TSV, the
# CSV, the JSON; inside writing each (its temporary written, not yet linked); after the
# JSON is placed and the directory synced, before the client unlinks the segment.
KILL_POINTS = [("_place", 0, "before"), ("_place", 1, "before"), ("_place", 2, "before"),
               ("_link", 0, "before"), ("_link", 1, "before"), ("_link", 2, "before"),
               ("_sync_dir", 0, "after")]


def test_an_exited_process_not_yet_reaped_is_dead_to_the_savers() -> None:
    """A process that has exited but is not reaped yet (a zombie: a controller whose client
    died waits for init to reap it, 1.6 s in this VM) is gone for ``shm.pid_alive``, which a
    saver waits on (``control/recovery.py --after``) and the next start's recovery asks."""
    child = subprocess.Popen([sys.executable, "-c", "pass"])
    stat = Path(f"/proc/{child.pid}/stat")
    deadline = time.monotonic() + 30.0
    while stat.read_text().rsplit(")", 1)[1].split()[0] != "Z":
        assert time.monotonic() < deadline, "the child never exited"
        time.sleep(0.005)
    try:
        assert not shm.pid_alive(child.pid), "a zombie counted as alive"
    finally:
        child.wait()
    assert shm.pid_alive(os.getpid())


def wait_dead(pid: int, timeout: float = 30.0) -> None:
    deadline = time.monotonic() + timeout
    while shm.pid_alive(pid):
        assert time.monotonic() < deadline, f"process {pid} still alive"
        time.sleep(0.02)


@pytest.mark.parametrize(("where", "count", "when"), KILL_POINTS,
                         ids=[f"{when}{w}-{c}" for w, c, when in KILL_POINTS])
def test_a_saver_killed_anywhere_loses_no_run(tmp_path: Path, measured, where: str,
                                              count: int, when: str) -> None:
    runs = tmp_path / "runs"
    saver = subprocess.Popen([sys.executable, "-c", SAVER, str(runs), where, str(count), when],
                             stdout=subprocess.PIPE, text=True,
                             env={**os.environ, "PYTHONPATH": str(ROOT)})
    controller = int(saver.stdout.readline())
    rest = saver.stdout.read()
    assert saver.wait(60) == -signal.SIGKILL and "saved" not in rest, "the kill never came"
    wait_dead(controller)
    placed = when == "after"  # the kill came after the JSON was placed: the run was saved
    notices = recover_runs(tmp_path / "fallback")
    assert list_runs(runs), notices
    (info,) = list_runs(runs)
    run = load_run(info.files.json)
    assert path_rows(run) == 2001 < run.samples and run.meta.get("run_id")  # and its settle
    if placed:  # not saved twice
        assert info.status == "complete" and not run.meta.get("recovered")
    else:
        assert info.status == "recovered: complete" and run.meta["recovered"] is True
        # a client starting meanwhile (another test on another worker) may have recovered it
        # first, even before this test listed the runs: every start recovers every dead move
        # segment of the user, into its own directory; the notice is told by whichever
        # recovered it (once seen in CI: a listing taken to tell "saved" apart held it)
        ours = [n for n in notices if str(runs) in n]
        assert ours == [] or "recovered a step run" in ours[0], notices
    leftovers = sorted(p.name for p in runs.iterdir()
                       if p.suffix == ".tmp" or not RunFiles.from_json(p).json.exists())
    assert leftovers == [], "a killed save left parts behind"
    assert [n for n in shm.leftover_segments() if shm.owner_pid(n) == saver.pid] == []
    measured("recovered", 0.0 if placed else 1.0)


def test_a_controller_killed_with_its_client_leaves_the_run_to_the_next_start(
        tmp_path: Path) -> None:
    """Both processes killed mid-move: the segment holds the rows recorded up to the kill,
    and the next start saves them as an interrupted run."""
    runs = tmp_path / "runs"
    script = textwrap.dedent("""
        import sys, time
        from control import ControlClient
        from control.motion import moves
        client = ControlClient("unimate2000b", data_dir=sys.argv[1])
        start = client.status().position
        path = moves.step(start, 1, start[1] + 10.0, duration=20.0, machine=client.machine)
        client.move(path, kind="step")
        while client.status().move_done < 500:
            time.sleep(0.01)
        print(client.pid, flush=True)
        time.sleep(60)
    """)
    client = subprocess.Popen([sys.executable, "-c", script, str(runs)], stdout=subprocess.PIPE,
                              text=True, env={**os.environ, "PYTHONPATH": str(ROOT)})
    controller = int(client.stdout.readline())
    os.kill(controller, signal.SIGKILL)
    client.kill()
    client.wait(30)
    wait_dead(controller)
    recover_runs(tmp_path / "fallback")
    (info,) = list_runs(runs)
    assert info.status == "recovered: interrupted: the client and the controller died"
    assert info.samples >= 500
    doc = json.loads(info.files.json.read_text())
    assert doc["meta"]["recovered"] is True


def test_a_run_its_client_could_not_save_is_saved_by_the_next_start(tmp_path: Path) -> None:
    """The data directory is unusable when the move ends (a file where it should be): the
    client keeps the run in its segment and exits; once the directory is usable, the next
    start saves the run, marked recovered."""
    runs = tmp_path / "runs"
    runs.write_text("a file where the runs' directory should be")
    script = textwrap.dedent("""
        import json, sys
        from control import ControlClient
        from control.motion import moves
        with ControlClient("unimate2000b", lockstep=True, data_dir=sys.argv[1],
                           heartbeat_timeout_s=3.0) as client:
            start = client.status().position
            path = moves.step(start, 1, start[1] + 10.0, duration=2.0, machine=client.machine)
            result = client.wait(client.move(path, kind="step"), timeout=60)
        print(json.dumps({"error": result.save_error}), flush=True)
    """)
    done = subprocess.run([sys.executable, "-c", script, str(runs)], capture_output=True,
                          text=True, timeout=120, env={**os.environ, "PYTHONPATH": str(ROOT)})
    assert done.returncode == 0, done.stderr
    assert "where the next start saves it" in json.loads(done.stdout)["error"]
    runs.unlink()
    notices = recover_runs(tmp_path / "fallback")
    (info,) = list_runs(runs)
    assert info.status == "recovered: complete", notices
    assert path_rows(load_run(info.files.json)) == 2001 < info.samples  # and its settle
