"""Runs left in the move segments of processes that died are saved at the next start:
complete and listed, marked recovered, once only, with a killed save's leftovers cleared;
a run that cannot be saved yet stays whole for the start after. The run keeper that does
it keeps the same rules for a live client's runs, in the order they were handed over."""

from __future__ import annotations

import contextlib
import fcntl
import os
from multiprocessing import shared_memory
from pathlib import Path

import numpy as np
import pytest

from control.recorder import list_runs, load_run, save_run, stem_base
from control.recovery import recover_runs
from control.rt import shm
from control.rt.layout import MoveLayout
from control.run_keeper import FinishedMove, RunKeeper, keep
from control.runs import encode_meta, run_from_segment, segment_meta
from hw.machine import load_machine

UNIMATE = load_machine("unimate2000b")
ROWS = 500


def dead_pid() -> int:
    """A pid no process can have: the kernel's pid_max itself."""
    return int(Path("/proc/sys/kernel/pid_max").read_text())


def orphaned(name: str) -> str:
    """Segment ``name`` (this process's) given a dead owner's name, as its client's death
    leaves it: only then may a starting client recover it. One named for a dead owner from
    the start was any starting client's: another test's, starting while this one set its
    segment up, took it first (its run saved twice, or in that client's directory)."""
    dead = shm.segment_name(name.split("_", 2)[-1], pid=dead_pid())
    os.rename(shm.SHM_DIR / name, shm.SHM_DIR / dead)
    return dead


class LeftSegment:
    """A move segment as a killed client leaves it: metadata, a record, maybe a status. Made
    under this process's name, as its client made it while it lived; ``orphan`` gives it a
    dead owner's. With ``pid`` (this process's), a live client's, as a run keeper gets it."""

    def __init__(self, data_dir: Path, status: str = "complete", recorded: int = ROWS,
                 pid: int | None = None) -> None:
        self.dies = pid is None
        owner = dead_pid() if pid is None else pid
        self.meta = segment_meta(UNIMATE, "step", UNIMATE.sample_time_s, data_dir, owner,
                                 {"backend": "sim", "coefficients": {}})
        encoded = encode_meta(self.meta)
        self.layout = MoveLayout(ROWS, 6, len(encoded))
        self.name = shm.segment_name(f"mv{os.urandom(3).hex()}", pid=os.getpid())
        with shm._untracked():
            self.segment = shared_memory.SharedMemory(self.name, create=True,
                                                      size=self.layout.size)
        buf = self.segment.buf
        self.layout.write_header(buf)
        self.layout.write_meta(buf, encoded)
        record = self.layout.record(buf)
        record[:, 0] = np.arange(ROWS) * 1e-3
        record[:, 1:] = np.linspace(0.0, 1.0, ROWS)[:, None]
        buf[MoveLayout.RECORDED_OFFSET:MoveLayout.RECORDED_OFFSET + 8] = \
            recorded.to_bytes(8, "little")
        if status:
            self.layout.write_status(buf, status)

    def run(self):
        return run_from_segment(self.segment.buf, self.layout, self.meta, "complete")

    def orphan(self) -> None:
        if self.dies and shm.owner_pid(self.name) == os.getpid():
            self.name = orphaned(self.name)

    def gone(self) -> bool:
        return self.name not in shm.leftover_segments()

    def close(self) -> None:
        shm.release(self.segment, unlink=False)
        with contextlib.suppress(FileNotFoundError):
            os.unlink(shm.SHM_DIR / self.name)


class Left:
    """The test's left segments (``left(...)`` makes one); ``recover`` orphans them, then
    recovers as a starting client does."""

    def __init__(self, data_dir: Path) -> None:
        self.data_dir = data_dir
        self.made: list[LeftSegment] = []

    def __call__(self, **options) -> LeftSegment:
        self.made.append(LeftSegment(self.data_dir, **options))
        return self.made[-1]

    def recover(self, fallback: Path, wait_s: float = 10.0) -> list[str]:
        for segment in self.made:
            segment.orphan()
        return recover_runs(fallback, wait_s)


