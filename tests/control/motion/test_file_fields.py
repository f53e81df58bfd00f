"""Reading path and pose files within a bound on their lines and bytes, before they are parsed."""

from __future__ import annotations

import gzip
import os
import re
from pathlib import Path

import pytest

from control.motion import file_fields
from control.motion.file_fields import FileBound, move_file_bound, read_text_file

BOUND = FileBound("a test file", 4, 40, "the test's why", "the test's fix")


def write(tmp_path: Path, data: bytes | str) -> Path:
    path = tmp_path / "f.txt"
    path.write_bytes(data.encode() if isinstance(data, str) else data)
    return path


def test_a_file_at_its_bound_is_read_whole(tmp_path: Path) -> None:
    text = "header\n1\n2\n" + "3" * 28 + "\n"  # 4 lines, 40 bytes
    assert read_text_file(write(tmp_path, text), BOUND) == (tmp_path / "f.txt", text)


@pytest.mark.parametrize(("text", "found"), [
    ("h\n1\n2\n3\n4", "5 lines"),
    ("h\n1\n2\n3\n\n", "at least 5 lines"),
    ("h\r\n1\r2\x0c3\u20284", "5 lines"),
    ("h\n" + "1" * 39, "41 bytes"),
])
def test_one_line_or_byte_past_the_bound_is_refused_naming_both(tmp_path: Path, text: str,
                                                                found: str) -> None:
    path = write(tmp_path, text)
    message = (f"{path}: {found}; a test file may hold at most 4 lines and 40 bytes "
               "(the test's why): the test's fix")
    with pytest.raises(ValueError, match=f"^{re.escape(message)}$"):
        read_text_file(path, BOUND)


def test_line_ends_split_between_two_reads_are_counted_once(tmp_path: Path,
                                                            monkeypatch: pytest.MonkeyPatch
                                                            ) -> None:
    """Read three bytes at a time, "\\r\\n" and the three bytes of "\\u2028" fall across reads:
    still the lines ``str.splitlines`` finds, no more."""
    monkeypatch.setattr(file_fields, "CHUNK_BYTES", 3)
    text = "ab\r\ncd\r\nx\u2028y\u2028\r\rz"
    assert len(text.splitlines()) == 7
    path = write(tmp_path, text)
    assert read_text_file(path, FileBound("f", 7, 100, "", ""))[1] == text
    with pytest.raises(ValueError, match=": 7 lines; f may hold at most 6 lines"):
        read_text_file(path, FileBound("f", 6, 100, "", ""))


def test_a_file_bigger_than_its_bound_is_refused_before_it_is_read(tmp_path: Path) -> None:
    """A 2 GB file (sparse: nothing is written) is refused from its size, at once."""
    path = tmp_path / "huge.tsv"
    with path.open("wb") as file:
        file.truncate(2 * 10**9)
    with pytest.raises(ValueError, match=r"huge\.tsv: 2000\.0 MB; a test file may hold at most "
                                         r"4 lines and 40 bytes"):
        read_text_file(path, BOUND)


@pytest.mark.timeout(20)  # a FIFO opened for reading waits for a writer: for ever
def test_a_fifo_a_device_or_a_directory_is_refused_at_once_naming_what_it_is(
        tmp_path: Path) -> None:
    """Only a regular file is read: a named pipe (that no one writes to), /dev/zero (it never
    ends) and a directory are each refused before anything is read, in one line that names
    the file, what it is and what to give instead."""
    fifo = tmp_path / "path.tsv"
    os.mkfifo(fifo)
    for path, kind in ((fifo, "a named pipe (FIFO)"), (Path("/dev/zero"), "a character device"),
                       (tmp_path, "a directory")):
        message = f"{path}: not a regular file but {kind}: give a test file"
        with pytest.raises(ValueError, match=f"^{re.escape(message)}$"):
            read_text_file(path, BOUND)


def test_a_byte_order_mark_is_no_part_of_the_text(tmp_path: Path) -> None:
    """A file saved by a Windows editor (or Excel's CSV UTF-8) starts with a byte-order mark:
    the text is what follows it, so a CSV's first column is still ``t``."""
    path = write(tmp_path, b"\xef\xbb\xbft,inout\n0,1500\n")
    assert read_text_file(path, BOUND)[1] == "t,inout\n0,1500\n"


def test_a_dense_file_is_refused_where_it_passes_the_bound(tmp_path: Path) -> None:
    """Two million short lines: refused when the lines read pass the bound, near the start."""
    path = write(tmp_path, "1\n" * 2_000_000)
    with pytest.raises(ValueError, match=r": at least 1,048,576 lines in its first 2\.1 MB of "
                                         r"4\.0 MB; a test file may hold at most 600,000 lines"):
        read_text_file(path, FileBound("a test file", 600_000, 10**9, "why", "fix"))


def test_a_move_files_bound_is_a_line_per_sample_of_the_longest_move_and_a_header() -> None:
    bound = move_file_bound("a path file", 0.001, 600.0, "split it")
    assert (bound.lines, bound.size) == (600_002, 600_002 * file_fields.BYTES_PER_ROW)
    assert bound.why == ("one point per 1 ms sample of the longest move allowed, 600 s, and a "
                         "header, at 512 bytes a line")
    assert move_file_bound("f", 0.01, 600.0, "").lines == 60_002


def test_a_file_that_cannot_be_read_or_is_not_text_names_itself(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match=r"missing\.csv: cannot read: No such file"):
        read_text_file(tmp_path / "missing.csv", BOUND)
    with pytest.raises(ValueError, match=r"f\.txt: not a text file"):
        read_text_file(write(tmp_path, b"\xff\xfe1\n"), BOUND)


def test_a_gzipped_file_is_read_through_gzip_and_bounded_by_what_it_unpacks_to(
        tmp_path: Path) -> None:
    """A saved run's ``.csv.gz`` plays again as a path file: read as its text. The bound holds
    for the text: 100 MB of zeros packed into 100 kB is stopped a chunk past the bound, and a
    packed file cut short or not gzip at all is refused naming the file."""
    text = "header\n1\n2\n3\n"
    packed = tmp_path / "run.csv.gz"
    packed.write_bytes(gzip.compress(text.encode()))
    assert read_text_file(packed, BOUND) == (packed, text)
    assert file_fields.format_suffix(packed) == ".csv"
    bomb = tmp_path / "bomb.tsv.gz"
    # a hundred 1 MB members, one stream to gzip: packing 100 MB whole took 0.3-0.6 s
    bomb.write_bytes(gzip.compress(bytes(10**6)) * 100)
    assert bomb.stat().st_size < 200_000
    megabyte = FileBound("a test file", 10, 10**6, "why", "fix")
    with pytest.raises(ValueError, match=r"bomb\.tsv\.gz: more than 1\.0 MB; a test file"):
        read_text_file(bomb, megabyte)
    cut = tmp_path / "cut.csv.gz"
    cut.write_bytes(packed.read_bytes()[:-12])
    with pytest.raises(ValueError, match=r"cut\.csv\.gz: cannot read: Compressed file ended"):
        read_text_file(cut, BOUND)
    plain = tmp_path / "plain.csv.gz"
    plain.write_text(text)
    with pytest.raises(ValueError, match=r"plain\.csv\.gz: cannot read: Not a gzipped file"):
        read_text_file(plain, BOUND)
