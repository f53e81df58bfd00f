"""Numbers read from a line of a path or pose file, with errors that name the line."""

from __future__ import annotations

import math


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