@pytest.fixture
def left(tmp_path: Path):
    made = Left(tmp_path / "runs")
    yield made
    for segment in made.made:
        segment.close()


def test_a_finished_move_its_client_never_saved_is_saved_and_marked(left, tmp_path) -> None:
    segment = left()
    notices = left.recover(tmp_path / "fallback")
    (info,) = list_runs(tmp_path / "runs")
    run = load_run(info.files.json)
    assert run.status == "recovered: complete" and run.samples == ROWS
    assert run.meta["recovered"] is True and run.meta["run_id"] == segment.meta["run_id"]
    assert segment.gone()
    assert any(str(info.files.json) in n for n in notices)
    assert left.recover(tmp_path / "fallback") == [] and len(list_runs(tmp_path / "runs")) == 1


def test_a_move_that_never_ended_says_so(left, tmp_path) -> None:
    left(status="", recorded=200)
    left.recover(tmp_path / "fallback")
    (info,) = list_runs(tmp_path / "runs")
    assert info.status == "recovered: interrupted: the client and the controller died"
    assert info.samples == 200


def test_a_save_killed_before_its_json_is_redone_and_its_leftovers_cleared(left,
                                                                          tmp_path) -> None:
    segment = left()
    runs = tmp_path / "runs"
    runs.mkdir(parents=True)
    base = stem_base(segment.run())
    (runs / f"{base}.tsv.gz").write_text("half")
    (runs / f"{base}.csv.gz").write_text("half")
    (runs / f".{dead_pid()}-0123.tmp").write_text("half")
    (runs / f".{os.getpid()}-4567.tmp").write_text("a live saver's")
    left.recover(tmp_path / "fallback")
    (info,) = list_runs(runs)
    assert load_run(info.files.json).samples == ROWS
    assert not (runs / f".{dead_pid()}-0123.tmp").exists()
    assert (runs / f".{os.getpid()}-4567.tmp").exists(), "a live process's temp file went"
    assert sorted(p.name for p in runs.iterdir()) == [f".{os.getpid()}-4567.tmp", *(
        f"{info.files.stem}{ext}" for ext in (".csv.gz", ".json", ".tsv.gz"))], \
        "the halves are gone, the run saved in their place"


def test_a_save_killed_after_its_json_is_not_saved_twice(left, tmp_path) -> None:
    segment = left()
    save_run(segment.run(), tmp_path / "runs")
    left.recover(tmp_path / "fallback")
    (info,) = list_runs(tmp_path / "runs")
    assert info.status == "complete" and segment.gone()


def test_a_run_its_own_directory_cannot_take_goes_to_the_starting_clients(left,
                                                                        tmp_path) -> None:
    left()
    (tmp_path / "runs").write_text("a file where the runs' directory should be")
    left.recover(tmp_path / "fallback")
    (info,) = list_runs(tmp_path / "fallback")
    assert info.status == "recovered: complete"


def test_a_run_that_can_be_saved_nowhere_now_stays_for_the_next_start(left, tmp_path) -> None:
    segment = left()
    (tmp_path / "runs").write_text("a file where the runs' directory should be")
    (tmp_path / "fallback").write_text("and another where the fallback should be")
    notices = left.recover(tmp_path / "fallback")
    assert any("kept for the next start" in n for n in notices), notices
    assert not segment.gone()
    (tmp_path / "runs").unlink()
    left.recover(tmp_path / "fallback")
    assert segment.gone() and len(list_runs(tmp_path / "runs")) == 1


def test_a_segment_that_is_not_a_move_is_removed_with_a_notice(tmp_path) -> None:
    with shm._untracked():
        junk = shared_memory.SharedMemory(shm.segment_name("mvjunk"), create=True, size=4096)
    name = orphaned(junk.name.lstrip("/"))
    try:
        notices = recover_runs(tmp_path / "fallback")
        assert any(n.startswith(f"removed {name}: not a move segment") for n in notices)
        assert name not in shm.leftover_segments()
    finally:
        shm.release(junk, unlink=False)
        with contextlib.suppress(FileNotFoundError):
            os.unlink(shm.SHM_DIR / name)


