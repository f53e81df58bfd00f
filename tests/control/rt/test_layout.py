"""The shared-memory records round-trip exactly."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from control.rt.layout import (
    HIST_BINS,
    CoefficientLayout,
    ControlLayout,
    LatencyHistogram,
    MoveLayout,
)
from hw.machine import load_machine


@pytest.mark.parametrize("name", ["unimate2000b", "rig"])
def test_every_coefficient_set_round_trips(name: str) -> None:
    machine = load_machine(name)
    layout = CoefficientLayout(machine.n_joints)
    for c in machine.coefficients.values():
        packed = layout.struct.pack(*layout.encode(c))
        back = layout.decode(layout.struct.unpack(packed), c.name)
        assert (back.kp, back.w, back.ki, back.kd) == (c.kp, c.w, c.ki, c.kd)
        assert (back.filter, back.filter_divisor, back.integral_limit, back.duty_limit) == (
            c.filter, c.filter_divisor, c.integral_limit, c.duty_limit)


def test_feed_forward_gains_round_trip() -> None:
    machine = load_machine("unimate2000b")
    layout = CoefficientLayout(6)
    c = replace(machine.track, kv=(0.25, 1.0, 2.0, 0.5, 0.5, 0.4))
    back = layout.decode(layout.struct.unpack(layout.struct.pack(*layout.encode(c))), "track")
    assert back.kv == c.kv


def test_too_many_taps_is_a_clear_error() -> None:
    machine = load_machine("rig")
    c = machine.track
    long = type(c)(**{**c.__dict__, "kp": ((1.0,) * 9,)})
    with pytest.raises(ValueError, match=r"kp\[0\] has 9 taps; at most 8 fit"):
        CoefficientLayout(1).encode(long)


def test_status_decodes_what_was_packed() -> None:
    layout = ControlLayout(6).status
    values = [7, 2_000_000_000, 123, 1, 4 | 64 | 256 | 512, 3, 10, 100, 5000, 9000, 2, 1500,
              4000, 10**9, 5 * 10**8, 0.5, 0.25, 6.4]
    values += [float(i) for i in range(24)] + [0.25, math.nan, 0.5, 0.0, 1.0, 2.0]
    values += [*range(6), 0, 1, 0, 2, 0, 0, *range(8)]
    values += [b"link lost"]
    status = layout.decode(layout.struct.unpack(layout.struct.pack(*values)))
    assert status.tick == 7 and status.time_s == 2.0 and status.homed and status.moving
    assert status.paused and (status.feed_override, status.feed_rate) == (0.5, 0.25)
    assert status.supply_mpa == 6.4
    assert status.position == (0.0, 1.0, 2.0, 3.0, 4.0, 5.0)
    assert status.valve == (18.0, 19.0, 20.0, 21.0, 22.0, 23.0)
    assert status.settling and status.settle_s[0] == 0.25 and math.isnan(status.settle_s[1])
    assert status.glitches == (0, 1, 0, 2, 0, 0)
    assert status.link["crc_errors"] == 2 and status.fault == "link lost"
    assert status.late_last_us == 5.0 and status.compute_max_us == 4.0
    assert status.compute_total_s == 1.0 and status.io_total_s == 0.5


def test_move_layout_sizes_follow_the_move() -> None:
    small, big = MoveLayout(250, 6), MoveLayout(20_000, 6)
    record = 8 * (1 + 3 * 6)  # a row: t, desired, actual, duty
    assert big.size - small.size == record * (20_000 - 250)  # the rest is fixed
    assert big.size - big.record_offset == record * 20_000


def test_a_move_segment_has_room_for_its_settle_after_the_path() -> None:
    """Issue 24: the record holds the path's rows, then the settle's; the header says how
    many of each, so whoever saves the run reads both."""
    layout = MoveLayout(250, 6, meta_size=12, settle_rows=2002)
    assert layout.size - MoveLayout(250, 6, meta_size=12).size == 8 * (1 + 3 * 6) * 2002
    buf = memoryview(bytearray(layout.size))
    layout.write_header(buf)
    read = MoveLayout.read_header(buf)
    assert (read.samples, read.settle_rows, read.rows, read.meta_size) == (250, 2002, 2252, 12)
    assert read.record(buf).shape == (2252, 19)


def test_a_timeline_written_after_the_loop_reads_back_and_none_is_none() -> None:
    layout = MoveLayout(10, 6, meta_size=12)
    buf = memoryview(bytearray(layout.size))
    assert layout.read_timeline(buf) is None
    timeline = {"gaps": [[1.5, 0.2]], "feed": [[0.0, 0.5]], "pauses": [], "supply": []}
    layout.write_timeline(buf, timeline)
    assert layout.read_timeline(buf) == timeline
    with pytest.raises(ValueError, match="does not fit"):
        layout.write_timeline(buf, {"supply": [[0.0, 1.0]] * 100_000})


def test_histogram_percentiles_and_rows() -> None:
    values = np.zeros(HIST_BINS + 5, np.int64)
    values[2] = 90  # 10-15 µs
    values[3] = 9  # 15-20 µs
    values[10] = 1  # 50-55 µs
    values[HIST_BINS + 1:] = [11_500, 54_000, 100 * 14_000, 100]
    h = LatencyHistogram.from_counters(values, overruns=0)
    assert h.percentile(50) == 15.0 and h.percentile(99) == 20.0 and h.percentile(100) == 55.0
    assert (h.min_us, h.max_us, h.mean_us) == (11.5, 54.0, 14.0)
    rows = h.rows(up_to_us=20)
    assert rows[2] == (10.0, 15.0, 90) and rows[-1] == (20.0, float("inf"), 1)
