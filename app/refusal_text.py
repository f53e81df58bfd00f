"""What a refused command means for the operator at the TUI: the client's errors name API
calls (``set_coefficients(..., override=...)``) that no key of the TUI makes."""

from __future__ import annotations


def in_tui_words(exc: BaseException) -> str:
    """``exc``'s message, with a refused gain set's advice in terms of the TUI's tabs."""
    problems = getattr(exc, "problems", ())  # control.identify.gains.GainError (scipy: not here)
    if not problems:
        return str(exc)
    return (f"the gain check refused the set, nothing applied: {'; '.join(problems)}. Lower "
            "that joint's kp or ki in the table (or fix its sign) and apply again, or identify "
            "the joint (Identify tab, F8) and apply the gains it proposes there")
