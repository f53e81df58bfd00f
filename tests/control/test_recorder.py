"""Saved runs: round trip at the written precision, the thesis's TSV columns, never
overwritten, clear failures."""

from __future__ import annotations

import errno
import gzip
import json
import os
import re
import subprocess
import sys
import tempfile
import threading
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from control import recorder
from control.motion import moves
from control.motion.path_files import read_path
from control.recorder import (
    RecorderError,
    Run,
    RunFiles,
    as_written,
    csv_text,
    default_data_dir,
    list_runs,
    load_run,
    save_run,
    table_text,
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


def test_round_trip_is_exact_at_the_written_precision(tmp_path: Path) -> None:
    run = make_run()
    files = save_run(run, tmp_path)
    assert files.stem == "20240301-093015-unimate2000b-step"
    assert visible(tmp_path) == [f"{files.stem}.{ext}" for ext in ("csv.gz", "json", "tsv.gz")]
    back = load_run(files.json)
    assert back == as_written(run)
    assert load_run(files.csv) == back and load_run(tmp_path / files.stem) == back
    assert back.meta == {"target": 10.5, "joint": 2}
    assert back.coefficients["kp"][2] == [UNIMATE.track.kp[2][0]]  # track set, Up/Down
    assert back.joint_resolution == tuple(abs(j.encoder.gradient) for j in UNIMATE.joints)
    half_unit = 0.5 * 10.0 ** -np.array(back.decimals())  # (J,) a tenth of a count, halved
    assert back.decimals() == (2, 3, 3, 3, 3, 3)
    assert np.all(np.abs(back.actual - run.actual) <= half_unit + 1e-9)
    assert back.desired_decimals() == (6, 7, 7, 7, 7, 7)  # rounding: ≤ 0.2 % of max_accel
    assert np.all(np.abs(back.desired - run.desired)
                  <= 0.5 * 10.0 ** -np.array(back.desired_decimals()) + 1e-9)
    assert np.abs(back.duty - run.duty).max() <= 0.005 + 1e-9
    assert np.abs(back.t - run.t).max() <= 0.5e-6


def test_numbers_are_written_at_the_precision_that_matters(tmp_path: Path) -> None:
    n = 3
    t = np.array([0.0, 0.0010004, 1.25])
    desired = np.tile([1508.4405000000002, 0.0056, 6.4968, -0.00488, 2.49876, 100.0], (n, 1))
    duty = np.tile([0.0, -17.206093, 26.1, -0.001, 100.0, 0.0], (n, 1))
    run = Run.from_machine(UNIMATE, "step", "complete", UNIMATE.track, t, desired, desired,
                           duty, start_time="2024-03-01T09:30:15+00:00")
    files = save_run(run, tmp_path)
    row = table_text(files.csv).splitlines()[2].split(",")
    assert row[0] == "0.001"  # to the µs, trailing zeros dropped
    # desired to 10⁻⁶ mm (its max_accel's share at 1 ms), actual to a tenth of a count:
    # In/Out's 0.26 mm to 0.01 mm
    assert row[1:4] == ["1508.4405", "1508.44", "0"]
    assert row[4:7] == ["0.0056", "0.006", "-17.21"]  # Rotate's 0.03° to 0.001°; duty 0.01 %
    assert row[10:13] == ["-0.00488", "-0.005", "0"]  # −0.001 % is written as 0, not −0
    assert row[16:19] == ["100", "100", "0"]
    assert table_text(files.tsv).splitlines()[2].split("\t") == ["2", *row[1:]]
    doc = json.loads(files.json.read_text())
    assert doc["version"] == 4
    assert doc["decimals"] == {"t": 6, "desired": [6, 7, 7, 7, 7, 7],
                               "actual": [2, 3, 3, 3, 3, 3], "duty": 2}
    assert doc["joints"][0] == {"name": "In/Out", "unit": "mm", "resolution": 0.2617,
                                "max_accel": 2000.0}


def test_a_run_that_does_not_know_its_encoders_keeps_every_digit_of_its_positions(
        tmp_path: Path) -> None:
    made = make_run()
    run = Run(made.machine, made.kind, made.status, made.start_time, made.sample_time_s,
              made.coefficients, made.joint_names, made.joint_units, made.t, made.desired,
              made.actual, made.duty, made.meta)
    back = load_run(save_run(run, tmp_path).json)
    assert run.decimals() == run.desired_decimals() == (None,) * 6
    assert back == as_written(run)
    assert back.actual.tolist() == run.actual.tolist()
    assert back.desired.tolist() == run.desired.tolist()


def test_a_version_1_run_still_loads(tmp_path: Path) -> None:
    files = save_run(make_run(), tmp_path)
    doc = json.loads(files.json.read_text())
    doc["version"] = 1
    del doc["decimals"]
    for joint in doc["joints"]:
        del joint["resolution"]
    files.json.write_text(json.dumps(doc))
    back = load_run(files.json)
    assert back.joint_resolution == () and back.samples == 50


def test_a_version_2_run_with_plain_tables_still_loads(tmp_path: Path) -> None:
    """Runs saved before the tables were gzipped: the JSON names plain .tsv and .csv."""
    files = save_run(make_run(), tmp_path)
    doc = json.loads(files.json.read_text())
    doc["version"] = 2
    doc["files"].update(tsv=f"{files.stem}.tsv", csv=f"{files.stem}.csv")
    files.json.write_text(json.dumps(doc))
    for packed in (files.tsv, files.csv):
        packed.with_suffix("").write_text(table_text(packed))
        packed.unlink()
    back = load_run(files.json)
    assert back == as_written(make_run())
    (listed,) = list_runs(tmp_path)
    assert listed.files.csv.name == f"{files.stem}.csv" and listed.files.csv.exists()


def test_the_tables_are_a_tenth_of_what_they_were(tmp_path: Path) -> None:
    """A six-joint 3.4 s sine on Rotate, as the simulator records one (actual positions in
    whole encoder counts, lagging): its gzipped TSV and CSV take at most a tenth of the same
    tables written as version 1 did, every number in 17 digits (issue 13: 0.8 MB each for
    3.4 s), and the precision that matters is kept (the round trip above)."""
    n, dt = 3_400, UNIMATE.sample_time_s
    start = np.array([1508.4405, 0.0055, 1.4968, -0.00488, 2.49876, -0.00895])
    end = start + np.array([0.0, 20.0, 0.0, 0.0, 0.0, 0.0])
    desired = moves.sine(start, end, period=n * dt, duration=n * dt, machine=UNIMATE)[:n]
    counts = np.array(recorder.resolution(UNIMATE))
    actual = np.round(np.roll(desired, 40, axis=0) / counts) * counts  # lagging, in counts
    duty = np.clip(np.gradient(desired, dt, axis=0) * 3.0 + 1e-3 * (desired - actual), -100, 100)
    run = Run.from_machine(UNIMATE, "sine", "complete", UNIMATE.track, np.arange(n) * dt,
                           desired, actual, duty, start_time="2024-03-01T09:30:15+00:00")
    files = save_run(run, tmp_path)
    packed = files.tsv.stat().st_size + files.csv.stat().st_size
    columns = np.column_stack([run.t, run.desired, run.actual, run.duty])
    in_full = 2 * sum(len(repr(v)) + 1 for v in columns.ravel().tolist())
    plain = len(table_text(files.tsv)) + len(csv_text(run))
    print(f"tables: {packed / 1e3:.0f} kB gzipped, {plain / 1e3:.0f} kB plain, "
          f"{in_full / 1e3:.0f} kB in 17 digits")
    assert packed <= in_full / 10, (packed, in_full)


def test_rig_counts_survive(tmp_path: Path) -> None:
    run = make_run(RIG)
    counts = np.round(run.actual / 0.1) + np.arange(run.samples)[:, None]  # 0.1 mm counts
    run = Run.from_machine(RIG, "ramp", "complete", RIG.track, run.t, run.desired,
                           0.1 * counts, run.duty, start_time=run.start_time)
    back = load_run(save_run(run, tmp_path).json)
    assert np.round(back.actual / 0.1).tolist() == counts.tolist()
    assert np.abs(back.actual - run.actual).max() < 1e-9  # 0.1 mm written to 0.01 mm


def test_tsv_has_the_columns_of_option_c_savedata(tmp_path: Path) -> None:
    run = make_run()
    rows = table_text(save_run(run, tmp_path).tsv).splitlines()
    written = as_written(run)
    assert len(rows) == run.samples
    for k in (0, 17, run.samples - 1):
        cells = rows[k].split("\t")
        assert len(cells) == 1 + 3 * UNIMATE.n_joints  # sample, then (desired, actual, PWM) × 6
        assert cells[0] == str(k)
        values = np.array(cells[1:], dtype=float).reshape(UNIMATE.n_joints, 3)
        assert values[:, 0].tolist() == written.desired[k].tolist()
        assert values[:, 1].tolist() == written.actual[k].tolist()
        assert values[:, 2].tolist() == written.duty[k].tolist()


def test_csv_header_names_joints_and_units(tmp_path: Path) -> None:
    files = save_run(make_run(), tmp_path)
    header = table_text(files.csv).splitlines()[0].split(",")
    assert header[:4] == ["t [s]", "In/Out desired [mm]", "In/Out actual [mm]", "In/Out duty [%]"]
    assert header[-1] == "Swivel duty [%]" and len(header) == 19


def test_json_carries_the_metadata(tmp_path: Path) -> None:
    files = save_run(make_run(status="estop"), tmp_path)
    doc = json.loads(files.json.read_text())
    assert doc["machine"] == "unimate2000b" and doc["kind"] == "step"
    assert doc["status"] == "estop"
    assert doc["sample_time_s"] == 0.001 and doc["samples"] == 50
    assert doc["start_time"] == "2024-03-01T09:30:15.250000+00:00"
    assert doc["joints"][2] == {"name": "Up/Down", "unit": "deg", "resolution": 0.01432,
                                "max_accel": 150.0}
    assert doc["coefficients"]["name"] == "track"
    assert doc["files"] == {"tsv": f"{files.stem}.tsv.gz", "csv": f"{files.stem}.csv.gz",
                            "json": f"{files.stem}.json"}


def test_same_second_saves_never_overwrite(tmp_path: Path) -> None:
    first = save_run(make_run(), tmp_path)
    second = save_run(make_run(), tmp_path)
    assert second.stem == f"{first.stem}-2"
    assert json.loads(second.json.read_text())["files"]["csv"] == f"{first.stem}-2.csv.gz"
    (tmp_path / f"{first.stem}-3.csv.gz").write_text("someone else's file")
    third = save_run(make_run(), tmp_path)  # -3 is partly taken: skipped, the stray file kept
    assert third.stem == f"{first.stem}-4"
    assert (tmp_path / f"{first.stem}-3.csv.gz").read_text() == "someone else's file"
    assert not (tmp_path / f"{first.stem}-3.tsv.gz").exists()


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
    assert load_run(first.json) == as_written(make_run()) == load_run(second.json)
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
    cut = table_text(files.csv).rsplit("\n", 2)[0] + "\n"  # last row lost
    files.csv.write_bytes(gzip.compress(cut.encode()))
    with pytest.raises(RecorderError, match=r"damaged run .*49×19 numbers, the metadata says 50"):
        load_run(files.json)
    files.csv.write_bytes(files.csv.read_bytes()[:-20])  # the gzip stream cut short
    with pytest.raises(RecorderError, match=r"\.csv\.gz: cannot read"):
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


def test_a_saved_runs_csv_plays_again_as_a_path_even_at_max_accel(tmp_path: Path) -> None:
    """The desired path is saved to the decimals its max_accel needs: the path rules judge
    accelerations at the sample time, and a ramp that keeps max_accel exactly still plays."""
    here = np.array([1508.4405000000002, 0.0055000000000120, 6.4968, -0.00488, 2.49876, 0.1])
    end = here + np.array([300.0, 40.0, 15.0, 30.0, 20.0, 10.0])
    path = moves.ramp(here, end, moves.min_ramp_time(here, end, UNIMATE), machine=UNIMATE)
    t = np.arange(len(path)) * UNIMATE.sample_time_s
    noisy = path + np.random.default_rng(3).normal(0.0, 0.05, path.shape)
    run = Run.from_machine(UNIMATE, "ramp", "complete", UNIMATE.track, t, path, noisy,
                           np.zeros_like(path))
    points = read_path(save_run(run, tmp_path).csv, UNIMATE, tuple(here))
    assert points.q.tolist() == as_written(run).desired.tolist()


# -- the tables' text, written a block at a time (control/decimal_text.py) ----------------------
# The writer before it (commit 5c3a3f2), a %-format and regular expressions per row: the
# reference the new one must match byte for byte.
_OLD_TRAILING = re.compile(r"(\.\d*?)0+(?=[,\t\n])")
_OLD_BARE_POINT = re.compile(r"\.(?=[,\t\n])")
_OLD_NEGATIVE_ZERO = re.compile(r"(?<=[,\t])-0(?=[,\t\n])")


def old_table(rows: np.ndarray, sep: str, formats: list[str]) -> str:
    if not len(rows):
        return ""
    line = sep.join("%r" if f == "r" else f"%{f}" for f in formats) + "\n"
    text = "".join(line % tuple(row) for row in rows.tolist())
    text = _OLD_BARE_POINT.sub("", _OLD_TRAILING.sub(r"\1", text))
    return _OLD_NEGATIVE_ZERO.sub("0", text)


def old_formats(run: Run) -> list[str]:
    out = []
    full = None in run.desired_decimals()
    for d, a in zip(run.desired_decimals(), run.decimals(), strict=True):
        out += ["r" if full else f".{d}f", "r" if a is None else f".{a}f", ".2f"]
    return out


def old_texts(run: Run) -> tuple[str, str]:
    """The TSV and the CSV's rows as the old writer made them."""
    by_joint = np.stack([run.desired, run.actual, run.duty], axis=2)
    joints = by_joint.reshape(run.samples, 3 * len(run.joint_names))
    count = np.arange(run.samples, dtype=np.float64)[:, None]
    return (old_table(np.concatenate([count, joints], axis=1), "\t", ["d", *old_formats(run)]),
            old_table(np.concatenate([run.t[:, None], joints], axis=1), ",",
                      [".6f", *old_formats(run)]))


def new_texts(run: Run) -> tuple[str, str]:
    pieces = list(recorder._tables(run))
    return (b"".join(tsv for tsv, _ in pieces).decode(),
            b"".join(table for _, table in pieces).decode())


ANY_FLOAT = st.floats(width=64)  # NaN, ±inf, subnormals, 1e308 and -0.0 among them
NEAR_A_TIE = st.builds(lambda k, p: k * 10.0 ** -p, st.integers(-10**7, 10**7),
                       st.integers(0, 9)).map(lambda x: x + 5e-4)  # x.xxx5: %.3f's ties
IN_COUNTS = st.builds(lambda k, c: k * c, st.integers(-100_000, 100_000),
                      st.sampled_from([0.2617, 0.0295, 0.01432, 0.1, 0.0348]))
EXACT_TIE = st.builds(lambda k, j: k / 2.0**j, st.integers(-10**6, 10**6),
                      st.integers(1, 8))  # 0.125 at 2 decimals, 0.0625 at 3: half to even
PATH_LIKE = st.floats(-2000.0, 2000.0) | st.floats(-1e-3, 1e-3)
NUMBERS = st.one_of(ANY_FLOAT, NEAR_A_TIE, EXACT_TIE, IN_COUNTS, PATH_LIKE)


@st.composite
def random_runs(draw: st.DrawFn) -> Run:
    machine = draw(st.sampled_from([UNIMATE, RIG]))
    n, j = draw(st.integers(0, 20)), machine.n_joints
    t = draw(arrays(np.float64, n, elements=st.one_of(NUMBERS, st.floats(0.0, 700.0))))
    desired, actual, duty = (draw(arrays(np.float64, (n, j), elements=NUMBERS))
                             for _ in range(3))
    run = Run.from_machine(machine, "path", "complete", machine.track, t, desired, actual, duty,
                           start_time="2024-03-01T09:30:15+00:00")
    if draw(st.booleans()):  # a run that does not know its encoders: actual in full
        run = replace(run, joint_resolution=())
    if draw(st.booleans()):  # nor its max_accel: desired in full
        run = replace(run, joint_max_accel=())
    return run


def in_blocks_of(rows: int, texts: Callable[[Run], tuple[str, str]], run: Run
                 ) -> tuple[str, str]:
    """``texts(run)`` written ``rows`` rows a block (``recorder.ROWS_AT_ONCE``)."""
    usual = recorder.ROWS_AT_ONCE
    recorder.ROWS_AT_ONCE = rows
    try:
        return texts(run)
    finally:
        recorder.ROWS_AT_ONCE = usual


@settings(max_examples=100, deadline=None)
@given(random_runs(), st.integers(4, 25))
def test_the_tables_are_the_old_writers_byte_for_byte(run: Run, rows: int) -> None:
    assert in_blocks_of(rows, new_texts, run) == old_texts(run)


def test_a_recorded_run_across_blocks_is_the_old_writers_byte_for_byte() -> None:
    """A run as a controller records one (positions wandering, actual in encoder counts,
    duty clipped), longer than a block: the numbers the fast path writes, not Python."""
    n = 10_000
    rng = np.random.default_rng(11)
    t = np.arange(n) * UNIMATE.sample_time_s
    desired = np.cumsum(rng.normal(0.0, 0.01, (n, 6)), axis=0) + rng.uniform(-100, 100, 6)
    counts = np.array(recorder.resolution(UNIMATE))
    actual = np.round(desired / counts) * counts
    duty = np.clip(rng.normal(0.0, 40.0, (n, 6)), -100.0, 100.0)
    run = Run.from_machine(UNIMATE, "path", "complete", UNIMATE.track, t, desired, actual,
                           duty, start_time="2024-03-01T09:30:15+00:00")
    assert in_blocks_of(4_096, new_texts, run) == old_texts(run)


@settings(max_examples=10, deadline=None)
@given(reach=st.lists(st.floats(-1.0, 1.0), min_size=6, max_size=6),
       seconds=st.floats(0.3, 2.0), seed=st.integers(0, 2**32 - 1))
def test_what_is_written_loads_back_and_plays_as_a_path(reach: list[float], seconds: float,
                                                        seed: int) -> None:
    """A ramp between random points inside the joints' limits, followed with noise: saved, it
    loads back as written and its CSV plays as a path file with every desired digit."""
    limits = np.array([[j.lower, j.upper] for j in UNIMATE.joints])
    middle, half = limits.mean(axis=1), np.diff(limits, axis=1)[:, 0] / 4
    here = middle + 0.5 * half * np.array(reach[::-1])
    end = middle + half * np.array(reach)
    path = moves.ramp(here, end, max(seconds, moves.min_ramp_time(here, end, UNIMATE)),
                      machine=UNIMATE)
    counts = np.array(recorder.resolution(UNIMATE))
    duty = np.clip(np.random.default_rng(seed).normal(0.0, 30.0, path.shape), -100.0, 100.0)
    run = Run.from_machine(UNIMATE, "ramp", "complete", UNIMATE.track,
                           np.arange(len(path)) * UNIMATE.sample_time_s, path,
                           np.round(path / counts) * counts, duty)
    with tempfile.TemporaryDirectory() as directory:
        files = save_run(run, Path(directory))
        back = load_run(files.json)
        assert back == as_written(run)
        assert read_path(files.csv, UNIMATE, tuple(here)).q.tolist() == back.desired.tolist()


def decimals_of(text: str) -> int:
    """How many decimals a number's text carries (an exponent counts as too many)."""
    assert "e" not in text.lower(), text
    return len(text.partition(".")[2])


def test_every_exported_number_carries_no_more_digits_than_its_precision(
        tmp_path: Path) -> None:
    """Positions off by float arithmetic's noise (1508.4405000000002), metrics with 17 digits:
    the CSV and TSV write each column at most to its decimals (JSON ``decimals``), and the
    JSON's numbers have at most 10 significant digits."""
    n = 200
    rng = np.random.default_rng(2)
    t = np.arange(n) * UNIMATE.sample_time_s + rng.uniform(-2e-4, 2e-4, n) / 3
    base = np.array([1508.4405, 0.0055, 6.4968, -0.00488, 2.49876, 0.1])
    desired = base + np.linspace(0, 1, n)[:, None] / 3 + 2e-13
    actual = desired + rng.normal(0.0, 0.05, (n, 6))
    duty = rng.uniform(-100.0, 100.0, (n, 6)) / 3
    run = Run.from_machine(UNIMATE, "ramp", "complete", UNIMATE.track, t, desired, actual,
                           duty, meta={"initial": 0.005500000000012051,
                                       "results": [{"overshoot_pct": 1.283333333333303}]})
    files = save_run(run, tmp_path)
    doc = json.loads(files.json.read_text())
    places = doc["decimals"]
    assert places["desired"] is not None, "the desired positions are written in full"
    per_joint = [[d, a, places["duty"]] for d, a in zip(places["desired"], places["actual"],
                                                         strict=True)]
    columns = [places["t"], *[p for joint in per_joint for p in joint]]
    for table, sep in ((files.csv, ","), (files.tsv, "\t")):
        rows = [line.split(sep) for line in table_text(table).splitlines()[sep == ",":]]
        most = np.array([[decimals_of(v) for v in row] for row in rows]).max(axis=0)
        assert np.all(most[1:] <= columns[1:]), (table.name, most, columns)
        assert most[0] <= (columns[0] if sep == "," else 0)
        assert most[1:].max() > 2  # not all rounded away
    numbers = re.findall(r"-?\d+\.\d+(?:[eE][-+]?\d+)?", files.json.read_text())
    assert numbers and all(len(re.sub(r"[-.]|^-?0\.0*|[eE].*", "", x)) <= 10
                           for x in numbers), [x for x in numbers if len(x) > 12]
    assert doc["meta"]["initial"] == 0.0055
