"""``servodesk runs list|show|export`` in real subprocesses, over a data directory of runs
saved by the recorder: what they print, what they write, and exit 2 with the reason for a
run that is not there, is damaged, or a view or place that cannot be used."""

from __future__ import annotations

import gzip
import json
import os
import resource
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from control.recorder import RecorderError, Run, load_run, save_run, table_text
from hw.machine import load_machine

ROOT = Path(__file__).resolve().parents[2]
ENV = {**os.environ, "PYTHONPATH": str(ROOT)}


def servodesk(*args: str, data_dir: Path, memory: int | None = None
              ) -> subprocess.CompletedProcess[str]:
    """``servodesk runs ARGS``; ``memory`` caps its address space (bytes): past it, MemoryError."""
    def cap() -> None:
        if memory is not None:
            resource.setrlimit(resource.RLIMIT_AS, (memory, memory))

    return subprocess.run([sys.executable, "-m", "app", "runs", *args, "--data-dir",
                           str(data_dir)], cwd=ROOT, env=ENV, capture_output=True, text=True,
                          timeout=60, preexec_fn=cap)


def rig_step(start_time: str, status: str = "complete") -> Run:
    """A rig step 0 → 50 mm answered by a first-order lag of 0.1 s, 2 s at 1 ms."""
    rig = load_machine("rig")
    t = np.arange(2001) * 1e-3
    desired = np.where(t > 0, 50.0, 0.0)[:, None]
    actual = (50.0 * (1 - np.exp(-t / 0.1)))[:, None]
    return Run.from_machine(rig, "step", status, rig.track, t, desired, actual,
                            np.zeros_like(actual), start_time=start_time,
                            meta={"joint": "Ram", "target": 50.0, "approach_samples": 0,
                                  "moving": [0], "open_loop": False, "backend": "sim"})


@pytest.fixture
def data_dir(tmp_path: Path) -> Path:
    save_run(rig_step("2026-11-20T10:00:00+00:00"), tmp_path)
    save_run(rig_step("2026-11-21T10:00:00+00:00", "estop: operator E-stop"), tmp_path)
    return tmp_path


def test_list_prints_one_line_per_run_newest_first(data_dir: Path) -> None:
    done = servodesk("list", data_dir=data_dir)
    assert done.returncode == 0, done.stderr
    lines = done.stdout.splitlines()
    assert [line.split()[0] for line in lines] == ["20261121-100000-rig-step",
                                                   "20261120-100000-rig-step"]
    assert "estop: operator E-stop  2001 samples" in lines[0]


def test_list_as_json_and_an_empty_or_damaged_directory(data_dir: Path, tmp_path: Path) -> None:
    (data_dir / "20261119-100000-rig-step.json").write_text("{not json")
    runs = json.loads(servodesk("list", "--json", data_dir=data_dir).stdout)
    assert [(r["stem"], r["status"], r["samples"]) for r in runs[:2]] == [
        ("20261121-100000-rig-step", "estop: operator E-stop", 2001),
        ("20261120-100000-rig-step", "complete", 2001)]
    assert runs[2]["stem"] == "20261119-100000-rig-step" and runs[2]["problem"]
    empty = servodesk("list", "--json", data_dir=tmp_path / "none")
    assert (empty.returncode, json.loads(empty.stdout)) == (0, [])


def test_show_gives_the_fields_and_the_result_metrics(data_dir: Path) -> None:
    done = servodesk("show", "20261120-100000-rig-step", data_dir=data_dir)
    assert done.returncode == 0, done.stderr
    lines = done.stdout.splitlines()
    assert lines[:2] == ["20261120-100000-rig-step", "rig · step · complete"]
    assert "target: 50.0" in lines
    header = next(i for i, line in enumerate(lines) if line.startswith("joint "))
    assert lines[header + 1].split()[:2] == ["Ram", "+50.00"]
    shown = json.loads(servodesk("show", "latest", "--json", data_dir=data_dir).stdout)
    [metric] = shown["metrics"]
    assert shown["stem"] == "20261121-100000-rig-step"
    # a first-order lag of τ = 0.1 s rises 10 → 90 % in τ·ln 9 = 0.2197 s
    assert metric["rise_time_s"] == pytest.approx(0.1 * np.log(9), abs=2e-3)
    assert metric["overshoot"] == 0.0


def test_show_takes_a_path_to_any_of_the_runs_files(data_dir: Path) -> None:
    csv = data_dir / "20261120-100000-rig-step.csv.gz"
    done = servodesk("show", str(csv), "--json", data_dir=data_dir / "elsewhere")
    assert done.returncode == 0, done.stderr
    assert json.loads(done.stdout)["status"] == "complete"


@pytest.mark.parametrize("args, message", [
    (["show", "20261231-000000-rig-step"], "RUN 20261231-000000-rig-step: no run"),
    (["show", "20261119-100000-rig-step"], "not a servodesk run"),
    (["export", "latest", "--view", "plotsix-1-3"], "--view plotsix-1-3: this run's plots "
                                                    "are plotdata-Ram"),
    (["export", "latest", "--format", "csv", "--view", "plotdata-Ram"], "--view: a CSV export"),
    (["export", "latest", "--out", "/proc/nope/plot.svg"], "--out: cannot write"),
])
def test_bad_input_exits_2_with_the_reason(args: list[str], message: str,
                                           data_dir: Path) -> None:
    (data_dir / "20261119-100000-rig-step.json").write_text('{"machine": "rig"}')
    done = servodesk(*args, data_dir=data_dir)
    assert (done.returncode, done.stdout) == (2, ""), done.stderr
    assert done.stderr.startswith("servodesk: ") and message in done.stderr, done.stderr
    assert "Traceback" not in done.stderr


