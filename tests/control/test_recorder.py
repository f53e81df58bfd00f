"""Saved runs: round trip, the thesis's TSV columns, never overwritten, clear failures."""

from __future__ import annotations

import errno
import json
import os
import subprocess
import sys
import threading
from pathlib import Path

import numpy as np
import pytest

from control import recorder
from control.recorder import (
    RecorderError,
    Run,
    RunFiles,
    default_data_dir,
    list_runs,
    load_run,
    save_run,
)
from hw.machine import load_machine

ROOT = Path(__file__).resolve().parents[2]

UNIMATE = load_machine("unimate2000b")
RIG = load_machine("rig")


def make_run(machine=UNIMATE, n: int = 50, start: str = "2024-03-01T09:30:15.250000+00:00",
             kind: str = "step", status: str = "complete") -> Run:
    rng = np.random.default_rng(7)
    j = machine.n_joints
    t = np.arange(n) * machine.sample_time_s
    desired = np.tile(np.linspace(0.0, 10.0, j), (n, 1)) + 1000.1
    actual = desired + rng.normal(0.0, 0.05, (n, j))
    duty = rng.uniform(-100.0, 100.0, (n, j)).round(0)
    return Run.from_machine(machine, kind, status, machine.track, t, desired, actual, duty,
                            start_time=start, meta={"target": np.float64(10.5), "joint": 2})


def visible(directory: Path) -> list[str]:
    return sorted(p.name for p in directory.iterdir())


def test_round_trip_is_exact(tmp_path: Path) -> None:
    run = make_run()
    files = save_run(run, tmp_path)
    assert files.stem == "20240301-093015-unimate2000b-step"
    assert visible(tmp_path) == [f"{files.stem}.{ext}" for ext in ("csv", "json", "tsv")]
    back = load_run(files.json)
    assert back == run
    assert load_run(files.csv) == run and load_run(tmp_path / files.stem) == run
    assert back.meta == {"target": 10.5, "joint": 2}
    assert back.coefficients["kp"][2] == [31.0]  # Unimate track set, Up/Down


def test_rig_precision_survives(tmp_path: Path) -> None:
    run = make_run(RIG)
    fine = run.actual + 0.1 * np.arange(run.samples)[:, None]  # 0.1 mm encoder steps
    run = Run.from_machine(RIG, "ramp", "complete", RIG.track, run.t, run.desired, fine,
                           run.duty, start_time=run.start_time)
    assert load_run(save_run(run, tmp_path).json).actual.tolist() == fine.tolist()


def test_tsv_has_the_columns_of_option_c_savedata(tmp_path: Path) -> None:
    run = make_run()
    rows = save_run(run, tmp_path).tsv.read_text().splitlines()
    assert len(rows) == run.samples
    for k in (0, 17, run.samples - 1):
        cells = rows[k].split("\t")
        assert len(cells) == 1 + 3 * UNIMATE.n_joints  # sample, then (desired, actual, PWM) × 6
        assert cells[0] == str(k)
        values = np.array(cells[1:], dtype=float).reshape(UNIMATE.n_joints, 3)
        assert values[:, 0].tolist() == run.desired[k].tolist()
        assert values[:, 1].tolist() == run.actual[k].tolist()
        assert values[:, 2].tolist() == run.duty[k].tolist()


def test_csv_header_names_joints_and_units(tmp_path: Path) -> None:
    files = save_run(make_run(), tmp_path)
    header = files.csv.read_text().splitlines()[0].split(",")
    assert header[:4] == ["t [s]", "In/Out desired [mm]", "In/Out actual [mm]", "In/Out duty [%]"]
    assert header[-1] == "Swivel duty [%]" and len(header) == 19


