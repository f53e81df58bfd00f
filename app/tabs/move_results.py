"""The Moves tab's result table: how a finished move went, by its kind
(``control.motion.plan.summaries``). A step's response (step and overshoot, rise,
settling, steady error), a smooth path's tracking error (travel, RMS and max error, when,
at the end), a sine's fundamentals (amplitude, ratio, phase lag); one row per joint the
move moved. Units follow the numbers; the columns are short, so the table fits the
narrowest screen (80 columns)."""

from __future__ import annotations

import math

from control.motion.moves import SineSummary, StepSummary, TrackingSummary
from control.motion.plan import Summary

COLUMNS = {
    "step": ("joint", "step", "overshoot", "rise s", "settle s", "steady e", "max |e|"),
    "tracking": ("joint", "travel", "RMS e", "max |e|", "at s", "end e"),
    "sine": ("joint", "amplitude", "ratio", "lag °", "period s", "RMS e", "max |e|"),
}


def columns(rows: list[tuple[str, Summary]]) -> tuple[str, ...]:
    """The table's columns for these rows (a step's when there are none)."""
    return COLUMNS[rows[0][1].METRIC] if rows else COLUMNS["step"]


def cells(label: str, s: Summary) -> tuple[str, ...]:
    """One row of the table, as ``columns`` names them."""
    u = _unit(s.unit)
    if isinstance(s, StepSummary):
        return (label, f"{s.step:+.2f}{u}", f"{s.overshoot:.2f}{u} {s.overshoot_pct:.0f}%",
                _number(s.rise_time_s, ".3f"), _number(s.settling_time_s, ".3f"),
                _number(s.steady_state_error, "+.3f", u), _number(s.max_abs_error, ".3f", u))
    if isinstance(s, TrackingSummary):
        return (label, _number(s.travel, ".2f", u), _number(s.rms_error, ".3f", u),
                _number(s.max_abs_error, ".3f", u), _number(s.max_error_time_s, ".2f"),
                _number(s.final_error, "+.3f", u))
    assert isinstance(s, SineSummary)
    return (label, _number(s.amplitude, ".2f", u), _number(s.amplitude_ratio, ".3f"),
            _number(s.phase_lag_deg, "+.1f"), _number(s.period_s, ".2f"),
            _number(s.rms_error, ".3f", u), _number(s.max_abs_error, ".3f", u))


def _unit(unit: str) -> str:
    return "°" if unit == "deg" else f" {unit}"


def _number(value: float | None, spec: str, unit: str = "") -> str:
    return "–" if value is None or not math.isfinite(value) else f"{value:{spec}}{unit}"