def test_latest_in_an_empty_directory_is_exit_2(tmp_path: Path) -> None:
    done = servodesk("show", "latest", data_dir=tmp_path)
    assert done.returncode == 2 and "no runs in" in done.stderr


def test_export_writes_the_runs_tab_plot_as_svg_or_text(data_dir: Path, tmp_path: Path) -> None:
    done = servodesk("export", "20261120-100000-rig-step", data_dir=data_dir)
    assert done.returncode == 0, done.stderr
    svg = data_dir / "plots" / "20261120-100000-rig-step-plotdata-Ram.svg"
    assert done.stdout.splitlines() == [str(svg)]
    assert svg.read_text().startswith("<svg")
    out = tmp_path / "out" / "ram"
    done = servodesk("export", "latest", "--format", "txt", "--view", "plotdata-ram", "--out",
                     str(out), data_dir=data_dir)
    assert done.returncode == 0, done.stderr
    text = out.with_suffix(".txt").read_text()
    assert "error" in text and "\x1b" not in text  # plotdata.m's panels, plain text
    assert text.splitlines()[0] == "20261121-100000-rig-step · estop: operator E-stop · " \
                                   "plotdata Ram"
    assert sum(0x2800 < ord(c) < 0x2900 for c in text) > 100  # the curves, in braille dots


def test_export_csv_is_the_runs_table_unpacked(data_dir: Path, tmp_path: Path) -> None:
    out = tmp_path / "copy.csv"
    done = servodesk("export", "latest", "--format", "csv", "--out", str(out), data_dir=data_dir)
    assert done.returncode == 0, done.stderr
    saved = data_dir / "20261121-100000-rig-step.csv.gz"
    assert out.read_text() == table_text(saved) and out.read_text().startswith("t [s],")


def test_export_as_mcap_writes_the_whole_run(data_dir: Path, tmp_path: Path) -> None:
    from control.run_mcap import read_mcap

    out = tmp_path / "out" / "step.mcap"
    done = servodesk("export", "latest", "--format", "mcap", "--out", str(out),
                     data_dir=data_dir)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == str(out)
    record, topics = read_mcap(out)
    assert record["status"] == "estop: operator E-stop"
    assert [len(topics[t]) for t in ("/joints/desired", "/joints/actual", "/joints/duty")] \
        == [2001] * 3
    assert topics["/joints/actual"][-1][1]["Ram"] == pytest.approx(50 * (1 - np.exp(-20)))
    refused = servodesk("export", "latest", "--format", "mcap", "--view", "position",
                        data_dir=data_dir)
    assert refused.returncode == 2 and "MCAP export is the whole run" in refused.stderr


def gzip_bomb(path: Path, gigabytes: int) -> None:
    """A ``.csv.gz`` of a few MB that unpacks to ``gigabytes`` GB of rows of zeros: 64 MB
    members, packed once and written again and again (a gzip file may hold many)."""
    member = gzip.compress(b"0,0,0,0\n" * ((64 << 20) // 8), compresslevel=9)
    with path.open("wb") as file:
        for _ in range(gigabytes * 16):
            file.write(member)


def test_a_gzip_bomb_in_place_of_a_runs_table_is_exit_2_with_one_line(
        data_dir: Path) -> None:
    """The CSV of a 2,001-sample run replaced by 2 GB of rows packed into ~4 MB: ``runs show``
    (whose address space is capped at 1 GB, as a small machine's memory would be) reads no
    more than the run's metadata says its table holds and exits 2 in one line naming the
    file and that bound; before, it unpacked the whole and died of MemoryError. The Runs
    tab's loader, ``load_run``, raises the same RecorderError."""
    stem = "20261121-100000-rig-step"
    gzip_bomb(data_dir / f"{stem}.csv.gz", 2)
    done = servodesk("show", stem, data_dir=data_dir, memory=1 << 30)
    assert (done.returncode, done.stdout) == (2, ""), done.stderr[-2000:]
    message = "the table of a run of 2,001 samples may hold at most 2,002 lines and "
    assert done.stderr.startswith(f"servodesk: RUN {stem}: {data_dir / stem}.csv.gz: ")
    assert message in done.stderr and done.stderr.count("\n") == 1, done.stderr[-2000:]
    with pytest.raises(RecorderError, match=message):
        load_run(data_dir / f"{stem}.json")
    assert servodesk("show", "20261120-100000-rig-step", data_dir=data_dir).returncode == 0


@pytest.mark.timeout(60)
def test_a_fifo_in_place_of_a_runs_file_is_refused_not_waited_on(data_dir: Path) -> None:
    """A named pipe in place of a run's JSON, and of another's CSV: ``runs list`` lists the
    first as damaged, and ``runs show`` of either exits 2 at once naming the FIFO (each read
    would wait for ever on a writer that never comes)."""
    os.mkfifo(data_dir / "20261119-100000-rig-step.json")
    (data_dir / "20261121-100000-rig-step.csv.gz").unlink()
    os.mkfifo(data_dir / "20261121-100000-rig-step.csv.gz")
    runs = json.loads(servodesk("list", "--json", data_dir=data_dir).stdout)
    assert runs[2]["stem"] == "20261119-100000-rig-step"
    assert "not a regular file but a named pipe (FIFO)" in runs[2]["problem"]
    for run, fifo in (("latest", "20261121-100000-rig-step.csv.gz"),
                      ("20261119-100000-rig-step", "20261119-100000-rig-step.json")):
        done = servodesk("show", run, data_dir=data_dir)
        assert done.returncode == 2 and done.stderr.count("\n") == 1, done.stderr
        assert f"{fifo}: not a regular file but a named pipe (FIFO)" in done.stderr