def test_json_carries_the_metadata(tmp_path: Path) -> None:
    files = save_run(make_run(status="estop"), tmp_path)
    doc = json.loads(files.json.read_text())
    assert doc["machine"] == "unimate2000b" and doc["kind"] == "step"
    assert doc["status"] == "estop"
    assert doc["sample_time_s"] == 0.001 and doc["samples"] == 50
    assert doc["start_time"] == "2024-03-01T09:30:15.250000+00:00"
    assert doc["joints"][2] == {"name": "Up/Down", "unit": "deg"}
    assert doc["coefficients"]["name"] == "track"
    assert doc["files"] == {"tsv": f"{files.stem}.tsv", "csv": f"{files.stem}.csv",
                            "json": f"{files.stem}.json"}


def test_same_second_saves_never_overwrite(tmp_path: Path) -> None:
    first = save_run(make_run(), tmp_path)
    second = save_run(make_run(), tmp_path)
    assert second.stem == f"{first.stem}-2"
    assert json.loads(second.json.read_text())["files"]["csv"] == f"{first.stem}-2.csv"
    (tmp_path / f"{first.stem}-3.csv").write_text("someone else's file")
    third = save_run(make_run(), tmp_path)  # -3 is partly taken: skipped, the stray file kept
    assert third.stem == f"{first.stem}-4"
    assert (tmp_path / f"{first.stem}-3.csv").read_text() == "someone else's file"
    assert not (tmp_path / f"{first.stem}-3.tsv").exists()


def test_concurrent_saves_do_not_collide(tmp_path: Path) -> None:
    runs = [make_run(n=20 + i) for i in range(12)]
    saved: list[RunFiles] = []
    barrier = threading.Barrier(len(runs))

    def save(run: Run) -> None:
        barrier.wait()
        saved.append(save_run(run, tmp_path))

    threads = [threading.Thread(target=save, args=(r,)) for r in runs]
    for th in threads:
        th.start()
    for th in threads:
        th.join()
    assert len({f.stem for f in saved}) == len(runs)
    assert sorted(load_run(f.json).samples for f in saved) == [r.samples for r in runs]
    assert len(visible(tmp_path)) == 3 * len(runs)  # no temporary files left


def test_an_unusable_directory_raises_a_clear_error(tmp_path: Path) -> None:
    blocker = tmp_path / "file"
    blocker.write_text("")
    with pytest.raises(RecorderError, match=r"cannot save the step run in .*file/runs: "
                                            r"Not a directory"):
        save_run(make_run(), blocker / "runs")


READ_ONLY_SAVE = (
    "import sys; from pathlib import Path; from control.recorder import RecorderError, "
    "load_run, save_run\n"
    "try:\n    save_run(load_run(Path(sys.argv[1])), Path(sys.argv[2]))\n"
    "except RecorderError as exc:\n    print(exc)\n")


def test_a_read_only_directory_raises_and_leaves_nothing(tmp_path: Path) -> None:
    """Unwritable for whoever runs the test: a user's directory without write permission;
    for root, who writes anywhere, a read-only bind mount of it in a mount namespace of its
    own (util-linux's unshare)."""
    saved = save_run(make_run(), tmp_path / "elsewhere")
    target = tmp_path / "read-only"
    target.mkdir()
    script = [sys.executable, "-c", READ_ONLY_SAVE, str(saved.json), str(target)]
    if os.geteuid() == 0:
        mount = f"mount --bind {target} {target} && mount -o remount,ro,bind {target} && "
        script = ["unshare", "--mount", "--propagation", "private", "sh", "-c",
                  mount + " ".join(f"'{arg}'" for arg in script)]
        reason = "Read-only file system"
    else:
        target.chmod(0o500)
        reason = "Permission denied"
    try:
        done = subprocess.run(script, capture_output=True, text=True, timeout=60,
                              env={**os.environ, "PYTHONPATH": str(ROOT)})
    finally:
        target.chmod(0o700)
    if os.geteuid() == 0 and done.returncode and "mount" in done.stderr:
        pytest.skip(f"root here may not mount (no CAP_SYS_ADMIN): {done.stderr.strip()}")
    assert done.returncode == 0, done.stderr
    assert f"cannot save the step run in {target}: {reason}" in done.stdout
    assert visible(target) == []


