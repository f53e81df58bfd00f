"""Latency statistics of the loop: wake-up lateness histogram (Table 2.1), compute, overruns."""

from __future__ import annotations

from control.rt.layout import HIST_BIN_NS, HIST_BINS


class LatencyStats:
    """Tallies kept in the process (shared memory costs per access); the histogram and its
    min/max/sum/count cells are written to shared memory for the client."""

    def __init__(self, hist: memoryview, period_ns: int, overrun_fraction: float) -> None:
        self.hist = hist  # HIST_BINS + 1 bins, then min, max, sum, count (int64)
        self.period_ns = period_ns
        self.overrun_fraction = overrun_fraction
        self.window_start_ns = 0  # the current one-second window of the overload watch
        self.window_ticks = 0  # ticks in it, and how many of them ended past their deadline
        self.window_late = 0
        self.late_ns = 0
        self.late_max_ns = 0
        self.late_min_ns = -1  # none yet
        self.late_sum_ns = 0
        self.late_count = 0
        self.overruns = 0
        self.compute_ns = 0
        self.compute_max_ns = 0
        self.compute_total_ns = 0
        self.io_total_ns = 0  # time inside backend.read/write, part of compute

    def woke(self, late: int) -> None:
        """Tally a wake-up ``late`` ns after its deadline."""
        late = max(0, late)
        self.late_ns = late
        hist = self.hist
        hist[min(late // HIST_BIN_NS, HIST_BINS)] += 1
        base = HIST_BINS + 1
        if late < self.late_min_ns or self.late_min_ns < 0:
            self.late_min_ns = hist[base] = late
        if late > self.late_max_ns:
            self.late_max_ns = hist[base + 1] = late
        self.late_sum_ns += late
        self.late_count += 1
        hist[base + 2] = self.late_sum_ns
        hist[base + 3] = self.late_count

    def computed(self, ns: int) -> None:
        self.compute_ns = ns
        if ns > self.compute_max_ns:
            self.compute_max_ns = ns
        self.compute_total_ns += ns

    def next_deadline(self, deadline: int, now: int) -> int:
        """The next grid point after ``deadline``; one already past is an overrun, skipped."""
        period = self.period_ns
        deadline += period
        behind = now - deadline
        self.window_ticks += 1
        if behind > 0:
            missed = behind // period + 1
            self.overruns += missed
            self.window_late += 1
            deadline += missed * period
        return deadline

    def overloaded(self, now: int) -> float:
        """Once a second: the fraction of that second's ticks that overran if it is more than
        ``overrun_fraction`` (a board flooding the link, a starved CPU), else 0. One long
        stall is one late tick: the move goes on, and the stall is listed in its run."""
        if now - self.window_start_ns < 1_000_000_000:
            return 0.0
        fraction = self.window_late / self.window_ticks if self.window_ticks else 0.0
        self.window_start_ns, self.window_ticks, self.window_late = now, 0, 0
        return fraction if fraction > self.overrun_fraction else 0.0
