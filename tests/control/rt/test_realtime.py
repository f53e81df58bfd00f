"""The control process's core: each controller on a host claims the highest-numbered core
no other has claimed, the last is shared when all are, and a claim ends with its process."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
from pathlib import Path

import pytest

from control import ControlClient
from control.rt.realtime import claim_cpu
from tests.control.waiting import wait_until


def test_each_claim_takes_the_highest_free_core_and_then_none_is_free(tmp_path: Path) -> None:
    """Within one process each open is its own claim, as another process's would be."""
    assert [claim_cpu([0, 1, 2], tmp_path) for _ in range(4)] == [2, 1, 0, None]


def test_a_symbolic_link_or_a_file_we_cannot_open_is_no_claim_of_ours(tmp_path: Path) -> None:
    (tmp_path / "servodesk-rt-cpu1.lock").symlink_to(tmp_path / "elsewhere")
    assert claim_cpu([0, 1], tmp_path) == 0
    assert not (tmp_path / "elsewhere").exists()


def test_a_fifo_in_a_claims_place_is_no_claim_and_holds_nothing_up(tmp_path: Path) -> None:
    """Another user's FIFO where a claim file goes: opening it waited for a writer, so the
    controller claiming cores never started (it hung in ``open``)."""
    fifo = tmp_path / "servodesk-rt-cpu1.lock"
    os.mkfifo(fifo)
    claimed: list[int | None] = []
    claiming = threading.Thread(target=lambda: claimed.append(claim_cpu([0, 1], tmp_path)),
                                daemon=True)
    claiming.start()
    claiming.join(10)
    if claiming.is_alive():
        os.close(os.open(fifo, os.O_WRONLY | os.O_NONBLOCK))  # a writer lets the open return
        pytest.fail("claiming a core waits on the FIFO")
    assert claimed == [0]


def test_a_claim_ends_with_its_process(tmp_path: Path) -> None:
    holder = subprocess.Popen(
        [sys.executable, "-c", "import sys, time\nfrom pathlib import Path\n"
         "from control.rt.realtime import claim_cpu\n"
         f"print(claim_cpu([0, 1], Path({str(tmp_path)!r})), flush=True)\ntime.sleep(60)\n"],
        stdout=subprocess.PIPE, text=True, cwd=Path(__file__).parents[3])
    try:
        assert holder.stdout is not None and holder.stdout.readline().strip() == "1"
        assert claim_cpu([0, 1], tmp_path) == 0  # (this process holds 0 from now on)
    finally:
        holder.kill()
        holder.wait(timeout=10)
    assert claim_cpu([0, 1], tmp_path) == 1


@pytest.mark.skipif(len(os.sched_getaffinity(0)) < 2, reason="one core: nothing to spread")
def test_two_controllers_run_on_two_cores(tmp_path: Path, monkeypatch: pytest.MonkeyPatch
                                          ) -> None:
    """A real-time controller beside another (a rig and a robot on one host) takes a core
    of its own rather than waiting for the other's ticks on the same one. Their claims are
    kept apart from the host's: another test worker's controller, or a benchmark's, holding
    the other core would rightly make them share the last (a failure seen at load)."""
    monkeypatch.setenv("SERVODESK_CPU_CLAIMS", str(tmp_path))
    with (ControlClient("rig", data_dir=tmp_path / "a") as one,
          ControlClient("unimate2000b", data_dir=tmp_path / "b") as two):
        if not (one.realtime and two.realtime):
            pytest.skip("no SCHED_FIFO here (root or CAP_SYS_NICE): controllers are not pinned")
        wait_until(lambda: len(os.sched_getaffinity(one.pid)) == 1
                   and len(os.sched_getaffinity(two.pid)) == 1, 10, "both pinned")
        assert os.sched_getaffinity(one.pid) != os.sched_getaffinity(two.pid)


def test_a_controller_on_a_shared_core_runs_no_warm_up_and_says_so(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Every core claimed (three controllers on two cores, say): the one that shares the last
    runs no warm-up, whose window before its own deadline would hold the other's ticks, and
    its notice says why. With a core of its own it runs one (its counters at exit)."""
    monkeypatch.setenv("SERVODESK_CPU_CLAIMS", str(tmp_path))
    monkeypatch.setenv("SERVODESK_WARM_UP", "report")

    def warm_up_of(client: ControlClient) -> bool:
        os.kill(client.pid, signal.SIGTERM)  # its loop ends and the counters are written
        wait_until(lambda: not client.alive, 10, "the controller's end")
        return "warm-up: windows" in client.controller_log()

    with ControlClient("unimate2000b", data_dir=tmp_path / "a") as alone:
        if not alone.realtime:
            pytest.skip("no SCHED_FIFO here (root or CAP_SYS_NICE): controllers are not pinned")
        assert "shared" not in alone.notice and warm_up_of(alone), alone.controller_log()
    cpus = sorted(os.sched_getaffinity(0))
    for _ in cpus:  # this process holds every core from now on
        claim_cpu(cpus, tmp_path)
    with ControlClient("unimate2000b", data_dir=tmp_path / "b") as beside:
        assert f"CPU {cpus[-1]} shared" in beside.notice, beside.notice
        assert not warm_up_of(beside), beside.controller_log()


def test_a_clients_threads_keep_off_its_real_time_controllers_core(tmp_path: Path,
                                                                    monkeypatch: pytest.MonkeyPatch
                                                                    ) -> None:
    """A client thread on the controller's core waited out its spin and tick, and its command
    went out just after a tick, a whole period before the next (control/off_core.py): while
    the controller runs, no thread of the client's process is on its core; after, they may be."""
    monkeypatch.setenv("SERVODESK_CPU_CLAIMS", str(tmp_path))
    before = os.sched_getaffinity(0)
    if len(before) < 2:
        pytest.skip("one core: there is no other to keep to")
    with ControlClient("rig", data_dir=tmp_path / "runs") as client:
        if not client.realtime:
            pytest.skip("no SCHED_FIFO here (root or CAP_SYS_NICE): controllers are not pinned")
        (core,) = os.sched_getaffinity(client.pid)
        for task in os.listdir("/proc/self/task"):  # the client's own threads among them
            assert core not in os.sched_getaffinity(int(task)), task
    assert os.sched_getaffinity(0) == before
