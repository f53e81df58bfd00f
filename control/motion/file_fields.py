"""Reading path and pose files: the text, and numbers whose errors name the line."""

from __future__ import annotations

import csv
import math
from collections.abc import Iterator
from pathlib import Path


def read_text_file(path: str | Path, error: type[ValueError] = ValueError) -> tuple[Path, str]:
    """``(path, text)`` of a UTF-8 file; ``error`` names the file if it cannot be read."""
    path = Path(path).expanduser()
    try:
        return path, path.read_text(encoding="utf-8")
    except OSError as exc:
        raise error(f"{path}: cannot read: {exc.strerror or exc}") from None
    except UnicodeDecodeError:
        raise error(f"{path}: not a text file") from None


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
