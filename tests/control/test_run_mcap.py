"""A run as MCAP: every sample of every joint on its channel at its time, NaN as null, the
stalls, feed changes and end on /events, the gains once, the run's metadata; read back with
the mcap package's own reader. The numbers are those of the run's own tables, at their precision."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader

from control.recorder import Run, as_written
from control.run_mcap import read_mcap, write_mcap
from hw.machine import load_machine

UNIMATE = load_machine("unimate2000b")


def six_joint_run(samples: int = 1500) -> Run:
    rng = np.random.default_rng(3)
    t = np.arange(samples) * UNIMATE.sample_time_s
    desired = rng.normal(size=(samples, 6)) * 10.0
    actual = desired + rng.normal(size=(samples, 6))
    desired[:5, 2] = np.nan  # open loop for a while
    duty = rng.uniform(-100, 100, size=(samples, 6))
    return Run.from_machine(UNIMATE, "path", "complete", UNIMATE.track, t, desired, actual,
                            duty, start_time="2026-11-25T01:00:00.250000+00:00",
                            meta={"gaps": [[0.5, 0.06]], "feed": [[0.2, 0.5]],
                                  "pauses": [[0.9, 0.3]], "backend": "sim"})


def test_every_sample_reads_back_on_its_channel_at_its_time(tmp_path: Path) -> None:
    run = six_joint_run()
    path = write_mcap(run, tmp_path / "run.mcap")
    record, topics = read_mcap(path)
    start_ns = 1_795_568_400_250_000_000  # 2026-11-25T01:00:00.25Z
    assert record["machine"] == "unimate2000b" and record["kind"] == "path"
    assert record["meta"]["backend"] == "sim"
    assert record["joints"] == [[n, u] for n, u in zip(run.joint_names, run.joint_units,
                                                         strict=True)]
    written = as_written(run)  # every number at the precision of the run's own tables
    for topic, values in (("/joints/desired", written.desired),
                          ("/joints/actual", written.actual), ("/joints/duty", written.duty)):
        messages = topics[topic]
        assert len(messages) == run.samples
        stamps = np.array([stamp for stamp, _ in messages])
        np.testing.assert_array_equal(stamps - stamps[0], np.round(run.t * 1e9).astype(int))
        assert stamps[0] == start_ns
        back = np.array([[np.nan if m[name] is None else m[name] for name in run.joint_names]
                         for _, m in messages])
        np.testing.assert_array_equal(back, values)  # as written, NaN where it was NaN
    (_, gains), = topics["/gains"]
    assert gains == json.loads(json.dumps(run.coefficients)) and gains["kp"]
    events = [(e["kind"], e["t_s"]) for _, e in topics["/events"]]
    assert events == [("feed", 0.2), ("stall", 0.5), ("feed hold", 0.9),
                      ("end", pytest.approx(run.t[-1]))]
    assert topics["/events"][-1][1]["text"] == "complete"


def test_a_failed_write_leaves_no_file(tmp_path: Path) -> None:
    run = six_joint_run(10)
    target = tmp_path / "missing" / "run.mcap"
    with pytest.raises(OSError):
        write_mcap(run, target)
    assert not target.exists() and not list(tmp_path.rglob("*.tmp"))


def test_its_numbers_carry_no_more_digits_than_the_runs_tables(tmp_path: Path) -> None:
    """Each message's text, as Foxglove reads it: desired to its joint's max_accel decimals
    (6 for In/Out, 7 for the angles), actual to a tenth of an encoder count, duty to 0.01 %;
    the float noise of 1508.4405000000002 is gone."""
    run = six_joint_run(300)
    run = Run.from_machine(UNIMATE, "path", "complete", UNIMATE.track, run.t,
                           run.desired + 1508.4405000000002, run.actual, run.duty / 3)
    path = write_mcap(run, tmp_path / "run.mcap")
    most: dict[str, np.ndarray] = {}
    with path.open("rb") as stream:
        for _, channel, message in make_reader(stream).iter_messages():
            if channel.topic in ("/joints/desired", "/joints/actual", "/joints/duty"):
                values = re.findall(r": (-?[\d.]+|null)", message.data.decode())
                places = np.array([len(v.partition(".")[2]) for v in values])
                most[channel.topic] = np.maximum(most.get(channel.topic, places), places)
    assert most["/joints/desired"].tolist() == [6, 7, 7, 7, 7, 7]
    assert most["/joints/actual"].tolist() == [2, 3, 3, 3, 3, 3]
    assert most["/joints/duty"].tolist() == [2] * 6
