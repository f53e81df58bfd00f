"""Reading path and pose files (and saved runs' tables, ``control/recorder.py``): the text,
bounded before it is parsed, and numbers whose errors name the line.

A file is read in chunks and refused as soon as it holds more lines or bytes than its
``FileBound`` allows, so neither the time nor the memory spent on a huge file grows with
it: a move file's bound is one line per sample of the longest move allowed (and a
header), at ``BYTES_PER_ROW`` bytes a line (``move_file_bound``). A file whose name ends
in ``.gz`` (a saved run's ``.csv.gz``) is read through gzip, and the bound holds for what
it unpacks to: a small file that unpacks to a huge one is stopped at the bound too. Only a
regular file is read (a named pipe or a device is refused at once, ``hw.user_files``), as
UTF-8 with or without a byte-order mark.
"""

from __future__ import annotations

import csv
import gzip
import math
import os
import zlib
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import BinaryIO

from hw.user_files import TEXT_ENCODING, NotRegularFile, open_regular

# Generous: a saved run's CSV row, 19 numbers written in full (-1.2345678901234567), is < 480.
BYTES_PER_ROW = 512
CHUNK_BYTES = 1 << 20
# Where str.splitlines ends a line, in UTF-8 (the parsers number lines as it does); "\r\n"
# is one end. None of these bytes occurs inside another character's UTF-8 encoding.
LINE_ENDS = tuple(c.encode() for c in "\n\r\x0b\x0c\x1c\x1d\x1e\x85\u2028\u2029")


@dataclass(frozen=True)
class FileBound:
    """The most ``what`` (a path file) may hold, checked as it is read, before it is parsed:
    ``lines`` lines (counted as ``str.splitlines`` counts them) and ``size`` bytes. ``why``
    says what the bound follows from and ``fix`` what to do with a file past it."""

    what: str
    lines: int
    size: int
    why: str
    fix: str


def move_file_bound(what: str, sample_time_s: float, longest_s: float, fix: str) -> FileBound:
    """The bound of a file of points for one move: one line per sample of the longest move
    (``longest_s`` at ``sample_time_s``, both ends included) and a header line,
    ``BYTES_PER_ROW`` bytes each."""
    lines = math.floor(longest_s / sample_time_s + 1e-9) + 2
    return FileBound(what, lines, lines * BYTES_PER_ROW,
                     f"one point per {sample_time_s * 1e3:g} ms sample of the longest move "
                     f"allowed, {longest_s:g} s, and a header, at {BYTES_PER_ROW} bytes a line",
                     fix)


def read_text_file(path: str | Path, bound: FileBound,
                   error: type[ValueError] = ValueError) -> tuple[Path, str]:
    """``(path, text)`` of a UTF-8 file within ``bound``; ``error`` names the file if it
    cannot be read or is past the bound (how far, the bound and why)."""
    path = Path(path).expanduser()
    try:
        with open_regular(path) as raw, (gzip.GzipFile(fileobj=raw) if gzipped(path)
                                         else raw) as file:
            # packed, its size on disk says nothing of its text's (a gzip's header is 20 bytes)
            size = 0 if gzipped(path) else os.fstat(raw.fileno()).st_size
            data = _read_bounded(file, size, bound, path, error)
    except NotRegularFile as exc:
        raise error(f"{path}: {exc.strerror}: give {bound.what}") from None
    except (OSError, EOFError, zlib.error) as exc:  # gzip: not one, cut short, damaged
        raise error(f"{path}: cannot read: {getattr(exc, 'strerror', None) or exc}") from None
    try:
        return path, data.decode(TEXT_ENCODING)
    except UnicodeDecodeError:
        raise error(f"{path}: not a text file") from None


def gzipped(path: Path) -> bool:
    return path.suffix.lower() == ".gz"


def format_suffix(path: Path) -> str:
    """The suffix that names a file's format, under any ``.gz``: ``.csv`` for ``x.csv.gz``."""
    return (path.with_suffix("") if gzipped(path) else path).suffix.lower()


def _read_bounded(file: BinaryIO, size: int, bound: FileBound, path: Path,
                  error: type[ValueError]) -> bytearray:
    """The bytes of ``file``, read a chunk at a time; ``error`` as soon as they pass
    ``bound`` (at once when its ``size``, if known, is already past it)."""
    if size > bound.size:
        raise error(_past(path, _bytes(size), bound))
    data, ends, counted = bytearray(), 0, 0
    while chunk := file.read(CHUNK_BYTES):
        data += chunk
        if len(data) > bound.size:
            raise error(_past(path, f"more than {_bytes(bound.size)}", bound))
        cut = _safe_cut(data, max(counted, len(data) - len(chunk)))
        if cut > counted:
            ends += _line_ends(data, counted, cut)
            counted = cut
        if ends > bound.lines:
            raise error(_past(path, f"at least {ends:,} lines{_so_far(len(data), size)}", bound))
    lines = ends + _line_ends(data, counted, len(data)) + (not data.endswith(LINE_ENDS))
    if data and lines > bound.lines:
        raise error(_past(path, f"{lines:,} lines", bound))
    return data


def _safe_cut(data: bytearray, start: int) -> int:
    """Where to stop counting line ends in ``data`` so that none runs across the cut: after
    its last ``"\\n"``, or after a last ``"\\r"`` that is not its last byte (0: no such place
    after ``start``). The other line ends are one byte, or bytes ≥ 0x80 that no ASCII byte
    can split."""
    return max(data.rfind(b"\n", start) + 1, data.rfind(b"\r", start, len(data) - 1) + 1)


def _line_ends(data: bytearray, start: int, end: int) -> int:
    """How many lines end in ``data[start:end]`` (``"\\r\\n"`` ends one)."""
    return (sum(data.count(e, start, end) for e in LINE_ENDS)
            - data.count(b"\r\n", start, end))


def _past(path: Path, found: str, bound: FileBound) -> str:
    return (f"{path}: {found}; {bound.what} may hold at most {bound.lines:,} lines and "
            f"{_bytes(bound.size)} ({bound.why}): {bound.fix}")


def _bytes(n: int) -> str:
    return f"{n:,} bytes" if n < 10**6 else f"{n / 1e6:.1f} MB"


def _so_far(read: int, size: int) -> str:
    """Where reading stopped, when that was before the end of the file."""
    return f" in its first {_bytes(read)} of {_bytes(size)}" if read < size else ""


def csv_lines(text: str, source: str,
              error: type[ValueError] = ValueError) -> Iterator[tuple[int, list[str]]]:
    """``(line number, fields)`` of each CSV line that holds something: blank lines, lines of
    empty fields and ``#`` comments are skipped; a line csv cannot split (a stray carriage
    return inside a field, a field past csv's size limit) raises ``error`` naming it. Lines
    are counted as ``str.splitlines`` counts them, like the TSV reader's."""
    reader = csv.reader(text.splitlines())
    while True:
        try:
            row = next(reader)
        except StopIteration:
            return
        except csv.Error as exc:
            raise error(f"{source}: line {reader.line_num}: {exc}") from None
        if any(c.strip() for c in row) and not row[0].lstrip().startswith("#"):
            yield reader.line_num, row


def field_number(text: str, source: str, line: int, field: int,
                 error: type[ValueError] = ValueError) -> float:
    """The finite number in field ``field`` of line ``line`` of ``source``, else ``error``."""
    try:
        value = float(text.strip())
    except ValueError:
        raise error(f"{source}: line {line}: field {field} {text.strip()!r} is not a "
                    "number") from None
    if not math.isfinite(value):
        raise error(f"{source}: line {line}: field {field} is {value}, not a finite number")
    return value
