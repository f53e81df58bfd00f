"""The run directory cannot take the run when a move ends: disk full, or not a directory.

"Disk full" is honest here: a 64 KiB tmpfs mounted for the test (root only) is
the data directory, and a run of a few thousand samples does not fit. Where
mounting is not allowed the tmpfs case is skipped and the unwritable case (a
data directory whose parent is a file) still runs. Either way the operator is
told, the run is kept in memory and in its move segment, nothing half-written is
left, and the run can be saved elsewhere; the next start saves it from the segment
(tests/faults/test_saving.py shows that after a client exits).
"""

from __future__ import annotations

import os
import subprocess
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pytest

from control import ControlClient, MoveResult
from control.motion import moves
from control.motion.plan import path_rows
from control.recorder import RecorderError, as_written, load_run, save_run
from control.rt import shm
from hw.machine import load_machine

UNIMATE = load_machine("unimate2000b")
ROTATE = UNIMATE.joint_index("rotate")


@contextmanager
def tiny_tmpfs(path: Path, size: str) -> Iterator[Path]:
    """A tmpfs of ``size`` mounted at ``path``; skips the test where mounting is refused."""
    path.mkdir()
    mounted = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(path)],
                             capture_output=True, text=True, check=False)
    if mounted.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs to fill (needs root): {mounted.stderr.strip()}")
    try:
        yield path
    finally:
        subprocess.run(["umount", "-l", str(path)], check=False)


def remount(path: Path, size_bytes: int) -> None:
    subprocess.run(["mount", "-o", f"remount,size={size_bytes}", str(path)], check=True)


def run_a_step(controller: Callable[..., ControlClient], data_dir: Path
               ) -> tuple[ControlClient, MoveResult, np.ndarray]:
    """A 3 s step on Rotate saving into ``data_dir``: the client, its result, its path."""
    client = controller(lockstep=True, data_dir=data_dir)
    start = client.status().position
    path = moves.step(start, ROTATE, start[ROTATE] + 10.0, duration=3.0, machine=UNIMATE)
    return client, client.wait(client.move(path, kind="step"), timeout=60), path


def assert_kept_and_saved_elsewhere(client: ControlClient, result: MoveResult,
                                    path: np.ndarray, elsewhere: Path, reason: str) -> None:
    """The operator was told why, the whole run is in memory, and it saves elsewhere."""
    assert result.complete and result.files is None
    assert reason in result.save_error
    assert result.save_error.startswith("run not saved (cannot save the step run in ")
    assert result.save_error.endswith("it is kept in memory (save it elsewhere from the Runs "
                                      "tab) and in shared memory, where the next start saves it")
    assert path_rows(result.run) == len(path) <= result.run.samples  # the path, then its settle
    np.testing.assert_allclose(result.run.desired[:len(path)], path, atol=1e-9)
    files = save_run(result.run, elsewhere)
    assert load_run(files.json) == as_written(result.run)
    kept = [n for n in shm.leftover_segments()
            if shm.owner_pid(n) == os.getpid() and shm.is_move_segment(n)]
    assert len(kept) == 1, "the unsaved run's segment was not kept"
    client.release_kept(result.run)  # saved elsewhere: the copy for the next start can go
    assert kept[0] not in shm.leftover_segments()


def test_a_full_disk_keeps_the_run_in_memory_and_leaves_nothing_half_written(
        controller, tmp_path: Path, measured) -> None:
    """The data directory is an 8 KiB tmpfs when a 3 s move ends, smaller than its gzipped
    tables (about 12 kB each): the move completes,
    the result says the run was not saved and why (no space left), the run is whole in
    memory and saves elsewhere, and the full directory holds no partial file. Then, with
    room for the first of the run's three files but not the second, a save fails the same
    way and removes the file it had placed."""
    with tiny_tmpfs(tmp_path / "full", "8k") as full:
        client, result, path = run_a_step(controller, full)
        assert_kept_and_saved_elsewhere(client, result, path, tmp_path / "elsewhere",
                                        "No space left on device")
        assert list(full.iterdir()) == []

        sizes = sorted(p.stat().st_size for p in (tmp_path / "elsewhere").iterdir())
        measured("run_bytes", sum(sizes), "B")
        remount(full, (sizes[-1] + sizes[-2] // 2 + 4095) // 4096 * 4096)
        with pytest.raises(RecorderError, match="No space left on device"):
            save_run(result.run, full)
        assert list(full.iterdir()) == []


def test_an_unusable_data_directory_keeps_the_run_in_memory(controller, tmp_path: Path) -> None:
    """The data directory's parent is a file (root can write anywhere, so a read-only
    directory would not stop it): the move completes, the operator is told the directory
    is not a directory, and the run is whole in memory and saves elsewhere."""
    blocker = tmp_path / "not-a-directory"
    blocker.write_text("a file where the data directory's parent should be\n")
    client, result, path = run_a_step(controller, blocker / "runs")
    assert_kept_and_saved_elsewhere(client, result, path, tmp_path / "elsewhere",
                                    "Not a directory")
    assert blocker.is_file() and os.path.getsize(blocker) > 0