def test_disk_full_midway_leaves_nothing_behind(tmp_path: Path,
                                                monkeypatch: pytest.MonkeyPatch) -> None:
    real_fsync = os.fsync
    calls = []

    def fsync(fd: int) -> None:
        calls.append(fd)
        if len(calls) == 3:  # tsv and csv are in place; the JSON hits a full disk
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        real_fsync(fd)

    monkeypatch.setattr(recorder.os, "fsync", fsync)
    run = make_run()
    with pytest.raises(RecorderError, match=f"in {tmp_path}: No space left on device"):
        save_run(run, tmp_path)
    assert visible(tmp_path) == []  # neither the placed files nor any temporary file
    assert isinstance(RecorderError("x"), OSError)


def test_without_hard_links_it_still_never_overwrites(tmp_path: Path,
                                                      monkeypatch: pytest.MonkeyPatch) -> None:
    def no_link(src: Path, dst: Path) -> None:
        raise OSError(errno.EPERM, "Operation not permitted")  # as on FAT

    monkeypatch.setattr(recorder.os, "link", no_link)
    first, second = save_run(make_run(), tmp_path), save_run(make_run(), tmp_path)
    assert second.stem == f"{first.stem}-2"
    assert load_run(first.json) == make_run() == load_run(second.json)
    assert len(visible(tmp_path)) == 6


def test_list_runs_newest_first_and_damaged_ones_listed(tmp_path: Path) -> None:
    older = save_run(make_run(start="2024-03-01T09:30:15+00:00"), tmp_path)
    newer = save_run(make_run(start="2024-03-02T08:00:00+00:00", kind="ramp"), tmp_path)
    same_second = save_run(make_run(start="2024-03-01T09:30:15+00:00"), tmp_path)
    broken = tmp_path / "20240301-120000-unimate2000b-sine.json"
    broken.write_text('{"format": "servodesk-run", "machine": ')
    (tmp_path / ".abc.tmp").write_text("a temporary file of a save in progress")
    runs = list_runs(tmp_path)
    assert [r.files.stem for r in runs] == [newer.stem, broken.stem, same_second.stem, older.stem]
    damaged = runs[1]
    assert damaged.damaged and "damaged run metadata" in damaged.problem
    assert not runs[0].damaged and runs[0].kind == "ramp" and runs[0].samples == 50
    assert list_runs(tmp_path / "missing") == []


def test_list_order_of_many_same_second_saves_follows_the_suffix(tmp_path: Path) -> None:
    stems = [save_run(make_run(n=5), tmp_path).stem for _ in range(11)]
    assert stems[-1].endswith("-11")
    assert [r.files.stem for r in list_runs(tmp_path)] == stems[::-1]  # -11 before -10 before -9


def test_loading_a_damaged_run_says_what_is_wrong(tmp_path: Path) -> None:
    files = save_run(make_run(), tmp_path)
    files.csv.write_text(files.csv.read_text().rsplit("\n", 2)[0] + "\n")  # last row lost
    with pytest.raises(RecorderError, match=r"damaged run .*49×19 numbers, the metadata says 50"):
        load_run(files.json)
    with pytest.raises(RecorderError, match="cannot read"):
        load_run(tmp_path / "nothing.json")


def test_run_checks_its_shapes_and_compares_by_value() -> None:
    run = make_run()
    with pytest.raises(ValueError, match=r"actual must be \(N, J\) = \(50, 6\), got \(50, 5\)"):
        Run.from_machine(UNIMATE, "step", "complete", UNIMATE.track, run.t, run.desired,
                         run.actual[:, :5], run.duty)
    assert make_run() == make_run()
    assert make_run(status="estop") != make_run()


def test_empty_run_round_trips(tmp_path: Path) -> None:
    empty = np.empty((0, 1))
    run = Run.from_machine(RIG, "step", "interrupted: operator", RIG.track, np.empty(0), empty,
                           empty, empty, start_time="2024-03-01T09:30:15+00:00")
    assert load_run(save_run(run, tmp_path).json) == run


def test_default_data_dir_is_under_the_user_data_dir() -> None:
    path = default_data_dir()
    assert path.name == "runs" and "servodesk" in path.parts
