"""Path files are bounded before they are parsed: a line per sample of the longest move."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from control.motion.path_files import MAX_MOVE_S, PathFileError, path_file_bound, read_path
from hw.machine import load_machine

UNIMATE = load_machine("unimate2000b")
HOLD = (1500.0, 0.0, 0.0, 0.0, 0.0, 0.0)
ROW = "0.5\t1500\t0\t0\t0\t0\t0\n"


def test_the_bound_is_a_line_per_sample_of_the_longest_move_and_a_header() -> None:
    bound = path_file_bound(UNIMATE)
    samples = round(MAX_MOVE_S / UNIMATE.sample_time_s) + 1
    assert (bound.lines, bound.size) == (samples + 1, (samples + 1) * 512)


def test_a_path_file_one_line_past_its_bound_is_refused_with_the_reason(tmp_path: Path) -> None:
    path = tmp_path / "long.tsv"
    path.write_text(ROW * (path_file_bound(UNIMATE).lines + 1))
    message = (f"{path}: at least 600,003 lines; a path file may hold at most 600,002 lines "
               "and 307.2 MB (one point per 1 ms sample of the longest move allowed, 600 s, "
               "and a header, at 512 bytes a line): split it into moves of at most 600 s, or "
               "thin its points")
    with pytest.raises(PathFileError, match=f"^{re.escape(message)}$"):
        read_path(path, UNIMATE, HOLD)


def test_a_path_file_far_past_its_bound_is_refused_where_reading_passes_it(
        tmp_path: Path) -> None:
    """Three times the lines allowed: reading stops at the bound, a third of the way in."""
    path = tmp_path / "dense.tsv"
    path.write_text(ROW * 1_800_000)
    try:
        with pytest.raises(PathFileError, match=r"dense\.tsv: at least 6\d\d,\d\d\d lines in "
                                                r"its first 1\d\.\d MB of 34\.2 MB; a path file"):
            read_path(path, UNIMATE, HOLD)
    finally:
        path.unlink()  # pytest keeps the last runs' temporary directories


def test_a_path_file_at_its_bound_loads(tmp_path: Path) -> None:
    """The longest move allowed, a point per sample, under a header: 600,002 lines."""
    path = tmp_path / "longest.csv"
    path.write_text("inout\n" + "1500\n" * (path_file_bound(UNIMATE).lines - 1))
    points = read_path(path, UNIMATE, HOLD)
    assert len(points.t) == 600_001 and points.duration == pytest.approx(MAX_MOVE_S)