def test_a_move_segment_of_another_layout_version_is_left_alone(left, tmp_path) -> None:
    """Upgraded beside a running older servodesk, a start must not take that version's
    unsaved run for junk and remove it (it did: a test run of one version beside another's
    lost its runs)."""
    segment = left()
    header = MoveLayout.HEADER
    magic, version, samples, n = header.unpack_from(segment.segment.buf, 0)
    header.pack_into(segment.segment.buf, 0, magic, version - 1, samples, n)
    (notice,) = left.recover(tmp_path / "fallback")
    assert notice.startswith(f"left {segment.name} alone: a run a servodesk of another version")
    assert f"(layout v{version - 1})" in notice
    assert not segment.gone() and list_runs(tmp_path / "runs") == []


def test_a_segment_another_start_recovers_is_waited_for_then_left_to_it(left, tmp_path) -> None:
    segment = left()
    fd = os.open(shm.SHM_DIR / segment.name, os.O_RDONLY)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)  # as a second client starting at the same time holds it
        segment.orphan()
        (notice,) = recover_runs(tmp_path / "fallback", wait_s=0.02)
        assert "to the process recovering it" in notice
        assert not segment.gone() and list_runs(tmp_path / "runs") == []
    finally:
        os.close(fd)
    (notice,) = left.recover(tmp_path / "fallback")
    assert "recovered" in notice and segment.gone()
    assert len(list_runs(tmp_path / "runs")) == 1


# -- the run keeper: the same rules for a live client's runs, on a thread of its own ------------


def test_a_keeper_saves_its_runs_in_the_order_handed_over_and_unlinks_each(left,
                                                                          tmp_path) -> None:
    segments = [left(pid=os.getpid()) for _ in range(3)]
    for s in segments:  # one start time: the order shows in the stems' -2, -3
        s.meta["start_time"] = "2024-03-01T09:30:15+00:00"
    keeper, kept = RunKeeper(), []
    for s in segments:
        keeper.hand(FinishedMove(s.segment, s.layout, s.meta, "complete"), kept.append)
    assert keeper.wait(60.0) and keeper.in_hand == 0
    stems = [k.files.stem for k in kept]
    assert stems == [stems[0], f"{stems[0]}-2", f"{stems[0]}-3"]
    assert [k.run.meta["run_id"] for k in kept] == [s.meta["run_id"] for s in segments]
    assert all(s.gone() for s in segments) and not any(k.kept for k in kept)


def test_a_run_the_disk_refuses_stays_whole_in_its_segment_and_says_why(left, tmp_path) -> None:
    segment = left()
    (tmp_path / "runs").write_text("a file where the runs' directory should be")
    kept = keep(FinishedMove(segment.segment, segment.layout, segment.meta, "complete"))
    assert kept.kept and kept.files is None and kept.problem.startswith("cannot save the step")
    assert kept.run is not None and kept.run.samples == ROWS and not segment.gone()
    (tmp_path / "runs").unlink()
    assert left.recover(tmp_path / "fallback") and segment.gone()
    assert len(list_runs(tmp_path / "runs")) == 1


def test_a_keeper_measures_a_run_saves_what_it_measured_and_skips_an_empty_one(
        left, tmp_path) -> None:
    done, empty = left(pid=os.getpid()), left(recorded=0, pid=os.getpid())
    keeper, kept = RunKeeper(), []
    measure = lambda run: (("metrics", run.samples), {"results": [run.samples]})  # noqa: E731
    for s in (done, empty):
        keeper.hand(FinishedMove(s.segment, s.layout, s.meta, "complete"), kept.append,
                    measure=measure, save_empty=False)
    assert keeper.wait(60.0)
    assert kept[0].results == ("metrics", ROWS)
    assert load_run(kept[0].files.json).meta["results"] == [ROWS]
    assert kept[1].files is None and not kept[1].kept and empty.gone()
    assert len(list_runs(tmp_path / "runs")) == 1
